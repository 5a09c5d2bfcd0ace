#include "core/bow/bow_vector.h"

#include <cmath>

#include <gtest/gtest.h>

namespace recog {
namespace {

TEST(BowVectorTest, ConstructionSortsAndMergesRepeatedWords) {
  BowVector v({{7, 1.f}, {2, 0.5f}, {7, 2.f}});
  ASSERT_EQ(v.size(), 2u);
  EXPECT_EQ(v.entries()[0].word, 2u);
  EXPECT_EQ(v.entries()[1].word, 7u);
  EXPECT_FLOAT_EQ(v.entries()[1].value, 3.f);
  EXPECT_FLOAT_EQ(v.ValueOf(7), 3.f);
  EXPECT_FLOAT_EQ(v.ValueOf(3), 0.f);
}

TEST(BowVectorTest, L1NormalisationMakesValuesSumToOne) {
  BowVector v({{1, 1.f}, {2, 3.f}});
  v.Normalize(BowNormalization::kL1);
  EXPECT_FLOAT_EQ(v.ValueOf(1), 0.25f);
  EXPECT_FLOAT_EQ(v.ValueOf(2), 0.75f);
}

TEST(BowVectorTest, L2NormalisationMakesUnitLength) {
  BowVector v({{1, 3.f}, {2, 4.f}});
  v.Normalize(BowNormalization::kL2);
  EXPECT_FLOAT_EQ(v.ValueOf(1), 0.6f);
  EXPECT_FLOAT_EQ(v.ValueOf(2), 0.8f);
}

TEST(BowVectorTest, NormalisingAnEmptyOrZeroVectorLeavesItUnchanged) {
  BowVector empty;
  empty.Normalize(BowNormalization::kL1);
  EXPECT_TRUE(empty.empty());
  BowVector zero({{4, 0.f}});
  zero.Normalize(BowNormalization::kL1);
  EXPECT_FLOAT_EQ(zero.ValueOf(4), 0.f);
  EXPECT_FALSE(std::isnan(zero.entries()[0].value));
}

}  // namespace
}  // namespace recog
