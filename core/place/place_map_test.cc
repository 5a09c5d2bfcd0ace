#include "core/place/place_map.h"

#include <set>
#include <thread>

#include <gtest/gtest.h>

#include "core/index/memory_index_store.h"
#include "core/place/map_registry.h"
#include "core/place/place_test_frames.h"

namespace recog {
namespace {

class PlaceMapTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    vocabulary_ = new std::shared_ptr<const Vocabulary>(testing::TrainPlacesVocabulary());
    tour_ = new std::vector<FeatureSet>(testing::Extract(testing::TourWithRevisits()));
  }
  static void TearDownTestSuite() {
    delete vocabulary_;
    delete tour_;
  }

  void SetUp() override {
    ASSERT_NE(*vocabulary_, nullptr);
    auto registry = MapRegistry::Open(&store_, *vocabulary_);
    ASSERT_TRUE(registry.ok()) << registry.status().ToString();
    registry_ = std::move(registry).value();
    params_.recent_frames = 4;
    params_.recent_seconds = 4;
    params_.temporal_matches = 2;
  }

  std::shared_ptr<PlaceMap> Create(const std::string& name, const LoopDetectorParams& params) {
    auto map = registry_->Create(name, params);
    EXPECT_TRUE(map.ok()) << map.status().ToString();
    return map.ok() ? map.value() : nullptr;
  }

  // Adds the first visits of places 0 1 2 3 (frames 0..15, timestamp = frame index).
  static void AddFirstVisits(PlaceMap& map) {
    for (size_t i = 0; i < 16; ++i) {
      auto added = map.Add((*tour_)[i], double(i));
      ASSERT_TRUE(added.ok()) << added.status().ToString();
      EXPECT_EQ(added->loop.entry, EntryId(i));
      EXPECT_EQ(added->loop.match, kInvalidEntryId);
      EXPECT_FALSE(added->match_timestamp.has_value());
    }
  }

  static std::shared_ptr<const Vocabulary>* vocabulary_;
  static std::vector<FeatureSet>* tour_;
  MemoryIndexStore store_;
  std::unique_ptr<MapRegistry> registry_;
  LoopDetectorParams params_;
};
std::shared_ptr<const Vocabulary>* PlaceMapTest::vocabulary_ = nullptr;
std::vector<FeatureSet>* PlaceMapTest::tour_ = nullptr;

TEST_F(PlaceMapTest, QueryFindsTheAddedPlaceAndChangesNothing) {
  std::shared_ptr<PlaceMap> map = Create("m", params_);
  ASSERT_NE(map, nullptr);
  AddFirstVisits(*map);
  const std::vector<FeatureSet>& tour = *tour_;
  for (size_t i = 16; i < tour.size(); ++i) {
    auto r = map->Query(tour[i]);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    const EntryId first_visit = i < 20 ? 0 : 4;
    EXPECT_EQ(r->loop.status, LoopStatus::kLoopDetected) << i;
    EXPECT_EQ(r->loop.entry, kInvalidEntryId);
    EXPECT_GE(r->loop.match, first_visit) << i;
    EXPECT_LT(r->loop.match, first_visit + 4) << i;
    ASSERT_TRUE(r->match_timestamp.has_value());
    EXPECT_EQ(*r->match_timestamp, double(r->loop.match));  // the timestamp it was added with
    EXPECT_FALSE(r->fundamental.has_value());               // not asked for
    EXPECT_FALSE(r->relative_pose.has_value());
  }
  EXPECT_EQ(map->frames(), 16u);
  EXPECT_EQ(map->next_frame_id(), 16u);
}

TEST_F(PlaceMapTest, DetectQueriesThenAddsAsTheLoopDetectorDoes) {
  std::shared_ptr<PlaceMap> map = Create("m", params_);
  ASSERT_NE(map, nullptr);
  MemoryIndexStore store;
  auto db = Database::Create(&store, "reference", *vocabulary_);
  ASSERT_TRUE(db.ok());
  auto reference = LoopDetector::Create(db->get(), params_);
  ASSERT_TRUE(reference.ok());
  int loops = 0;
  for (size_t i = 0; i < tour_->size(); ++i) {
    auto r = map->Detect((*tour_)[i], double(i));
    auto expected = reference->Process((*tour_)[i], double(i));
    ASSERT_TRUE(r.ok() && expected.ok());
    EXPECT_EQ(r->loop.entry, EntryId(i));
    EXPECT_EQ(r->loop.status, expected->status) << i;
    EXPECT_EQ(r->loop.match, expected->match) << i;
    EXPECT_EQ(r->loop.inliers, expected->inliers) << i;
    EXPECT_EQ(r->match_timestamp.has_value(), expected->match != kInvalidEntryId) << i;
    if (r->loop.status == LoopStatus::kLoopDetected) ++loops;
  }
  EXPECT_GT(loops, 0);
  EXPECT_EQ(map->frames(), tour_->size());
}

