// Learning an object model from an RGB-D recording (rgbd_recording.h): the folder's frames paired
// by number, a synthetic walk around a box whose later views get poses close to the truth, bad
// depth images, and the real visp-rbt-cube recording learned from frame 0's pose (shared data).
#include "tools/evaluation/rgbd_recording.h"

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "core/common/rotation_angle.h"
#include "tests/testing/data_paths.h"
#include "tests/testing/test_data.h"
#include "tests/testing/vocabularies.h"
#include "tools/evaluation/frame_poses.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/evaluation/object_sequence_generator.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

ModelBuildOptions NoImages() {
  ModelBuildOptions build;
  build.keep_images = false;
  return build;
}

class RgbdRecordingTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("recog_rgbd_recording_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "images");
    fs::create_directories(dir_ / "depth");
  }
  void TearDown() override { fs::remove_all(dir_); }

  void WriteImage(const std::string& relative, const cv::Mat& image) const {
    ASSERT_TRUE(cv::imwrite((dir_ / relative).string(), image)) << relative;
  }

  // Frame i of a tiny recording: a 64 x 48 grey colour image and a depth image of 1 m.
  void WriteTinyFrame(int i) const {
    char image[64], depth[64];
    std::snprintf(image, sizeof(image), "images/color_image_%04d.png", i);
    std::snprintf(depth, sizeof(depth), "depth/depth_image_%04d.png", i);
    WriteImage(image, cv::Mat(48, 64, CV_8UC3, cv::Scalar(90, 120, 150)));
    WriteImage(depth, cv::Mat(48, 64, CV_16U, cv::Scalar(1000)));
  }

  fs::path dir_;
  ModelBuilder builder_{testing::BundledObjectVocabulary(), NoImages()};
};

TEST_F(RgbdRecordingTest, FramesArePairedByTheirNumbers) {
  WriteTinyFrame(10);
  WriteTinyFrame(2);
  WriteImage("depth/depth_image_0005.png",
             cv::Mat(48, 64, CV_16U, cv::Scalar(0)));  // no colour image: ignored
  auto frames = ListRgbdRecording(dir_.string());
  ASSERT_TRUE(frames.ok()) << frames.status().ToString();
  ASSERT_EQ(frames->size(), 2u);
  EXPECT_EQ((*frames)[0].number, 2);
  EXPECT_EQ(fs::path((*frames)[0].image).filename(), "color_image_0002.png");
  EXPECT_EQ(fs::path((*frames)[0].depth).filename(), "depth_image_0002.png");
  EXPECT_EQ((*frames)[1].number, 10);
  EXPECT_EQ(fs::path((*frames)[1].depth).filename(), "depth_image_0010.png");
}

TEST_F(RgbdRecordingTest, AMissingOrAmbiguousFrameIsAClearError) {
  WriteTinyFrame(0);
  WriteImage("images/color_image_0001.png", cv::Mat(48, 64, CV_8UC3));
  Status s = ListRgbdRecording(dir_.string()).status();
  EXPECT_EQ(s.code(), StatusCode::kNotFound);
  EXPECT_NE(s.message().find("no depth image of frame 1"), std::string::npos) << s.message();
  WriteImage("images/other_1.png", cv::Mat(48, 64, CV_8UC3));
  s = ListRgbdRecording(dir_.string()).status();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("are both frame 1"), std::string::npos) << s.message();
  fs::remove(dir_ / "images/other_1.png");
  WriteImage("images/first.png", cv::Mat(48, 64, CV_8UC3));
  s = ListRgbdRecording(dir_.string()).status();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("has no frame number"), std::string::npos) << s.message();
  fs::remove(dir_ / "images/first.png");
  fs::remove_all(dir_ / "depth");
  EXPECT_EQ(ListRgbdRecording(dir_.string()).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(ListRgbdRecording((dir_ / "none").string()).status().code(), StatusCode::kNotFound);
}

