#include "core/common/median.h"

#include <gtest/gtest.h>

namespace recog {
namespace {

TEST(MedianTest, TheMiddleValueOfAnOddCount) {
  EXPECT_EQ(Median({3, 1, 2}), 2.0);
  EXPECT_EQ(Median({7}), 7.0);
  EXPECT_EQ(Median({5, -1, 5, 9, 0}), 5.0);
}

TEST(MedianTest, TheMeanOfTheTwoMiddleValuesOfAnEvenCount) {
  EXPECT_EQ(Median({4, 1, 3, 2}), 2.5);
  EXPECT_EQ(Median({10, 0}), 5.0);
  EXPECT_EQ(Median({2, 2, 9, 1, 2, 8}), 2.0);
}

TEST(MedianTest, NoValuesGiveZero) { EXPECT_EQ(Median({}), 0.0); }

}  // namespace
}  // namespace recog
