#include "core/place/loop_detector.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/features/feature_extractor.h"
#include "core/index/memory_index_store.h"
#include "core/place/place_test_frames.h"
#include "tests/testing/option_cases.h"

namespace recog {
namespace {

using testing::Extract;
using testing::Places;
using testing::TourWithRevisits;
using testing::Visit;

class LoopDetectorTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    vocabulary_ = new std::shared_ptr<const Vocabulary>(testing::TrainPlacesVocabulary());
    ASSERT_NE(*vocabulary_, nullptr);
  }
  static void TearDownTestSuite() { delete vocabulary_; }

  void SetUp() override {
    auto db = Database::Create(&store_, "seq", *vocabulary_);
    ASSERT_TRUE(db.ok());
    db_ = std::move(db).value();
    params_.recent_frames = 4;
    params_.temporal_matches = 2;
  }

  std::vector<LoopResult> Run(const std::vector<cv::Mat>& frames, LoopDetectorParams params,
                              Database* db = nullptr) {
    auto detector = LoopDetector::Create(db ? db : db_.get(), params);
    EXPECT_TRUE(detector.ok()) << detector.status().ToString();
    auto extractor = CreateFeatureExtractor(FeatureOptions{});
    std::vector<LoopResult> results;
    for (const cv::Mat& frame : frames) {
      FeatureSet f;
      EXPECT_TRUE((*extractor)->Extract(frame, &f).ok());
      auto r = detector->Process(f);
      EXPECT_TRUE(r.ok()) << r.status().ToString();
      results.push_back(std::move(r).value());
    }
    return results;
  }

  // Every field but the timings.
  static void ExpectSameResult(const LoopResult& a, const LoopResult& b, const std::string& where) {
    EXPECT_EQ(a.status, b.status) << where;
    EXPECT_EQ(a.entry, b.entry) << where;
    EXPECT_EQ(a.match, b.match) << where;
    EXPECT_EQ(a.score, b.score) << where;
    EXPECT_EQ(a.normalized_score, b.normalized_score) << where;
    EXPECT_EQ(a.previous_score, b.previous_score) << where;
    EXPECT_EQ(a.island_first, b.island_first) << where;
    EXPECT_EQ(a.island_last, b.island_last) << where;
    EXPECT_EQ(a.island_score, b.island_score) << where;
    EXPECT_EQ(a.consistent_queries, b.consistent_queries) << where;
    EXPECT_EQ(a.correspondences, b.correspondences) << where;
    EXPECT_EQ(a.inliers, b.inliers) << where;
    EXPECT_EQ(a.fundamental, b.fundamental) << where;
  }

  // Run with every frame calibrated (camera matrix `K`, no 3D points), from `features`.
  std::vector<LoopResult> RunCalibrated(const std::vector<FeatureSet>& features,
                                        const LoopDetectorParams& params, Database* db) {
    auto detector = LoopDetector::Create(db, params);
    EXPECT_TRUE(detector.ok()) << detector.status().ToString();
    FrameGeometry geometry;
    geometry.K = cv::Matx33d(300, 0, 128, 0, 300, 192, 0, 0, 1);
    std::vector<LoopResult> results;
    for (const FeatureSet& f : features) {
      auto r = detector->Process(f, std::nullopt, {}, &geometry);
      EXPECT_TRUE(r.ok()) << r.status().ToString();
      results.push_back(std::move(r).value());
    }
    return results;
  }

  std::unique_ptr<Database> NewDatabase(const std::string& name) {
    auto db = Database::Create(&store_, name, *vocabulary_);
    EXPECT_TRUE(db.ok());
    return std::move(db).value();
  }

  static std::shared_ptr<const Vocabulary>* vocabulary_;
  MemoryIndexStore store_;
  std::unique_ptr<Database> db_;
  LoopDetectorParams params_;
};
std::shared_ptr<const Vocabulary>* LoopDetectorTest::vocabulary_ = nullptr;

TEST_F(LoopDetectorTest, RevisitsAreDetectedOnceTheIslandIsTemporallyConsistent) {
  const std::vector<LoopResult> results = Run(TourWithRevisits(), params_);
  ASSERT_EQ(results.size(), 24u);
  int detections = 0;
  for (size_t i = 0; i < results.size(); ++i) {
    const LoopResult& r = results[i];
    EXPECT_EQ(r.entry, EntryId(i));
    if (r.status != LoopStatus::kLoopDetected) continue;
    ++detections;
    ASSERT_GE(i, 16u) << "only revisit frames can close a loop";
    const EntryId first_visit = i < 20 ? 0 : 4;  // place 0 at frames 0-3, place 1 at 4-7
    EXPECT_GE(r.match, first_visit);
    EXPECT_LT(r.match, first_visit + 4);
    EXPECT_GE(r.inliers.size(), 12u);
    EXPECT_GE(r.normalized_score, params_.alpha);
    EXPECT_GE(r.consistent_queries, params_.temporal_matches);
    EXPECT_LE(r.island_first, r.match);
    EXPECT_GE(r.island_last, r.match);
  }
  EXPECT_GE(detections, 4);
  // The first revisit frame has no consistent predecessor yet.
  EXPECT_EQ(results[16].status, LoopStatus::kFailedTemporalConsistency);
  EXPECT_EQ(results[16].consistent_queries, 0u);
  // The very first frame has nothing to normalise with.
  EXPECT_EQ(results[0].status, LoopStatus::kLowScoreWithPrevious);
}

TEST_F(LoopDetectorTest, ATourWithoutRevisitsHasNoLoop) {
  const std::vector<cv::Mat> places = Places();
  std::vector<cv::Mat> frames;
  for (const cv::Mat& place : places) {
    for (const cv::Mat& v : Visit(place, 5)) frames.push_back(v);
  }
  LoopDetectorParams params = params_;
  params.temporal_matches = 0;  // the most permissive setting: only geometry stands in the way
  for (const LoopResult& r : Run(frames, params)) {
    EXPECT_NE(r.status, LoopStatus::kLoopDetected) << "frame " << r.entry << " -> " << r.match;
  }
}

TEST_F(LoopDetectorTest, RecentFramesAreNeverCandidates) {
  const std::vector<cv::Mat> frames = Visit(Places()[0], 10);
  LoopDetectorParams params = params_;
  params.recent_frames = 20;
  for (const LoopResult& r : Run(frames, params)) {
    EXPECT_TRUE(r.status == LoopStatus::kNoCandidates ||
                r.status == LoopStatus::kLowScoreWithPrevious)
        << LoopStatusName(r.status);
  }
}

TEST_F(LoopDetectorTest, ABlankFrameIsSkippedWithoutBreakingTheFramesAfterIt) {
  std::vector<cv::Mat> frames = TourWithRevisits();
  frames.insert(frames.begin() + 18, cv::Mat(384, 256, CV_8U, cv::Scalar(128)));
  LoopDetectorParams params = params_;
  params.recent_frames = 5;
  const std::vector<LoopResult> results = Run(frames, params);
  EXPECT_EQ(results[18].status, LoopStatus::kTooFewFeatures);
  // The frame after the blank one is normalised with the frame before it, and queried.
  EXPECT_NE(results[19].status, LoopStatus::kLowScoreWithPrevious);
  EXPECT_GT(results[19].previous_score, params.min_score_with_previous);
  int detections_after_blank = 0;
  for (size_t i = 19; i < results.size(); ++i) {
    detections_after_blank += results[i].status == LoopStatus::kLoopDetected;
  }
  EXPECT_GE(detections_after_blank, 2);
}

