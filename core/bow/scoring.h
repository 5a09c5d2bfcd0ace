// Similarity scores between two BowVectors, all computable from the words the vectors share.
//
// Every score is written as  Finish( sum over common words i of Term(v_i, w_i), QueryConstant(v) ),
// which is what lets an inverted index score a query against every stored entry while touching
// only the postings of the query's words (thesis Algorithm 1 and Algorithm 5). Score() applies the
// same three pieces with a linear merge of two vectors, so both paths agree by construction.
//
// | type          | expects vectors | value                                   | range, best  |
// |---------------|-----------------|-----------------------------------------|--------------|
// | kL1           | L1-normalised   | sum min(v,w)   = 1 - |v-w|_1 / 2  (3.10) | [0,1], high  |
// | kL2           | L2-normalised   | 1 - sqrt(1 - v.w) = 1 - |v-w|_2 / sqrt2 | [0,1], high  |
// | kChiSquare    | L1-normalised   | 2 sum v w/(v+w) = 1 - chi2/2     (5.12) | [0,1], high  |
// | kKL           | L1-normalised   | KL(v||w), eps for words missing in w     | [0,inf), low |
// | kBhattacharyya| L1-normalised   | sum sqrt(v w)                     (5.5)  | [0,1], high  |
// | kDotProduct   | any             | sum v w                                  | high         |
//
// kL2 is ill-conditioned near 1: a rounding error e in v.w becomes sqrt(e) in the score, so two
// identical float-valued vectors score about 1 - 1e-4, not exactly 1.
//
// The numbering of ScoringType and WeightingType is DBoW2's, so vocabulary files carry it as is.
#pragma once

#include <cfloat>
#include <cmath>
#include <cstdint>
#include <string_view>

#include "core/bow/bow_vector.h"
#include "core/common/status.h"

namespace recog {

enum class ScoringType : uint8_t {
  kL1 = 0,
  kL2 = 1,
  kChiSquare = 2,
  kKL = 3,
  kBhattacharyya = 4,
  kDotProduct = 5,
};

struct ScoringTraits {
  BowNormalization normalization;  // what Transform must produce for this score
  bool higher_is_better;           // false only for the KL divergence
};

ScoringTraits TraitsOf(ScoringType type);
std::string_view ScoringName(ScoringType type);  // "l1", "l2", "chi2", "kl", "bhattacharyya", "dot"
StatusOr<ScoringType> ParseScoring(std::string_view name);

// The log-epsilon that KL uses for a word of v absent from w (same constant as DBoW2).
inline const double kKlLogEpsilon = std::log(DBL_EPSILON);

// Contribution of one common word with value v in the query and w in the entry (both > 0).
inline double CommonTerm(ScoringType type, double v, double w) {
  switch (type) {
    case ScoringType::kL1:
      return v < w ? v : w;
    case ScoringType::kL2:
      return v * w;
    case ScoringType::kChiSquare:
      return 2.0 * v * w / (v + w);
    case ScoringType::kKL:
      return v * (kKlLogEpsilon - std::log(w));
    case ScoringType::kBhattacharyya:
      return std::sqrt(v * w);
    case ScoringType::kDotProduct:
      return v * w;
  }
  return 0.0;
}

// The part of a score that depends on the query alone (0 except for KL).
double QueryConstant(ScoringType type, const BowVector& query);

// Turns the sum of CommonTerm over the common words into the score.
inline double FinishScore(ScoringType type, double sum, double query_constant) {
  switch (type) {
    case ScoringType::kL2:
      return sum >= 1.0 ? 1.0 : 1.0 - std::sqrt(1.0 - sum);
    case ScoringType::kKL:
      return query_constant + sum;
    default:
      return sum;
  }
}

// Score of `query` against `entry` with a linear merge over the common words.
double Score(ScoringType type, const BowVector& query, const BowVector& entry);

}  // namespace recog
