// ObjectTracker on a synthetic stream: a poster rendered along a smooth trajectory is recognised
// once, then tracked with its pose; a frame without it loses it and the next frame recognises it
// again. Learning from a recording of the turning poster (recording_learner.h) adds views with
// their true poses. (The real sequence, visp-cube, is in tools/evaluation/object_tracking_test.cc.)
#include "core/object/tracking/object_tracker.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/rotation_angle.h"
#include "core/index/memory_index_store.h"
#include "core/object/builder/model_builder.h"
#include "core/object/tracking/recording_learner.h"
#include "tests/testing/option_cases.h"
#include "tests/testing/recognizers.h"
#include "tests/testing/test_data.h"
#include "tests/testing/vocabularies.h"

namespace recog {
namespace {

constexpr double kWidth = 0.64, kHeight = 0.48;  // metres

class ObjectTrackerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    poster_ = cv::imread(testing::ProjectTestData("corridor/1.jpg"), cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(poster_.empty());
    ModelBuilder builder(testing::BundledObjectVocabulary());
    auto model = builder.FromFaceImages("poster", {{BoxSide::kFront, poster_}}, kWidth, kHeight);
    ASSERT_TRUE(model.ok()) << model.status().ToString();
    model_ = std::move(*model);
    auto database = ObjectDatabase::Open(&store_, testing::BundledObjectVocabulary());
    ASSERT_TRUE(database.ok()) << database.status().ToString();
    database_ = std::move(*database);
    ASSERT_TRUE(database_->Put(model_).ok());
    camera_ = {500, 500, 320, 240, {}};
  }

  // Frame i of a slow pan: the poster turns 2 degrees and slides 1 cm a frame.
  static RigidTransform PoseAt(int i) {
    RigidTransform pose;
    cv::Rodrigues(cv::Vec3d(0.1 * CV_PI / 180 * i, (2.0 * i - 10) * CV_PI / 180, 0), pose.R);
    pose.t = {0.01 * i - 0.05, 0.0, 1.0 + 0.01 * i};
    return pose;
  }

  cv::Mat Render(const RigidTransform& camera_from_object) const {
    const RigidTransform m = camera_from_object * model_.faces[0].object_from_face;
    const cv::Matx33d plane(m.R(0, 0), m.R(0, 1), m.t[0], m.R(1, 0), m.R(1, 1), m.t[1], m.R(2, 0),
                            m.R(2, 1), m.t[2]);
    const cv::Matx33d scale(kWidth / poster_.cols, 0, 0, 0, kHeight / poster_.rows, 0, 0, 0, 1);
    cv::Mat view;
    cv::warpPerspective(poster_, view, cv::Mat(camera_.K() * plane * scale), cv::Size(640, 480),
                        cv::INTER_LINEAR, cv::BORDER_CONSTANT, 90);
    return view;
  }