TEST_F(LoopDetectorTest, EveryGeometryCheckFindsTheLoops) {
  for (GeometryCheck check :
       {GeometryCheck::kDirectIndex, GeometryCheck::kExhaustive, GeometryCheck::kNone}) {
    MemoryIndexStore store;
    auto db = Database::Create(&store, "g", *vocabulary_);
    ASSERT_TRUE(db.ok());
    LoopDetectorParams params = params_;
    params.geometry = check;
    int detections = 0;
    for (const LoopResult& r : Run(TourWithRevisits(), params, db->get())) {
      if (r.status == LoopStatus::kLoopDetected) {
        ++detections;
        if (check == GeometryCheck::kNone) {
          EXPECT_TRUE(r.inliers.empty());
        } else {
          EXPECT_GE(r.correspondences, r.inliers.size());
        }
      }
    }
    EXPECT_GE(detections, 4) << GeometryCheckName(check);
  }
}

TEST_F(LoopDetectorTest, TimestampsMakeTheRecentWindowASpanOfSeconds) {
  const std::vector<cv::Mat> frames = Visit(Places()[0], 8);
  LoopDetectorParams params = params_;
  params.recent_frames = 1000;  // ignored when timestamps are given
  params.recent_seconds = 2.5;
  params.temporal_matches = 0;
  params.geometry = GeometryCheck::kNone;
  auto detector = LoopDetector::Create(db_.get(), params);
  ASSERT_TRUE(detector.ok());
  auto extractor = CreateFeatureExtractor(FeatureOptions{});
  for (size_t i = 0; i < frames.size(); ++i) {
    FeatureSet f;
    ASSERT_TRUE((*extractor)->Extract(frames[i], &f).ok());
    auto r = detector->Process(f, 100.0 + double(i));
    ASSERT_TRUE(r.ok());
    if (r->match != kInvalidEntryId) {
      EXPECT_LE(double(r->match) + 3.0, double(i)) << "frame " << i << " matched a recent frame";
    }
    if (i >= 4) {
      EXPECT_NE(r->status, LoopStatus::kNoCandidates) << "frame " << i;
    }
  }
}

TEST_F(LoopDetectorTest, RunsAreDeterministic) {
  MemoryIndexStore store;
  auto db = Database::Create(&store, "again", *vocabulary_);
  ASSERT_TRUE(db.ok());
  const auto a = Run(TourWithRevisits(), params_);
  const auto b = Run(TourWithRevisits(), params_, db->get());
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].status, b[i].status);
    EXPECT_EQ(a[i].match, b[i].match);
    EXPECT_EQ(a[i].inliers, b[i].inliers);
  }
}

TEST_F(LoopDetectorTest, DetectorsOfTwoMapsRunAtOnceAndGiveTheirSerialResults) {
  const std::vector<cv::Mat> tour = TourWithRevisits();
  std::vector<cv::Mat> reversed(tour.rbegin(), tour.rend());
  const auto serial_a = Run(tour, params_);
  MemoryIndexStore serial_store;
  auto serial_db = Database::Create(&serial_store, "b", *vocabulary_);
  ASSERT_TRUE(serial_db.ok());
  const auto serial_b = Run(reversed, params_, serial_db->get());

  MemoryIndexStore store;  // one store, two maps, two threads
  auto db_a = Database::Create(&store, "a", *vocabulary_);
  auto db_b = Database::Create(&store, "b", *vocabulary_);
  ASSERT_TRUE(db_a.ok() && db_b.ok());
  std::vector<LoopResult> a, b;
  std::thread ta([&] { a = Run(tour, params_, db_a->get()); });
  std::thread tb([&] { b = Run(reversed, params_, db_b->get()); });
  ta.join();
  tb.join();
  ASSERT_EQ(a.size(), serial_a.size());
  ASSERT_EQ(b.size(), serial_b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].status, serial_a[i].status) << i;
    EXPECT_EQ(a[i].match, serial_a[i].match) << i;
    EXPECT_EQ(b[i].status, serial_b[i].status) << i;
    EXPECT_EQ(b[i].match, serial_b[i].match) << i;
  }
}

