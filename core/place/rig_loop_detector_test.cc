// The rig detector on the place test frames: a front + rear rig whose rear camera, on the way
// back, sees what its front camera saw on the way out (a loop no single camera closes), tau_c over
// rig frames, Query leaving the map alone, frames that survive reopening and removal, and bad
// frames refused naming the camera. The
// geometry across cameras (real 3D motions, extrinsics 10° off) is tested on rendered rig drives
// in tools/evaluation/rig_place_test.cc.
#include "core/place/rig_loop_detector.h"

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/index/memory_index_store.h"
#include "core/place/map_registry.h"
#include "core/place/place_test_frames.h"
#include "tests/testing/option_cases.h"

namespace recog {
namespace {

// Textured noise that shares no scene with the places (a view nobody has seen).
cv::Mat Unseen(const cv::Size& size, int seed) {
  cv::Mat noise(size.height / 8, size.width / 8, CV_8U);
  cv::RNG rng(uint64_t(seed) + 1);
  rng.fill(noise, cv::RNG::UNIFORM, 0, 256);
  cv::Mat image;
  cv::resize(noise, image, size, 0, 0, cv::INTER_NEAREST);
  cv::GaussianBlur(image, image, cv::Size(3, 3), 0);
  return image;
}

std::vector<RigCamera> FrontAndRear(const cv::Size& size) {
  RigCamera front;
  front.name = "front";
  front.size = size;
  front.K = cv::Matx33d(300, 0, size.width / 2.0, 0, 300, size.height / 2.0, 0, 0, 1);
  front.body_t_camera = {0, 0, 0.4};
  RigCamera rear = front;
  rear.name = "rear";
  rear.body_R_camera = cv::Matx33d(-1, 0, 0, 0, 1, 0, 0, 0, -1);  // looking back
  rear.body_t_camera = {0, 0, -0.4};
  return {front, rear};
}

class RigLoopDetectorTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    vocabulary_ = new std::shared_ptr<const Vocabulary>(testing::TrainPlacesVocabulary());
  }
  static void TearDownTestSuite() { delete vocabulary_; }

  void SetUp() override {
    places_ = testing::Places();
    size_ = places_[0].size();
    params_.detector.recent_frames = 4;
  }

  std::unique_ptr<Database> NewDatabase(const std::string& name) {
    auto db = Database::Create(&store_, name, *vocabulary_);
    EXPECT_TRUE(db.ok()) << db.status().ToString();
    return std::move(db).value();
  }

  RigFrame Frame(const cv::Mat& front, const cv::Mat& rear) const {
    RigFrame frame;
    frame.cameras = testing::Extract({front, rear});
    return frame;
  }

  // Out: the front camera sees place 0, the rear place 1 (4 frames). Then 2 frames of views
  // nobody saw, tau_c's 4 frames ending with them. Back: the rear camera sees place 0 again, the
  // front camera views nobody saw (4 frames).
  std::vector<RigFrame> OutAndBack() const {
    std::vector<RigFrame> frames;
    const auto out_front = testing::Visit(places_[0], 4);
    const auto out_rear = testing::Visit(places_[1], 4);
    for (size_t i = 0; i < 4; ++i) frames.push_back(Frame(out_front[i], out_rear[i]));
    for (int i = 0; i < 2; ++i)
      frames.push_back(Frame(Unseen(size_, 10 + i), Unseen(size_, 20 + i)));
    const auto back_rear = testing::Visit(places_[0], 4, 2);
    for (size_t i = 0; i < 4; ++i) frames.push_back(Frame(Unseen(size_, int(i)), back_rear[i]));
    return frames;
  }

  static std::shared_ptr<const Vocabulary>* vocabulary_;
  MemoryIndexStore store_;
  std::vector<cv::Mat> places_;
  cv::Size size_;
  RigLoopParams params_;
};
std::shared_ptr<const Vocabulary>* RigLoopDetectorTest::vocabulary_ = nullptr;