TEST_F(PlaceMapTest, ExtrasComeOnlyWhenAskedAndVerifiedAndThePoseNeedsTheCamera) {
  std::shared_ptr<PlaceMap> map = Create("m", params_);
  ASSERT_NE(map, nullptr);
  AddFirstVisits(*map);
  const FeatureSet& revisit = (*tour_)[17];

  PlaceResultOptions fundamental_only;
  fundamental_only.include_fundamental = true;
  auto r = map->Query(revisit, fundamental_only);
  ASSERT_TRUE(r.ok());
  ASSERT_EQ(r->loop.status, LoopStatus::kLoopDetected);
  ASSERT_FALSE(r->loop.inliers.empty());
  ASSERT_TRUE(r->fundamental.has_value());
  EXPECT_EQ(*r->fundamental, r->loop.fundamental);
  EXPECT_NE(cv::norm(*r->fundamental), 0.0);
  EXPECT_FALSE(r->relative_pose.has_value());

  PlaceResultOptions pose;
  pose.include_relative_pose = true;
  r = map->Query(revisit, pose);  // no camera matrix: no pose
  ASSERT_TRUE(r.ok());
  EXPECT_FALSE(r->relative_pose.has_value());
  EXPECT_FALSE(r->fundamental.has_value());

  // Without geometric verification a loop has no inliers and so no extras, asked or not.
  LoopDetectorParams unverified = params_;
  unverified.geometry = GeometryCheck::kNone;
  std::shared_ptr<PlaceMap> plain = Create("plain", unverified);
  ASSERT_NE(plain, nullptr);
  AddFirstVisits(*plain);
  PlaceResultOptions everything = pose;
  everything.include_fundamental = true;
  everything.camera_matrix = cv::Matx33d(400, 0, 128, 0, 400, 192, 0, 0, 1);
  r = plain->Query(revisit, everything);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->loop.status, LoopStatus::kLoopDetected);
  EXPECT_TRUE(r->match_timestamp.has_value());
  EXPECT_FALSE(r->fundamental.has_value());
  EXPECT_FALSE(r->relative_pose.has_value());
}

// The client's id of frame i of the tour in these tests.
std::string ClientId(size_t i) { return "kf-" + std::to_string(i); }