TEST_F(LoopDetectorTest, BadParametersAndBadInputAreErrors) {
  LoopDetectorParams bad = params_;
  bad.alpha = -1;
  EXPECT_EQ(LoopDetector::Create(db_.get(), bad).status().code(), StatusCode::kInvalidArgument);
  bad = params_;
  bad.epipolar.min_inliers = 5;
  EXPECT_EQ(LoopDetector::Create(db_.get(), bad).status().code(), StatusCode::kInvalidArgument);
  bad = params_;
  bad.matching.ratio = 0;
  EXPECT_EQ(LoopDetector::Create(db_.get(), bad).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(LoopDetector::Create(nullptr, params_).status().code(), StatusCode::kInvalidArgument);

  auto detector = LoopDetector::Create(db_.get(), params_);
  ASSERT_TRUE(detector.ok());
  FeatureSet wrong;
  wrong.descriptors = cv::Mat(10, 64, CV_8U, cv::Scalar(0));
  wrong.keypoints.resize(10);
  EXPECT_EQ(detector->Process(wrong).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(db_->size(), 0u) << "a refused frame is not added";
}

TEST_F(LoopDetectorTest, AddedFramesContinueTheSequenceAsProcessedFramesWould) {
  // With timestamps, so that tau_c depends on the timestamps of the added entries.
  const std::vector<FeatureSet> tour = Extract(TourWithRevisits());
  LoopDetectorParams params = params_;
  params.recent_seconds = 4.5;  // the 4 frames before, as recent_frames
  auto processed = LoopDetector::Create(db_.get(), params);
  MemoryIndexStore store;
  auto db = Database::Create(&store, "added", *vocabulary_);
  ASSERT_TRUE(processed.ok() && db.ok());
  auto added = LoopDetector::Create(db->get(), params);
  ASSERT_TRUE(added.ok());
  std::vector<LoopResult> expected;
  for (size_t i = 0; i < tour.size(); ++i) {
    auto r = processed->Process(tour[i], 10.0 + double(i));
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    expected.push_back(std::move(r).value());
  }
  // The last frames of the first visits found no island, so the revisits do not depend on how
  // the first visits were fed: an island that far back is not consistent with anything.
  for (size_t i = 16 - params.consistency_max_query_gap; i < 16; ++i) {
    ASSERT_EQ(expected[i].island_first, kInvalidEntryId) << i;
  }

  for (size_t i = 0; i < 16; ++i) {
    auto id = added->Add(tour[i], 10.0 + double(i));
    ASSERT_TRUE(id.ok()) << id.status().ToString();
    EXPECT_EQ(*id, EntryId(i));
  }
  EXPECT_EQ((*db)->size(), 16u);
  int detections = 0;
  for (size_t i = 16; i < tour.size(); ++i) {
    auto r = added->Process(tour[i], 10.0 + double(i));
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    ExpectSameResult(*r, expected[i], "frame " + std::to_string(i));
    detections += r->status == LoopStatus::kLoopDetected;
  }
  EXPECT_GE(detections, 4);
  // The first processed frame is normalised with the last added one.
  EXPECT_GT(expected[16].previous_score, params.min_score_with_previous);
}

TEST_F(LoopDetectorTest, AddedFramesCountInTheGapBetweenConsistentQueries) {
  const std::vector<FeatureSet> tour = Extract(TourWithRevisits());
  const std::vector<LoopResult> processed = Run(TourWithRevisits(), params_);
  ASSERT_NE(processed[16].island_first, kInvalidEntryId);
  ASSERT_GE(processed[19].consistent_queries, 1u);

  MemoryIndexStore store;
  auto db = Database::Create(&store, "gap", *vocabulary_);
  ASSERT_TRUE(db.ok());
  auto detector = LoopDetector::Create(db->get(), params_);
  ASSERT_TRUE(detector.ok());
  for (size_t i = 0; i < 17; ++i) ASSERT_TRUE(detector->Process(tour[i]).ok());
  // Frames 17 and 18 are added: frame 19 is 3 frames after the last query, more than
  // consistency_max_query_gap, so its island starts a new count.
  for (size_t i = 17; i < 19; ++i) EXPECT_EQ(detector->Add(tour[i]).value(), EntryId(i));
  auto r = detector->Process(tour[19]);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->entry, 19u);
  EXPECT_EQ(r->match, processed[19].match);
  EXPECT_EQ(r->consistent_queries, 0u);
  EXPECT_EQ(r->status, LoopStatus::kFailedTemporalConsistency);
  // Normalised with the added frame 18, as the processed frame 19 was with the processed one.
  EXPECT_EQ(r->previous_score, processed[19].previous_score);
}

TEST_F(LoopDetectorTest, QueryRecognisesAnAddedPlaceAndChangesNothing) {
  const std::vector<FeatureSet> tour = Extract(TourWithRevisits());
  auto queried = LoopDetector::Create(db_.get(), params_);
  MemoryIndexStore store;
  auto db = Database::Create(&store, "untouched", *vocabulary_);
  ASSERT_TRUE(queried.ok() && db.ok());
  auto untouched = LoopDetector::Create(db->get(), params_);
  ASSERT_TRUE(untouched.ok());
  for (size_t i = 0; i < 16; ++i) {  // the first visits of places 0 1 2 3
    ASSERT_TRUE(queried->Add(tour[i]).ok());
    ASSERT_TRUE(untouched->Add(tour[i]).ok());
  }

  // Every revisit frame (places 0 then 1) is recognised at once, without any temporal
  // consistency, and nothing is added.
  for (size_t i = 16; i < tour.size(); ++i) {
    auto r = queried->Query(tour[i]);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    const EntryId first_visit = i < 20 ? 0 : 4;
    EXPECT_EQ(r->status, LoopStatus::kLoopDetected) << i << " " << LoopStatusName(r->status);
    EXPECT_GE(r->match, first_visit) << i;
    EXPECT_LT(r->match, first_visit + 4) << i;
    EXPECT_GE(r->inliers.size(), 12u) << i;
    EXPECT_GE(r->correspondences, r->inliers.size()) << i;
    EXPECT_EQ(r->entry, kInvalidEntryId);
    EXPECT_EQ(r->consistent_queries, 0u);
    EXPECT_EQ(r->acceptance, LoopAcceptance::kRelocalisation);
    EXPECT_EQ(r->previous_score, 0.0);
    EXPECT_GT(r->score, 0.0);
    EXPECT_LE(r->normalized_score, 1.0);
    EXPECT_GE(r->normalized_score, params_.alpha);
    EXPECT_LE(r->island_first, r->match);
    EXPECT_GE(r->island_last, r->match);
    EXPECT_GE(r->island_score, r->normalized_score);
    EXPECT_EQ(r->timings.insertion, 0.0);
  }
  EXPECT_EQ(db_->size(), 16u);
  EXPECT_EQ(db_->next_entry_id(), 16u);

  // A detector that answered queries between its frames processes them as one that did not.
  for (size_t i = 16; i < tour.size(); ++i) {
    ASSERT_TRUE(queried->Query(tour[i]).ok());
    auto a = queried->Process(tour[i]);
    auto b = untouched->Process(tour[i]);
    ASSERT_TRUE(a.ok() && b.ok());
    ExpectSameResult(*a, *b, "frame " + std::to_string(i));
  }
}

TEST_F(LoopDetectorTest, ExcludedFramesAreNeverCandidatesOfProcessOrQuery) {
  // A SLAM leaves out its keyframes covisible with the query: here the first visit of place 0
  // (entries 0-3), which the revisit frames 16-19 would otherwise match.
  const std::vector<FeatureSet> tour = Extract(TourWithRevisits());
  auto detector = LoopDetector::Create(db_.get(), params_);
  ASSERT_TRUE(detector.ok());
  for (size_t i = 0; i < 16; ++i) ASSERT_TRUE(detector->Add(tour[i]).ok());
  const std::vector<EntryId> covisible = {3, 1, 2, 0, 999};  // any order; 999 is not in the map
  for (size_t i = 16; i < 20; ++i) {
    auto all = detector->Query(tour[i]);
    auto without = detector->Query(tour[i], nullptr, covisible);
    ASSERT_TRUE(all.ok() && without.ok());
    EXPECT_LT(all->match, 4u) << "without an exclusion the first visit is found, frame " << i;
    for (const LoopCandidate& c : without->candidates) {
      EXPECT_GE(c.entry, 4u) << "an excluded frame came back as a candidate of frame " << i;
    }
    EXPECT_NE(without->status, LoopStatus::kLoopDetected) << i;
  }
  auto processed = detector->Process(tour[16], std::nullopt, {}, nullptr, covisible);
  ASSERT_TRUE(processed.ok());
  for (const LoopCandidate& c : processed->candidates) EXPECT_GE(c.entry, 4u);
  EXPECT_EQ(processed->entry, 16u) << "the frame is added as usual";
}

TEST_F(LoopDetectorTest, QueryOnAnEmptyMapHasNoCandidates) {
  const auto detector = LoopDetector::Create(db_.get(), params_);
  ASSERT_TRUE(detector.ok());
  auto r = detector->Query(Extract({Places()[0]})[0]);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status, LoopStatus::kNoCandidates);
  EXPECT_EQ(r->match, kInvalidEntryId);
  EXPECT_EQ(db_->size(), 0u);
}

TEST_F(LoopDetectorTest, QueryWithTooFewFeaturesIsNotAnswered) {
  auto detector = LoopDetector::Create(db_.get(), params_);
  ASSERT_TRUE(detector.ok());
  const std::vector<FeatureSet> place = Extract(Visit(Places()[0], 2));
  ASSERT_TRUE(detector->Add(place[0]).ok());
  // The other view of the same place, cut down to fewer features than min_features.
  FeatureSet few;
  few.keypoints.assign(place[1].keypoints.begin(),
                       place[1].keypoints.begin() + params_.min_features - 1);
  few.descriptors = place[1].descriptors.rowRange(0, int(params_.min_features) - 1).clone();
  auto r = detector->Query(few);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status, LoopStatus::kTooFewFeatures);
  EXPECT_EQ(r->match, kInvalidEntryId);
  r = detector->Query(Extract({cv::Mat(384, 256, CV_8U, cv::Scalar(128))})[0]);  // blank
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status, LoopStatus::kTooFewFeatures);
}

