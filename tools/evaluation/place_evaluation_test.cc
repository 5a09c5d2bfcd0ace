#include "tools/evaluation/place_evaluation.h"

#include <filesystem>
#include <fstream>
#include <map>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "core/vocabulary/vocabulary_io.h"
#include "tests/testing/test_data.h"
#include "tools/common/cli_support.h"
#include "tools/evaluation/sequence_generator.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

std::shared_ptr<const Vocabulary> PlaceVocabulary() {
  auto v = LoadVocabulary(DefaultPlaceVocabularyPath());
  EXPECT_TRUE(v.ok()) << v.status().ToString();
  return std::make_shared<const Vocabulary>(std::move(v).value());
}

SequenceFeatures Extract(const std::string& spec) {
  auto source = FrameSource::Open(spec);
  EXPECT_TRUE(source.ok()) << source.status().ToString();
  auto sequence = ExtractSequence(*source, FeatureOptions{}, false);
  EXPECT_TRUE(sequence.ok()) << sequence.status().ToString();
  return std::move(sequence).value();
}

TEST(PlaceEvaluationTest, CorridorIsDetectedWithFullPrecisionAndTheTargetRecall) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("places/corridor/ground_truth.txt");
  const SequenceFeatures sequence = Extract(testing::SharedData("places/corridor/images"));
  auto truth = ReadGroundTruth(testing::SharedData("places/corridor/ground_truth.txt"));
  ASSERT_TRUE(truth.ok());
  auto e = EvaluatePlace(sequence, *truth, PlaceVocabulary(), PlaceEvaluationOptions{});
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  EXPECT_EQ(e->frames, 84);
  EXPECT_EQ(e->query_frames_with_truth, 44);
  EXPECT_EQ(e->precision, 1.0);
  EXPECT_GE(e->recall, 0.65);
  EXPECT_EQ(e->timing_ms.count("verification"), 1u);
}

