// The object evaluation's image transforms and the ViSP file readers.
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

#include "tests/testing/test_data.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/evaluation/visp_files.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

// Where the transformed camera sees an object point must be where the transformed image moved
// the original pixel.
TEST(ObjectEvaluationTest, TransformedCamerasSeeThePointsWhereTheImageMovedThem) {
  const cv::Point3d x(0.1, -0.05, 0.02);
  for (ImageTransform transform :
       {ImageTransform::kHalfScale, ImageTransform::kRotate90, ImageTransform::kRotate180}) {
    cv::Mat image(480, 640, CV_8U, cv::Scalar(0));
    CameraIntrinsics camera{600, 600, 320, 240, {}};
    RigidTransform pose;
    cv::Rodrigues(cv::Vec3d(0.2, -0.1, 0.3), pose.R);
    pose.t = {0.01, 0.02, 1.0};
    cv::Point2d before, after;
    ASSERT_TRUE(ProjectPoint(camera, pose, x, &before));
    TransformView(transform, &image, &camera, &pose);
    ASSERT_TRUE(ProjectPoint(camera, pose, x, &after));
    cv::Point2d expected;
    switch (transform) {
      case ImageTransform::kHalfScale:
        EXPECT_EQ(image.size(), cv::Size(320, 240));
        expected = {(before.x + 0.5) / 2 - 0.5, (before.y + 0.5) / 2 - 0.5};
        break;
      case ImageTransform::kRotate90:
        EXPECT_EQ(image.size(), cv::Size(480, 640));
        expected = {479 - before.y, before.x};
        break;
      default:
        expected = {639 - before.x, 479 - before.y};
    }
    EXPECT_NEAR(after.x, expected.x, 1e-9) << ImageTransformName(transform);
    EXPECT_NEAR(after.y, expected.y, 1e-9) << ImageTransformName(transform);
  }
}

TEST(ObjectEvaluationTest, RotationErrorIsTheAngleBetweenTwoRotations) {
  cv::Matx33d a, b;
  cv::Rodrigues(cv::Vec3d(0, 0, 0.1), a);
  cv::Rodrigues(cv::Vec3d(0, 0, 0.3), b);
  EXPECT_NEAR(RotationErrorDeg(a, b), 0.2 * 180 / CV_PI, 1e-9);
  EXPECT_NEAR(RotationErrorDeg(a, a), 0.0, 1e-6);
  EXPECT_EQ(ParseImageTransform("rot45").status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(*ParseImageTransform("scale0.5"), ImageTransform::kHalfScale);
}

class VispFilesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("recog_visp_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Write(const std::string& name, const std::string& text) {
    std::ofstream(dir_ / name) << text;
    return (dir_ / name).string();
  }
  fs::path dir_;
};

TEST_F(VispFilesTest, ReadsFacesFromPointsAndAPose) {
  const std::string cao = Write("square.cao",
                                "V1\n# points\n4\n0 0 0\n1 0 0 # a comment\n1 1 0\n0 1 0\n"
                                "0\n0\n1\n4 0 1 2 3\n0\n0\n");
  auto faces = ReadCaoFaces(cao);
  ASSERT_TRUE(faces.ok()) << faces.status().ToString();
  ASSERT_EQ(faces->size(), 1u);
  EXPECT_EQ((*faces)[0].corners[2], cv::Point3d(1, 1, 0));
  auto pose = ReadVispPose(Write("p.pos", "0.1 0.2 0.5\n0 0 1.5707963267948966\n"));
  ASSERT_TRUE(pose.ok());
  EXPECT_NEAR(pose->R(0, 1), -1.0, 1e-9);  // 90 degrees about z
  EXPECT_EQ(pose->t, cv::Vec3d(0.1, 0.2, 0.5));
}

TEST_F(VispFilesTest, MalformedFilesAreRejected) {
  EXPECT_EQ(ReadCaoFaces((dir_ / "missing.cao").string()).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(ReadCaoFaces(Write("a.cao", "V2\n")).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadCaoFaces(Write("b.cao", "V1\n2\n0 0 0\n1 0 0\n0\n0\n1\n3 0 1 7\n")).status().code(),
            StatusCode::kInvalidArgument);  // corner 7 does not exist
  EXPECT_EQ(ReadCaoFaces(Write("c.cao", "V1\n1\n0 0 x\n")).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadVispPose(Write("d.pos", "1 2 3\n")).status().code(), StatusCode::kInvalidArgument);
}

TEST(VispFilesSharedDataTest, ReadsTheVispCube) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/visp-cube/cube.cao");
  auto faces = ReadCaoFaces(testing::SharedData("objects/visp-cube/cube.cao"));
  ASSERT_TRUE(faces.ok()) << faces.status().ToString();
  EXPECT_EQ(faces->size(), 6u);
  auto pose = ReadVispPose(testing::SharedData("objects/visp-cube/cube.0.pos"));
  ASSERT_TRUE(pose.ok());
  EXPECT_NEAR(pose->t[2], 0.5071128378, 1e-12);
}

}  // namespace
}  // namespace recog::cli
