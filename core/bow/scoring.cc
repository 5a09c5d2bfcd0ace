#include "core/bow/scoring.h"

namespace recog {

ScoringTraits TraitsOf(ScoringType type) {
  switch (type) {
    case ScoringType::kL2:
      return {BowNormalization::kL2, true};
    case ScoringType::kKL:
      return {BowNormalization::kL1, false};
    case ScoringType::kDotProduct:
      return {BowNormalization::kNone, true};
    default:
      return {BowNormalization::kL1, true};
  }
}

std::string_view ScoringName(ScoringType type) {
  switch (type) {
    case ScoringType::kL1:
      return "l1";
    case ScoringType::kL2:
      return "l2";
    case ScoringType::kChiSquare:
      return "chi2";
    case ScoringType::kKL:
      return "kl";
    case ScoringType::kBhattacharyya:
      return "bhattacharyya";
    case ScoringType::kDotProduct:
      return "dot";
  }
  return "unknown";
}

StatusOr<ScoringType> ParseScoring(std::string_view name) {
  for (ScoringType t : {ScoringType::kL1, ScoringType::kL2, ScoringType::kChiSquare,
                        ScoringType::kKL, ScoringType::kBhattacharyya, ScoringType::kDotProduct}) {
    if (name == ScoringName(t)) return t;
  }
  return Status::InvalidArgument("unknown scoring '" + std::string(name) +
                                 "' (expected l1, l2, chi2, kl, bhattacharyya or dot)");
}

double QueryConstant(ScoringType type, const BowVector& query) {
  if (type != ScoringType::kKL) return 0.0;
  // KL(v||w) = sum_{v and w} v log(v/w) + sum_{v only} v (log v - log eps)
  //          = sum_v v (log v - log eps) + sum_{v and w} v (log eps - log w).
  double constant = 0.0;
  for (const BowEntry& e : query.entries()) {
    if (e.value > 0.f) constant += e.value * (std::log(double(e.value)) - kKlLogEpsilon);
  }
  return constant;
}

double Score(ScoringType type, const BowVector& query, const BowVector& entry) {
  const auto a = query.entries();
  const auto b = entry.entries();
  double sum = 0.0;
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (a[i].word == b[j].word) {
      if (a[i].value > 0.f && b[j].value > 0.f) sum += CommonTerm(type, a[i].value, b[j].value);
      ++i;
      ++j;
    } else if (a[i].word < b[j].word) {
      ++i;
    } else {
      ++j;
    }
  }
  return FinishScore(type, sum, QueryConstant(type, query));
}

}  // namespace recog
