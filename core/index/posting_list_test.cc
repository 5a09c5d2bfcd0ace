#include "core/index/posting_list.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <map>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "core/vocabulary/vocabulary.h"
#include "tests/testing/synthetic.h"

namespace recog {
namespace {

struct Visited {
  EntryId entry;
  uint32_t value_bits;
  friend bool operator==(const Visited&, const Visited&) = default;
};

std::vector<Visited> AllPostings(const PostingList& list, float word_weight,
                                 const std::vector<float>& scales) {
  std::vector<Visited> out;
  list.ForEach(word_weight, scales.data(), [&](EntryId entry, float value) {
    out.push_back({entry, std::bit_cast<uint32_t>(value)});
  });
  return out;
}

Visited Expect(EntryId entry, float value) { return {entry, std::bit_cast<uint32_t>(value)}; }

TEST(PostingListTest, BagsOfWordsOfTheVocabularyDecodeExactlyWithNothingStoredAside) {
  TrainingOptions options = testing::SmallTrainingOptions(8, 3, /*threads=*/1, 1);
  auto vocabulary = TrainVocabulary(testing::ClusteredTrainingSet(40, 150, 1), options);
  ASSERT_TRUE(vocabulary.ok()) << vocabulary.status().ToString();
  for (BowNormalization norm :
       {BowNormalization::kL1, BowNormalization::kL2, BowNormalization::kNone}) {
    std::map<WordId, PostingList> lists;
    std::map<WordId, std::vector<Visited>> expected;
    std::vector<float> scales;
    for (EntryId id = 0; id < 60; ++id) {
      // Up to 315 features of 40 clusters: no word occurs more than 31 times in an entry.
      const cv::Mat descriptors =
          testing::ClusteredBinaryDescriptors(20 + int(id) * 5, 40, 0.08, 100 + id);
      BowVector bow;
      ASSERT_TRUE(vocabulary->Transform(descriptors, &bow, nullptr, 0, norm).ok());
      scales.push_back(PostingList::FitScale(bow.entries(), *vocabulary));
      for (const BowEntry& e : bow.entries()) {
        lists[e.word].Append(id, e.value, vocabulary->WordWeight(e.word), scales.back());
        expected[e.word].push_back(Expect(id, e.value));
      }
    }
    size_t stored = 0;
    for (const auto& [word, list] : lists) {
      EXPECT_EQ(AllPostings(list, vocabulary->WordWeight(word), scales), expected[word]);
      stored += list.stored_values();
    }
    EXPECT_EQ(stored, 0u) << "normalisation " << int(norm);
  }
}

TEST(PostingListTest, ValuesOfAnyOtherFormAreKeptAsTheyAre) {
  PostingList list;
  const std::vector<float> scales(8, 0.25);
  // With word weight 2 and scale 0.25, multiples of 0.5 up to 31 of them fit in the code.
  const std::vector<float> values = {1.5f, 0.3f, 0.f, 20.f, 3.7e-30f, 0.5f, 15.5f};
  for (EntryId id = 0; id < values.size(); ++id) list.Append(id, values[id], 2.0, scales[id]);
  std::vector<Visited> expected;
  for (EntryId id = 0; id < values.size(); ++id) expected.push_back(Expect(id, values[id]));
  EXPECT_EQ(AllPostings(list, 2.0, scales), expected);
  EXPECT_EQ(list.stored_values(), 4u);  // 0.3, 0, 20 (40 occurrences) and 3.7e-30
  PostingList unscaled;                 // an entry without a scale stores every value
  unscaled.Append(3, 1.5f, 2.0, 0.0);
  EXPECT_EQ(unscaled.stored_values(), 1u);
  EXPECT_EQ(unscaled.ValueAt(0, 2.0, 0.0), 1.5f);
}

// Entries on five pages of 65,536 ids, so that blocks of 32 postings straddle pages.
class PagedPostingListTest : public ::testing::Test {
 protected:
  void SetUp() override {
    scales_.assign(400'000, 0.125);
    for (EntryId i = 0; i < 100; ++i) {
      const EntryId entry = i * 3001 + 7;
      const float value = i % 9 == 0 ? 0.3f : float(1 + i % 5) * 0.125f;  // some stored
      list_.Append(entry, value, 1.0, scales_[entry]);
      expected_.push_back(Expect(entry, value));
    }
  }
  PostingList list_;
  std::vector<float> scales_;
  std::vector<Visited> expected_;
};

TEST_F(PagedPostingListTest, RangeByRangeVisitsEveryPostingOnceInOrder) {
  std::vector<Visited> visited;
  size_t position = 0;
  for (uint64_t begin = 0; begin < 400'000; begin += 16'384) {
    const uint64_t page = begin >> PostingList::kPageBits;
    list_.VisitRange(&position, list_.PageEnd(page), page, begin + 16'384, 1.0, scales_.data(),
                     [&](EntryId entry, float value) {
                       EXPECT_GE(entry, begin);
                       EXPECT_LT(entry, begin + 16'384);
                       visited.push_back({entry, std::bit_cast<uint32_t>(value)});
                     });
  }
  EXPECT_EQ(visited, expected_);
  EXPECT_EQ(position, list_.size());
}

TEST_F(PagedPostingListTest, LookupsFindEveryEntryAndNoOther) {
  size_t block = PostingList::kNotFound;
  for (size_t i = 0; i < expected_.size(); ++i) {
    const EntryId entry = expected_[i].entry;
    block = list_.BlockOf(entry, block);
    ASSERT_NE(block, PostingList::kNotFound);
    const size_t position = list_.FindInBlock(block, entry);
    ASSERT_EQ(position, i);
    EXPECT_EQ(std::bit_cast<uint32_t>(list_.ValueAt(position, 1.0, 0.125)),
              expected_[i].value_bits);
  }
  // Absent: before the first posting, between two, and the same low bits on another page.
  EXPECT_EQ(list_.BlockOf(3, PostingList::kNotFound), PostingList::kNotFound);
  for (EntryId absent : {EntryId(8), EntryId(3001 + 8), EntryId(65536 + 7), EntryId(399'999)}) {
    const size_t b = list_.BlockOf(absent, PostingList::kNotFound);
    ASSERT_NE(b, PostingList::kNotFound);
    EXPECT_EQ(list_.FindInBlock(b, absent), PostingList::kNotFound) << absent;
  }
}

TEST_F(PagedPostingListTest, ErasingKeepsTheOthersFindableWithTheirValues) {
  for (size_t i : {size_t(99), size_t(45), size_t(27), size_t(0)}) {  // stored and coded values
    EXPECT_TRUE(list_.Erase(expected_[i].entry));
    expected_.erase(expected_.begin() + ptrdiff_t(i));
  }
  // Absent: before the first posting, between two, on another page, beyond the last.
  for (EntryId absent : {EntryId(3), EntryId(7), EntryId(65536 + 7), EntryId(1'000'000)}) {
    EXPECT_FALSE(list_.Erase(absent)) << absent;
  }
  EXPECT_EQ(AllPostings(list_, 1.0, scales_), expected_);
  for (size_t i = 0; i < expected_.size(); ++i) {
    const size_t block = list_.BlockOf(expected_[i].entry, PostingList::kNotFound);
    EXPECT_EQ(list_.FindInBlock(block, expected_[i].entry), i);
  }
  EXPECT_EQ(list_.stored_values(), 8u);  // the 12 multiples of 9 below 100, less the 4 erased
}

TEST_F(PagedPostingListTest, RestoreTakesGoodPartsAndRefusesDamagedOnes) {
  std::vector<uint8_t> present(400'000, 0);
  for (const Visited& v : expected_) present[v.entry] = 1;
  PostingList restored;
  EXPECT_EQ(restored.Restore(list_.parts(), 400'000, present.data(), 1.0, scales_.data()), "");
  EXPECT_EQ(AllPostings(restored, 1.0, scales_), expected_);
  EXPECT_EQ(restored.FindInBlock(restored.BlockOf(expected_[50].entry, PostingList::kNotFound),
                                 expected_[50].entry),
            50u);

  using Damage = std::function<void(PostingList::Parts&)>;
  const std::vector<std::pair<std::string, Damage>> damages = {
      {"order", [](auto& p) { std::swap(p.postings[3], p.postings[4]); }},
      {"stored code", [](auto& p) { p.postings[1].code = 7; }},
      {"no occurrences", [](auto& p) { p.postings[1].code = 3; }},
      {"stored position", [](auto& p) { p.stored[1].position = 10; }},
      {"stored value", [](auto& p) { p.stored[0].value = -1.f; }},
      {"stored -0", [](auto& p) { p.stored[0].value = -0.f; }},  // Append keeps +0
      {"page end", [](auto& p) { p.page_end.back() = 1000; }},
      {"pages out of order", [](auto& p) { p.page_end[1] = p.page_end[0] - 1; }},
      {"postings beyond the pages", [](auto& p) { p.postings.push_back(p.postings.back()); }},
  };
  for (const auto& [what, damage] : damages) {
    PostingList::Parts parts = list_.parts();
    damage(parts);
    PostingList list;
    EXPECT_NE(list.Restore(std::move(parts), 400'000, present.data(), 1.0, scales_.data()), "")
        << what;
    EXPECT_TRUE(list.empty()) << what;
  }
  // An entry that is not indexed, or beyond the ids covered.
  present[expected_[10].entry] = 0;
  EXPECT_NE(restored.Restore(list_.parts(), 400'000, present.data(), 1.0, scales_.data()), "");
  present[expected_[10].entry] = 1;
  EXPECT_NE(
      restored.Restore(list_.parts(), expected_.back().entry, present.data(), 1.0, scales_.data()),
      "");
}

}  // namespace
TEST(PostingListTest, RestoredListsGetRoomSpreadOverOneGrowthStep) {
  // Between none and an eighth more than the postings, differing from word to word, so that
  // restored lists do not all copy themselves on the same new frame.
  std::vector<size_t> capacities;
  for (uint32_t word = 0; word < 1000; ++word) {
    const size_t capacity = PostingList::RestoredCapacity(80'000, word);
    ASSERT_GE(capacity, 80'000u);
    ASSERT_LT(capacity, 90'000u);
    capacities.push_back(capacity);
  }
  std::sort(capacities.begin(), capacities.end());
  EXPECT_LT(capacities[100], 81'500u);  // about a tenth within the first tenth of the step
  EXPECT_GT(capacities[900], 88'500u);
  EXPECT_GT(std::unique(capacities.begin(), capacities.end()) - capacities.begin(), 900);
  EXPECT_EQ(PostingList::RestoredCapacity(0, 12), 0u);
}

}  // namespace recog