// The issue-41 courtyard: keyframes metres apart whose other façades repeat the same windows,
// judged by the true geometry of their poses. The keyframes preset as it was before its
// correspondences came from every pair with a cross check (through the direct index, ratio 0.6,
// 12 inliers for a consistent loop, 20 for strong evidence), without its spread floor, closed
// 22 -> 2 on 13 inliers none of which lie on the true geometry; the keyframes preset with the
// camera known does not: it closes 16 of the 24 frames with a true earlier match and nothing false
// (10 with the correspondences before), 5 -> 1 among them: the truth counts keyframes 4 apart, and
// the preset's recent window (3 keyframes) lets them through. A loop of a pair listed as
// ambiguous whose inliers match a
// look-alike façade (23 -> 2 once, 15 inliers, one on the true geometry) is counted false rather
// than left out of precision.
TEST(PlaceEvaluationTest, TheCourtyardsLookAlikeFacadesAreJudgedByTheTrueGeometry) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("places/strecha-keyframes/castle-P30/poses.txt");
  const std::string scene = testing::SharedData("places/strecha-keyframes/castle-P30/");
  auto source = FrameSource::Open(scene + "images");
  ASSERT_TRUE(source.ok());
  SequenceGeometryOptions camera;
  camera.camera = {919.8267, 921.3867, 506.8967, 335.6033, {}};
  auto sequence = ExtractSequence(*source, PlaceFeatureOptions(), false, nullptr, camera);
  ASSERT_TRUE(sequence.ok()) << sequence.status().ToString();
  auto truth = ReadGroundTruth(scene + "ground_truth.txt");
  ASSERT_TRUE(truth.ok());
  ASSERT_TRUE(ReadAmbiguousPairs(scene + "ambiguous.txt", &*truth).ok());
  auto poses = ReadCameraPoses(scene + "poses.txt");
  ASSERT_TRUE(poses.ok()) << poses.status().ToString();
  const CameraTrajectory trajectory{*poses, camera.camera.K()};

  PlaceEvaluationOptions keyframes;
  keyframes.detector = LoopDetectorParams::Keyframes();
  auto e = EvaluatePlace(*sequence, *truth, PlaceVocabulary(), keyframes, nullptr, &trajectory);
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  EXPECT_GE(e->correct, 15);
  EXPECT_EQ(e->correct, e->detections - e->ambiguous);
  const auto four_back = std::find_if(e->loops.begin(), e->loops.end(), [](const DetectedLoop& l) {
    return l.status == LoopStatus::kLoopDetected && l.query == 4;
  });
  ASSERT_NE(four_back, e->loops.end()) << "5 -> 1, 4 keyframes back";
  EXPECT_EQ(four_back->match, 0);
  EXPECT_TRUE(four_back->correct);
  // Up to 10 candidates verified a frame: the cost of one is its share of the frame's.
  ASSERT_EQ(e->timing_ms.count("verification_per_candidate"), 1u);
  EXPECT_GT(e->timing_ms.at("verification_per_candidate").median, 0.0);
  EXPECT_LE(e->timing_ms.at("verification_per_candidate").max, e->timing_ms.at("verification").max);
  for (const DetectedLoop& loop : e->loops) {
    if (loop.status != LoopStatus::kLoopDetected) continue;
    EXPECT_TRUE(loop.evidence.calibrated);
    ASSERT_TRUE(loop.geometry.has_value());
    EXPECT_GT(loop.geometry->distance_m, 0.0);
    EXPECT_FALSE(loop.query == 21 && loop.match == 1);
    // Whatever the pair's listing, a loop is right only when its inliers agree with the truth,
    // and an ambiguous pair is left out only then.
    if (!loop.geometry->agrees) {
      EXPECT_FALSE(loop.correct);
      EXPECT_FALSE(loop.ambiguous) << loop.query + 1 << " -> " << loop.match + 1;
    }
  }

  PlaceEvaluationOptions before = keyframes;
  before.detector.geometry = GeometryCheck::kDirectIndex;
  before.detector.matching = MatchOptions{};
  before.detector.epipolar.min_inliers = 12;
  before.detector.strong_min_inliers = 20;
  before.detector.verified_candidates = 1;
  before.detector.recent_frames = 4;
  before.detector.min_spread = 0.0;
  auto old = EvaluatePlace(*sequence, *truth, PlaceVocabulary(), before, nullptr, &trajectory);
  ASSERT_TRUE(old.ok());
  EXPECT_LT(old->precision, e->precision);
  bool look_alike = false;
  for (const DetectedLoop& loop : old->loops) {
    if (loop.status != LoopStatus::kLoopDetected || loop.query != 21 || loop.match != 1) continue;
    look_alike = true;
    EXPECT_FALSE(loop.correct);
    EXPECT_EQ(loop.geometry->agreeing, 0u);
  }
  EXPECT_TRUE(look_alike);
}

TEST(PlaceEvaluationTest, TheFirstFortyCorridorFramesHaveNoLoop) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("places/corridor/images/40.jpg");
  const fs::path list =
      fs::temp_directory_path() / ("recog_first40_" + std::to_string(::getpid()) + ".txt");
  {
    std::ofstream out(list);
    for (int i = 1; i <= 40; ++i) {
      out << testing::SharedData("places/corridor/images/" + std::to_string(i) + ".jpg") << "\n";
    }
  }
  const SequenceFeatures sequence = Extract(list.string());
  fs::remove(list);
  GroundTruth none;
  none.frames = 40;
  none.matches.resize(40);
  auto e = EvaluatePlace(sequence, none, PlaceVocabulary(), PlaceEvaluationOptions{});
  ASSERT_TRUE(e.ok());
  EXPECT_EQ(e->detections, 0);
}

