#include "core/index/database.h"

#include <algorithm>
#include <cstring>
#include <functional>
#include <map>
#include <random>
#include <thread>

#include <gtest/gtest.h>

#include "core/index/memory_index_store.h"
#include "tests/testing/synthetic.h"

namespace recog {
namespace {

std::shared_ptr<const Vocabulary> SmallVocabulary(uint64_t seed = 1) {
  TrainingOptions options = testing::SmallTrainingOptions(8, 3, /*threads=*/1, seed);
  auto v = TrainVocabulary(testing::ClusteredTrainingSet(40, 150, seed), options);
  EXPECT_TRUE(v.ok()) << v.status().ToString();
  return std::make_shared<const Vocabulary>(std::move(v).value());
}

// `count` clustered descriptors with keypoints on a grid.
FeatureSet SyntheticFeatures(int count, uint64_t seed) {
  FeatureSet f;
  f.descriptors = testing::ClusteredBinaryDescriptors(count, 40, 0.08, seed);
  for (int i = 0; i < count; ++i) {
    f.keypoints.emplace_back(float(i % 40) * 10.f, float(i / 40) * 10.f, 31.f, float(i), 1.f, 0);
  }
  return f;
}

class DatabaseTest : public ::testing::Test {
 protected:
  void SetUp() override {
    vocabulary_ = SmallVocabulary();
    auto db = Database::Create(&store_, "map-1", vocabulary_);
    ASSERT_TRUE(db.ok()) << db.status().ToString();
    db_ = std::move(db).value();
  }

  BowVector BowOf(const FeatureSet& f, ScoringType scoring = ScoringType::kL1) const {
    BowVector bow;
    EXPECT_TRUE(
        vocabulary_->Transform(f.descriptors, &bow, nullptr, 0, TraitsOf(scoring).normalization)
            .ok());
    return bow;
  }

  MemoryIndexStore store_;
  std::shared_ptr<const Vocabulary> vocabulary_;
  std::unique_ptr<Database> db_;
};

TEST_F(DatabaseTest, AnEntryIsItsOwnBestMatch) {
  std::vector<FeatureSet> sets;
  for (int i = 0; i < 20; ++i) {
    sets.push_back(SyntheticFeatures(150, 100 + i));
    auto id = db_->Add(sets.back());
    ASSERT_TRUE(id.ok()) << id.status().ToString();
    EXPECT_EQ(*id, EntryId(i));
  }
  EXPECT_EQ(db_->size(), 20u);
  std::vector<QueryResult> results;
  for (int i = 0; i < 20; ++i) {
    ASSERT_TRUE(db_->Query(BowOf(sets[i]), {.max_results = 3}, &results).ok());
    ASSERT_EQ(results.size(), 3u);
    EXPECT_EQ(results[0].id, EntryId(i));
    EXPECT_NEAR(results[0].score, 1.0, 1e-5);
    EXPECT_GE(results[0].score, results[1].score);
    EXPECT_GE(results[1].score, results[2].score);
  }
}

// A map scored with the test's scoring type, and the bag of words of every entry it was given.
class DatabaseScoringTest : public ::testing::TestWithParam<ScoringType> {
 protected:
  void SetUp() override {
    auto db = Database::Create(&store_, "m", vocabulary_, GetParam());
    ASSERT_TRUE(db.ok()) << db.status().ToString();
    db_ = std::move(db).value();
  }

  // The bag of words of synthetic features, normalised as the scoring type needs.
  BowVector BowOf(int features, uint64_t seed) const {
    BowVector bow;
    EXPECT_TRUE(vocabulary_
                    ->Transform(SyntheticFeatures(features, seed).descriptors, &bow, nullptr, 0,
                                TraitsOf(GetParam()).normalization)
                    .ok());
    return bow;
  }

  // Adds `count` entries of `min_features` + i % `spread` features (seeds from `seed`).
  void AddEntries(int count, int min_features, int spread, uint64_t seed) {
    for (int i = 0; i < count; ++i) {
      const FeatureSet f = SyntheticFeatures(min_features + i % spread, seed + uint64_t(i));
      ASSERT_TRUE(db_->Add(f).ok());
      bows_.push_back(BowOf(min_features + i % spread, seed + uint64_t(i)));
    }
  }