TEST_F(PlaceMapTest, TheMatchAndTheTopCandidatesComeWithTheirClientIdsAndTheInliersAsPixels) {
  std::shared_ptr<PlaceMap> map = Create("m", params_);
  ASSERT_NE(map, nullptr);
  for (size_t i = 0; i < 16; ++i) ASSERT_TRUE(map->Add((*tour_)[i], double(i), ClientId(i)).ok());
  const FeatureSet& revisit = (*tour_)[17];

  auto plain = map->Query(revisit);
  ASSERT_TRUE(plain.ok());
  ASSERT_EQ(plain->loop.status, LoopStatus::kLoopDetected);
  EXPECT_EQ(plain->match_client_id, ClientId(plain->loop.match));  // always, asked or not
  EXPECT_TRUE(plain->candidates.empty());                          // not asked for
  EXPECT_TRUE(plain->correspondences.empty());
  ASSERT_GT(plain->loop.candidates.size(), 3u);

  PlaceResultOptions options;
  options.top_k = 3;
  options.include_correspondences = true;
  auto r = map->Query(revisit, options);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->loop.status, LoopStatus::kLoopDetected);
  ASSERT_EQ(r->candidates.size(), 3u);
  const double best = r->candidates[0].score;
  bool match_listed = false;
  for (size_t i = 0; i < r->candidates.size(); ++i) {
    const PlaceCandidate& c = r->candidates[i];
    EXPECT_EQ(c.frame, r->loop.candidates[i].entry);  // the query's order: best score first
    if (i > 0) {
      EXPECT_LE(c.score, r->candidates[i - 1].score);
    }
    EXPECT_EQ(c.client_id, ClientId(c.frame));
    EXPECT_DOUBLE_EQ(c.normalized_score, c.score / best);  // a query normalises by the best
    if (c.frame == r->loop.match) {
      match_listed = true;
      ASSERT_TRUE(c.inliers.has_value());
      EXPECT_EQ(*c.inliers, r->loop.inliers.size());
    } else {
      EXPECT_FALSE(c.inliers.has_value()) << c.frame;
    }
  }
  EXPECT_TRUE(match_listed);
  options.top_k = PlaceResultOptions::kMaxTopK;  // more than the query returned: all of them
  auto all = map->Query(revisit, options);
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->candidates.size(), all->loop.candidates.size());

  ASSERT_FALSE(r->loop.inliers.empty());
  ASSERT_EQ(r->correspondences.size(), r->loop.inliers.size());
  const FeatureSet& matched = (*tour_)[r->loop.match];  // what the map stored for the match
  for (size_t i = 0; i < r->correspondences.size(); ++i) {
    const PlaceCorrespondence& c = r->correspondences[i];
    EXPECT_EQ(c.query_index, r->loop.inliers[i].a);
    EXPECT_EQ(c.match_index, r->loop.inliers[i].b);
    ASSERT_LT(c.query_index, revisit.keypoints.size());
    ASSERT_LT(c.match_index, matched.keypoints.size());
    EXPECT_EQ(c.query_pixel, revisit.keypoints[c.query_index].pt);
    EXPECT_EQ(c.match_pixel, matched.keypoints[c.match_index].pt);
  }
}

