// Camera poses of a sequence and what they say of a loop (`recog eval place --poses`), and the
// ambiguous pairs that precision leaves out.
#include "tools/evaluation/camera_trajectory.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "tools/evaluation/ground_truth.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

const cv::Matx33d kCamera(500, 0, 320, 0, 500, 240, 0, 0, 1);

class CameraTrajectoryTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("recog_trajectory_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Write(const std::string& name, const std::string& text) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path) << text;
    return path;
  }

  fs::path dir_;
};

// A camera at `center` turned `yaw` radians about the world's y axis.
CameraPose Pose(double yaw, const cv::Vec3d& center) {
  CameraPose pose;
  pose.world_from_camera =
      cv::Matx33d(std::cos(yaw), 0, std::sin(yaw), 0, 1, 0, -std::sin(yaw), 0, std::cos(yaw));
  pose.center = center;
  return pose;
}

// Both cameras' keypoints of points 5-9 m in front of the world origin.
void Project(const CameraPose& a, const CameraPose& b, int n, FeatureSet* fa, FeatureSet* fb) {
  cv::RNG rng(3);
  for (int i = 0; i < n; ++i) {
    const cv::Vec3d world(rng.uniform(-2.0, 2.0), rng.uniform(-1.5, 1.5), rng.uniform(5.0, 9.0));
    for (const auto& [pose, features] : {std::pair{&a, fa}, std::pair{&b, fb}}) {
      const cv::Vec3d x = pose->world_from_camera.t() * (world - pose->center);
      const cv::Vec3d pixel = kCamera * x;
      features->keypoints.emplace_back(float(pixel[0] / pixel[2]), float(pixel[1] / pixel[2]),
                                       31.f);
    }
  }
}

TEST_F(CameraTrajectoryTest, PosesAreReadAndBadLinesNamed) {
  const std::string good = Write("poses.txt",
                                 "# r11 .. r33 cx cy cz\n"
                                 "1 0 0 0 1 0 0 0 1 0 0 0\n\n"
                                 "0 0 1 0 1 0 -1 0 0 2.5 0 -1\n");
  auto poses = ReadCameraPoses(good);
  ASSERT_TRUE(poses.ok()) << poses.status().ToString();
  ASSERT_EQ(poses->size(), 2u);
  EXPECT_EQ((*poses)[1].center, cv::Vec3d(2.5, 0, -1));
  EXPECT_EQ(ReadCameraPoses((dir_ / "none.txt").string()).status().code(), StatusCode::kNotFound);
  for (const std::string& bad :
       {std::string("1 0 0 0 1 0 0 0 1 0 0\n"), std::string("2 0 0 0 1 0 0 0 1 0 0 0\n"),
        std::string("1 0 0 0 1 0 0 0 1 0 0 x\n"), std::string("1 0 0 0 1 0 0 0 1 nan 0 0\n"),
        std::string("1 0 0 0 1 0 0 0 1 0 inf 0\n"), std::string("# nothing\n")}) {
    const Status status = ReadCameraPoses(Write("bad.txt", bad)).status();
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << bad;
  }
  EXPECT_NE(ReadCameraPoses(Write("bad.txt", "1 0 0 0 1 0 0 0 1 0 0\n"))
                .status()
                .message()
                .find("line 1"),
            std::string::npos);
}

TEST_F(CameraTrajectoryTest, ALoopsInliersAreJudgedByTheTrueGeometry) {
  const CameraPose a = Pose(0.0, {0, 0, 0}), b = Pose(0.4, {1.5, 0.2, 0.5});
  FeatureSet fa, fb;
  Project(a, b, 60, &fa, &fb);
  std::vector<Match> right, wrong;
  for (uint32_t i = 0; i < 60; ++i) {
    right.push_back({i, i, 0});
    wrong.push_back({i, (i * 7 + 3) % 60, 0});
  }
  const LoopGeometryTruth truth = ScoreLoopGeometry(a, b, kCamera, fa, fb, right);
  EXPECT_NEAR(truth.distance_m, cv::norm(cv::Vec3d(1.5, 0.2, 0.5)), 1e-9);
  EXPECT_NEAR(truth.angle_deg, 0.4 * 180 / CV_PI, 1e-6);
  EXPECT_EQ(truth.inliers, 60u);
  EXPECT_EQ(truth.agreeing, 60u);
  EXPECT_TRUE(truth.agrees);
  const LoopGeometryTruth shuffled = ScoreLoopGeometry(a, b, kCamera, fa, fb, wrong);
  EXPECT_LT(shuffled.agreeing, 60u * kMinAgreeingShare);
  EXPECT_FALSE(shuffled.agrees);
  // x_query^T F x_match = 0 for a true correspondence.
  const cv::Matx33d F = TrueFundamental(a, b, kCamera);
  const cv::Vec3d q(fa.keypoints[4].pt.x, fa.keypoints[4].pt.y, 1);
  const cv::Vec3d m(fb.keypoints[4].pt.x, fb.keypoints[4].pt.y, 1);
  EXPECT_NEAR(q.dot(F * m), 0.0, 1e-6 * cv::norm(F));
}

TEST_F(CameraTrajectoryTest, TheTrajectoryIsDrawnWithItsLoops) {
  std::vector<CameraPose> poses;
  for (int i = 0; i < 12; ++i) {
    poses.push_back(Pose(i * 0.5, {5 * std::cos(i * 0.5), 0.1 * i, 5 * std::sin(i * 0.5)}));
  }
  const std::string path = (dir_ / "trajectory.png").string();
  ASSERT_TRUE(WriteTrajectoryPlot(poses,
                                  {{11, 0, DrawnLoop::Verdict::kCorrect},
                                   {9, 2, DrawnLoop::Verdict::kFalse},
                                   {8, 1, DrawnLoop::Verdict::kAmbiguous}},
                                  "a circle", path, 400)
                  .ok());
  const cv::Mat image = cv::imread(path);
  ASSERT_EQ(image.size(), cv::Size(400, 400));
  // Green, red and orange lines are there.
  int green = 0, red = 0, orange = 0;
  for (const auto& p : cv::Mat_<cv::Vec3b>(image)) {
    green += p == cv::Vec3b(40, 160, 40);
    red += p == cv::Vec3b(40, 40, 220);
    orange += p == cv::Vec3b(0, 150, 250);
  }
  EXPECT_GT(green, 50);
  EXPECT_GT(red, 50);
  EXPECT_GT(orange, 50);
  EXPECT_FALSE(WriteTrajectoryPlot({}, {}, "none", path).ok());
}

TEST_F(CameraTrajectoryTest, AmbiguousPairsAreReadEitherWayRound) {
  GroundTruth truth;
  truth.frames = 10;
  truth.matches.resize(10);
  ASSERT_TRUE(ReadAmbiguousPairs(Write("a.txt", "# i j\n10 2\n3 7\n\n"), &truth).ok());
  EXPECT_TRUE(truth.IsAmbiguous(9, 1));
  EXPECT_TRUE(truth.IsAmbiguous(1, 9));
  EXPECT_TRUE(truth.IsAmbiguous(6, 2));
  EXPECT_FALSE(truth.IsAmbiguous(9, 2));
  for (const std::string& bad :
       {std::string("11 2\n"), std::string("3 3\n"), std::string("3 x\n"), std::string("0 1\n")}) {
    EXPECT_EQ(ReadAmbiguousPairs(Write("b.txt", bad), &truth).code(), StatusCode::kDataLoss) << bad;
  }
  EXPECT_EQ(ReadAmbiguousPairs((dir_ / "none").string(), &truth).code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace recog::cli