  MemoryIndexStore store_;
  std::shared_ptr<const Vocabulary> vocabulary_ = SmallVocabulary();
  std::unique_ptr<Database> db_;
  std::vector<BowVector> bows_;
};

TEST_P(DatabaseScoringTest, QueryEqualsScoringEveryEntryByBruteForce) {
  const ScoringType type = GetParam();
  AddEntries(60, 40, 50, 500);
  for (int q = 0; q < 10; ++q) {
    const BowVector query = BowOf(80, 900 + uint64_t(q));
    std::vector<QueryResult> expected;
    for (EntryId id = 0; id < bows_.size(); ++id) {
      bool shares_a_word = false;
      for (const BowEntry& e : query.entries()) shares_a_word |= bows_[id].ValueOf(e.word) > 0;
      if (shares_a_word) expected.push_back({id, Score(type, query, bows_[id])});
    }
    const bool higher = TraitsOf(type).higher_is_better;
    std::stable_sort(expected.begin(), expected.end(), [&](const auto& a, const auto& b) {
      return higher ? a.score > b.score : a.score < b.score;
    });
    std::vector<QueryResult> results;
    ASSERT_TRUE(db_->Query(query, {.max_results = 15}, &results).ok());
    ASSERT_EQ(results.size(), std::min<size_t>(15, expected.size()));
    for (size_t i = 0; i < results.size(); ++i) {
      EXPECT_NEAR(results[i].score, expected[i].score,
                  1e-6 * std::max(1.0, std::fabs(expected[i].score)))
          << ScoringName(type) << " rank " << i;
    }
  }
}

TEST_P(DatabaseScoringTest, BoundedQueryScoresItsCandidatesExactly) {
  // A map whose lists are long enough to be searched by block, some entries removed (their lists
  // re-indexed) and the map reopened (its lists indexed anew). A query allowed to read only its
  // rarest word's list in full returns exactly the entries of that list (no entry sharing only
  // commoner words), each with its exact score over all the query's words.
  const ScoringType type = GetParam();
  AddEntries(240, 30, 40, 2000);
  const auto removed = [](EntryId id) { return id % 9 == 4; };
  for (EntryId id = 0; id < bows_.size(); ++id) {
    if (removed(id)) {
      ASSERT_TRUE(db_->Remove(id).ok());
    }
  }
  for (bool reopened : {false, true}) {
    if (reopened) {
      auto opened = Database::Open(&store_, "m", vocabulary_);
      ASSERT_TRUE(opened.ok()) << opened.status().ToString();
      db_ = std::move(opened).value();
    }
    for (int q = 0; q < 8; ++q) {
      const BowVector query = BowOf(70, 3000 + uint64_t(q));
      // The entries holding each query word; the rarest word is the one held by the fewest.
      std::vector<std::vector<EntryId>> holders(query.size());
      for (EntryId id = 0; id < bows_.size(); ++id) {
        for (size_t w = 0; w < query.size(); ++w) {
          if (!removed(id) && bows_[id].ValueOf(query.entries()[w].word) > 0) {
            holders[w].push_back(id);
          }
        }
      }
      std::erase_if(holders, [](const auto& h) { return h.empty(); });
      const auto rarest = std::min_element(holders.begin(), holders.end(),
                                           [](auto& a, auto& b) { return a.size() < b.size(); });
      ASSERT_GT(db_->Stats().postings, rarest->size());
      const QueryOptions options{
          .max_results = 300, .full_scan_postings = 1, .rescored_candidates = 300};
      std::vector<QueryResult> results;
      ASSERT_TRUE(db_->Query(query, options, &results).ok());
      std::vector<EntryId> ids;
      for (const QueryResult& r : results) {
        ids.push_back(r.id);
        EXPECT_NEAR(r.score, Score(type, query, bows_[r.id]),
                    1e-6 * std::max(1.0, std::fabs(r.score)))
            << ScoringName(type) << " entry " << r.id << (reopened ? " reopened" : "");
      }
      std::sort(ids.begin(), ids.end());
      EXPECT_EQ(ids, *rarest) << ScoringName(type) << " query " << q;
      std::vector<QueryResult> exhaustive;
      ASSERT_TRUE(
          db_->Query(query, {.max_results = 300, .full_scan_postings = 0}, &exhaustive).ok());
      EXPECT_GT(exhaustive.size(), results.size()) << "the bound left no entry out";
    }
  }
}

TEST_P(DatabaseScoringTest, ABoundedQueryKeepsTheBestOnItsScannedWordTiesToTheLowerId) {
  // Every bag of words twice, side by side (so every score ties with the next entry's), and a
  // query of two common words that reads only the shorter list and keeps a few candidates: they
  // are the best on that word alone, a tie going to the lower id, each returned with its whole
  // score.
  const ScoringType type = GetParam();
  for (int i = 0; i < 60; ++i) {  // twins: entries 2i and 2i + 1
    AddEntries(1, 30 + i % 20, 1, 2000 + uint64_t(i));
    AddEntries(1, 30 + i % 20, 1, 2000 + uint64_t(i));
  }
  std::map<WordId, size_t> holders;
  for (const BowVector& bow : bows_) {
    for (const BowEntry& e : bow.entries()) ++holders[e.word];
  }
  std::vector<std::pair<size_t, WordId>> by_holders;
  for (const auto& [word, count] : holders) by_holders.push_back({count, word});
  std::sort(by_holders.rbegin(), by_holders.rend());
  const double sign = TraitsOf(type).higher_is_better ? 1.0 : -1.0;
  int queries = 0;
  for (size_t k = 1; k < by_holders.size() && queries < 6; ++k) {
    // The scanned word: held by fewer entries than the completed one, and by enough.
    const auto [count, scanned] = by_holders[k];
    const WordId completed = by_holders[0].second;
    if (count == by_holders[0].first || count < 16) continue;
    ++queries;
    const float scanned_value = 0.2f + 0.1f * float(k % 5);
    const BowVector query = scanned < completed
                                ? BowVector({{scanned, scanned_value}, {completed, 0.5f}})
                                : BowVector({{completed, 0.5f}, {scanned, scanned_value}});
    std::vector<QueryResult> on_scanned;  // sign x the scanned word's term
    for (EntryId id = 0; id < bows_.size(); ++id) {
      if (const float value = bows_[id].ValueOf(scanned); value > 0) {
        on_scanned.push_back({id, sign * CommonTerm(type, scanned_value, value)});
      }
    }
    // Odd, so that it cuts a pair of twins whenever the sorted candidates end at one; and a
    // quarter, so that most entries come after the first ones kept and must beat them.
    const size_t keep = (on_scanned.size() / 4) | 1;
    std::stable_sort(on_scanned.begin(), on_scanned.end(),
                     [](const auto& a, const auto& b) { return a.score > b.score; });
    std::vector<EntryId> expected;
    for (size_t i = 0; i < keep; ++i) expected.push_back(on_scanned[i].id);
    std::sort(expected.begin(), expected.end());

    std::vector<QueryResult> results;
    ASSERT_TRUE(
        db_->Query(query,
                   {.max_results = keep, .full_scan_postings = 1, .rescored_candidates = keep},
                   &results)
            .ok());
    std::vector<EntryId> ids;
    for (const QueryResult& r : results) {
      ids.push_back(r.id);
      EXPECT_NEAR(r.score, Score(type, query, bows_[r.id]),
                  1e-6 * std::max(1.0, std::fabs(r.score)))
          << ScoringName(type) << " entry " << r.id;
    }
    std::sort(ids.begin(), ids.end());
    EXPECT_EQ(ids, expected) << ScoringName(type) << " word " << scanned;
  }
  EXPECT_EQ(queries, 6) << "the map has too few common words";
}

INSTANTIATE_TEST_SUITE_P(AllScores, DatabaseScoringTest,
                         ::testing::Values(ScoringType::kL1, ScoringType::kL2,
                                           ScoringType::kChiSquare, ScoringType::kKL,
                                           ScoringType::kBhattacharyya, ScoringType::kDotProduct),
                         [](const auto& info) { return std::string(ScoringName(info.param)); });

TEST(DatabaseQueryTest, AMapOfSeveralScanRangesScoresEveryEntryExactly) {
  // A query adds up its lists' postings 16,384 entry ids at a time: 70,000 entries take five
  // ranges. Whatever the range an entry falls in, and wherever a query's id bound cuts a range, it
  // is returned with its brute-force score, by the exhaustive query and by the bounded one.
  MemoryIndexStore store;
  const auto vocabulary = SmallVocabulary();
  auto created = Database::Create(&store, "m", vocabulary, ScoringType::kL1);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  Database& db = **created;
  const auto bow_of = [&](int features, uint64_t seed) {
    BowVector bow;
    EXPECT_TRUE(vocabulary
                    ->Transform(SyntheticFeatures(features, seed).descriptors, &bow, nullptr, 0,
                                BowNormalization::kL1)
                    .ok());
    return bow;
  };
  std::vector<BowVector> bows;
  for (uint64_t i = 0; i < 70000; ++i) {
    ASSERT_TRUE(db.Add(SyntheticFeatures(2, 10000 + i)).ok());
    bows.push_back(bow_of(2, 10000 + i));
  }
  const BowVector query = bow_of(12, 7);
  // The entries of each query word's list below an id bound, and every entry sharing a word.
  const auto expected_below = [&](EntryId bound, size_t* rarest_list) {
    std::vector<QueryResult> expected;
    std::vector<size_t> list_sizes(query.size(), 0);
    for (EntryId id = 0; id < bound; ++id) {
      bool shares_a_word = false;
      for (size_t w = 0; w < query.size(); ++w) {
        const bool holds = bows[id].ValueOf(query.entries()[w].word) > 0;
        list_sizes[w] += holds;
        shares_a_word |= holds;
      }
      if (shares_a_word) expected.push_back({id, Score(ScoringType::kL1, query, bows[id])});
    }
    std::erase(list_sizes, 0);
    *rarest_list = *std::min_element(list_sizes.begin(), list_sizes.end());
    return expected;
  };
  const auto by_id = [](std::vector<QueryResult> results) {
    std::sort(results.begin(), results.end(),
              [](const QueryResult& a, const QueryResult& b) { return a.id < b.id; });
    return results;
  };
  for (const EntryId bound : {EntryId(70000), EntryId(40000)}) {
    size_t rarest_list = 0;
    const std::vector<QueryResult> expected = expected_below(bound, &rarest_list);
    ASSERT_GT(expected.back().id, bound - 1000) << "the query's lists reach the bound's range";
    std::vector<QueryResult> results;
    ASSERT_TRUE(db.Query(query,
                         {.max_results = 70000, .max_entry_id = bound, .full_scan_postings = 0},
                         &results)
                    .ok());
    results = by_id(results);
    ASSERT_EQ(results.size(), expected.size()) << "bound " << bound;
    for (size_t i = 0; i < results.size(); ++i) {
      ASSERT_EQ(results[i].id, expected[i].id) << "bound " << bound;
      EXPECT_NEAR(results[i].score, expected[i].score, 1e-9) << "entry " << results[i].id;
    }
    // Bounded to its rarest list: exactly that list's entries, each with its whole score.
    ASSERT_TRUE(db.Query(query,
                         {.max_results = 70000,
                          .max_entry_id = bound,
                          .full_scan_postings = 1,
                          .rescored_candidates = 70000},
                         &results)
                    .ok());
    ASSERT_EQ(results.size(), rarest_list) << "bound " << bound;
    for (const QueryResult& r : results) {
      ASSERT_LT(r.id, bound);
      EXPECT_NEAR(r.score, Score(ScoringType::kL1, query, bows[r.id]), 1e-9) << "entry " << r.id;
    }
  }
}

TEST(DatabaseQueryTest, MapsQueriedInTurnOnOneThreadEachGiveTheirOwnAnswer) {
  // A thread's query scratch serves every map it queries: a large map and a small one, queried in
  // turn, give the answers they give alone (the small map's entries are the large one's first).
  // Between two queries of the large map run 250 to 260 of the small one, so that the scratch's
  // one-byte stamps wrap, and the large map's entries come back to the stamp of their last touch.
  auto vocabulary = SmallVocabulary();
  MemoryIndexStore store;
  auto large = Database::Create(&store, "large", vocabulary);
  auto small = Database::Create(&store, "small", vocabulary);
  ASSERT_TRUE(large.ok() && small.ok());
  for (int i = 0; i < 80; ++i) {
    const FeatureSet f = SyntheticFeatures(60, 700 + i);
    ASSERT_TRUE((*large)->Add(f).ok());
    if (i < 7) {
      ASSERT_TRUE((*small)->Add(f).ok());
    }
  }
  BowVector query;
  ASSERT_TRUE(
      vocabulary->Transform(SyntheticFeatures(60, 703).descriptors, &query, nullptr, 0).ok());
  std::vector<QueryResult> large_alone, small_alone, results;
  ASSERT_TRUE((*large)->Query(query, {.max_results = 100}, &large_alone).ok());
  ASSERT_TRUE((*small)->Query(query, {.max_results = 100}, &small_alone).ok());
  ASSERT_EQ(small_alone.size(), 7u);
  ASSERT_GT(large_alone.size(), 7u);
  EXPECT_EQ(large_alone[0].id, 3u);
  EXPECT_EQ(small_alone[0].id, 3u);
  const auto answers_as_alone = [&](const Database& db, const std::vector<QueryResult>& alone) {
    if (!db.Query(query, {.max_results = 100}, &results).ok()) return false;
    return results.size() == alone.size() &&
           std::equal(results.begin(), results.end(), alone.begin(),
                      [](auto& a, auto& b) { return a.id == b.id && a.score == b.score; });
  };
  for (int between = 250; between <= 260; ++between) {
    ASSERT_TRUE(answers_as_alone(**large, large_alone)) << "before " << between << " small ones";
    for (int i = 0; i < between; ++i) ASSERT_TRUE(answers_as_alone(**small, small_alone));
  }
  EXPECT_TRUE(answers_as_alone(**large, large_alone));
}

TEST_F(DatabaseTest, EntriesAtOrAboveTheBoundAreNotScored) {
  const FeatureSet f = SyntheticFeatures(100, 7);
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(db_->Add(f).ok());
  std::vector<QueryResult> results;
  ASSERT_TRUE(db_->Query(BowOf(f), {.max_results = 20, .max_entry_id = 4}, &results).ok());
  ASSERT_EQ(results.size(), 4u);
  for (size_t i = 0; i < results.size(); ++i) EXPECT_EQ(results[i].id, EntryId(i)) << "ties by id";
}

TEST_F(DatabaseTest, AnEntrySharingOnlyZeroWeightsIsStillReturnedWithScoreZero) {
  // A query tells the entries its words touched by their sums; an entry whose only common word
  // weighs 0 in it (written +0 or -0) still shares that word, as the linear merge says, whether
  // the query reads every list or only its rarest one.
  FeatureSet empty;
  empty.descriptors = cv::Mat(0, 32, CV_8U);
  const WordId rare = 3, common = 4;
  for (const float zero : {0.f, -0.f}) {  // entries 0 and 1
    ASSERT_TRUE(db_->AddConverted(BowVector({{rare, zero}}), FeatureVector(), empty, {}).ok());
  }
  for (int i = 0; i < 3; ++i) {  // entries 2 to 4
    ASSERT_TRUE(db_->AddConverted(BowVector({{common, 1.f}}), FeatureVector(), empty, {}).ok());
  }
  const BowVector query({{rare, 0.5f}, {common, 0.5f}});
  for (const size_t budget : {size_t(0), size_t(1)}) {
    std::vector<QueryResult> results;
    ASSERT_TRUE(
        db_->Query(query, {.max_results = 10, .full_scan_postings = budget}, &results).ok());
    // Every list read: entries 2 to 4 first (0.5), then 0 and 1. Only the rarest list read: its
    // two entries.
    ASSERT_EQ(results.size(), budget == 0 ? 5u : 2u) << "budget " << budget;
    const size_t zeros = results.size() - 2;
    for (size_t i = 0; i < results.size(); ++i) {
      const bool zero = i >= results.size() - 2;
      EXPECT_EQ(results[i].id, zero ? EntryId(i - zeros) : EntryId(2 + i)) << "rank " << i;
      EXPECT_EQ(results[i].score, zero ? 0.0 : 0.5) << "rank " << i;
      EXPECT_FALSE(std::signbit(results[i].score)) << "rank " << i << " kept a -0 weight";
    }
  }
}

TEST_F(DatabaseTest, RemovedEntriesLeaveTheIndexAndTheirIdsAreNotReused) {
  const FeatureSet a = SyntheticFeatures(100, 1), b = SyntheticFeatures(100, 2);
  ASSERT_TRUE(db_->Add(a).ok());
  ASSERT_TRUE(db_->Add(b).ok());
  const size_t postings_before = db_->Stats().postings;
  ASSERT_TRUE(db_->Remove(0).ok());
  EXPECT_FALSE(db_->Contains(0));
  EXPECT_EQ(db_->Get(0).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(db_->Remove(0).code(), StatusCode::kNotFound);
  EXPECT_EQ(db_->Stats().postings, postings_before - BowOf(a).size());
  std::vector<QueryResult> results;
  ASSERT_TRUE(db_->Query(BowOf(a), {.max_results = 10}, &results).ok());
  for (const QueryResult& r : results) EXPECT_NE(r.id, 0u);
  EXPECT_EQ(db_->next_entry_id(), 2u);
  auto id = db_->Add(a);
  ASSERT_TRUE(id.ok());
  EXPECT_EQ(*id, 2u);
  EXPECT_EQ(db_->next_entry_id(), 3u);
  ASSERT_TRUE(db_->Clear().ok());
  EXPECT_EQ(db_->size(), 0u);
  EXPECT_EQ(db_->Stats().postings, 0u);
  ASSERT_TRUE(db_->Query(BowOf(a), {}, &results).ok());
  EXPECT_TRUE(results.empty());
}

TEST_F(DatabaseTest, GetReturnsEveryPartAsAdded) {
  const FeatureSet f = SyntheticFeatures(90, 3);
  EntryMetadata meta;
  meta.timestamp = 12.5;
  meta.user_data = std::string("cam\0era-1", 9);
  auto id = db_->Add(f, meta);
  ASSERT_TRUE(id.ok());
  auto record = db_->Get(*id);
  ASSERT_TRUE(record.ok());
  EXPECT_EQ(record->metadata.timestamp, 12.5);
  EXPECT_EQ(record->metadata.user_data, meta.user_data);
  EXPECT_EQ(record->metadata.num_features, 90u);
  EXPECT_EQ(record->keypoints.size(), 90u);
  EXPECT_EQ(cv::norm(record->descriptors, f.descriptors, cv::NORM_HAMMING), 0.0);
  BowVector bow;
  FeatureVector direct;
  ASSERT_TRUE(vocabulary_->Transform(f.descriptors, &bow, &direct, 2).ok());
  EXPECT_EQ(record->bow, bow);
  EXPECT_EQ(record->direct, direct);
}

TEST_F(DatabaseTest, ReopeningRebuildsTheSameIndex) {
  std::vector<FeatureSet> sets;
  for (int i = 0; i < 15; ++i) {
    sets.push_back(SyntheticFeatures(120, 40 + i));
    ASSERT_TRUE(db_->Add(sets.back()).ok());
  }
  ASSERT_TRUE(db_->Remove(14).ok());  // the last id must not come back after the reopen
  std::vector<std::vector<QueryResult>> before(sets.size());
  for (size_t i = 0; i < sets.size(); ++i) {
    ASSERT_TRUE(db_->Query(BowOf(sets[i]), {.max_results = 5}, &before[i]).ok());
  }
  const DatabaseStats stats = db_->Stats();
  db_.reset();
  auto reopened = Database::Open(&store_, "map-1", vocabulary_);
  ASSERT_TRUE(reopened.ok()) << reopened.status().ToString();
  EXPECT_EQ((*reopened)->Stats().postings, stats.postings);
  EXPECT_EQ((*reopened)->size(), 14u);
  for (size_t i = 0; i < sets.size(); ++i) {
    std::vector<QueryResult> after;
    ASSERT_TRUE((*reopened)->Query(BowOf(sets[i]), {.max_results = 5}, &after).ok());
    EXPECT_EQ(after, before[i]);
  }
  auto id = (*reopened)->Add(sets[0]);
  ASSERT_TRUE(id.ok());
  EXPECT_EQ(*id, 15u);
}

// The top-5 answers of `db` to each of `sets`.
std::vector<std::vector<QueryResult>> Answers(const Database& db,
                                              const std::vector<BowVector>& queries) {
  std::vector<std::vector<QueryResult>> answers(queries.size());
  for (size_t i = 0; i < queries.size(); ++i) {
    EXPECT_TRUE(db.Query(queries[i], {.max_results = 5}, &answers[i]).ok());
  }
  return answers;
}

TEST_F(DatabaseTest, ReopeningFromASnapshotGivesTheSameIndexAndReadsOnlyTheLaterEntries) {
  std::vector<BowVector> queries;
  for (int i = 0; i < 20; ++i) {
    const FeatureSet f = SyntheticFeatures(120, 70 + i);
    queries.push_back(BowOf(f));
    ASSERT_TRUE(db_->Add(f).ok());
    if (i == 14) {
      ASSERT_TRUE(db_->Remove(3).ok());  // a hole the snapshot must keep
      auto bytes = db_->SaveSnapshot();
      ASSERT_TRUE(bytes.ok()) << bytes.status().ToString();
      EXPECT_GT(*bytes, 0u);
      EXPECT_EQ(*db_->SaveSnapshot(), 0u);  // nothing changed since
    }
  }
  const auto before = Answers(*db_, queries);
  const DatabaseStats stats = db_->Stats();
  db_.reset();

  auto reopened = Database::Open(&store_, "map-1", vocabulary_);
  ASSERT_TRUE(reopened.ok()) << reopened.status().ToString();
  const DatabaseOpenReport& report = (*reopened)->open_report();
  EXPECT_TRUE(report.from_snapshot);
  EXPECT_EQ(report.snapshot_covers, 15u);
  EXPECT_EQ(report.entries_read, 5u);
  EXPECT_EQ(report.snapshot_rejected, "");
  EXPECT_EQ((*reopened)->Stats().postings, stats.postings);
  EXPECT_EQ((*reopened)->Stats().words_in_use, stats.words_in_use);
  EXPECT_EQ((*reopened)->size(), 19u);
  EXPECT_FALSE((*reopened)->Contains(3));
  EXPECT_EQ(Answers(**reopened, queries), before);
  const FeatureSet added = SyntheticFeatures(120, 90);
  auto id = (*reopened)->Add(added);
  ASSERT_TRUE(id.ok());
  EXPECT_EQ(*id, 20u);
  queries.push_back(BowOf(added));
  const auto loaded_then_added = Answers(**reopened, queries);
  const DatabaseStats loaded_stats = (*reopened)->Stats();

  // The same index as a rebuild from the entries.
  ASSERT_TRUE(store_.DropSnapshot((*reopened)->info().id).ok());
  reopened->reset();
  auto rebuilt = Database::Open(&store_, "map-1", vocabulary_);
  ASSERT_TRUE(rebuilt.ok());
  EXPECT_FALSE((*rebuilt)->open_report().from_snapshot);
  EXPECT_EQ((*rebuilt)->open_report().entries_read, 20u);
  EXPECT_EQ((*rebuilt)->Stats().postings, loaded_stats.postings);
  EXPECT_EQ(Answers(**rebuilt, queries), loaded_then_added);
}

TEST_F(DatabaseTest, ARemovalAfterASnapshotMakesTheNextOpenRebuild) {
  for (int i = 0; i < 6; ++i) ASSERT_TRUE(db_->Add(SyntheticFeatures(100, 200 + i)).ok());
  ASSERT_TRUE(db_->SaveSnapshot().ok());
  ASSERT_TRUE(db_->Remove(2).ok());
  db_.reset();
  auto reopened = Database::Open(&store_, "map-1", vocabulary_);
  ASSERT_TRUE(reopened.ok());
  EXPECT_FALSE((*reopened)->open_report().from_snapshot);
  EXPECT_EQ((*reopened)->open_report().snapshot_rejected, "");
  EXPECT_EQ((*reopened)->open_report().entries_read, 5u);
  EXPECT_FALSE((*reopened)->Contains(2));
  // The next save writes a new snapshot, which the next open uses.
  EXPECT_GT(*(*reopened)->SaveSnapshot(), 0u);
  reopened->reset();
  reopened = Database::Open(&store_, "map-1", vocabulary_);
  ASSERT_TRUE(reopened.ok());
  EXPECT_TRUE((*reopened)->open_report().from_snapshot);
  EXPECT_EQ((*reopened)->size(), 5u);
}

// A store whose snapshots come back altered by `damage`.
class SnapshotDamagingStore : public MemoryIndexStore {
 public:
  std::function<void(std::string*)> damage;

  StatusOr<std::unique_ptr<SnapshotReader>> ReadSnapshot(MapId map) override {
    RECOG_ASSIGN_OR_RETURN(std::unique_ptr<SnapshotReader> reader,
                           MemoryIndexStore::ReadSnapshot(map));
    std::string bytes(reader->size(), '\0');
    RECOG_RETURN_IF_ERROR(reader->Read(bytes.data(), bytes.size()));
    damage(&bytes);
    return std::unique_ptr<SnapshotReader>(new BytesReader(reader->covers(), std::move(bytes)));
  }

 private:
  class BytesReader : public SnapshotReader {
   public:
    BytesReader(EntryId covers, std::string bytes) : covers_(covers), bytes_(std::move(bytes)) {}
    EntryId covers() const override { return covers_; }
    uint64_t size() const override { return bytes_.size(); }
    Status Read(void* out, size_t size) override {
      if (size == 0) return Status::Ok();
      if (bytes_.size() - position_ < size) return Status::DataLoss("the snapshot ends early");
      std::memcpy(out, bytes_.data() + position_, size);
      position_ += size;
      return Status::Ok();
    }

   private:
    EntryId covers_;
    std::string bytes_;
    size_t position_ = 0;
  };
};

TEST(DatabaseSnapshotTest, ADamagedSnapshotIsRejectedDroppedAndTheIndexRebuilt) {
  SnapshotDamagingStore store;
  const auto vocabulary = SmallVocabulary();
  std::vector<BowVector> queries;
  std::vector<std::vector<QueryResult>> expected;
  {
    auto db = Database::Create(&store, "m", vocabulary);
    ASSERT_TRUE(db.ok());
    for (int i = 0; i < 8; ++i) {
      const FeatureSet f = SyntheticFeatures(100, 300 + i);
      ASSERT_TRUE((*db)->Add(f).ok());
      BowVector bow;
      ASSERT_TRUE(vocabulary->Transform(f.descriptors, &bow).ok());
      queries.push_back(std::move(bow));
    }
    expected = Answers(**db, queries);
  }
  // The header (magic, map id), an entry flag, a posting's entry id, the checksum, a cut end, a
  // byte too many and lengths beyond the snapshot. The header is 56 bytes, the 8 entry flags
  // follow, then the lists.
  const std::vector<std::pair<std::string, std::function<void(std::string*)>>> damages = {
      {"magic", [](std::string* b) { (*b)[0] ^= 1; }},
      {"map id", [](std::string* b) { (*b)[12] ^= 1; }},
      {"entry flag", [](std::string* b) { (*b)[58] = 0; }},
      {"posting", [](std::string* b) { (*b)[b->size() / 2] ^= 0x10; }},
      {"checksum", [](std::string* b) { b->back() ^= 1; }},
      {"cut", [](std::string* b) { b->resize(b->size() - 9); }},
      {"trailing byte", [](std::string* b) { b->push_back('x'); }},
      // A header and a first list that claim 2^31 postings: refused before anything is allocated.
      {"huge list",
       [](std::string* b) {
         const uint64_t postings = uint64_t(1) << 31;
         std::memcpy(b->data() + 48, &postings, sizeof(postings));
         const uint32_t count = uint32_t(postings);
         std::memcpy(b->data() + 56 + 8, &count, sizeof(count));
       }},
  };
  for (const auto& [what, damage] : damages) {
    SCOPED_TRACE(what);
    {
      auto db = Database::Open(&store, "m", vocabulary);
      ASSERT_TRUE(db.ok());
      ASSERT_TRUE((*db)->SaveSnapshot().ok());
    }
    store.damage = damage;
    auto db = Database::Open(&store, "m", vocabulary);
    store.damage = [](std::string*) {};
    ASSERT_TRUE(db.ok()) << db.status().ToString();
    EXPECT_FALSE((*db)->open_report().from_snapshot);
    EXPECT_NE((*db)->open_report().snapshot_rejected, "");
    EXPECT_EQ((*db)->open_report().entries_read, 8u);
    EXPECT_EQ((*db)->size(), 8u);
    EXPECT_EQ(Answers(**db, queries), expected);
    EXPECT_EQ(store.ReadSnapshot((*db)->info().id).status().code(), StatusCode::kNotFound);
  }
}

TEST_F(DatabaseTest, AnotherVocabularyIsRefused) {
  auto other = SmallVocabulary(/*seed=*/99);
  ASSERT_NE(other->checksum(), vocabulary_->checksum());
  auto opened = Database::Open(&store_, "map-1", other);
  EXPECT_EQ(opened.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(opened.status().message().find("map-1"), std::string::npos);
  EXPECT_EQ(Database::Open(&store_, "no-such-map", vocabulary_).status().code(),
            StatusCode::kNotFound);
  EXPECT_EQ(Database::Create(&store_, "map-1", vocabulary_).status().code(),
            StatusCode::kAlreadyExists);
  EXPECT_EQ(Database::Create(&store_, "bad name!", vocabulary_).status().code(),
            StatusCode::kInvalidArgument);
}

TEST_F(DatabaseTest, EntriesThatDoNotFitAreRefusedAndNothingIsStored) {
  const FeatureSet f = SyntheticFeatures(50, 5);
  BowVector bow;
  FeatureVector direct;
  ASSERT_TRUE(vocabulary_->Transform(f.descriptors, &bow, &direct, 2).ok());

  BowVector foreign_word({{WordId(vocabulary_->num_words() + 3), 1.f}});
  EXPECT_EQ(db_->AddConverted(foreign_word, direct, f).status().code(),
            StatusCode::kInvalidArgument);
  FeatureVector short_direct;
  EXPECT_EQ(db_->AddConverted(bow, short_direct, f).status().code(), StatusCode::kInvalidArgument);
  FeatureSet missing_keypoints = f;
  missing_keypoints.keypoints.pop_back();
  EXPECT_EQ(db_->AddConverted(bow, direct, missing_keypoints).status().code(),
            StatusCode::kInvalidArgument);
  FeatureSet wrong_length = f;
  wrong_length.descriptors = cv::Mat(50, 64, CV_8U, cv::Scalar(1));
  EXPECT_EQ(db_->Add(wrong_length).status().code(), StatusCode::kInvalidArgument);
  EntryMetadata huge;
  huge.user_data.assign(70000, 'x');
  EXPECT_EQ(db_->Add(f, huge).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(db_->size(), 0u);
  EXPECT_EQ(store_.NextEntryId(db_->info().id).value(), 0u);

  std::vector<QueryResult> results;
  EXPECT_EQ(db_->Query(foreign_word, {}, &results).code(), StatusCode::kInvalidArgument);
}

TEST_F(DatabaseTest, AnEmptyImageIsAValidEntry) {
  FeatureSet empty;
  empty.descriptors = cv::Mat(0, 32, CV_8U);
  auto id = db_->Add(empty);
  ASSERT_TRUE(id.ok()) << id.status().ToString();
  EXPECT_TRUE(db_->Contains(*id));
}

TEST_F(DatabaseTest, OpeningAStoreWithInconsistentEntriesIsDataLoss) {
  ASSERT_TRUE(db_->Add(SyntheticFeatures(60, 1)).ok());
  auto record = db_->Get(0);
  ASSERT_TRUE(record.ok());
  record->id = 1;
  record->metadata.num_features = 10;  // the direct index refers to 60 features
  ASSERT_TRUE(store_.CommitEntry(db_->info().id, *record).ok());
  db_.reset();
  auto opened = Database::Open(&store_, "map-1", vocabulary_);
  EXPECT_EQ(opened.status().code(), StatusCode::kDataLoss);
  EXPECT_NE(opened.status().message().find("entry 1"), std::string::npos)
      << opened.status().message();
}

TEST_F(DatabaseTest, PostingsTakeAboutThreeBytesEach) {
  for (int i = 0; i < 200; ++i) ASSERT_TRUE(db_->Add(SyntheticFeatures(150, 3000 + i)).ok());
  const DatabaseStats stats = db_->Stats();
  ASSERT_GT(stats.postings, 10000u);
  EXPECT_EQ(stats.values_stored_aside, 0u);
  // Beyond the lists: one PostingList per word, a flag (1 byte) and a scale (4) per entry.
  const double list_bytes = double(stats.index_bytes) -
                            double(vocabulary_->num_words() * sizeof(PostingList)) - 200.0 * 5;
  EXPECT_LE(list_bytes / double(stats.postings), 3.6);
}

TEST_F(DatabaseTest, ConcurrentQueriesWhileAddingGiveTheSerialResults) {
  // 40 entries first; then one thread adds 60 more while three threads query the first 40 (the
  // bound keeps the answers independent of the adds) and must get the serial answers every time.
  for (int i = 0; i < 40; ++i) ASSERT_TRUE(db_->Add(SyntheticFeatures(100, 700 + i)).ok());
  std::vector<BowVector> queries;
  std::vector<std::vector<QueryResult>> serial(10);
  for (int q = 0; q < 10; ++q) {
    queries.push_back(BowOf(SyntheticFeatures(100, 700 + q * 3)));
    ASSERT_TRUE(db_->Query(queries[q], {.max_results = 5, .max_entry_id = 40}, &serial[q]).ok());
  }
  std::atomic<bool> adding{true};
  std::atomic<int> mismatches{0}, queries_run{0};
  std::thread writer([&] {
    for (int i = 0; i < 60; ++i) EXPECT_TRUE(db_->Add(SyntheticFeatures(100, 800 + i)).ok());
    adding = false;
  });
  std::vector<std::thread> readers;
  for (int t = 0; t < 3; ++t) {
    readers.emplace_back([&, t] {
      std::vector<QueryResult> results;
      for (int n = 0; adding || n < 20; ++n) {
        const int q = (n + t) % 10;
        if (!db_->Query(queries[q], {.max_results = 5, .max_entry_id = 40}, &results).ok() ||
            results != serial[q]) {
          ++mismatches;
        }
        ++queries_run;
      }
    });
  }
  writer.join();
  for (std::thread& r : readers) r.join();
  EXPECT_EQ(mismatches.load(), 0);
  EXPECT_GE(queries_run.load(), 60);
  EXPECT_EQ(db_->size(), 100u);
  // And the final state equals a database built serially from the same entries.
  MemoryIndexStore serial_store;
  auto serial_db = Database::Create(&serial_store, "serial", vocabulary_);
  ASSERT_TRUE(serial_db.ok());
  for (int i = 0; i < 40; ++i) ASSERT_TRUE((*serial_db)->Add(SyntheticFeatures(100, 700 + i)).ok());
  for (int i = 0; i < 60; ++i) ASSERT_TRUE((*serial_db)->Add(SyntheticFeatures(100, 800 + i)).ok());
  for (const BowVector& q : queries) {
    std::vector<QueryResult> a, b;
    ASSERT_TRUE(db_->Query(q, {.max_results = 10}, &a).ok());
    ASSERT_TRUE((*serial_db)->Query(q, {.max_results = 10}, &b).ok());
    EXPECT_EQ(a, b);
  }
}

}  // namespace
}  // namespace recog

namespace recog {
namespace {

TEST(DatabaseBcMatchingTest, KeepsBhattacharyyaCandidatesWithinBetaRankedByChiSquare) {
  MemoryIndexStore store;
  auto vocabulary = SmallVocabulary();
  auto db = Database::Create(&store, "objects", vocabulary, ScoringType::kBhattacharyya);
  ASSERT_TRUE(db.ok());
  std::vector<BowVector> bows;
  for (int i = 0; i < 40; ++i) {
    const FeatureSet f = SyntheticFeatures(60 + i % 30, 700 + i);
    ASSERT_TRUE((*db)->Add(f).ok());
    BowVector bow;
    ASSERT_TRUE(vocabulary->Transform(f.descriptors, &bow, nullptr, 0, BowNormalization::kL1).ok());
    bows.push_back(bow);
  }
  for (int q = 0; q < 8; ++q) {
    BowVector query;
    ASSERT_TRUE(vocabulary
                    ->Transform(SyntheticFeatures(50, 950 + q).descriptors, &query, nullptr, 0,
                                BowNormalization::kL1)
                    .ok());
    for (const double beta : {0.0, 0.5, 0.9}) {
      // Brute force: both scores of every entry, then Algorithm 5's selection.
      std::vector<BcMatch> expected;
      double best = 0;
      for (EntryId id = 0; id < bows.size(); ++id) {
        const double b = Score(ScoringType::kBhattacharyya, query, bows[id]);
        // The chi-square score is s_chi2 = 1 - chi2 / 2 (eq. 5.12).
        const double c = Score(ScoringType::kChiSquare, query, bows[id]);
        if (b > 0) expected.push_back({id, b, c});
        best = std::max(best, b);
      }
      std::erase_if(expected, [&](const BcMatch& m) { return m.bhattacharyya < beta * best; });
      std::stable_sort(expected.begin(), expected.end(), [](const BcMatch& a, const BcMatch& b) {
        return a.chi_square > b.chi_square;
      });
      std::vector<BcMatch> results;
      ASSERT_TRUE((*db)->QueryBcMatching(query, beta, 100, &results).ok());
      ASSERT_EQ(results.size(), expected.size()) << "beta " << beta;
      for (size_t i = 0; i < results.size(); ++i) {
        EXPECT_NEAR(results[i].bhattacharyya, expected[i].bhattacharyya, 1e-5);
        EXPECT_NEAR(results[i].chi_square, expected[i].chi_square, 1e-5);
      }
      if (beta > 0.8) {
        EXPECT_LT(results.size(), bows.size());
      }
    }
  }
}

TEST(DatabaseBcMatchingTest, RefusesMapsThatAreNotL1Normalised) {
  MemoryIndexStore store;
  auto db = Database::Create(&store, "places", SmallVocabulary(), ScoringType::kL2);
  ASSERT_TRUE(db.ok());
  std::vector<BcMatch> results;
  EXPECT_EQ((*db)->QueryBcMatching(BowVector(), 0.5, 10, &results).code(),
            StatusCode::kFailedPrecondition);
}

TEST_F(DatabaseTest, ObjectEntriesKeepTheirThreeDPoints) {
  const FeatureSet f = SyntheticFeatures(30, 5);
  BowVector bow;
  FeatureVector direct;
  ASSERT_TRUE(vocabulary_->Transform(f.descriptors, &bow, &direct, 2).ok());
  std::vector<cv::Point3f> points;
  for (int i = 0; i < 30; ++i) points.emplace_back(float(i), float(-i), 0.5f);
  auto id = db_->AddConverted(bow, direct, f, {}, points);
  ASSERT_TRUE(id.ok()) << id.status().ToString();
  auto record = db_->Get(*id);
  ASSERT_TRUE(record.ok());
  EXPECT_EQ(record->points, points);
  points.pop_back();
  EXPECT_EQ(db_->AddConverted(bow, direct, f, {}, points).status().code(),
            StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace recog