TEST_F(RgbdRecordingTest, ADepthImageOfTheWrongTypeOrSizeIsRefused) {
  WriteTinyFrame(0);
  WriteTinyFrame(1);
  auto frames = ListRgbdRecording(dir_.string());
  ASSERT_TRUE(frames.ok()) << frames.status().ToString();
  RgbdRecordingOptions options;
  options.name = "tiny";
  options.camera = {60, 60, 32, 24, {}};
  options.first_pose.t = {0, 0, 1};
  options.box.size = {0.5, 0.5, 0.1};
  const std::string depth = (dir_ / "depth/depth_image_0000.png").string();
  for (const cv::Mat& bad :
       {cv::Mat(48, 64, CV_8U, cv::Scalar(100)), cv::Mat(24, 32, CV_16U, cv::Scalar(1000))}) {
    ASSERT_TRUE(cv::imwrite(depth, bad));
    const Status s = LearnFromRgbdRecording(&builder_, *frames, options).status();
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(s.message().find("depth image '" + depth + "' must be CV_16UC1 of 64x48"),
              std::string::npos)
        << s.message();
  }
  options.depth_scale = 0;
  EXPECT_EQ(LearnFromRgbdRecording(&builder_, *frames, options).status().code(),
            StatusCode::kInvalidArgument);
  options.depth_scale = 1000;
  EXPECT_EQ(LearnFromRgbdRecording(&builder_, {}, options).status().code(),
            StatusCode::kInvalidArgument);
}

// The generator's training walk around a box (azimuth evenly from -50 to 50 degrees, the box
// centred at about 15 % of the frame, no camera effects) as a recording with exact poses: given
// frame 0's pose, the learner follows the box round and its later views get poses close to the
// truth.
TEST_F(RgbdRecordingTest, LearnsViewsOfASyntheticWalkWithPosesCloseToTheTruth) {
  constexpr int kFrames = 13;
  ObjectSequenceOptions o;
  o.shape = ObjectShape::kBox;
  o.frames = 2;
  o.training_views = kFrames;
  o.seed = 3;
  auto generator = ObjectSequenceGenerator::Create(
      {testing::ProjectTestData("corridor/1.jpg"), testing::ProjectTestData("corridor/41.jpg"),
       testing::ProjectTestData("corridor/1.jpg"), testing::ProjectTestData("corridor/41.jpg")},
      {testing::ProjectTestData("corridor/20.jpg"), testing::ProjectTestData("corridor/60.jpg")},
      o);
  ASSERT_TRUE(generator.ok()) << generator.status().ToString();
  std::map<int, RigidTransform> truth;
  for (int i = 0; i < kFrames; ++i) {
    auto view = generator->TrainingView(i);
    ASSERT_TRUE(view.ok()) << view.status().ToString();
    char image[64], depth[64];
    std::snprintf(image, sizeof(image), "images/%06d.png", i);
    std::snprintf(depth, sizeof(depth), "depth/%06d.png", i);
    WriteImage(image, view->image);
    WriteImage(depth, view->depth);
    truth[i] = view->truth.camera_from_object;
  }
  auto frames = ListRgbdRecording(dir_.string());
  ASSERT_TRUE(frames.ok()) << frames.status().ToString();
  RgbdRecordingOptions options;
  options.name = o.ObjectName();
  options.camera = generator->camera();
  options.first_pose = truth[0];
  options.box.size = {o.width, o.height, o.depth};
  size_t reports = 0;
  std::vector<RgbdViewReport> view_report;
  auto learned = LearnFromRgbdRecording(
      &builder_, *frames, options,
      [&](size_t done, size_t total, size_t /*views*/) {
        EXPECT_EQ(done, ++reports);
        EXPECT_EQ(total, size_t(kFrames - 1));
      },
      &view_report);
  ASSERT_TRUE(learned.ok()) << learned.status().ToString();
  EXPECT_EQ(reports, size_t(kFrames - 1));
  // The builder's report is on the learned views, none of which is off its depth.
  ASSERT_EQ(view_report.size(), learned->views.size());
  for (size_t i = 0; i < view_report.size(); ++i) {
    EXPECT_EQ(view_report[i].name, learned->views[i].name);
    EXPECT_FALSE(view_report[i].LooksMisposed()) << view_report[i].name;
  }
  std::printf("synthetic walk of %d frames: %zu views, found in %zu frames, %zu points\n", kFrames,
              learned->views.size(), learned->frames_found, learned->model.points.size());
  ASSERT_GE(learned->views.size(), 2u);
  EXPECT_EQ(learned->views[0].name, "000000");
  for (const PosedImage& view : learned->views) {
    const std::optional<int> frame = FrameNumber(view.name);
    ASSERT_TRUE(frame && truth.count(*frame)) << view.name;
    const RigidTransform& expected = truth[*frame];
    EXPECT_LT(RotationAngleDeg(view.camera_from_object.R, expected.R), 2.0) << view.name;
    EXPECT_LT(cv::norm(view.camera_from_object.t - expected.t), 0.01) << view.name;
  }
  EXPECT_EQ(learned->model.metadata.name, "synthetic-box");
  EXPECT_EQ(learned->model.metadata.source, "rgbd");
  for (int axis = 0; axis < 3; ++axis) {
    EXPECT_LE(learned->model.metadata.dimensions[axis], options.box.size[axis] + 0.006) << axis;
  }
}