TEST(PlaceEvaluationTest, ATourOfDistinctPlacesWithoutRevisitsHasNoLoop) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("training/caltech101");
  auto photos = ListImages(testing::SharedData("training/caltech101"));
  ASSERT_TRUE(photos.ok());
  SequenceOptions options;
  options.places = 60;
  options.frames_per_place = 5;
  options.revisit_fraction = 0.0;
  auto generator = SequenceGenerator::Create(*photos, options);
  ASSERT_TRUE(generator.ok()) << generator.status().ToString();
  SequenceFeatures sequence;
  auto extractor = CreateFeatureExtractor(FeatureOptions{});
  for (int i = 0; i < generator->num_frames(); ++i) {
    auto frame = generator->Frame(i);
    ASSERT_TRUE(frame.ok());
    FeatureSet f;
    ASSERT_TRUE((*extractor)->Extract(frame->image, &f).ok());
    sequence.features.push_back(std::move(f));
    sequence.feature_ms.push_back(0.0);
    sequence.names.push_back(std::to_string(i + 1));
  }
  const GroundTruth truth = generator->BuildGroundTruth();
  ASSERT_EQ(truth.QueriesWithMatches(), 0);
  auto e = EvaluatePlace(sequence, truth, PlaceVocabulary(), PlaceEvaluationOptions{});
  ASSERT_TRUE(e.ok());
  EXPECT_EQ(e->detections, 0);
}

// tau_c counts frames without timestamps and seconds with them: the corridor's four demo frames
// twice are all within the 20 most recent frames, and within 20 s when 1 s apart (also from a
// clock that starts at 0.0, as KITTI's: 0.0 is a time, not "none"), but 100 s apart every earlier
// frame is a candidate.
TEST(PlaceEvaluationTest, TimestampsSetTauCInSeconds) {
  SequenceFeatures sequence = Extract(testing::ProjectTestData("corridor"));
  ASSERT_EQ(sequence.features.size(), 4u);
  for (size_t i = 0; i < 4; ++i) sequence.features.push_back(sequence.features[i]);
  const auto candidates = [&](const std::vector<std::optional<double>>& timestamps) {
    sequence.timestamps = timestamps;
    auto results = DetectLoops(sequence, PlaceVocabulary(), PlaceEvaluationOptions{});
    EXPECT_TRUE(results.ok()) << results.status().ToString();
    std::vector<EntryId> matches;
    for (const LoopResult& r : *results) matches.push_back(r.match);
    return matches;
  };
  for (const EntryId match : candidates({})) EXPECT_EQ(match, kInvalidEntryId);
  for (const EntryId match : candidates({1, 2, 3, 4, 5, 6, 7, 8})) {
    EXPECT_EQ(match, kInvalidEntryId);
  }
  for (const EntryId match : candidates({0, 1, 2, 3, 4, 5, 6, 7})) {
    EXPECT_EQ(match, kInvalidEntryId);
  }
  const std::vector<EntryId> matches = candidates({100, 200, 300, 400, 500, 600, 700, 800});
  int repeated = 0;
  for (size_t i = 4; i < 8; ++i) repeated += matches[i] == EntryId(i - 4);
  EXPECT_GE(repeated, 3);
}