TEST_F(LoopDetectorTest, AddAndQueryRefuseDescriptorsOfAnotherFormat) {
  auto detector = LoopDetector::Create(db_.get(), params_);
  ASSERT_TRUE(detector.ok());
  FeatureSet wrong;
  wrong.descriptors = cv::Mat(30, 64, CV_8U, cv::Scalar(0));
  wrong.keypoints.resize(30);
  EXPECT_EQ(detector->Query(wrong).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(detector->Add(wrong).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(db_->size(), 0u) << "a refused frame is not added";
}

TEST_F(LoopDetectorTest, QueriesFromTwoThreadsWhileAnotherProcessesGiveTheirSerialResults) {
  const std::vector<cv::Mat> places = Places();
  std::vector<cv::Mat> map_frames, query_frames, processed_frames;
  for (int p : {0, 1}) {
    for (const cv::Mat& v : Visit(places[size_t(p)], 4)) map_frames.push_back(v);
    for (const cv::Mat& v : Visit(places[size_t(p)], 3, 2)) query_frames.push_back(v);
  }
  for (int p : {2, 3}) {
    for (const cv::Mat& v : Visit(places[size_t(p)], 4)) processed_frames.push_back(v);
  }
  const std::vector<FeatureSet> map = Extract(map_frames);
  const std::vector<FeatureSet> queries = Extract(query_frames);
  const std::vector<FeatureSet> processed = Extract(processed_frames);

  auto detector = LoopDetector::Create(db_.get(), params_);
  MemoryIndexStore serial_store;
  auto serial_db = Database::Create(&serial_store, "serial", *vocabulary_);
  ASSERT_TRUE(detector.ok() && serial_db.ok());
  auto serial = LoopDetector::Create(serial_db->get(), params_);
  ASSERT_TRUE(serial.ok());
  for (const FeatureSet& f : map) {
    ASSERT_TRUE(detector->Add(f).ok());
    ASSERT_TRUE(serial->Add(f).ok());
  }
  std::vector<LoopResult> expected_queries;
  for (size_t i = 0; i < queries.size(); ++i) {
    expected_queries.push_back(detector->Query(queries[i]).value());
    const EntryId first_visit = i < 3 ? 0 : 4;
    EXPECT_EQ(expected_queries[i].status, LoopStatus::kLoopDetected) << i;
    EXPECT_GE(expected_queries[i].match, first_visit) << i;
    EXPECT_LT(expected_queries[i].match, first_visit + 4) << i;
  }
  std::vector<LoopResult> expected_processed;
  for (const FeatureSet& f : processed) expected_processed.push_back(serial->Process(f).value());

  constexpr int kRounds = 3;
  std::vector<LoopResult> processed_results;
  std::vector<std::vector<LoopResult>> query_results(2);
  std::thread writer([&] {
    for (const FeatureSet& f : processed) processed_results.push_back(detector->Process(f).value());
  });
  std::vector<std::thread> readers;
  for (std::vector<LoopResult>& results : query_results) {
    readers.emplace_back([&] {
      for (int round = 0; round < kRounds; ++round) {
        for (const FeatureSet& f : queries) results.push_back(detector->Query(f).value());
      }
    });
  }
  writer.join();
  for (std::thread& t : readers) t.join();

  // The processed frames are of other places: they change none of the queries, whichever of them
  // a query saw.
  for (size_t i = 0; i < queries.size(); ++i) {
    ExpectSameResult(detector->Query(queries[i]).value(), expected_queries[i],
                     "query " + std::to_string(i) + " after processing");
  }
  for (size_t t = 0; t < query_results.size(); ++t) {
    ASSERT_EQ(query_results[t].size(), kRounds * queries.size());
    for (size_t i = 0; i < query_results[t].size(); ++i) {
      ExpectSameResult(query_results[t][i], expected_queries[i % queries.size()],
                       "thread " + std::to_string(t) + " query " + std::to_string(i));
    }
  }
  ASSERT_EQ(processed_results.size(), expected_processed.size());
  for (size_t i = 0; i < processed_results.size(); ++i) {
    ExpectSameResult(processed_results[i], expected_processed[i], "frame " + std::to_string(i));
  }
  EXPECT_EQ(db_->size(), map.size() + processed.size());
}

// Real revisits of a 3D corridor: frames 1 and 20, the upside-down place that matches neither,
// then frames 41 (same place as 1) and 60 (same as 20), the bundled corridor frames.
std::vector<cv::Mat> CorridorRevisits() {
  std::vector<cv::Mat> frames;
  for (const char* name : {"corridor/1.jpg", "corridor/20.jpg"}) {
    auto f = ReadGrayImage(testing::ProjectTestData(name));
    EXPECT_TRUE(f.ok());
    frames.push_back(*f);
  }
  for (const cv::Mat& v : Visit(Places()[3], 5)) frames.push_back(v);
  for (const char* name : {"corridor/41.jpg", "corridor/60.jpg"}) {
    auto f = ReadGrayImage(testing::ProjectTestData(name));
    EXPECT_TRUE(f.ok());
    frames.push_back(*f);
  }
  return frames;
}

TEST_F(LoopDetectorTest, AStrongCandidateIsAcceptedWithoutTemporalConsistency) {
  const std::vector<LoopResult> results = Run(CorridorRevisits(), params_);
  ASSERT_EQ(results.size(), 9u);
  int strong = 0;
  for (size_t i = 7; i < 9; ++i) {
    const LoopResult& r = results[i];
    if (r.status != LoopStatus::kLoopDetected) continue;
    ++strong;
    EXPECT_EQ(r.acceptance, LoopAcceptance::kStrongEvidence) << i;
    EXPECT_LT(r.consistent_queries, params_.temporal_matches) << i;
    EXPECT_EQ(r.match, i == 7 ? 0u : 1u) << "frame 41 is frame 1's place, 60 is 20's";
    EXPECT_GE(r.inliers.size(), params_.strong_min_inliers);
  }
  EXPECT_GE(strong, 1);
  for (size_t i = 0; i < 7; ++i) EXPECT_NE(results[i].status, LoopStatus::kLoopDetected) << i;

  // The thesis's detector waits for k consistent queries, which these two frames lack.
  LoopDetectorParams thesis = LoopDetectorParams::Thesis();
  thesis.recent_frames = params_.recent_frames;
  thesis.temporal_matches = params_.temporal_matches;
  MemoryIndexStore store;
  auto db = Database::Create(&store, "thesis", *vocabulary_);
  ASSERT_TRUE(db.ok());
  for (const LoopResult& r : Run(CorridorRevisits(), thesis, db->get())) {
    EXPECT_NE(r.status, LoopStatus::kLoopDetected) << r.entry;
    EXPECT_EQ(r.acceptance, LoopAcceptance::kNone);
  }
}

TEST_F(LoopDetectorTest, ACandidateThatFailsVerificationGivesWayToTheNextOnes) {
  // Frame 41 revisits frame 1's place. Between them, a look-alike: frame 41's own features with
  // their keypoints shuffled, so it has the best score of all (the same words) and no geometry.
  auto extractor = CreateFeatureExtractor(FeatureOptions{});
  ASSERT_TRUE(extractor.ok());
  const std::vector<cv::Mat> corridor = CorridorRevisits();  // 1, 20, 5 views of a place, 41, 60
  std::vector<FeatureSet> frames;
  for (size_t i : {0u, 7u, 2u, 3u, 4u, 5u, 6u, 7u}) {
    FeatureSet f;
    ASSERT_TRUE((*extractor)->Extract(corridor[i], &f).ok());
    frames.push_back(std::move(f));
  }
  std::vector<cv::KeyPoint>& look_alike = frames[1].keypoints;
  std::shuffle(look_alike.begin(), look_alike.end(), std::mt19937(7));

  const auto run = [&](uint32_t verified_candidates) {
    LoopDetectorParams params = params_;
    params.verified_candidates = verified_candidates;
    MemoryIndexStore store;
    auto db = Database::Create(&store, "look-alike", *vocabulary_);
    EXPECT_TRUE(db.ok());
    auto detector = LoopDetector::Create(db->get(), params);
    EXPECT_TRUE(detector.ok());
    LoopResult last;
    for (const FeatureSet& f : frames) {
      auto r = detector->Process(f);
      EXPECT_TRUE(r.ok()) << r.status().ToString();
      last = std::move(r).value();
    }
    return last;
  };
  // The best candidate alone: the look-alike (entry 1), which fails.
  const LoopResult best_only = run(1);
  ASSERT_FALSE(best_only.candidates.empty());
  EXPECT_EQ(best_only.candidates.front().entry, 1u);
  EXPECT_EQ(best_only.match, 1u);
  EXPECT_NE(best_only.status, LoopStatus::kLoopDetected);
  // Three candidates: the look-alike fails, frame 1 (entry 0) is strong evidence.
  const LoopResult three = run(3);
  EXPECT_EQ(three.status, LoopStatus::kLoopDetected);
  EXPECT_EQ(three.acceptance, LoopAcceptance::kStrongEvidence);
  EXPECT_EQ(three.match, 0u);
  EXPECT_GE(three.evidence.inliers, params_.strong_min_inliers);
  EXPECT_LE(three.island_first, 0u);
  EXPECT_LT(three.island_last, three.entry) << "the match's island lies among the earlier entries";
  const auto frame_1 = std::find_if(best_only.candidates.begin(), best_only.candidates.end(),
                                    [](const LoopCandidate& c) { return c.entry == 0; });
  ASSERT_NE(frame_1, best_only.candidates.end());
  EXPECT_EQ(three.score, frame_1->score) << "the match's own score";
  EXPECT_GT(three.timings.verification, 0.0);
  EXPECT_EQ(best_only.timings.verified_candidates, 1u);
  EXPECT_GE(three.timings.verified_candidates, 2u) << "the look-alike, then frame 1";
  EXPECT_LE(three.timings.verified_candidates, 3u);
}

TEST_F(LoopDetectorTest, ACandidateAHomographyExplainsStillNeedsTemporalConsistency) {
  // The tour's revisits are shifted copies of flat images: F fits them, and so does H.
  const std::vector<LoopResult> results = Run(TourWithRevisits(), params_);
  EXPECT_EQ(results[16].status, LoopStatus::kFailedTemporalConsistency);
  for (const LoopResult& r : results) {
    EXPECT_NE(r.acceptance, LoopAcceptance::kStrongEvidence) << r.entry;
  }
  // Without the model selection, the same first revisit frame passes as strong.
  LoopDetectorParams no_model_selection = params_;
  no_model_selection.strong_max_homography_ratio = 1.0;
  MemoryIndexStore store;
  auto db = Database::Create(&store, "planar", *vocabulary_);
  ASSERT_TRUE(db.ok());
  const std::vector<LoopResult> unchecked = Run(TourWithRevisits(), no_model_selection, db->get());
  EXPECT_EQ(unchecked[16].status, LoopStatus::kLoopDetected);
  EXPECT_EQ(unchecked[16].acceptance, LoopAcceptance::kStrongEvidence);
  EXPECT_EQ(unchecked[16].consistent_queries, 0u);
}

TEST_F(LoopDetectorTest, ThesisModeIsTheDetectorWithoutStrongAcceptance) {
  const LoopDetectorParams thesis = LoopDetectorParams::Thesis();
  EXPECT_FALSE(thesis.strong_acceptance);
  EXPECT_TRUE(LoopDetectorParams{}.strong_acceptance);
  EXPECT_EQ(thesis.temporal_matches, 3u);
  EXPECT_DOUBLE_EQ(thesis.alpha, 0.3);
  EXPECT_EQ(thesis.epipolar.min_inliers, 12u);
  EXPECT_EQ(ParseDetectorPreset("thesis")->strong_acceptance, false);
  EXPECT_EQ(ParseDetectorPreset("default")->strong_acceptance, true);
  EXPECT_EQ(ParseDetectorPreset("dloop").status().code(), StatusCode::kInvalidArgument);

  // Where no candidate is strong, the trial verifications leave no trace: every result is the
  // thesis detector's, and every loop was accepted by temporal consistency.
  LoopDetectorParams thesis_here = params_;
  thesis_here.strong_acceptance = false;
  const std::vector<LoopResult> a = Run(TourWithRevisits(), thesis_here);
  MemoryIndexStore store;
  auto db = Database::Create(&store, "default", *vocabulary_);
  ASSERT_TRUE(db.ok());
  const std::vector<LoopResult> b = Run(TourWithRevisits(), params_, db->get());
  ASSERT_EQ(a.size(), b.size());
  int loops = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    ExpectSameResult(a[i], b[i], "frame " + std::to_string(i));
    EXPECT_EQ(a[i].acceptance, b[i].acceptance) << i;
    if (a[i].status == LoopStatus::kLoopDetected) {
      ++loops;
      EXPECT_EQ(a[i].acceptance, LoopAcceptance::kTemporalConsistency) << i;
    }
  }
  EXPECT_GE(loops, 4);
}

TEST_F(LoopDetectorTest, KeyframesThatShareNoSceneWithTheirPredecessorAreStillQueried) {
  // One keyframe per place (places 0 1 2 3), then places 0 and 1 again from another viewpoint:
  // no keyframe overlaps the one before it.
  const std::vector<cv::Mat> places = Places();
  std::vector<cv::Mat> frames;
  for (int p : {0, 1, 2, 3, 0, 1}) {
    frames.push_back(Visit(places[size_t(p)], 1, frames.size() >= 4 ? 6 : 0).front());
  }
  // A minimum score with the previous frame no pair reaches stands for "no overlap" whatever
  // the vocabulary.
  LoopDetectorParams video = params_;
  video.recent_frames = 1;
  video.min_score_with_previous = 1.0;
  LoopDetectorParams keyframes = LoopDetectorParams::Keyframes();
  keyframes.recent_frames = 1;
  keyframes.min_score_with_previous = 1.0;
  EXPECT_EQ(keyframes.preset, DetectorPreset::kKeyframes);
  EXPECT_EQ(ParseDetectorPreset("keyframes")->normalisation, ScoreNormalisation::kBestCandidate);

  const std::vector<LoopResult> by_video = Run(frames, video);
  MemoryIndexStore store;
  auto db = Database::Create(&store, "keyframes", *vocabulary_);
  ASSERT_TRUE(db.ok());
  const std::vector<LoopResult> by_keyframes = Run(frames, keyframes, db->get());
  // Normalised by the previous keyframe, the revisits are never even queried.
  for (size_t i : {4u, 5u}) {
    EXPECT_EQ(by_video[i].status, LoopStatus::kLowScoreWithPrevious) << i;
    EXPECT_TRUE(by_video[i].candidates.empty()) << i;
  }
  // Normalised by the best candidate, each revisit is queried and finds its place, and the
  // first keyframe is queried too (it has no predecessor to need).
  EXPECT_EQ(by_keyframes[0].status, LoopStatus::kNoCandidates);
  int loops = 0;
  for (size_t i : {4u, 5u}) {
    const LoopResult& r = by_keyframes[i];
    ASSERT_FALSE(r.candidates.empty()) << i;
    EXPECT_EQ(r.match, EntryId(i - 4)) << i;
    EXPECT_DOUBLE_EQ(r.candidates.front().normalized_score, 1.0) << "eta of the best is 1";
    EXPECT_EQ(r.previous_score, 0.0);
    if (r.status == LoopStatus::kLoopDetected) {
      ++loops;
      EXPECT_NE(r.acceptance, LoopAcceptance::kNone);
    }
  }
  EXPECT_GE(loops, 1);
}

TEST_F(LoopDetectorTest, BadStrongAcceptanceParametersAreRefused) {
  const auto refused = [&](const LoopDetectorParams& p) {
    return LoopDetector::Create(db_.get(), p).status().code() == StatusCode::kInvalidArgument;
  };
  LoopDetectorParams bad = params_;
  bad.strong_temporal_matches = params_.temporal_matches + 1;
  EXPECT_TRUE(refused(bad));
  bad = params_;
  bad.strong_min_inliers = uint32_t(params_.epipolar.min_inliers) - 1;
  EXPECT_TRUE(refused(bad));
  bad = params_;
  bad.strong_min_spread = 1.5;
  EXPECT_TRUE(refused(bad));
  bad = params_;
  bad.strong_max_homography_ratio = -0.1;
  EXPECT_TRUE(refused(bad));
  bad = params_;
  bad.model_selection.sigma_px = 0;
  EXPECT_TRUE(refused(bad));
  bad = params_;
  bad.model_selection.confidence = 1.0;
  EXPECT_TRUE(refused(bad));
  LoopDetectorParams good = params_;
  good.strong_temporal_matches = params_.temporal_matches;
  good.strong_min_inliers = uint32_t(params_.epipolar.min_inliers);
  EXPECT_TRUE(LoopDetector::Create(db_.get(), good).ok());
}

TEST(LoopStatusTest, NamesAreDistinctAndGeometryNamesParse) {
  std::set<std::string_view> names;
  for (LoopStatus s :
       {LoopStatus::kLoopDetected, LoopStatus::kTooFewFeatures, LoopStatus::kLowScoreWithPrevious,
        LoopStatus::kNoCandidates, LoopStatus::kLowScore, LoopStatus::kNoConsistentIsland,
        LoopStatus::kFailedTemporalConsistency, LoopStatus::kFailedGeometry}) {
    names.insert(LoopStatusName(s));
  }
  EXPECT_EQ(names.size(), 8u);
  for (GeometryCheck c :
       {GeometryCheck::kDirectIndex, GeometryCheck::kExhaustive, GeometryCheck::kNone}) {
    EXPECT_EQ(ParseGeometryCheck(GeometryCheckName(c)).value(), c);
  }
  EXPECT_FALSE(ParseGeometryCheck("homography").ok());
  for (ScoreNormalisation n :
       {ScoreNormalisation::kPreviousFrame, ScoreNormalisation::kBestCandidate}) {
    EXPECT_EQ(ParseScoreNormalisation(ScoreNormalisationName(n)).value(), n);
  }
  EXPECT_EQ(ParseScoreNormalisation("median").status().code(), StatusCode::kInvalidArgument);
  for (DetectorPreset p :
       {DetectorPreset::kDefault, DetectorPreset::kThesis, DetectorPreset::kKeyframes}) {
    EXPECT_EQ(ParseDetectorPreset(DetectorPresetName(p))->preset, p);
  }
  std::set<std::string_view> acceptances;
  for (LoopAcceptance a : {LoopAcceptance::kNone, LoopAcceptance::kTemporalConsistency,
                           LoopAcceptance::kStrongEvidence, LoopAcceptance::kRelocalisation}) {
    acceptances.insert(LoopAcceptanceName(a));
  }
  EXPECT_EQ(acceptances.size(), 4u);
}

// Frames with a FrameGeometry (metric loops, thesis §3.3.3; the loops themselves are checked on
// rendered RGB-D and stereo sequences in tools/evaluation/metric_sequence_test.cc).
TEST_F(LoopDetectorTest, AFramesPointsAreKeptWithItsEntry) {
  auto detector = LoopDetector::Create(db_.get(), params_);
  ASSERT_TRUE(detector.ok());
  const std::vector<FeatureSet> features = Extract(Visit(Places()[0], 2));
  const float nan = std::numeric_limits<float>::quiet_NaN();
  FrameGeometry geometry{cv::Matx33d(300, 0, 128, 0, 300, 192, 0, 0, 1), {}};
  for (size_t i = 0; i < features[0].size(); ++i) {
    geometry.points.push_back(i % 4 == 0 ? cv::Point3f(nan, nan, nan)
                                         : cv::Point3f(0.1f, 0.2f, 1.0f + 0.01f * float(i)));
  }
  auto processed = detector->Process(features[0], std::nullopt, {}, &geometry);
  ASSERT_TRUE(processed.ok()) << processed.status().ToString();
  EXPECT_FALSE(processed->metric.checked);
  auto added = detector->Add(features[1]);  // without geometry: no points
  ASSERT_TRUE(added.ok());
  auto entry = db_->Get(processed->entry, kEntryFeatures);
  ASSERT_TRUE(entry.ok());
  ASSERT_EQ(entry->points.size(), geometry.points.size());
  EXPECT_TRUE(std::isnan(entry->points[0].z));
  EXPECT_EQ(entry->points[1], geometry.points[1]);
  entry = db_->Get(*added, kEntryFeatures);
  ASSERT_TRUE(entry.ok());
  EXPECT_TRUE(entry->points.empty());
}

TEST_F(LoopDetectorTest, BadFrameGeometryAndMetricParametersAreInvalidArgument) {
  LoopDetectorParams bad = params_;
  bad.metric.min_inlier_ratio = 1.5;
  EXPECT_EQ(LoopDetector::Create(db_.get(), bad).status().code(), StatusCode::kInvalidArgument);
  bad = params_;
  bad.metric.threshold_px = 0;
  EXPECT_EQ(LoopDetector::Create(db_.get(), bad).status().code(), StatusCode::kInvalidArgument);
  bad = params_;
  bad.metric.min_inliers = 3;
  EXPECT_EQ(LoopDetector::Create(db_.get(), bad).status().code(), StatusCode::kInvalidArgument);

  auto detector = LoopDetector::Create(db_.get(), params_);
  ASSERT_TRUE(detector.ok());
  const FeatureSet features = Extract(Visit(Places()[0], 1))[0];
  FrameGeometry no_camera;  // K all zeros
  auto s = detector->Process(features, std::nullopt, {}, &no_camera).status();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("camera matrix"), std::string::npos) << s.ToString();
  FrameGeometry too_few{cv::Matx33d(300, 0, 128, 0, 300, 192, 0, 0, 1),
                        std::vector<cv::Point3f>(3, cv::Point3f(0, 0, 1))};
  s = detector->Add(features, std::nullopt, {}, &too_few).status();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("3 3D points"), std::string::npos) << s.ToString();
  EXPECT_EQ(detector->Query(features, &no_camera).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(db_->size(), 0u) << "a refused frame is not added";
}