TEST_F(PlaceMapTest, DetectReturnsTheClientIdsOfItsMatchesAndBadOptionsAddNothing) {
  std::shared_ptr<PlaceMap> map = Create("m", params_);
  ASSERT_NE(map, nullptr);
  PlaceResultOptions too_many;
  too_many.top_k = PlaceResultOptions::kMaxTopK + 1;
  auto refused = map->Detect((*tour_)[0], 0, too_many, ClientId(0));
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(map->Query((*tour_)[0], too_many).status().code(), StatusCode::kInvalidArgument);
  auto too_long = map->Detect((*tour_)[0], 0, {}, std::string(kMaxClientIdBytes + 1, 'x'));
  EXPECT_EQ(too_long.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(map->Add((*tour_)[0], 0, std::string(kMaxClientIdBytes + 1, 'x')).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(map->frames(), 0u);
  EXPECT_EQ(map->next_frame_id(), 0u);

  PlaceResultOptions options;
  options.top_k = 2;
  int loops = 0;
  for (size_t i = 0; i < tour_->size(); ++i) {
    auto r = map->Detect((*tour_)[i], double(i), options, ClientId(i));
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_EQ(r->loop.entry, EntryId(i));
    EXPECT_LE(r->candidates.size(), 2u);
    for (const PlaceCandidate& c : r->candidates) {
      EXPECT_EQ(c.client_id, ClientId(c.frame));
      EXPECT_DOUBLE_EQ(c.normalized_score, c.score / r->loop.previous_score);  // eq. 3.11
    }
    if (r->loop.match != kInvalidEntryId) {
      EXPECT_EQ(r->match_client_id, ClientId(r->loop.match));
    }
    if (r->loop.status == LoopStatus::kLoopDetected) ++loops;
  }
  EXPECT_GT(loops, 0);
}

TEST_F(PlaceMapTest, ARemovedFrameIsNeverACandidateAgain) {
  std::shared_ptr<PlaceMap> map = Create("m", params_);
  ASSERT_NE(map, nullptr);
  // The first visit of place 0 is frames 0..3; frames 2 and 3 share one client id.
  for (size_t i = 0; i < 16; ++i) {
    ASSERT_TRUE(map->Add((*tour_)[i], double(i), i == 3 ? ClientId(2) : ClientId(i)).ok());
  }
  PlaceResultOptions options;
  options.top_k = PlaceResultOptions::kMaxTopK;
  const FeatureSet& revisit = (*tour_)[17];  // place 0 again
  auto before = map->Query(revisit, options);
  ASSERT_TRUE(before.ok());
  ASSERT_EQ(before->loop.status, LoopStatus::kLoopDetected);
  ASSERT_LT(before->loop.match, 4u);

  EXPECT_TRUE(map->RemoveFrame(0).ok());
  EXPECT_TRUE(map->RemoveFrame(1).ok());
  auto removed = map->RemoveFramesByClientId(ClientId(2));
  ASSERT_TRUE(removed.ok()) << removed.status().ToString();
  EXPECT_EQ(*removed, (std::vector<EntryId>{2, 3}));
  EXPECT_EQ(map->frames(), 12u);
  EXPECT_EQ(map->next_frame_id(), 16u);

  auto after = map->Query(revisit, options);
  ASSERT_TRUE(after.ok());
  EXPECT_TRUE(after->loop.match == kInvalidEntryId || after->loop.match >= 4u) << after->loop.match;
  for (const PlaceCandidate& c : after->candidates) EXPECT_GE(c.frame, 4u);
  for (const LoopCandidate& c : after->loop.candidates) EXPECT_GE(c.entry, 4u);

  // Unknown (or already removed) frames and client ids.
  EXPECT_EQ(map->RemoveFrame(0).code(), StatusCode::kNotFound);
  EXPECT_EQ(map->RemoveFrame(999).code(), StatusCode::kNotFound);
  EXPECT_EQ(map->RemoveFramesByClientId(ClientId(2)).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(map->RemoveFramesByClientId("").status().code(), StatusCode::kInvalidArgument);
  // A new frame gets a new id, never a removed one.
  auto added = map->Add((*tour_)[0], 20, ClientId(0));
  ASSERT_TRUE(added.ok());
  EXPECT_EQ(added->loop.entry, 16u);

  ASSERT_TRUE(registry_->Delete("m").ok());
  EXPECT_EQ(map->RemoveFrame(4).code(), StatusCode::kNotFound);
  EXPECT_EQ(map->RemoveFramesByClientId(ClientId(5)).status().code(), StatusCode::kNotFound);
}

TEST_F(PlaceMapTest, ADeletedMapRefusesWrites) {
  std::shared_ptr<PlaceMap> map = Create("gone", params_);
  ASSERT_NE(map, nullptr);
  ASSERT_TRUE(map->Add((*tour_)[0], 0).ok());
  EXPECT_FALSE(map->deleted());
  auto frames = registry_->Delete("gone");
  ASSERT_TRUE(frames.ok());
  EXPECT_EQ(*frames, 1u);
  EXPECT_TRUE(map->deleted());
  auto added = map->Add((*tour_)[1], 1);
  EXPECT_EQ(added.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(added.status().message(), "map 'gone' was deleted");
  EXPECT_EQ(map->Detect((*tour_)[1], 1).status().code(), StatusCode::kNotFound);
}

TEST_F(PlaceMapTest, TwoThreadsAddingToOneMapGetDistinctConsecutiveIds) {
  std::shared_ptr<PlaceMap> map = Create("shared", params_);
  ASSERT_NE(map, nullptr);
  std::vector<EntryId> ids[2];
  std::vector<std::thread> threads;
  for (int t = 0; t < 2; ++t) {
    threads.emplace_back([&, t] {
      for (size_t i = size_t(t); i < tour_->size(); i += 2) {
        auto r = t == 0 ? map->Add((*tour_)[i], 0) : map->Detect((*tour_)[i], 0);
        ASSERT_TRUE(r.ok()) << r.status().ToString();
        ids[t].push_back(r->loop.entry);
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  std::set<EntryId> all(ids[0].begin(), ids[0].end());
  all.insert(ids[1].begin(), ids[1].end());
  ASSERT_EQ(all.size(), tour_->size());  // no id given twice
  EXPECT_EQ(*all.begin(), 0u);
  EXPECT_EQ(*all.rbegin(), EntryId(tour_->size() - 1));
  EXPECT_EQ(map->frames(), tour_->size());
  EXPECT_EQ(map->next_frame_id(), EntryId(tour_->size()));
  for (const auto& per_thread : ids) {  // each thread's frames got increasing ids
    EXPECT_TRUE(std::is_sorted(per_thread.begin(), per_thread.end()));
  }
}

}  // namespace
}  // namespace recog