// Frames 1, 20, 41 and 60 of the corridor: 41 revisits 1, and 60 revisits 20.
TEST(PlaceEvaluationTest, ASecondRobotFindsTheFirstRobotsPlacesAsInterMapLoops) {
  const SequenceFeatures sequence = Extract(testing::ProjectTestData("corridor"));
  GroundTruth truth;
  truth.frames = 4;
  truth.matches = {{}, {}, {0}, {1}};
  auto e = EvaluateAcrossMaps(sequence, truth, 2, PlaceVocabulary(), {});
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  EXPECT_EQ(e->inter_map.frames, 2);
  EXPECT_EQ(e->inter_map.query_frames_with_truth, 2);
  EXPECT_EQ(e->own_map.query_frames_with_truth, 0);
  // 41 -> 1 is recognised; 60 -> 20 shares only 14 RANSAC inliers, under the 16 that one frame's
  // evidence needs (relocalisation_min_inliers), and is left out.
  EXPECT_EQ(e->inter_map.detections, 1);
  EXPECT_EQ(e->inter_map.correct, 1);
  ASSERT_EQ(e->inter_map.loops.size(), 2u);
  for (const DetectedLoop& loop : e->inter_map.loops) {
    EXPECT_LT(loop.match, 2) << "an inter-map loop matches a frame of robot A";
    if (loop.status == LoopStatus::kLoopDetected) {
      EXPECT_EQ(loop.acceptance, LoopAcceptance::kRelocalisation);
      EXPECT_EQ(loop.query, 2);
    } else {
      EXPECT_EQ(loop.status, LoopStatus::kFailedGeometry);
      EXPECT_LT(loop.inliers, LoopDetectorParams{}.relocalisation_min_inliers);
    }
  }
  EXPECT_EQ(e->own_map.detections, 0) << "robot B has not been anywhere twice";
  EXPECT_EQ(e->inter_map.timing_ms.count("features"), 0u);
  EXPECT_EQ(e->own_map.timing_ms.count("features"), 1u);
  // 60 -> 20 is the one miss, and why: 20 was the best candidate, and failed RANSAC.
  ASSERT_EQ(e->inter_map.misses.size(), 1u);
  const MissedRevisit& miss = e->inter_map.misses[0];
  EXPECT_EQ(miss.query, 3);
  EXPECT_EQ(miss.reason, MissReason::kFailedGeometry);
  EXPECT_EQ(miss.status, "failed_geometry");
  EXPECT_EQ(miss.candidate, 1);
  EXPECT_EQ(miss.true_candidate, 1);
  EXPECT_EQ(miss.true_rank, 1);
  ASSERT_TRUE(miss.inliers.has_value() && miss.correspondences.has_value());
  EXPECT_LT(*miss.inliers, LoopDetectorParams{}.relocalisation_min_inliers);
  EXPECT_GT(*miss.correspondences, *miss.inliers);
  EXPECT_EQ(e->inter_map.miss_reasons, (std::map<std::string, int>{{"failed_geometry", 1}}));
  EXPECT_TRUE(e->own_map.misses.empty());
}

TEST(PlaceEvaluationTest, RobotBsSequenceFollowsRobotAsWithItsOwnClock) {
  SequenceFeatures a = Extract(testing::ProjectTestData("corridor"));
  SequenceFeatures b = a;
  a.timestamps.clear();  // robot A's frames have no time, robot B's have their own clock
  b.timestamps = {0.0, 1.0, 2.0, 3.0};
  b.names = {"b1", "b2", "b3", "b4"};
  AppendSequence(b, &a);
  ASSERT_EQ(a.features.size(), 8u);
  ASSERT_EQ(a.names.size(), 8u);
  EXPECT_EQ(a.names[4], "b1");
  EXPECT_EQ(a.feature_ms.size(), 8u);
  ASSERT_EQ(a.timestamps.size(), 8u);
  EXPECT_FALSE(a.timestamps[3].has_value());
  EXPECT_EQ(a.timestamps[4], 0.0);
  EXPECT_EQ(a.features[5].keypoints.size(), b.features[1].keypoints.size());
  EXPECT_TRUE(a.geometry.empty()) << "neither has 3D points";
}

TEST(PlaceEvaluationTest, ASplitThatLeavesARobotNoFrameIsRefused) {
  const SequenceFeatures sequence = Extract(testing::ProjectTestData("corridor"));
  GroundTruth truth;
  truth.frames = 4;
  truth.matches.resize(4);
  for (int split : {0, 4, 9}) {
    EXPECT_EQ(EvaluateAcrossMaps(sequence, truth, split, PlaceVocabulary(), {}).status().code(),
              StatusCode::kInvalidArgument)
        << split;
  }
}

TEST(PlaceEvaluationTest, TheCorridorSplitBetweenTwoRobotsKeepsTheSingleMapRecall) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("places/corridor/ground_truth.txt");
  auto source = FrameSource::Open(testing::SharedData("places/corridor/images"));
  ASSERT_TRUE(source.ok());
  auto sequence = ExtractSequence(*source, PlaceFeatureOptions(), false);
  ASSERT_TRUE(sequence.ok());
  auto truth = ReadGroundTruth(testing::SharedData("places/corridor/ground_truth.txt"));
  ASSERT_TRUE(truth.ok());
  auto e = EvaluateAcrossMaps(*sequence, *truth, 40, PlaceVocabulary(), {});
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  EXPECT_EQ(e->inter_map.query_frames_with_truth, 44);
  EXPECT_EQ(e->inter_map.precision, 1.0);
  EXPECT_GE(e->inter_map.recall, 36.0 / 44) << "the single-map recall (README)";
  EXPECT_EQ(e->own_map.precision, 1.0);
}

