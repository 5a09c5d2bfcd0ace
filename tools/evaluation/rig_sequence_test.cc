// The front + rear rig drive: exact geometry (where each camera is), what each camera sees (the
// way back's rear camera sees the way out's front views, its front camera does not), the ground
// truth and the files a user gets.
#include "tools/evaluation/rig_sequence.h"

#include <filesystem>

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "tests/testing/data_paths.h"
#include "tools/evaluation/dataset_layouts.h"
#include "tools/evaluation/rig_test_photos.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

std::vector<cv::Mat> Photos() { return testing::CorridorTiles(); }

RigSequenceOptions Small() {
  RigSequenceOptions o;
  o.frames_per_leg = 10;
  o.image_size = {320, 240};
  o.focal_px = 200;
  return o;
}

// Good ORB matches (ratio test 0.75) between two images.
size_t OrbMatches(const cv::Mat& a, const cv::Mat& b) {
  cv::Ptr<cv::ORB> orb = cv::ORB::create(500);
  std::vector<cv::KeyPoint> ka, kb;
  cv::Mat da, db;
  orb->detectAndCompute(a, cv::noArray(), ka, da);
  orb->detectAndCompute(b, cv::noArray(), kb, db);
  if (da.empty() || db.empty()) return 0;
  std::vector<std::vector<cv::DMatch>> knn;
  cv::BFMatcher(cv::NORM_HAMMING).knnMatch(da, db, knn, 2);
  size_t good = 0;
  for (const auto& m : knn) good += m.size() == 2 && m[0].distance < 0.75 * m[1].distance;
  return good;
}

class RigSequenceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto sequence = GenerateRigSequence(Photos(), Small());
    ASSERT_TRUE(sequence.ok()) << sequence.status().ToString();
    sequence_ = new RigSequence(std::move(sequence).value());
  }
  static void TearDownTestSuite() { delete sequence_; }
  static RigSequence* sequence_;
};
RigSequence* RigSequenceTest::sequence_ = nullptr;

TEST_F(RigSequenceTest, TheWayBacksRearCameraStandsWhereTheWayOutsFrontCameraStood) {
  const RigSequence& s = *sequence_;
  const int n = Small().frames_per_leg;
  ASSERT_EQ(s.body_poses.size(), size_t(2 * n));
  ASSERT_EQ(s.frames.size(), size_t(2 * n));
  ASSERT_EQ(s.cameras.size(), 2u);
  EXPECT_EQ(s.cameras[0].name, "front");
  EXPECT_EQ(s.cameras[1].name, "rear");
  for (int i = 1; i < 2 * n; ++i) EXPECT_GT(s.timestamps[size_t(i)], s.timestamps[size_t(i - 1)]);
  EXPECT_GE(s.timestamps[size_t(n)] - s.timestamps[size_t(n - 1)], 60.0);  // round the block
  int revisits = 0;
  for (int i = 0; i < 2 * n; ++i) {
    const auto& matches = s.truth.matches[size_t(i)];
    EXPECT_EQ(matches.empty(), i < n) << "every way-back frame revisits, no way-out frame does";
    for (const int j : matches) {
      ++revisits;
      const CameraPose rear_back = CameraInWorld(s.body_poses[size_t(i)], s.cameras[1]);
      const CameraPose front_out = CameraInWorld(s.body_poses[size_t(j)], s.cameras[0]);
      EXPECT_LE(cv::norm(rear_back.center - front_out.center), Small().revisit_radius_m);
      const cv::Vec3d axis_back = rear_back.world_from_camera * cv::Vec3d(0, 0, 1);
      const cv::Vec3d axis_out = front_out.world_from_camera * cv::Vec3d(0, 0, 1);
      EXPECT_NEAR(axis_back.dot(axis_out), std::cos(3.0 * CV_PI / 180), 1e-9);
      const CameraPose front_back = CameraInWorld(s.body_poses[size_t(i)], s.cameras[0]);
      EXPECT_LT((front_back.world_from_camera * cv::Vec3d(0, 0, 1)).dot(axis_out), -0.99);
    }
  }
  EXPECT_GE(revisits, n);
}