// visp-rbt-cube: the learner runs from frame 0's pose of poses.txt, the model builds, and every
// view it chose has a pose within a few degrees and centimetres of poses.txt's (themselves good
// to about 1 degree and a few millimetres). How many views it finds is not asserted: the query's
// features still miss this small cube (recognition alone is nearly blind on it).
TEST_F(RgbdRecordingTest, VispRbtCubeLearnedFromFrameZerosPose) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/visp-rbt-cube/poses.txt");
  const std::string dir = testing::SharedData("objects/visp-rbt-cube");
  auto frames = ListRgbdRecording(dir);
  ASSERT_TRUE(frames.ok()) << frames.status().ToString();
  ASSERT_EQ(frames->size(), 50u);
  EXPECT_EQ(fs::path(frames->front().depth).filename(), "depth_image_0000.png");
  auto poses = ReadFramePoses(dir + "/poses.txt");
  ASSERT_TRUE(poses.ok()) << poses.status().ToString();
  ASSERT_EQ(poses->size(), 50u);
  RgbdRecordingOptions options;
  options.name = "visp-rbt-cube";
  options.camera = {
      607.178466796875, 607.2342529296875, 321.39129638671875, 241.91822814941406, {}};
  auto first = ReadPoseOfFrame(dir + "/poses.txt", frames->front().image);
  ASSERT_TRUE(first.ok()) << first.status().ToString();
  options.first_pose = *first;
  options.box.size = {0.085, 0.085, 0.085};
  std::vector<RgbdViewReport> view_report;
  auto learned = LearnFromRgbdRecording(&builder_, *frames, options, {}, &view_report);
  ASSERT_TRUE(learned.ok()) << learned.status().ToString();
  ASSERT_EQ(view_report.size(), learned->views.size());
  for (const RgbdViewReport& view : view_report) EXPECT_FALSE(view.LooksMisposed()) << view.name;
  std::printf("visp-rbt-cube: %zu views, found in %zu of %zu frames, %zu points\n",
              learned->views.size(), learned->frames_found, frames->size() - 1,
              learned->model.points.size());
  EXPECT_GT(learned->model.points.size(), 0u);
  EXPECT_EQ(learned->views[0].name, "color_image_0000");
  for (const PosedImage& view : learned->views) {
    const std::optional<int> frame = FrameNumber(view.name);
    ASSERT_TRUE(frame && poses->count(*frame)) << view.name;
    EXPECT_LT(RotationAngleDeg(view.camera_from_object.R, poses->at(*frame).R), 5.0) << view.name;
    EXPECT_LT(cv::norm(view.camera_from_object.t - poses->at(*frame).t), 0.03) << view.name;
  }
}

}  // namespace
}  // namespace recog::cli