// ---- ExplainMiss: why a revisit was missed ----

// Ten frames; frame 9 revisits frames 2 and 3.
GroundTruth NineRevisitsTwoAndThree() {
  GroundTruth truth;
  truth.frames = 10;
  truth.matches.resize(10);
  truth.matches[9] = {2, 3};
  return truth;
}

// Frame 9's result with `status`, the query's candidates `entries` (best first) and the best
// candidate `match`.
LoopResult ResultOfNine(LoopStatus status, std::vector<EntryId> entries,
                        EntryId match = kInvalidEntryId) {
  LoopResult r;
  r.status = status;
  r.match = match;
  for (const EntryId entry : entries) r.candidates.push_back({entry, 0.1, 0.5});
  return r;
}

TEST(ExplainMissTest, AFrameThatWasNotQueriedOrGotNoTruePlaceHasNoCandidateToBlame) {
  const GroundTruth truth = NineRevisitsTwoAndThree();
  const MapFrames map{0, 10};
  for (const LoopStatus status : {LoopStatus::kTooFewFeatures, LoopStatus::kLowScoreWithPrevious}) {
    const MissedRevisit miss = ExplainMiss(ResultOfNine(status, {}), 9, map, truth);
    EXPECT_EQ(miss.reason, MissReason::kNotQueried) << LoopStatusName(status);
    EXPECT_EQ(miss.status, LoopStatusName(status));
    EXPECT_EQ(miss.query, 9);
    EXPECT_FALSE(miss.candidate || miss.true_rank || miss.inliers);
  }
  const MissedRevisit nothing =
      ExplainMiss(ResultOfNine(LoopStatus::kNoCandidates, {}), 9, map, truth);
  EXPECT_EQ(nothing.reason, MissReason::kNoCandidate);
  EXPECT_EQ(nothing.status, "no_candidates");
  // Candidates, a wrong one verified, but no true place among them: the query lost it, not the
  // ranking.
  LoopResult wrong_only = ResultOfNine(LoopStatus::kFailedGeometry, {5, 7, 8}, 5);
  wrong_only.correspondences = 20;
  const MissedRevisit no_true = ExplainMiss(wrong_only, 9, map, truth);
  EXPECT_EQ(no_true.reason, MissReason::kNoCandidate);
  EXPECT_EQ(no_true.candidate, 5);
  EXPECT_FALSE(no_true.true_rank.has_value());
  EXPECT_EQ(no_true.correspondences, 20u);
}

TEST(ExplainMissTest, ATruePlaceAmongTheCandidatesIsGivenWithItsRank) {
  const GroundTruth truth = NineRevisitsTwoAndThree();
  const MapFrames map{0, 10};
  // No candidate reached alpha: no best one; frame 3 ranked second.
  for (const LoopStatus status : {LoopStatus::kLowScore, LoopStatus::kNoConsistentIsland}) {
    const MissedRevisit miss = ExplainMiss(ResultOfNine(status, {6, 3, 2}), 9, map, truth);
    EXPECT_EQ(miss.reason, MissReason::kLowScore) << LoopStatusName(status);
    EXPECT_FALSE(miss.candidate.has_value());
    EXPECT_EQ(miss.true_candidate, 3);
    EXPECT_EQ(miss.true_rank, 2);
  }
  // The best island's best entry is 5, verified and refused; the first true place is 4th.
  LoopResult wrong_top = ResultOfNine(LoopStatus::kFailedGeometry, {5, 7, 8, 2, 3}, 5);
  wrong_top.inliers.resize(4);
  wrong_top.correspondences = 20;
  MissedRevisit miss = ExplainMiss(wrong_top, 9, map, truth);
  EXPECT_EQ(miss.reason, MissReason::kWrongTopCandidate);
  EXPECT_EQ(miss.candidate, 5);
  EXPECT_EQ(miss.true_candidate, 2);
  EXPECT_EQ(miss.true_rank, 4);
  EXPECT_EQ(miss.inliers, 4u);
  EXPECT_EQ(miss.correspondences, 20u);
  // The database's best is true, but the best island's best entry (7) is not.
  miss =
      ExplainMiss(ResultOfNine(LoopStatus::kFailedTemporalConsistency, {3, 7}, 7), 9, map, truth);
  EXPECT_EQ(miss.reason, MissReason::kWrongTopCandidate);
  EXPECT_EQ(miss.candidate, 7);
  EXPECT_EQ(miss.true_rank, 1);
  EXPECT_FALSE(miss.inliers.has_value()) << "the status says no verification is kept";
}