// Loops between frames with a camera matrix carry the figures of the essential matrix of their
// inliers: on the tour's revisits (the same views shifted a few pixels: no parallax to speak of,
// every point in front or at infinity). The calibrated check decides only when enabled.
TEST_F(LoopDetectorTest, CalibratedLoopsCarryTheEssentialEvidenceAndTheCheckDecidesWhenEnabled) {
  const std::vector<FeatureSet> tour = Extract(TourWithRevisits());
  const std::vector<LoopResult> results = RunCalibrated(tour, params_, NewDatabase("cal").get());
  int loops = 0;
  for (const LoopResult& r : results) {
    if (r.status != LoopStatus::kLoopDetected) continue;
    ++loops;
    EXPECT_TRUE(r.evidence.calibrated);
    EXPECT_EQ(r.evidence.inliers, r.inliers.size());
    EXPECT_TRUE(r.evidence.in_front >= 0.9 || r.evidence.pure_rotation) << r.evidence.in_front;
    EXPECT_LT(r.evidence.rotation_deg, 5.0);
    EXPECT_GT(r.evidence.spread, 0.125);
    EXPECT_EQ(r.evidence.confirmations, 0u);
  }
  EXPECT_GE(loops, 4);
  // Without camera matrices the same loops are checked with F: not calibrated, spread set.
  for (const LoopResult& r : Run(TourWithRevisits(), params_, NewDatabase("plain").get())) {
    if (r.status != LoopStatus::kLoopDetected) continue;
    EXPECT_FALSE(r.evidence.calibrated);
    EXPECT_EQ(r.evidence.inliers, r.inliers.size());
    EXPECT_GT(r.evidence.spread, 0.0);
  }
  // A rotation bound no loop can meet: off by default, it changes nothing; enabled, every
  // candidate fails the check.
  LoopDetectorParams strict = params_;
  strict.calibrated.max_rotation_deg = 0.0;
  int unchecked = 0;
  for (const LoopResult& r : RunCalibrated(tour, strict, NewDatabase("unchecked").get())) {
    unchecked += r.status == LoopStatus::kLoopDetected;
  }
  EXPECT_EQ(unchecked, loops);
  strict.calibrated.enabled = true;
  for (const LoopResult& r : RunCalibrated(tour, strict, NewDatabase("strict").get())) {
    EXPECT_NE(r.status, LoopStatus::kLoopDetected);
  }
}