  cv::Mat poster_;
  MemoryIndexStore store_;
  ObjectModel model_;
  std::shared_ptr<ObjectDatabase> database_;
  CameraIntrinsics camera_;
};

TEST_F(ObjectTrackerTest, RecognisesOnceThenTracksWithThePose) {
  ObjectRecognizer recognizer = testing::MakeRecognizer(database_);
  ObjectTracker tracker(database_);
  std::vector<Detection> detections;
  std::vector<double> rotation_errors;
  for (int i = 0; i < 8; ++i) {
    TrackingTiming timing;
    ASSERT_TRUE(tracker.Track(recognizer, Render(PoseAt(i)), camera_, &detections, &timing).ok());
    ASSERT_EQ(detections.size(), 1u) << "frame " << i;
    const Detection& d = detections[0];
    EXPECT_EQ(d.name, "poster");
    EXPECT_EQ(d.tracked, i > 0) << "frame " << i;
    EXPECT_EQ(timing.recognized, i == 0) << "frame " << i;
    EXPECT_EQ(timing.tracked, i > 0 ? 1u : 0u);
    EXPECT_GE(d.inliers, tracker.options().matching.min_inliers);
    // A poster seen nearly face-on constrains its tilt weakly: one frame may be a few degrees off
    // (frame 1, the first tracked, before any motion is known, is 6.4 degrees off), the typical
    // frame is not.
    rotation_errors.push_back(RotationAngleDeg(d.camera_from_object.R, PoseAt(i).R));
    EXPECT_LT(rotation_errors.back(), 8.0) << "frame " << i;
    EXPECT_LT(cv::norm(d.camera_from_object.t - PoseAt(i).t), 0.02) << "frame " << i;
    EXPECT_GE(d.outline.size(), 4u);
  }
  EXPECT_EQ(tracker.tracked_objects(), 1u);
  std::nth_element(rotation_errors.begin(), rotation_errors.begin() + 4, rotation_errors.end());
  EXPECT_LT(rotation_errors[4], 1.0) << "median rotation error, degrees";
}

TEST_F(ObjectTrackerTest, LostWithoutTheObjectThenRecognisedAgain) {
  ObjectRecognizer recognizer = testing::MakeRecognizer(database_);
  ObjectTracker tracker(database_);
  std::vector<Detection> detections;
  TrackingTiming timing;
  ASSERT_TRUE(tracker.Track(recognizer, Render(PoseAt(0)), camera_, &detections).ok());
  ASSERT_TRUE(tracker.Track(recognizer, Render(PoseAt(1)), camera_, &detections).ok());
  ASSERT_EQ(detections.size(), 1u);
  EXPECT_TRUE(detections[0].tracked);
  const cv::Mat black(480, 640, CV_8U, cv::Scalar(0));
  ASSERT_TRUE(tracker.Track(recognizer, black, camera_, &detections, &timing).ok());
  EXPECT_TRUE(detections.empty());
  EXPECT_EQ(timing.lost, 1u);
  EXPECT_TRUE(timing.recognized);  // a lost object triggers the full search at once
  EXPECT_EQ(tracker.tracked_objects(), 0u);
  ASSERT_TRUE(tracker.Track(recognizer, Render(PoseAt(3)), camera_, &detections, &timing).ok());
  ASSERT_EQ(detections.size(), 1u);
  EXPECT_FALSE(detections[0].tracked);
  EXPECT_TRUE(timing.recognized);
  ASSERT_TRUE(tracker.Track(recognizer, Render(PoseAt(4)), camera_, &detections).ok());
  ASSERT_EQ(detections.size(), 1u);
  EXPECT_TRUE(detections[0].tracked);
}

TEST_F(ObjectTrackerTest, RecognitionRunsEveryIntervalWhileTracking) {
  ObjectRecognizer recognizer = testing::MakeRecognizer(database_);
  TrackingOptions options;
  options.recognition_interval = 3;
  ObjectTracker tracker(database_, options);
  std::vector<Detection> detections;
  for (int i = 0; i < 7; ++i) {
    TrackingTiming timing;
    ASSERT_TRUE(tracker.Track(recognizer, Render(PoseAt(i)), camera_, &detections, &timing).ok());
    EXPECT_EQ(timing.recognized, i % 3 == 0) << "frame " << i;
    ASSERT_EQ(detections.size(), 1u);
    EXPECT_EQ(detections[0].tracked, i > 0);  // a tracked object keeps its tracked detection
  }
  tracker.Reset();
  TrackingTiming timing;
  ASSERT_TRUE(tracker.Track(recognizer, Render(PoseAt(7)), camera_, &detections, &timing).ok());
  EXPECT_TRUE(timing.recognized);
  ASSERT_EQ(detections.size(), 1u);
  EXPECT_FALSE(detections[0].tracked);
}

TEST_F(ObjectTrackerTest, TracksFramesGivenAsFeaturesAndHonoursTheFilter) {
  ObjectRecognizer recognizer = testing::MakeRecognizer(database_);
  ObjectTracker tracker(database_);
  FeatureOptions feature_options;
  feature_options.orb = recognizer.options().orb;
  auto extractor = CreateFeatureExtractor(feature_options);
  ASSERT_TRUE(extractor.ok());
  std::vector<Detection> detections;
  for (int i = 0; i < 3; ++i) {
    FeatureSet features;
    ASSERT_TRUE((*extractor)->Extract(Render(PoseAt(i)), &features).ok());
    ASSERT_TRUE(tracker.TrackFeatures(recognizer, features, camera_, &detections).ok());
    ASSERT_EQ(detections.size(), 1u);
    EXPECT_EQ(detections[0].tracked, i > 0);
    EXPECT_LT(RotationAngleDeg(detections[0].camera_from_object.R, PoseAt(i).R), 1.0);
  }
  ObjectFilter other;
  other.names = {"not-the-poster"};
  ASSERT_TRUE(
      tracker.Track(recognizer, Render(PoseAt(3)), camera_, &detections, nullptr, other).ok());
  EXPECT_TRUE(detections.empty());
}

TEST_F(ObjectTrackerTest, BadInputIsRejectedAndKeepsTheTracks) {
  ObjectRecognizer recognizer = testing::MakeRecognizer(database_);
  ObjectTracker tracker(database_);
  std::vector<Detection> detections;
  ASSERT_TRUE(tracker.Track(recognizer, Render(PoseAt(0)), camera_, &detections).ok());
  EXPECT_EQ(tracker.Track(recognizer, cv::Mat(), camera_, &detections).code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(
      tracker.Track(recognizer, Render(PoseAt(1)), {0, 500, 320, 240, {}}, &detections).code(),
      StatusCode::kInvalidArgument);
  FeatureSet wrong_width;
  wrong_width.keypoints.resize(2);
  wrong_width.descriptors = cv::Mat(2, 16, CV_8U, cv::Scalar(0));
  EXPECT_EQ(tracker.TrackFeatures(recognizer, wrong_width, camera_, &detections).code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(tracker.tracked_objects(), 1u);
  ASSERT_TRUE(tracker.Track(recognizer, Render(PoseAt(1)), camera_, &detections).ok());
  ASSERT_EQ(detections.size(), 1u);
  EXPECT_TRUE(detections[0].tracked);
}

class RecordingLearnerTest : public ObjectTrackerTest {
 protected:
  void SetUp() override {
    ObjectTrackerTest::SetUp();
    // The poster's rectangle, as a CAD model would give it.
    const RigidTransform& face = model_.faces[0].object_from_face;
    for (const cv::Vec3d& corner : {cv::Vec3d(0, 0, 0), cv::Vec3d(kWidth, 0, 0),
                                    cv::Vec3d(kWidth, kHeight, 0), cv::Vec3d(0, kHeight, 0)}) {
      const cv::Vec3d corner_in_object = face.R * corner + face.t;
      poster_polygon_.corners.emplace_back(corner_in_object[0], corner_in_object[1],
                                           corner_in_object[2]);
    }
    first_ = {"frame0", Render(PoseAt(0)), camera_, PoseAt(0)};
    for (int i = 1; i <= 20; ++i)
      frames_.push_back({"frame" + std::to_string(i), Render(PoseAt(i))});
    build_ = [this](const std::vector<PosedImage>& views) {
      ++builds_;
      return builder_.FromPosedPolygons("poster", {poster_polygon_}, views);
    };
  }

  static ModelBuildOptions NoImages() {
    ModelBuildOptions options;
    options.keep_images = false;
    return options;
  }

  FacePolygon poster_polygon_;
  PosedImage first_;
  std::vector<RecordingFrame> frames_;  // frames 1..20: the poster turns 2 degrees a frame
  ModelBuilder builder_{testing::BundledObjectVocabulary(), NoImages()};
  ModelFromViews build_;
  int builds_ = 0;
};

// Direction of the camera centre from the object frame's origin, in the object frame.
cv::Vec3d ViewDirection(const RigidTransform& camera_from_object) {
  const cv::Vec3d centre = -(camera_from_object.R.t() * camera_from_object.t);
  return centre / cv::norm(centre);
}

double AngleDeg(const cv::Vec3d& a, const cv::Vec3d& b) {
  return std::acos(std::clamp(a.dot(b), -1.0, 1.0)) * 180.0 / CV_PI;
}

TEST_F(RecordingLearnerTest, AddsAViewEachTimeTheObjectHasTurnedFarEnoughWithItsTruePose) {
  RecordingLearningOptions options;
  options.min_view_angle_deg = 10;
  auto learned =
      LearnFromRecording(build_, testing::BundledObjectVocabulary(), first_, frames_, options);
  ASSERT_TRUE(learned.ok()) << learned.status().ToString();
  EXPECT_EQ(learned->frames_found, frames_.size());
  // The true directions turn by 30 degrees over the 20 frames: two views or more besides frame 0.
  ASSERT_GE(learned->views.size(), 3u);
  EXPECT_EQ(builds_, int(learned->views.size()));
  EXPECT_EQ(learned->model.views.size(), learned->views.size());
  std::vector<cv::Vec3d> true_directions = {ViewDirection(PoseAt(0))};
  for (size_t k = 1; k < learned->views.size(); ++k) {
    const int frame = int(learned->view_frames[k - 1]) + 1;  // frames_[i] is frame i + 1
    EXPECT_EQ(learned->views[k].name, "frame" + std::to_string(frame));
    // A plane's tilt is the least determined part of its pose: the same frame's rotation comes
    // out 0.4 degrees off in a Release build and 1.7 in RelWithDebInfo, where rounding sends RANSAC
    // down another path. A wrong view would be tens of degrees off.
    EXPECT_LT(RotationAngleDeg(learned->views[k].camera_from_object.R, PoseAt(frame).R), 2.5);
    EXPECT_LT(cv::norm(learned->views[k].camera_from_object.t - PoseAt(frame).t), 0.02);
    // Truly seen from a new direction (the estimated pose may be a fraction of a degree off).
    for (const cv::Vec3d& seen : true_directions) {
      EXPECT_GT(AngleDeg(ViewDirection(PoseAt(frame)), seen), options.min_view_angle_deg - 1)
          << "view " << k;
    }
    true_directions.push_back(ViewDirection(PoseAt(frame)));
  }
  // With twice the angle, fewer views.
  options.min_view_angle_deg = 20;
  auto fewer =
      LearnFromRecording(build_, testing::BundledObjectVocabulary(), first_, frames_, options);
  ASSERT_TRUE(fewer.ok()) << fewer.status().ToString();
  EXPECT_LT(fewer->views.size(), learned->views.size());
  EXPECT_GE(fewer->views.size(), 2u);
}

TEST_F(RecordingLearnerTest, NoViewIsLearnedFromFramesWithoutTheObject) {
  const std::vector<RecordingFrame> empty_frames = {
      {"grey", cv::Mat(480, 640, CV_8U, cv::Scalar(90))}, {"noise", [] {
                                                             cv::Mat noise(480, 640, CV_8U);
                                                             cv::randu(noise, 0, 255);
                                                             return noise;
                                                           }()}};
  auto learned =
      LearnFromRecording(build_, testing::BundledObjectVocabulary(), first_, empty_frames, {});
  ASSERT_TRUE(learned.ok()) << learned.status().ToString();
  EXPECT_EQ(learned->frames_found, 0u);
  EXPECT_EQ(learned->views.size(), 1u);
  EXPECT_TRUE(learned->view_frames.empty());
}

TEST_F(RecordingLearnerTest, BadInputAndTheBuildersErrorsAreReturned) {
  std::vector<RecordingFrame> frames = frames_;
  frames[3].image = cv::Mat(480, 640, CV_32F, cv::Scalar(0));
  auto not_8_bit =
      LearnFromRecording(build_, testing::BundledObjectVocabulary(), first_, frames, {});
  EXPECT_EQ(not_8_bit.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(not_8_bit.status().message().find("frame4"), std::string::npos)
      << not_8_bit.status().ToString();
  RecordingLearningOptions options;
  options.min_view_angle_deg = 0;
  EXPECT_EQ(LearnFromRecording(build_, testing::BundledObjectVocabulary(), first_, frames_, options)
                .status()
                .code(),
            StatusCode::kInvalidArgument);
  options = {};
  options.max_views = 0;
  EXPECT_EQ(LearnFromRecording(build_, testing::BundledObjectVocabulary(), first_, frames_, options)
                .status()
                .code(),
            StatusCode::kInvalidArgument);
  options = {};
  options.tracking.matching.ratio = std::nan("");
  const Status tracking =
      LearnFromRecording(build_, testing::BundledObjectVocabulary(), first_, frames_, options)
          .status();
  EXPECT_EQ(tracking.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(tracking.message(),
            "RecordingLearningOptions.tracking.matching.ratio = nan: must be in (0, 1]");
  EXPECT_EQ(builds_, 0);
  const ModelFromViews failing = [](const std::vector<PosedImage>&) -> StatusOr<ObjectModel> {
    return Status::InvalidArgument("view 'frame0' yields no point");
  };
  auto refused =
      LearnFromRecording(failing, testing::BundledObjectVocabulary(), first_, frames_, {});
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.status().message().find("no point"), std::string::npos);
}

TEST(TrackingOptionsTest, TheDefaultsAreValid) {
  EXPECT_TRUE(TrackingOptions().Validate().ok());
  EXPECT_TRUE(RecordingLearningOptions().Validate().ok());
  TrackingOptions off;
  off.recognition_interval = 0;  // no periodic recognition
  EXPECT_TRUE(off.Validate().ok());
}

// One field out of its range at a time, NaN and infinity among the values.
TEST(TrackingOptionsTest, EachFieldOutOfRangeIsRefusedWithItsNameAndValue) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<testing::BadOption<TrackingOptions>> cases = {
      {"recognition_interval = -1", [](TrackingOptions& o) { o.recognition_interval = -1; }},
      {"matching.window_px = nan", [&](TrackingOptions& o) { o.matching.window_px = nan; }},
      {"matching.reprojection_px = inf",
       [&](TrackingOptions& o) { o.matching.reprojection_px = inf; }},
      {"matching.min_inliers = 0", [](TrackingOptions& o) { o.matching.min_inliers = 0; }},
  };
  testing::ExpectEachRefused("TrackingOptions", cases);
  RecordingLearningOptions learning;
  learning.min_view_angle_deg = inf;
  EXPECT_EQ(learning.Validate().message(),
            "RecordingLearningOptions.min_view_angle_deg = inf: must be in (0, 180)");
}

}  // namespace
}  // namespace recog
