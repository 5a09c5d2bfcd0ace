#include "core/bow/scoring.h"

#include <cmath>
#include <map>
#include <random>

#include <gtest/gtest.h>

namespace recog {
namespace {

// Random sparse vector over `vocabulary` words with about `density` of them present.
BowVector RandomSparse(std::mt19937_64& rng, int vocabulary, double density, BowNormalization n) {
  std::bernoulli_distribution present(density);
  std::uniform_real_distribution<float> value(0.01f, 1.f);
  std::vector<BowEntry> entries;
  for (int w = 0; w < vocabulary; ++w) {
    if (present(rng)) entries.push_back({WordId(w), value(rng)});
  }
  BowVector v(std::move(entries));
  v.Normalize(n);
  return v;
}

// Dense copy, for the textbook formulas.
std::vector<double> Dense(const BowVector& v, int vocabulary) {
  std::vector<double> d(vocabulary, 0.0);
  for (const BowEntry& e : v.entries()) d[e.word] = e.value;
  return d;
}

// The definitions over all words, written independently of scoring.cc.
double DirectFormula(ScoringType type, const std::vector<double>& v, const std::vector<double>& w) {
  double sum = 0.0;
  switch (type) {
    case ScoringType::kL1:
      for (size_t i = 0; i < v.size(); ++i) sum += std::fabs(v[i] - w[i]);
      return 1.0 - 0.5 * sum;
    case ScoringType::kL2:
      for (size_t i = 0; i < v.size(); ++i) sum += (v[i] - w[i]) * (v[i] - w[i]);
      return 1.0 - std::sqrt(sum) / std::sqrt(2.0);
    case ScoringType::kChiSquare:
      for (size_t i = 0; i < v.size(); ++i) {
        if (v[i] + w[i] > 0) sum += (v[i] - w[i]) * (v[i] - w[i]) / (v[i] + w[i]);
      }
      return 1.0 - 0.5 * sum;
    case ScoringType::kKL:
      for (size_t i = 0; i < v.size(); ++i) {
        if (v[i] > 0) sum += v[i] * (std::log(v[i]) - (w[i] > 0 ? std::log(w[i]) : kKlLogEpsilon));
      }
      return sum;
    case ScoringType::kBhattacharyya:
      for (size_t i = 0; i < v.size(); ++i) sum += std::sqrt(v[i] * w[i]);
      return sum;
    case ScoringType::kDotProduct:
      for (size_t i = 0; i < v.size(); ++i) sum += v[i] * w[i];
      return sum;
  }
  return 0.0;
}

class ScoringFormulaTest : public ::testing::TestWithParam<ScoringType> {};

TEST_P(ScoringFormulaTest, CommonWordScoreEqualsTheFormulaOverAllWords) {
  const ScoringType type = GetParam();
  std::mt19937_64 rng(7);
  constexpr int kWords = 400;
  for (int trial = 0; trial < 50; ++trial) {
    const BowNormalization n = TraitsOf(type).normalization;
    const BowVector v = RandomSparse(rng, kWords, 0.1, n);
    const BowVector w = RandomSparse(rng, kWords, 0.1, n);
    const double expected = DirectFormula(type, Dense(v, kWords), Dense(w, kWords));
    EXPECT_NEAR(Score(type, v, w), expected, 1e-5 * std::max(1.0, std::fabs(expected)))
        << ScoringName(type) << " trial " << trial;
  }
}

// Scores with a fixed best and worst value (the dot product has neither).
class ScoringExtremesTest : public ::testing::TestWithParam<ScoringType> {};

TEST_P(ScoringExtremesTest, IdenticalVectorsScoreBestAndDisjointOnesWorst) {
  const ScoringType type = GetParam();
  const BowNormalization n = TraitsOf(type).normalization;
  BowVector v({{1, 0.2f}, {5, 0.3f}, {9, 0.5f}});
  BowVector w({{2, 0.5f}, {6, 0.5f}});
  v.Normalize(n);
  w.Normalize(n);
  if (TraitsOf(type).higher_is_better) {
    // L2 turns float rounding e of v.v into sqrt(e) (see scoring.h).
    const double tolerance = type == ScoringType::kL2 ? 1e-3 : 1e-6;
    EXPECT_NEAR(Score(type, v, v), 1.0, tolerance);
    EXPECT_NEAR(Score(type, v, w), 0.0, 1e-6);
  } else {
    EXPECT_NEAR(Score(type, v, v), 0.0, 1e-6);
    EXPECT_GT(Score(type, v, w), 10.0);
  }
}

INSTANTIATE_TEST_SUITE_P(AllScores, ScoringFormulaTest,
                         ::testing::Values(ScoringType::kL1, ScoringType::kL2,
                                           ScoringType::kChiSquare, ScoringType::kKL,
                                           ScoringType::kBhattacharyya, ScoringType::kDotProduct),
                         [](const auto& info) { return std::string(ScoringName(info.param)); });

INSTANTIATE_TEST_SUITE_P(BoundedScores, ScoringExtremesTest,
                         ::testing::Values(ScoringType::kL1, ScoringType::kL2,
                                           ScoringType::kChiSquare, ScoringType::kKL,
                                           ScoringType::kBhattacharyya),
                         [](const auto& info) { return std::string(ScoringName(info.param)); });

TEST(ScoringTest, BoundedScoresStayWithinZeroAndOne) {
  std::mt19937_64 rng(11);
  for (ScoringType type :
       {ScoringType::kL1, ScoringType::kL2, ScoringType::kChiSquare, ScoringType::kBhattacharyya}) {
    for (int trial = 0; trial < 100; ++trial) {
      const BowNormalization n = TraitsOf(type).normalization;
      const double s = Score(type, RandomSparse(rng, 100, 0.3, n), RandomSparse(rng, 100, 0.3, n));
      EXPECT_GE(s, -1e-9);
      EXPECT_LE(s, 1.0 + 1e-9);
    }
  }
}

TEST(ScoringTest, NamesRoundTripAndUnknownNamesAreRejected) {
  for (ScoringType type :
       {ScoringType::kL1, ScoringType::kL2, ScoringType::kChiSquare, ScoringType::kKL,
        ScoringType::kBhattacharyya, ScoringType::kDotProduct}) {
    auto parsed = ParseScoring(ScoringName(type));
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(*parsed, type);
  }
  EXPECT_EQ(ParseScoring("cosine").status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace recog