// With keyframe confirmations, a revisit's first verified loop is a candidate and the next
// frame's loop next to it is accepted, with its confirmation counted; without, both at once.
TEST_F(LoopDetectorTest, AKeyframeConfirmationTurnsTheFirstLoopIntoACandidate) {
  const std::vector<FeatureSet> tour = Extract(TourWithRevisits());
  const std::vector<LoopResult> at_once = RunCalibrated(tour, params_, NewDatabase("a").get());
  LoopDetectorParams confirmed = params_;
  confirmed.keyframe_confirmations = 1;
  const std::vector<LoopResult> later = RunCalibrated(tour, confirmed, NewDatabase("b").get());
  ASSERT_EQ(at_once.size(), later.size());
  size_t first = at_once.size();
  for (size_t i = 0; i < at_once.size(); ++i) {
    if (at_once[i].status == LoopStatus::kLoopDetected) {
      first = i;
      break;
    }
  }
  ASSERT_LT(first + 1, at_once.size());
  ASSERT_EQ(at_once[first + 1].status, LoopStatus::kLoopDetected);
  EXPECT_EQ(later[first].status, LoopStatus::kCandidate);
  EXPECT_EQ(later[first].match, at_once[first].match);  // the candidate says what it is
  EXPECT_EQ(later[first].evidence.confirmations, 0u);
  EXPECT_EQ(later[first + 1].status, LoopStatus::kLoopDetected);
  EXPECT_EQ(later[first + 1].evidence.confirmations, 1u);
  EXPECT_EQ(LoopStatusName(LoopStatus::kCandidate), "candidate");
  // With no gap allowed, only a loop to the very frame the previous one matched confirms it.
  confirmed.island_max_gap = 0;
  const std::vector<LoopResult> strict = RunCalibrated(tour, confirmed, NewDatabase("c").get());
  for (size_t i = 1; i < strict.size(); ++i) {
    if (strict[i].status != LoopStatus::kLoopDetected) continue;
    EXPECT_EQ(strict[i].match, strict[i - 1].match) << i;
    EXPECT_GE(strict[i].evidence.confirmations, 1u) << i;
  }
  confirmed.max_motion_disagreement_deg = 181.0;
  EXPECT_EQ(confirmed.Validate().code(), StatusCode::kInvalidArgument);
  confirmed.max_motion_disagreement_deg = 15.0;
  confirmed.keyframe_confirmations = LoopDetectorParams::kMaxKeyframeConfirmations;
  EXPECT_TRUE(confirmed.Validate().ok());
  confirmed.keyframe_confirmations = 0xFFFFFFFFu;
  EXPECT_EQ(confirmed.Validate().code(), StatusCode::kInvalidArgument);
}