TEST(ExplainMissTest, ATrueBestCandidateIsLostByConsistencyOrGeometry) {
  const GroundTruth truth = NineRevisitsTwoAndThree();
  const MapFrames map{0, 10};
  LoopResult waiting = ResultOfNine(LoopStatus::kFailedTemporalConsistency, {3, 2}, 3);
  waiting.consistent_queries = 1;
  MissedRevisit miss = ExplainMiss(waiting, 9, map, truth);
  EXPECT_EQ(miss.reason, MissReason::kNotConsistent);
  EXPECT_EQ(miss.candidate, 3);
  EXPECT_EQ(miss.consistent_queries, 1u);
  EXPECT_FALSE(miss.inliers.has_value());
  // Verified, but waiting for the next keyframes' confirmation.
  LoopResult unconfirmed = ResultOfNine(LoopStatus::kCandidate, {3}, 3);
  unconfirmed.inliers.resize(40);
  unconfirmed.correspondences = 70;
  miss = ExplainMiss(unconfirmed, 9, map, truth);
  EXPECT_EQ(miss.reason, MissReason::kNotConsistent);
  EXPECT_EQ(miss.inliers, 40u);
  EXPECT_FALSE(miss.consistent_queries.has_value());

  LoopResult failed = ResultOfNine(LoopStatus::kFailedGeometry, {2, 3}, 2);
  failed.inliers.resize(9);
  failed.correspondences = 34;
  miss = ExplainMiss(failed, 9, map, truth);
  EXPECT_EQ(miss.reason, MissReason::kFailedGeometry);
  EXPECT_EQ(miss.candidate, 2);
  EXPECT_EQ(miss.true_rank, 1);
  EXPECT_EQ(miss.inliers, 9u);
  EXPECT_EQ(miss.correspondences, 34u);
  EXPECT_FALSE(miss.failed_metric);
  failed.metric.checked = true;  // the 2D check passed, the 3D one did not
  EXPECT_TRUE(ExplainMiss(failed, 9, map, truth).failed_metric);
}

TEST(ExplainMissTest, ALoopDetectedForARevisitButNotCountedCorrectIsAWrongLoop) {
  const GroundTruth truth = NineRevisitsTwoAndThree();
  LoopResult loop = ResultOfNine(LoopStatus::kLoopDetected, {6, 2}, 6);
  loop.inliers.resize(30);
  loop.correspondences = 50;
  const MissedRevisit miss = ExplainMiss(loop, 9, {0, 10}, truth);
  EXPECT_EQ(miss.reason, MissReason::kWrongLoop);
  EXPECT_EQ(miss.candidate, 6);
  EXPECT_EQ(miss.true_rank, 2);
  EXPECT_EQ(miss.inliers, 30u);
  EXPECT_EQ(miss.correspondences, 50u);
}

