#include "core/bow/bow_vector.h"

#include <algorithm>
#include <cmath>

namespace recog {

BowVector::BowVector(std::vector<BowEntry> entries) {
  std::sort(entries.begin(), entries.end(),
            [](const BowEntry& a, const BowEntry& b) { return a.word < b.word; });
  for (const BowEntry& e : entries) {
    if (!entries_.empty() && entries_.back().word == e.word) {
      entries_.back().value += e.value;
    } else {
      entries_.push_back(e);
    }
  }
}

float BowVector::ValueOf(WordId word) const {
  auto it = std::lower_bound(entries_.begin(), entries_.end(), word,
                             [](const BowEntry& e, WordId w) { return e.word < w; });
  return (it != entries_.end() && it->word == word) ? it->value : 0.f;
}

void BowVector::Normalize(BowNormalization norm) {
  if (norm == BowNormalization::kNone) return;
  double total = 0.0;
  for (const BowEntry& e : entries_) {
    total += norm == BowNormalization::kL1 ? std::fabs(double(e.value)) : double(e.value) * e.value;
  }
  if (norm == BowNormalization::kL2) total = std::sqrt(total);
  if (total <= 0.0) return;
  for (BowEntry& e : entries_) e.value = float(e.value / total);
}

}  // namespace recog