// A small frame needs small_frame_min_inliers in every verification; a frame of unknown size
// or a large one does not.
TEST_F(LoopDetectorTest, SmallFramesNeedTheirOwnFloorOfInliers) {
  std::vector<FeatureSet> tour = Extract(TourWithRevisits());
  LoopDetectorParams params = params_;
  params.small_frame_min_inliers = 100000;  // more than any loop here has
  const auto loops = [&](const std::string& db_name) {
    int n = 0;
    for (const LoopResult& r : RunCalibrated(tour, params, NewDatabase(db_name).get())) {
      n += r.status == LoopStatus::kLoopDetected;
    }
    return n;
  };
  EXPECT_EQ(tour[0].image_size, cv::Size(256, 384));  // the extractor says where they came from
  EXPECT_GE(loops("large"), 4);                       // 98,304 pixels: not small
  for (FeatureSet& f : tour) f.image_size = cv::Size(160, 120);
  EXPECT_EQ(loops("small"), 0);
  for (FeatureSet& f : tour) f.image_size = cv::Size(0, 0);
  EXPECT_GE(loops("unknown"), 4);
}

TEST(LoopDetectorParamsTest, ThePresetsAreValid) {
  for (const char* mode : {"default", "thesis", "keyframes"}) {
    const StatusOr<LoopDetectorParams> params = ParseDetectorPreset(mode);
    ASSERT_TRUE(params.ok()) << mode;
    EXPECT_TRUE(params->Validate().ok()) << mode << ": " << params->Validate().ToString();
  }
  // The ends of the ranges are in them.
  LoopDetectorParams edges;
  edges.alpha = 0;
  edges.matching.ratio = 1;
  edges.min_spread = 1;
  edges.max_motion_disagreement_deg = 180;
  edges.keyframe_confirmations = LoopDetectorParams::kMaxKeyframeConfirmations;
  edges.strong_temporal_matches = edges.temporal_matches;
  edges.strong_min_inliers = uint32_t(edges.epipolar.min_inliers);
  EXPECT_TRUE(edges.Validate().ok()) << edges.Validate().ToString();
}

