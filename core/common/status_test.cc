#include "core/common/status.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace recog
