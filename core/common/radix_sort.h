// RadixSortByKey: a stable least-significant-digit radix sort by a 32-bit key.
//
// Used on the descriptor-conversion hot path, where a thousand (word, weight) or (node, feature)
// pairs are sorted per image: with 11-bit digits and only as many passes as the largest key
// needs (two for vocabularies below 4M nodes), it is faster than std::sort there
// (docs/evaluation.md, "Benchmarks"), and stable, so pairs that arrive in feature order stay in
// feature order within a key.
#pragma once

#include <array>
#include <bit>
#include <cstdint>
#include <utility>
#include <vector>

namespace recog {

// Sorts `items` by key_of(item) (a uint32_t no larger than `max_key`). `scratch` is working
// memory, reused across calls; on return it holds unspecified contents.
template <class T, class KeyOf>
void RadixSortByKey(std::vector<T>& items, std::vector<T>& scratch, uint32_t max_key,
                    KeyOf key_of) {
  constexpr int kDigitBits = 11;
  constexpr uint32_t kBuckets = 1u << kDigitBits;
  const int passes = (std::bit_width(max_key) + kDigitBits - 1) / kDigitBits;
  scratch.resize(items.size());
  std::array<uint32_t, kBuckets> count;
  for (int pass = 0; pass < passes; ++pass) {
    const int shift = pass * kDigitBits;
    count.fill(0);
    for (const T& item : items) ++count[(key_of(item) >> shift) & (kBuckets - 1)];
    uint32_t offset = 0;
    for (uint32_t& c : count) offset += std::exchange(c, offset);
    for (const T& item : items) scratch[count[(key_of(item) >> shift) & (kBuckets - 1)]++] = item;
    items.swap(scratch);
  }
}

}  // namespace recog