// What makes the sequence a test of rigs: on the way back, the rear camera sees the front camera's
// views of the way out, and the front camera sees other photos (the control finds no loop).
TEST_F(RigSequenceTest, OnlyTheRearCameraSeesTheWayOutsFrontViewsAgain) {
  const RigSequence& s = *sequence_;
  const int n = Small().frames_per_leg;
  size_t cross = 0, same = 0;
  for (int i = n; i < 2 * n; ++i) {
    const int j = s.truth.matches[size_t(i)].front();
    cross += OrbMatches(s.frames[size_t(i)][1].image, s.frames[size_t(j)][0].image);
    same += OrbMatches(s.frames[size_t(i)][0].image, s.frames[size_t(j)][0].image);
  }
  std::printf(
      "ORB matches over the way back: rear vs front of the way out %zu, front vs front %zu\n",
      cross, same);
  EXPECT_GT(cross, 3 * same);
  EXPECT_GT(cross, size_t(10 * n));
  // Depth: the exact depth of the nearest panel or wall along the camera's axis (0 where none).
  double max_depth_mm = 0;
  cv::minMaxLoc(s.frames[0][0].depth_mm, nullptr, &max_depth_mm);
  EXPECT_GT(max_depth_mm, 0);
}

TEST_F(RigSequenceTest, TheFilesReadAsARigFileOneDatasetPerCameraAndTheGroundTruth) {
  const fs::path dir = fs::path(::testing::TempDir()) / "rig_sequence";
  fs::remove_all(dir);
  ASSERT_TRUE(WriteRigSequence(*sequence_, true, dir.string()).ok());
  const YAML::Node rig = YAML::LoadFile((dir / "rig.yaml").string());
  ASSERT_EQ(rig["cameras"].size(), 2u);
  for (size_t c = 0; c < 2; ++c) {
    const YAML::Node camera = rig["cameras"][c];
    EXPECT_EQ(camera["name"].as<std::string>(), sequence_->cameras[c].name);
    EXPECT_EQ(camera["width"].as<int>(), 320);
    EXPECT_DOUBLE_EQ(camera["fx"].as<double>(), 200);
    ASSERT_EQ(camera["body_from_camera"]["rotation"].size(), 9u);
    cv::Matx33d R;
    for (int k = 0; k < 9; ++k) R.val[k] = camera["body_from_camera"]["rotation"][k].as<double>();
    EXPECT_LT(cv::norm(R * R.t() - cv::Matx33d::eye()), 1e-9);
    EXPECT_DOUBLE_EQ(camera["body_from_camera"]["translation"][2].as<double>(),
                     c == 0 ? 0.4 : -0.4);
    auto frames =
        ReadDatasetFrames((dir / sequence_->cameras[c].name).string(), DatasetLayout::kTum);
    ASSERT_TRUE(frames.ok()) << frames.status().ToString();
    ASSERT_EQ(frames->size(), sequence_->frames.size());
    EXPECT_NEAR(frames->back().timestamp, sequence_->timestamps.back(), 1e-6);
    EXPECT_FALSE(frames->front().depth.empty());
  }
  auto truth = ReadGroundTruth((dir / "ground_truth.txt").string());
  ASSERT_TRUE(truth.ok()) << truth.status().ToString();
  EXPECT_EQ(truth->matches, sequence_->truth.matches);
  EXPECT_TRUE(fs::exists(dir / "body_poses.txt"));
  // Never over existing data.
  EXPECT_EQ(WriteRigSequence(*sequence_, false, dir.string()).code(), StatusCode::kInvalidArgument);
}

TEST(RigSequenceOptionsTest, BadOptionsAndTooFewPhotosAreRefused) {
  RigSequenceOptions o = Small();
  o.frames_per_leg = 1;
  EXPECT_EQ(GenerateRigSequence(Photos(), o).status().code(), StatusCode::kInvalidArgument);
  o = Small();
  o.return_lateral_offset_m = 5;  // off the road
  EXPECT_EQ(o.Validate().code(), StatusCode::kInvalidArgument);
  const std::vector<cv::Mat> photos = Photos();
  const auto few = GenerateRigSequence({photos.begin(), photos.begin() + 3}, Small());
  EXPECT_EQ(few.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(few.status().message().find("needs 32 photos"), std::string::npos)
      << few.status().message();
}

}  // namespace
}  // namespace recog::cli
