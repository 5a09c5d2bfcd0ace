// BowVector: the bag-of-words of an image or object, a sparse vector word id -> weight.
//
// Entries are kept sorted by word id in one contiguous array so that two vectors are compared by
// a linear merge and the inverted index is updated in word order. The values are whatever the
// vocabulary's weighting produced (tf-idf by default), normalised as requested by the caller of
// Vocabulary::Transform (L1 by default, as the thesis does). A BowVector is reused across
// transforms: Clear() keeps its capacity, so steady-state conversion does not allocate.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace recog {

using WordId = uint32_t;
inline constexpr WordId kInvalidWordId = UINT32_MAX;

struct BowEntry {
  WordId word;
  float value;
  friend bool operator==(const BowEntry&, const BowEntry&) = default;
};

enum class BowNormalization : uint8_t {
  kNone = 0,
  kL1 = 1,  // sum of |values| = 1 (L1, chi-square, KL, Bhattacharyya scores)
  kL2 = 2,  // Euclidean norm = 1 (L2 score)
};

class BowVector {
 public:
  BowVector() = default;
  // Builds a vector from entries in any order; repeated words are summed.
  explicit BowVector(std::vector<BowEntry> entries);

  std::span<const BowEntry> entries() const { return entries_; }
  size_t size() const { return entries_.size(); }
  bool empty() const { return entries_.empty(); }
  void Clear() { entries_.clear(); }

  // Value of `word`, 0 when absent (binary search).
  float ValueOf(WordId word) const;

  // Scales the values so that the chosen norm is 1 (no-op for kNone or an all-zero vector).
  void Normalize(BowNormalization norm);

  // Appends an entry; words must be appended in strictly increasing order.
  void AppendSorted(WordId word, float value) { entries_.push_back({word, value}); }
  std::vector<BowEntry>& mutable_entries() { return entries_; }

  friend bool operator==(const BowVector&, const BowVector&) = default;

 private:
  std::vector<BowEntry> entries_;
};

}  // namespace recog
