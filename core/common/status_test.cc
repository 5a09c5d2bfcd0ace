#include "core/common/status.h"

#include <string>

#include <gtest/gtest.h>

#include "core/common/names.h"

namespace recog {
namespace {

StatusOr<int> ParsePositive(int v) {
  if (v <= 0) return Status::InvalidArgument("not positive: " + std::to_string(v));
  return v;
}

Status Doubled(int v, int* out) {
  RECOG_ASSIGN_OR_RETURN(const int parsed, ParsePositive(v));
  *out = 2 * parsed;
  return Status::Ok();
}

TEST(StatusTest, DefaultIsOkAndPrintsOk) {
  Status s;
  EXPECT_TRUE(s.ok());
  EXPECT_EQ(s.ToString(), "OK");
}

TEST(StatusTest, ErrorCarriesCodeAndMessage) {
  Status s = Status::DataLoss("file x is truncated");
  EXPECT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_EQ(s.ToString(), "DATA_LOSS: file x is truncated");
}

TEST(StatusTest, AuthenticationCodesHaveTheirCanonicalNames) {
  EXPECT_EQ(Status::Unauthenticated("no token").ToString(), "UNAUTHENTICATED: no token");
  EXPECT_EQ(Status::PermissionDenied("read only").code(), StatusCode::kPermissionDenied);
  EXPECT_EQ(StatusCodeName(StatusCode::kPermissionDenied), "PERMISSION_DENIED");
}

TEST(StatusTest, StatusOrHoldsValueOrError) {
  StatusOr<int> good = ParsePositive(3);
  ASSERT_TRUE(good.ok());
  EXPECT_EQ(*good, 3);
  StatusOr<int> bad = ParsePositive(-1);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
}

TEST(StatusTest, AssignOrReturnPropagatesErrorsAndUnwrapsValues) {
  int out = 0;
  EXPECT_TRUE(Doubled(4, &out).ok());
  EXPECT_EQ(out, 8);
  Status s = Doubled(0, &out);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(out, 8);
}

TEST(StatusTest, WithContextPrefixesTheMessageAndKeepsOrReplacesTheCode) {
  const Status parse = Status::InvalidArgument("line 3: expected a number");
  const Status located = parse.WithContext("vocabulary 'a.txt'");
  EXPECT_EQ(located.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(located.message(), "vocabulary 'a.txt': line 3: expected a number");
  const Status stored = parse.WithContext("stored map 'm'", StatusCode::kDataLoss);
  EXPECT_EQ(stored.code(), StatusCode::kDataLoss);
  EXPECT_EQ(stored.message(), "stored map 'm': line 3: expected a number");
}

TEST(StatusTest, WithContextLeavesOkAlone) {
  EXPECT_TRUE(Status::Ok().WithContext("anything").ok());
  EXPECT_TRUE(Status::Ok().WithContext("anything", StatusCode::kDataLoss).ok());
  EXPECT_EQ(Status::Ok().WithContext("anything").message(), "");
}

TEST(NamesTest, AcceptsLettersDigitsDotsUnderscoresAndDashesUpTo128Characters) {
  EXPECT_TRUE(ValidateName("map", "corridor-2024_01.a").ok());
  EXPECT_TRUE(ValidateName("map", std::string(128, 'x')).ok());
}

TEST(NamesTest, RefusesEmptyLongAndOddNamesSayingWhatKindOfName) {
  const Status empty = ValidateName("map", "");
  EXPECT_EQ(empty.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(empty.message(), "map name must have 1 to 128 characters");
  EXPECT_EQ(ValidateName("object", std::string(129, 'x')).code(), StatusCode::kInvalidArgument);
  for (const char* bad : {"a b", "a/b", "caf\xc3\xa9", "a:b", "..\\x"}) {
    const Status status = ValidateName("object", bad);
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << bad;
    EXPECT_EQ(status.message(), "object name '" + std::string(bad) +
                                    "' may only use letters, digits, '.', '_' and '-'");
  }
}

}  // namespace
}  // namespace recog