TEST_F(RigLoopDetectorTest, TheRearCameraClosesTheLoopTheFrontCameraSaw) {
  auto db = NewDatabase("rig");
  auto detector = RigLoopDetector::Create(db.get(), FrontAndRear(size_), params_);
  ASSERT_TRUE(detector.ok()) << detector.status().ToString();
  const std::vector<RigFrame> frames = OutAndBack();
  int loops = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    auto result = detector->Process(frames[i]);
    ASSERT_TRUE(result.ok()) << result.status().ToString();
    EXPECT_EQ(result->frame, std::optional<uint64_t>(2 * i));  // the first camera image's id
    if (i < 6) {
      EXPECT_NE(result->status, RigLoopStatus::kLoopDetected) << i;
      continue;
    }
    ASSERT_EQ(result->status, RigLoopStatus::kLoopDetected)
        << i << ": " << RigLoopStatusName(result->status);
    ++loops;
    ASSERT_TRUE(result->match_frame.has_value());
    EXPECT_LT(*result->match_frame, 8u) << i;  // rig frames 0-3 of the way out
    // Only the rear camera saw the place before, with the front camera.
    ASSERT_EQ(result->pairs.size(), 1u) << i;
    EXPECT_EQ(result->pairs[0].query_camera, 1u);
    EXPECT_EQ(result->pairs[0].match_camera, 0u);
    EXPECT_GE(result->pairs[0].verification.inliers.size(), 16u);
    EXPECT_FALSE(result->metric);  // no depth
  }
  EXPECT_EQ(loops, 4);
  EXPECT_EQ(detector->frames(), frames.size());
  EXPECT_EQ(db->size(), 2 * frames.size());
}

TEST_F(RigLoopDetectorTest, TheFrontCameraAloneFindsNoneOfThoseLoops) {
  auto db = NewDatabase("front-only");
  auto detector = RigLoopDetector::Create(db.get(), {FrontAndRear(size_).front()}, params_);
  ASSERT_TRUE(detector.ok()) << detector.status().ToString();
  for (const RigFrame& both : OutAndBack()) {
    RigFrame front;
    front.cameras = {both.cameras[0]};
    auto result = detector->Process(front);
    ASSERT_TRUE(result.ok()) << result.status().ToString();
    EXPECT_NE(result->status, RigLoopStatus::kLoopDetected) << *result->frame;
  }
}

TEST_F(RigLoopDetectorTest, RecentRigFramesAreNotCandidates) {
  auto db = NewDatabase("recent");
  params_.detector.recent_seconds = 10;
  auto detector = RigLoopDetector::Create(db.get(), FrontAndRear(size_), params_);
  ASSERT_TRUE(detector.ok());
  const auto views = testing::Visit(places_[0], 3);
  RigFrame frame = Frame(views[0], Unseen(size_, 7));
  frame.timestamp = 100.0;
  ASSERT_TRUE(detector->Process(frame).ok());
  frame = Frame(Unseen(size_, 8), views[1]);  // the rear sees it 5 s later: too recent
  frame.timestamp = 105.0;
  auto recent = detector->Process(frame);
  ASSERT_TRUE(recent.ok());
  EXPECT_EQ(recent->status, RigLoopStatus::kNoCandidates);
  frame = Frame(Unseen(size_, 9), views[2]);  // 20 s later: a loop
  frame.timestamp = 120.0;
  auto later = detector->Process(frame);
  ASSERT_TRUE(later.ok());
  EXPECT_EQ(later->status, RigLoopStatus::kLoopDetected) << RigLoopStatusName(later->status);
  EXPECT_EQ(later->match_frame, std::optional<uint64_t>(0));
}

TEST_F(RigLoopDetectorTest, QueryFindsThePlaceWithoutAddingTheFrame) {
  auto db = NewDatabase("query");
  auto detector = RigLoopDetector::Create(db.get(), FrontAndRear(size_), params_);
  ASSERT_TRUE(detector.ok());
  const std::vector<RigFrame> frames = OutAndBack();
  for (size_t i = 0; i < 4; ++i) ASSERT_TRUE(detector->Add(frames[i]).ok());
  auto found = detector->Query(frames[7]);  // the way back's rear camera
  ASSERT_TRUE(found.ok()) << found.status().ToString();
  EXPECT_EQ(found->status, RigLoopStatus::kLoopDetected) << RigLoopStatusName(found->status);
  EXPECT_FALSE(found->frame.has_value());
  EXPECT_EQ(detector->frames(), 4u);
  EXPECT_EQ(db->size(), 8u);
}