// Robot B's own map holds frames 4..9: its entry e is frame 4 + e.
TEST(ExplainMissTest, AnotherMapsEntriesAreItsOwnFrames) {
  GroundTruth truth = NineRevisitsTwoAndThree();
  truth.matches[9] = {3, 5};
  const MapFrames robot_b{4, 10};
  EXPECT_TRUE(RevisitsMap(truth, 9, robot_b));
  EXPECT_TRUE(RevisitsMap(truth, 9, {0, 4}));
  EXPECT_FALSE(RevisitsMap(truth, 9, {6, 10}));
  EXPECT_FALSE(RevisitsMap(truth, 8, {0, 10}));
  LoopResult r = ResultOfNine(LoopStatus::kFailedGeometry, {0, 1}, 1);
  const MissedRevisit miss = ExplainMiss(r, 9, robot_b, truth);
  EXPECT_EQ(miss.reason, MissReason::kFailedGeometry);
  EXPECT_EQ(miss.candidate, 5);
  EXPECT_EQ(miss.true_candidate, 5);
  EXPECT_EQ(miss.true_rank, 2);
}

TEST(PlaceEvaluationTest, AGroundTruthOfAnotherLengthIsRefused) {
  const SequenceFeatures sequence = Extract(testing::ProjectTestData("corridor"));
  GroundTruth truth;
  truth.frames = 5;
  truth.matches.resize(5);
  EXPECT_EQ(EvaluatePlace(sequence, truth, PlaceVocabulary(), {}).status().code(),
            StatusCode::kInvalidArgument);
}

TEST(PlaceEvaluationTest, FrameSourcesReadListsAndRefuseWhatTheyCannotRead) {
  const fs::path dir = fs::temp_directory_path() / ("recog_sources_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  {
    std::ofstream(dir / "list.txt") << "# two frames\n"
                                    << testing::ProjectTestData("corridor/1.jpg") << "\n\n"
                                    << testing::ProjectTestData("corridor/20.jpg") << "\n";
    std::ofstream(dir / "empty.txt") << "# nothing\n";
    std::ofstream(dir / "garbage.avi") << "not a video";
    std::ofstream(dir / "bad.txt") << (dir / "missing.jpg").string() << "\n";
  }
  EXPECT_EQ(Extract((dir / "list.txt").string()).features.size(), 2u);
  EXPECT_EQ(FrameSource::Open((dir / "empty.txt").string()).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(FrameSource::Open((dir / "garbage.avi").string()).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(FrameSource::Open((dir / "nope").string()).status().code(), StatusCode::kNotFound);
  // Cameras are camera:N; this machine has no /dev/video99.
  EXPECT_EQ(FrameSource::Open("camera:99").status().code(), StatusCode::kNotFound);
  for (const char* bad : {"camera:", "camera:x", "camera:-1", "camera:1x"}) {
    EXPECT_EQ(FrameSource::Open(bad).status().code(), StatusCode::kInvalidArgument) << bad;
  }
  auto bad = FrameSource::Open((dir / "bad.txt").string());
  ASSERT_TRUE(bad.ok());
  EXPECT_EQ(ExtractSequence(*bad, FeatureOptions{}, false).status().code(), StatusCode::kNotFound);
  fs::remove_all(dir);
}

TEST(PlaceEvaluationTest, AVideoFileIsReadFrameByFrame) {
  const fs::path path =
      fs::temp_directory_path() / ("recog_video_" + std::to_string(::getpid()) + ".avi");
  {
    cv::VideoWriter writer(path.string(), cv::CAP_OPENCV_MJPEG,
                           cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 5.0, cv::Size(512, 384));
    ASSERT_TRUE(writer.isOpened());
    for (const char* name : {"1.jpg", "20.jpg", "41.jpg"}) {
      writer.write(cv::imread(testing::ProjectTestData(std::string("corridor/") + name)));
    }
  }
  const SequenceFeatures sequence = Extract(path.string());
  fs::remove(path);
  ASSERT_EQ(sequence.features.size(), 3u);
  EXPECT_GT(sequence.features[0].size(), 100u);
  EXPECT_NE(sequence.names[2].find("#3"), std::string::npos);
}

}  // namespace
}  // namespace recog::cli
