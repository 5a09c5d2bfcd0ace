#include "core/common/option_checks.h"

#include <cmath>
#include <cstdint>
#include <limits>

#include <gtest/gtest.h>

namespace recog {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

// A member struct as the checks expect one: a Validate that takes its path.
struct Inner {
  double share = 0.5;
  Status Validate(std::string_view name = "Inner") const {
    OptionChecks check(name);
    check.InRange("share", share, RealRange::Closed(0, 1));
    return check.status();
  }
};

TEST(RealRangeTest, EndsAreIncludedOrNotAndNonFiniteValuesAreNeverInside) {
  EXPECT_TRUE(RealRange::Closed(0, 1).Contains(0));
  EXPECT_TRUE(RealRange::Closed(0, 1).Contains(1));
  EXPECT_FALSE(RealRange::OpenClosed(0, 1).Contains(0));
  EXPECT_TRUE(RealRange::OpenClosed(0, 1).Contains(1));
  EXPECT_FALSE(RealRange::Open(0, 1).Contains(1));
  EXPECT_TRUE(RealRange::AtLeast(0).Contains(0));
  EXPECT_FALSE(RealRange::Above(0).Contains(0));
  EXPECT_TRUE(RealRange::Above(0).Contains(1e300));
  for (const RealRange& range : {RealRange::Closed(0, 1), RealRange::AtLeast(0),
                                 RealRange::Above(-kInf), RealRange::Closed(-kInf, kInf)}) {
    EXPECT_FALSE(range.Contains(kNan)) << range.Describe();
    EXPECT_FALSE(range.Contains(kInf)) << range.Describe();
    EXPECT_FALSE(range.Contains(-kInf)) << range.Describe();
  }
}

TEST(RealRangeTest, DescribesItselfAsTheMessagesShowIt) {
  EXPECT_EQ(RealRange::OpenClosed(0, 1).Describe(), "in (0, 1]");
  EXPECT_EQ(RealRange::Closed(0, 180).Describe(), "in [0, 180]");
  EXPECT_EQ(RealRange::Open(0, 0.5).Describe(), "in (0, 0.5)");
  EXPECT_EQ(RealRange::AtLeast(0).Describe(), "finite and >= 0");
  EXPECT_EQ(RealRange::Above(1).Describe(), "finite and > 1");
}

TEST(RealTextTest, GivesTheShortestTextOfAValue) {
  EXPECT_EQ(RealText(0.3), "0.3");
  EXPECT_EQ(RealText(1.0000001), "1.0000001");
  EXPECT_EQ(RealText(-2), "-2");
  EXPECT_EQ(RealText(kInf), "inf");
  EXPECT_EQ(RealText(-kInf), "-inf");
  EXPECT_NE(RealText(kNan).find("nan"), std::string::npos);
}

TEST(OptionChecksTest, PassingChecksLeaveTheStatusOk) {
  OptionChecks check("Options");
  check.InRange("ratio", 1.0, RealRange::OpenClosed(0, 1));
  check.InRange("count", 5, 1, 5);
  check.AtLeast("size", size_t(1), 1);
  check.Require(true, "pair", 3u, "<= other (3)");
  check.Member("inner", Inner{});
  EXPECT_TRUE(check.status().ok()) << check.status().ToString();
}

TEST(OptionChecksTest, AFailureNamesTheStructTheFieldTheValueAndTheRange) {
  OptionChecks real("RecognitionOptions");
  real.InRange("ratio", kNan, RealRange::OpenClosed(0, 1));
  EXPECT_EQ(real.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(real.status().message(), "RecognitionOptions.ratio = nan: must be in (0, 1]");

  OptionChecks infinite("LoopDetectorParams");
  infinite.InRange("alpha", kInf, RealRange::AtLeast(0));
  EXPECT_EQ(infinite.status().message(), "LoopDetectorParams.alpha = inf: must be finite and >= 0");

  OptionChecks range("RoiOptions");
  range.InRange("seeds", 0, 1, 2048);
  EXPECT_EQ(range.status().message(), "RoiOptions.seeds = 0: must be in [1, 2048]");

  OptionChecks at_least("GuidedMatchOptions");
  at_least.AtLeast("min_inliers", size_t(0), 1);
  EXPECT_EQ(at_least.status().message(), "GuidedMatchOptions.min_inliers = 0: must be >= 1");

  OptionChecks rule("LoopDetectorParams");
  rule.Require(false, "strong_temporal_matches", 4u, "<= temporal_matches (3)");
  EXPECT_EQ(rule.status().message(),
            "LoopDetectorParams.strong_temporal_matches = 4: must be <= temporal_matches (3)");
}

TEST(OptionChecksTest, TheFirstFailureIsReported) {
  OptionChecks check("Options");
  check.InRange("first", -1.0, RealRange::AtLeast(0));
  check.InRange("second", 0, 1, 2);
  check.AtLeast("third", int64_t(-5), 0);
  EXPECT_EQ(check.status().message(), "Options.first = -1: must be finite and >= 0");
}

TEST(OptionChecksTest, AMemberIsNamedByItsPathInTheOuterStruct) {
  Inner inner;
  inner.share = kInf;
  EXPECT_EQ(inner.Validate().message(), "Inner.share = inf: must be in [0, 1]");
  OptionChecks check("Outer");
  check.Member("inner", inner);
  EXPECT_EQ(check.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(check.status().message(), "Outer.inner.share = inf: must be in [0, 1]");
}

}  // namespace
}  // namespace recog
