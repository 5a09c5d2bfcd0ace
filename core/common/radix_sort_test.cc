#include "core/common/radix_sort.h"

#include <algorithm>
#include <random>

#include <gtest/gtest.h>

namespace recog {
namespace {

using Pair = std::pair<uint32_t, uint32_t>;  // (key, original position)

TEST(RadixSortTest, SortsByKeyAndKeepsEqualKeysInInputOrder) {
  std::mt19937 rng(3);
  for (uint32_t max_key : {0u, 1u, 2047u, 2048u, 100000u, 1u << 22, UINT32_MAX}) {
    std::vector<Pair> items, scratch;
    for (uint32_t i = 0; i < 3000; ++i) {
      // Few distinct keys so that stability matters.
      const uint32_t key = max_key == 0 ? 0 : uint32_t(rng() % 50) * (max_key / 50);
      items.push_back({key, i});
    }
    std::vector<Pair> expected = items;
    std::stable_sort(expected.begin(), expected.end(),
                     [](const Pair& a, const Pair& b) { return a.first < b.first; });
    RadixSortByKey(items, scratch, max_key, [](const Pair& p) { return p.first; });
    EXPECT_EQ(items, expected) << "max_key " << max_key;
  }
}

TEST(RadixSortTest, EmptyAndSingleElementInputsAreFine) {
  std::vector<Pair> empty, scratch;
  RadixSortByKey(empty, scratch, 1000, [](const Pair& p) { return p.first; });
  EXPECT_TRUE(empty.empty());
  std::vector<Pair> one{{7, 0}};
  RadixSortByKey(one, scratch, 1000, [](const Pair& p) { return p.first; });
  EXPECT_EQ(one, (std::vector<Pair>{{7, 0}}));
}

}  // namespace
}  // namespace recog