TEST_F(RigLoopDetectorTest, BadFramesAreRefusedNamingTheCameraAndAddNothing) {
  auto db = NewDatabase("bad");
  auto detector = RigLoopDetector::Create(db.get(), FrontAndRear(size_), params_);
  ASSERT_TRUE(detector.ok());
  RigFrame frame = OutAndBack().front();
  RigFrame one_camera = frame;
  one_camera.cameras.pop_back();
  auto missing = detector->Process(one_camera);
  EXPECT_EQ(missing.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(missing.status().message().find("'rear'"), std::string::npos)
      << missing.status().ToString();

  RigFrame wrong_points = frame;
  wrong_points.points = {{}, std::vector<cv::Point3f>(3)};
  auto points = detector->Process(wrong_points);
  EXPECT_EQ(points.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(points.status().message().find("'rear'"), std::string::npos)
      << points.status().ToString();

  RigFrame wrong_descriptors = frame;
  wrong_descriptors.cameras[1].descriptors = cv::Mat(int(frame.cameras[1].size()), 16, CV_8U);
  auto descriptors = detector->Add(wrong_descriptors);
  EXPECT_EQ(descriptors.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(descriptors.status().message().find("'rear'"), std::string::npos)
      << descriptors.status().ToString();

  RigFrame outside = frame;
  outside.cameras[0].keypoints[0].pt.x = float(size_.width) + 3.0f;
  auto keypoint = detector->Process(outside);
  EXPECT_EQ(keypoint.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(keypoint.status().message().find("'front'"), std::string::npos)
      << keypoint.status().ToString();

  RigFrame long_id = frame;
  long_id.client_id = std::string(kMaxClientIdBytes + 1, 'k');
  EXPECT_EQ(detector->Add(long_id).status().code(), StatusCode::kInvalidArgument);

  EXPECT_EQ(detector->frames(), 0u);
  EXPECT_EQ(db->size(), 0u);
}

TEST_F(RigLoopDetectorTest, AReopenedMapKnowsItsRigFramesAndRemovedOnesStayGone) {
  auto db = NewDatabase("reopened");
  const std::vector<RigFrame> frames = OutAndBack();
  {
    auto detector = RigLoopDetector::Create(db.get(), FrontAndRear(size_), params_);
    ASSERT_TRUE(detector.ok());
    for (size_t i = 0; i < 4; ++i) {
      RigFrame frame = frames[i];
      frame.client_id = i == 1 ? "kf-1" : "kf";
      ASSERT_TRUE(detector->Add(frame).ok());
    }
  }
  auto reopened = RigLoopDetector::Create(db.get(), FrontAndRear(size_), params_);
  ASSERT_TRUE(reopened.ok()) << reopened.status().ToString();
  EXPECT_EQ(reopened->frames(), 4u);
  EXPECT_EQ(reopened->next_frame_id(), 8u);
  auto found = reopened->Query(frames[7]);
  ASSERT_TRUE(found.ok());
  ASSERT_EQ(found->status, RigLoopStatus::kLoopDetected) << RigLoopStatusName(found->status);
  const uint64_t match = *found->match_frame;
  EXPECT_EQ(match % 2, 0u);  // a rig frame's id, not its rear camera image's

  auto with_id = reopened->FramesWithClientId("kf-1");
  ASSERT_TRUE(with_id.ok());
  EXPECT_EQ(with_id.value(), std::vector<uint64_t>{2});

  // Excluded, then removed: the match is never a candidate again.
  const uint64_t excluded[] = {match};
  auto without = reopened->Query(frames[7], excluded);
  ASSERT_TRUE(without.ok());
  EXPECT_NE(without->match_frame, std::optional<uint64_t>(match));
  ASSERT_TRUE(reopened->RemoveFrame(match).ok());
  EXPECT_EQ(reopened->RemoveFrame(match).code(), StatusCode::kNotFound);
  EXPECT_EQ(reopened->RemoveFrame(match + 1).code(), StatusCode::kNotFound);  // a camera image
  EXPECT_EQ(reopened->frames(), 3u);
  EXPECT_EQ(db->size(), 6u);
  auto again = RigLoopDetector::Create(db.get(), FrontAndRear(size_), params_);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->frames(), 3u);
  auto after = again->Query(frames[7]);
  ASSERT_TRUE(after.ok());
  EXPECT_NE(after->match_frame, std::optional<uint64_t>(match));
  auto added = again->Add(frames[8]);
  ASSERT_TRUE(added.ok());
  EXPECT_EQ(added.value(), 8u);  // ids are never reused
}

TEST_F(RigLoopDetectorTest, ARigPlaceMapKeepsItsRigAcrossAReopenAndRefusesSingleCameraFrames) {
  const std::vector<RigFrame> frames = OutAndBack();
  uint64_t match = 0;
  {
    auto registry = MapRegistry::Open(&store_, *vocabulary_);
    ASSERT_TRUE(registry.ok());
    std::vector<RigCamera> skewed = FrontAndRear(size_);
    skewed[1].body_R_camera = cv::Matx33d(1, 0.1, 0, 0, 1, 0, 0, 0, 1);
    const Status refused = (*registry)->Create("skewed", params_.detector, "", skewed).status();
    EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(refused.message().find("'rear'"), std::string::npos) << refused.ToString();
    EXPECT_EQ((*registry)->Get("skewed").status().code(), StatusCode::kNotFound);

    auto map = (*registry)->Create("rig-map", params_.detector, "", FrontAndRear(size_));
    ASSERT_TRUE(map.ok()) << map.status().ToString();
    auto mono = (*registry)->Create("mono", params_.detector);
    ASSERT_TRUE(mono.ok());
    const Status single = (*map)->Add(frames[0].cameras[0], std::nullopt).status();
    EXPECT_EQ(single.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(single.message().find("front, rear"), std::string::npos) << single.ToString();
    EXPECT_EQ((*mono)->AddRig(frames[0]).status().code(), StatusCode::kInvalidArgument);

    for (size_t i = 0; i < 4; ++i) {
      RigFrame frame = frames[i];
      frame.timestamp = double(i);
      frame.client_id = "kf-" + std::to_string(i);
      auto added = (*map)->AddRig(frame);
      ASSERT_TRUE(added.ok()) << added.status().ToString();
      EXPECT_EQ(added->loop.frame, std::optional<uint64_t>(2 * i));
    }
    EXPECT_EQ((*map)->frames(), 4u);
    auto found = (*map)->QueryRig(frames[7], /*correspondences=*/true);
    ASSERT_TRUE(found.ok()) << found.status().ToString();
    ASSERT_EQ(found->loop.status, RigLoopStatus::kLoopDetected);
    match = *found->loop.match_frame;
    EXPECT_EQ(found->match_client_id, "kf-" + std::to_string(match / 2));
    EXPECT_EQ(found->match_timestamp, std::optional<double>(double(match / 2)));
    ASSERT_EQ(found->correspondences.size(), found->loop.pairs.size());
    for (size_t p = 0; p < found->loop.pairs.size(); ++p) {
      const RigCameraMatch& pair = found->loop.pairs[p];
      ASSERT_EQ(found->correspondences[p].size(), pair.verification.inliers.size());
      const PlaceCorrespondence& first = found->correspondences[p].front();
      EXPECT_EQ(first.query_pixel,
                frames[7].cameras[pair.query_camera].keypoints[first.query_index].pt);
    }
    auto plain = (*map)->QueryRig(frames[7]);
    ASSERT_TRUE(plain.ok());
    EXPECT_TRUE(plain->correspondences.empty()) << "only on request";
  }
  auto registry = MapRegistry::Open(&store_, *vocabulary_);
  ASSERT_TRUE(registry.ok()) << registry.status().ToString();
  auto map = (*registry)->Get("rig-map");
  ASSERT_TRUE(map.ok());
  ASSERT_EQ((*map)->rig().size(), 2u);
  EXPECT_EQ((*map)->rig()[1].name, "rear");
  EXPECT_EQ((*map)->rig()[1].body_R_camera, FrontAndRear(size_)[1].body_R_camera);
  EXPECT_EQ((*map)->frames(), 4u);
  auto again = (*map)->QueryRig(frames[7]);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->loop.match_frame, std::optional<uint64_t>(match));
  auto removed = (*map)->RemoveFramesByClientId("kf-" + std::to_string(match / 2));
  ASSERT_TRUE(removed.ok()) << removed.status().ToString();
  EXPECT_EQ(removed.value(), std::vector<EntryId>{EntryId(match)});
  EXPECT_EQ((*map)->RemoveFrame(EntryId(match)).code(), StatusCode::kNotFound);
  EXPECT_EQ((*map)->frames(), 3u);
  EXPECT_EQ((*registry)->Delete("rig-map").value(), 3u);
}

TEST_F(RigLoopDetectorTest, AMapWithAnUntaggedEntryIsNotARigMap) {
  auto db = NewDatabase("untagged");
  ASSERT_TRUE(db->Add(OutAndBack().front().cameras[0]).ok());  // a single-camera frame
  auto detector = RigLoopDetector::Create(db.get(), FrontAndRear(size_), params_);
  EXPECT_EQ(detector.status().code(), StatusCode::kDataLoss);
  EXPECT_NE(detector.status().message().find("entry 0"), std::string::npos)
      << detector.status().ToString();
}

TEST_F(RigLoopDetectorTest, ARigWithoutRigidExtrinsicsOrBadParametersIsRefused) {
  auto db = NewDatabase("refused");
  std::vector<RigCamera> rig = FrontAndRear(size_);
  rig[1].body_R_camera = cv::Matx33d(2, 0, 0, 0, 1, 0, 0, 0, 1);
  auto scaled = RigLoopDetector::Create(db.get(), rig, params_);
  EXPECT_EQ(scaled.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(scaled.status().message().find("'rear'"), std::string::npos);

  RigLoopParams no_verification = params_;
  no_verification.max_verified_frames = 0;
  EXPECT_FALSE(RigLoopDetector::Create(db.get(), FrontAndRear(size_), no_verification).ok());
  RigLoopParams no_tolerance = params_;
  no_tolerance.max_rotation_disagreement_deg = 0;
  EXPECT_FALSE(RigLoopDetector::Create(db.get(), FrontAndRear(size_), no_tolerance).ok());
  RigLoopParams inconsistent = params_;
  inconsistent.min_consistent_ratio = std::nan("");
  const Status refused =
      RigLoopDetector::Create(db.get(), FrontAndRear(size_), inconsistent).status();
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(refused.message(), "RigLoopParams.min_consistent_ratio = nan: must be in [0, 1]");
}

TEST(RigLoopParamsTest, EveryPresetAsTheDetectorIsValid) {
  for (const char* mode : {"default", "thesis", "keyframes"}) {
    RigLoopParams params;
    params.detector = *ParseDetectorPreset(mode);
    EXPECT_TRUE(params.Validate().ok()) << mode << ": " << params.Validate().ToString();
  }
}

// One field out of its range at a time, NaN and infinity among the values: the message names the
// field (the detector's by its path) and the value.
TEST(RigLoopParamsTest, EachFieldOutOfRangeIsRefusedWithItsNameAndValue) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<testing::BadOption<RigLoopParams>> cases = {
      {"max_verified_frames = 0", [](RigLoopParams& p) { p.max_verified_frames = 0; }},
      {"max_rotation_disagreement_deg = inf",
       [&](RigLoopParams& p) { p.max_rotation_disagreement_deg = inf; }},
      {"max_rotation_disagreement_deg = -1",
       [](RigLoopParams& p) { p.max_rotation_disagreement_deg = -1; }},
      {"min_consistent_ratio = nan", [&](RigLoopParams& p) { p.min_consistent_ratio = nan; }},
      {"min_consistent_ratio = 1.5", [](RigLoopParams& p) { p.min_consistent_ratio = 1.5; }},
      {"detector.alpha = inf", [&](RigLoopParams& p) { p.detector.alpha = inf; }},
      {"detector.ratio = nan", [&](RigLoopParams& p) { p.detector.matching.ratio = nan; }},
  };
  testing::ExpectEachRefused("RigLoopParams", cases);
}

}  // namespace
}  // namespace recog