// One field out of its range at a time, NaN and infinity among the values: the message names the
// field (a setting by its name in the settings table, another field by its path in
// LoopDetectorParams), its value and its range.
TEST(LoopDetectorParamsTest, EachFieldOutOfRangeIsRefusedWithItsNameAndValue) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  using P = LoopDetectorParams;
  const std::vector<testing::BadOption<P>> cases = {
      {"alpha = inf", [&](P& p) { p.alpha = inf; }},
      {"alpha = nan", [&](P& p) { p.alpha = nan; }},
      {"alpha = -1", [](P& p) { p.alpha = -1; }},
      {"min_score_with_previous = nan", [&](P& p) { p.min_score_with_previous = nan; }},
      {"recent_seconds = inf", [&](P& p) { p.recent_seconds = inf; }},
      {"max_query_results = 0", [](P& p) { p.max_query_results = 0; }},
      {"query_rescored_candidates = 0", [](P& p) { p.query_rescored_candidates = 0; }},
      {"island_min_size = 0", [](P& p) { p.island_min_size = 0; }},
      {"verified_candidates = 0", [](P& p) { p.verified_candidates = 0; }},
      {"ratio = nan", [&](P& p) { p.matching.ratio = nan; }},
      {"ratio = 0", [](P& p) { p.matching.ratio = 0; }},
      {"ransac_threshold_px = inf", [&](P& p) { p.epipolar.threshold_px = inf; }},
      {"ransac_confidence = 1", [](P& p) { p.epipolar.confidence = 1; }},
      {"ransac_max_iterations = 0", [](P& p) { p.epipolar.max_iterations = 0; }},
      {"min_inliers = 7", [](P& p) { p.epipolar.min_inliers = 7; }},
      {"metric.threshold_px = nan", [&](P& p) { p.metric.threshold_px = nan; }},
      {"metric.confidence = 0", [](P& p) { p.metric.confidence = 0; }},
      {"metric.max_iterations = -3", [](P& p) { p.metric.max_iterations = -3; }},
      {"metric.min_inliers = 5", [](P& p) { p.metric.min_inliers = 5; }},
      {"metric.min_inlier_ratio = 1.5", [](P& p) { p.metric.min_inlier_ratio = 1.5; }},
      {"metric.min_sigma_px = inf", [&](P& p) { p.metric.min_sigma_px = inf; }},
      {"calibrated.essential.threshold_px = 0",
       [](P& p) { p.calibrated.essential.threshold_px = 0; }},
      {"calibrated.essential.confidence = nan",
       [&](P& p) { p.calibrated.essential.confidence = nan; }},
      {"calibrated.essential.max_iterations = 0",
       [](P& p) { p.calibrated.essential.max_iterations = 0; }},
      {"calibrated_min_in_front = nan", [&](P& p) { p.calibrated.min_in_front = nan; }},
      {"calibrated_max_rotation_deg = 181", [](P& p) { p.calibrated.max_rotation_deg = 181; }},
      {"calibrated.min_parallax_deg = inf", [&](P& p) { p.calibrated.min_parallax_deg = inf; }},
      {"calibrated.min_rotation_only = -0.5", [](P& p) { p.calibrated.min_rotation_only = -0.5; }},
      {"calibrated_min_spread = nan", [&](P& p) { p.calibrated.min_spread = nan; }},
      {"keyframe_confirmations = 101", [](P& p) { p.keyframe_confirmations = 101; }},
      {"max_motion_disagreement_deg = nan", [&](P& p) { p.max_motion_disagreement_deg = nan; }},
      {"strong_temporal_matches = 4", [](P& p) { p.strong_temporal_matches = 4; }},
      {"strong_min_inliers = 11", [](P& p) { p.strong_min_inliers = 11; }},
      {"min_spread = inf", [&](P& p) { p.min_spread = inf; }},
      {"strong_min_spread = nan", [&](P& p) { p.strong_min_spread = nan; }},
      {"strong_max_homography_ratio = -inf", [&](P& p) { p.strong_max_homography_ratio = -inf; }},
      {"model_selection.sigma_px = nan", [&](P& p) { p.model_selection.sigma_px = nan; }},
      {"model_selection.threshold_px = inf", [&](P& p) { p.model_selection.threshold_px = inf; }},
      {"model_selection.confidence = 1", [](P& p) { p.model_selection.confidence = 1; }},
      {"model_selection.max_iterations = 0", [](P& p) { p.model_selection.max_iterations = 0; }},
  };
  testing::ExpectEachRefused("LoopDetectorParams", cases);
  LoopDetectorParams infinite;
  infinite.alpha = inf;
  EXPECT_EQ(infinite.Validate().message(),
            "LoopDetectorParams.alpha = inf: must be finite and >= 0");
  LoopDetectorParams rule;
  rule.strong_temporal_matches = rule.temporal_matches + 1;
  EXPECT_EQ(rule.Validate().message(),
            "LoopDetectorParams.strong_temporal_matches = 4: must be <= temporal_matches (3)");
}

// An entry whose stored features lost rows that its direct index still names (a damaged record):
// verifying against it is DATA_LOSS naming the entry; the other entries are verified as before.
TEST_F(LoopDetectorTest, AnEntryWhoseDirectIndexExceedsItsFeaturesIsDataLossNamingIt) {
  const std::vector<FeatureSet> tour = Extract(TourWithRevisits());
  auto detector = LoopDetector::Create(db_.get(), params_);
  ASSERT_TRUE(detector.ok());
  for (size_t i = 0; i < 4; ++i) ASSERT_TRUE(detector->Add(tour[i]).ok());
  const MapId map = db_->info().id;
  EntryRecord damaged;
  ASSERT_TRUE(store_.ReadEntry(map, 2, kEntryAllParts, &damaged).ok());
  const int kept = damaged.descriptors.rows / 2;
  damaged.descriptors = damaged.descriptors.rowRange(0, kept).clone();
  damaged.keypoints.resize(size_t(kept));
  ASSERT_TRUE(store_.RemoveEntry(map, 2).ok());
  ASSERT_TRUE(store_.CommitEntry(map, damaged).ok());

  LoopDetector::ConvertedFrame frame;
  ASSERT_TRUE(detector->ConvertForQuery(tour[2], &frame).ok());
  const Status refused = detector->VerifyEntry(tour[2], frame, 2).status();
  EXPECT_EQ(refused.code(), StatusCode::kDataLoss) << refused.ToString();
  EXPECT_EQ(refused.message().rfind("matching the frame (A) with entry 2 (B): the direct index of "
                                    "B names feature ",
                                    0),
            0u)
      << refused.message();
  EXPECT_NE(refused.message().find("but B has " + std::to_string(kept) + " features"),
            std::string::npos)
      << refused.message();
  ASSERT_TRUE(detector->ConvertForQuery(tour[1], &frame).ok());
  const StatusOr<LoopResult> intact = detector->VerifyEntry(tour[1], frame, 1);
  ASSERT_TRUE(intact.ok()) << intact.status().ToString();
  EXPECT_EQ(intact->status, LoopStatus::kLoopDetected);
}

}  // namespace
}  // namespace recog
