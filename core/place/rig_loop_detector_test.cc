// The rig detector on the place test frames: a front + rear rig whose rear camera, on the way
// back, sees what its front camera saw on the way out (a loop no single camera closes), tau_c over
// rig frames, Query leaving the map alone, and bad frames refused naming the camera. The
// geometry across cameras (real 3D motions, extrinsics 10° off) is tested on rendered rig drives
// in tools/evaluation/rig_place_test.cc.
#include "core/place/rig_loop_detector.h"

#include <gtest/gtest.h>

#include "core/index/memory_index_store.h"
#include "core/place/place_test_frames.h"

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
    EXPECT_EQ(result->frame, i);
    if (i < 6) {
      EXPECT_NE(result->status, RigLoopStatus::kLoopDetected) << i;
      continue;
    }
    ASSERT_EQ(result->status, RigLoopStatus::kLoopDetected)
        << i << ": " << RigLoopStatusName(result->status);
    ++loops;
    ASSERT_TRUE(result->match_frame.has_value());
    EXPECT_LT(*result->match_frame, 4u) << i;
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
    EXPECT_NE(result->status, RigLoopStatus::kLoopDetected) << result->frame;
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
  EXPECT_EQ(found->frame, 4u);
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

  EXPECT_EQ(detector->frames(), 0u);
  EXPECT_EQ(db->size(), 0u);
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
}

}  // namespace
}  // namespace recog
