#include "core/index/posting_list.h"

#include <cmath>
#include <limits>

#include "core/vocabulary/vocabulary.h"

namespace recog {
namespace {

// Lists grow by an eighth (at least 4 items) when they are full, instead of doubling.
constexpr size_t kGrowthDivisor = 8;

template <class T>
void AppendCompact(std::vector<T>& v, const T& item) {
  if (v.size() == v.capacity()) v.reserve(v.size() + v.size() / kGrowthDivisor + 4);
  v.push_back(item);
}

// The whole number of times `value` holds `unit` when it is one (within a hundredth), up to
// PostingList::kMaxOccurrences; 0 otherwise.
uint32_t WholeMultiple(double value, double unit) {
  const double ratio = value / unit;
  if (!(ratio >= 0.5 && ratio < PostingList::kMaxOccurrences + 0.5)) return 0;
  const double rounded = std::round(ratio);
  return std::fabs(ratio - rounded) < 0.01 ? uint32_t(rounded) : 0;
}

}  // namespace

float PostingList::FitScale(std::span<const BowEntry> bow, const Vocabulary& vocabulary) {
  // The smallest value per word weight is (nearly always) one occurrence's; the scale is then
  // averaged over every value that is a whole multiple of it, which evens out their roundings.
  double smallest = std::numeric_limits<double>::infinity();
  for (const BowEntry& e : bow) {
    const double weight = vocabulary.WordWeight(e.word);
    if (weight > 0.0 && e.value > 0.f) smallest = std::min(smallest, double(e.value) / weight);
  }
  if (!std::isfinite(smallest)) return 0.0;
  double sum = 0.0;
  size_t count = 0;
  for (const BowEntry& e : bow) {
    const double weight = vocabulary.WordWeight(e.word);
    if (!(weight > 0.0)) continue;
    if (const uint32_t occurrences = WholeMultiple(e.value / weight, smallest)) {
      sum += double(e.value) / (weight * occurrences);
      ++count;
    }
  }
  return float(count > 0 ? sum / double(count) : smallest);
}

void PostingList::Append(EntryId entry, float value, float word_weight, float entry_scale) {
  const size_t position = size();
  const size_t page = entry >> kPageBits;
  if (parts_.page_end.size() <= page) parts_.page_end.resize(page + 1, uint32_t(position));
  if (position % kBlock == 0) AppendCompact(block_first_, entry);
  uint8_t code = kStoredCode;
  if (entry_scale > 0.0 && word_weight > 0.0 && std::isfinite(value)) {
    if (const uint32_t occurrences = WholeMultiple(value, word_weight * entry_scale)) {
      const int64_t steps =
          int64_t(std::bit_cast<uint32_t>(value)) -
          int64_t(std::bit_cast<uint32_t>(Estimate(word_weight, occurrences, entry_scale)));
      if (steps >= -3 && steps <= 3) code = uint8_t(occurrences << 3 | uint32_t(steps + 3));
    }
  }
  if (code == kStoredCode) {
    // A zero is kept as +0: a query tells the entries it touched by their sums' bits, and a
    // term of -0 would leave an entry's untouched -0 as it was.
    AppendCompact(parts_.stored, StoredValue{uint32_t(position), value + 0.f});
  }
  const uint32_t low = entry & ((1u << kPageBits) - 1);
  AppendCompact(parts_.postings, Posting{{uint8_t(low), uint8_t(low >> 8)}, code});
  parts_.page_end[page] = uint32_t(position + 1);
}

bool PostingList::Erase(EntryId entry) {
  // The last block that starts at or before `entry`, searched rather than walked to.
  const auto after = std::upper_bound(block_first_.begin(), block_first_.end(), entry);
  if (after == block_first_.begin()) return false;
  const size_t block = size_t(after - block_first_.begin()) - 1;
  const size_t position = FindInBlock(block, entry);
  if (position == kNotFound) return false;
  parts_.postings.erase(parts_.postings.begin() + ptrdiff_t(position));
  for (size_t page = entry >> kPageBits; page < parts_.page_end.size(); ++page) {
    --parts_.page_end[page];
  }
  std::vector<StoredValue>& stored = parts_.stored;
  const auto it = std::lower_bound(stored.begin(), stored.end(), position,
                                   [](const StoredValue& s, size_t p) { return s.position < p; });
  auto next = it != stored.end() && it->position == position ? stored.erase(it) : it;
  for (; next != stored.end(); ++next) --next->position;
  IndexBlocks(block);
  return true;
}

void PostingList::Reserve(size_t postings) { parts_.postings.reserve(postings); }

size_t PostingList::RestoredCapacity(size_t postings, uint32_t word) {
  // A share of one growth step between 0 and 1, from the word id's bits mixed (Fibonacci hashing).
  const uint64_t share = (uint64_t(word) * 0x9E3779B97F4A7C15ull) >> 48;  // of 65,536
  return postings + size_t(uint64_t(postings / kGrowthDivisor) * share >> 16);
}

size_t PostingList::capacity_bytes() const {
  return parts_.postings.capacity() * sizeof(Posting) +
         parts_.page_end.capacity() * sizeof(uint32_t) +
         parts_.stored.capacity() * sizeof(StoredValue) + block_first_.capacity() * sizeof(EntryId);
}

std::string PostingList::Restore(Parts parts, EntryId covers, const uint8_t* present,
                                 float word_weight, const float* entry_scales) {
  parts_ = std::move(parts);
  block_first_.clear();
  const std::vector<Posting>& postings = parts_.postings;
  const std::vector<StoredValue>& stored = parts_.stored;
  std::string problem;
  size_t begin = 0, next_stored = 0;
  for (size_t page = 0; page < parts_.page_end.size() && problem.empty(); ++page) {
    const size_t end = parts_.page_end[page];
    if (end < begin || end > postings.size()) {
      problem = "a page directory out of order";
      break;
    }
    for (size_t p = begin; p < end; ++p) {
      const uint64_t entry = uint64_t(page) << kPageBits | postings[p].Low();
      if (entry >= covers || present[entry] == 0 ||
          (p > begin && postings[p].Low() <= postings[p - 1].Low())) {
        problem = "a posting of no indexed entry, or out of order";
        break;
      }
      const bool is_stored = (postings[p].code & 7) == kStoredCode;
      if (is_stored != (next_stored < stored.size() && stored[next_stored].position == p) ||
          (!is_stored && postings[p].code >> 3 == 0)) {
        problem = "a posting whose value code does not fit its stored values";
        break;
      }
      const float value = is_stored ? stored[next_stored++].value
                                    : Decode(postings[p].code, word_weight, entry_scales[entry]);
      if (!std::isfinite(value) || std::signbit(value)) {  // -0 too: Append keeps +0
        problem = "a posting without a weight";
        break;
      }
      if (p % kBlock == 0) block_first_.push_back(EntryId(entry));
    }
    begin = end;
  }
  if (problem.empty() && (begin != postings.size() || next_stored != stored.size())) {
    problem = "postings or stored values beyond its page directory";
  }
  if (!problem.empty()) parts_ = Parts();
  return problem;
}

float PostingList::StoredValueAt(size_t position) const {
  const auto it = std::lower_bound(parts_.stored.begin(), parts_.stored.end(), position,
                                   [](const StoredValue& s, size_t p) { return s.position < p; });
  return it->value;
}

EntryId PostingList::EntryAt(size_t position) const {
  const auto page = std::upper_bound(parts_.page_end.begin(), parts_.page_end.end(), position);
  return EntryId(size_t(page - parts_.page_end.begin()) << kPageBits) |
         parts_.postings[position].Low();
}

void PostingList::IndexBlocks(size_t first_block) {
  block_first_.resize(std::min(block_first_.size(), first_block));
  for (size_t p = first_block * kBlock; p < size(); p += kBlock) block_first_.push_back(EntryAt(p));
}

}  // namespace recog
