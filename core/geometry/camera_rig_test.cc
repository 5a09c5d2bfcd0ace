#include "core/geometry/camera_rig.h"

#include <cmath>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

namespace recog {
namespace {

cv::Matx33d TurnAboutY(double degrees) {
  const double a = degrees * CV_PI / 180.0;
  return {std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a)};
}

// A front camera and a left camera (EuRoC-like intrinsics and distortion).
std::vector<RigCamera> FrontAndLeft() {
  return {{"front",
           {640, 480},
           {400, 0, 319.5, 0, 401, 239.5, 0, 0, 1},
           {},
           LensModel::kRadialTangential,
           cv::Matx33d::eye(),
           {0, 0, 0.4}},
          {"left",
           {752, 480},
           {458.654, 0, 367.215, 0, 457.296, 248.375, 0, 0, 1},
           {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05},
           LensModel::kRadialTangential,
           TurnAboutY(-90),
           {-0.25, 0.01, 0.1}}};
}

TEST(CameraRigTest, ARigOfRigidCamerasValidates) { EXPECT_TRUE(ValidateRig(FrontAndLeft()).ok()); }

// What a robotics engineer gets wrong in a rig is refused, naming the camera.
TEST(CameraRigTest, AFaultyRigIsRefusedNamingTheCamera) {
  struct Case {
    std::string fault;
    void (*apply)(RigCamera*);
  };
  const std::vector<Case> cases = {
      {"is not a rotation", [](RigCamera* c) { c->body_R_camera *= 1.01; }},  // scaled
      {"is not a rotation",  // a reflection: orthonormal, det -1
       [](RigCamera* c) { c->body_R_camera = {-1, 0, 0, 0, 1, 0, 0, 0, 1}; }},
      {"is not a rotation", [](RigCamera* c) { c->body_R_camera(0, 1) = NAN; }},
      {"fx, fy > 0", [](RigCamera* c) { c->K(1, 1) = 0; }},
      {"finite cx, cy", [](RigCamera* c) { c->K(0, 2) = INFINITY; }},
      {"width and height", [](RigCamera* c) { c->size.width = 0; }},
      {"distortion needs 4, 5, 8, 12 or 14 coefficients, got 3",
       [](RigCamera* c) {
         c->distortion = {0.1, 0.2, 0.3};
       }},
      {"translation must be finite", [](RigCamera* c) { c->body_t_camera[1] = NAN; }},
      {"equidistant camera distortion needs 4 coefficients",
       [](RigCamera* c) {
         c->lens = LensModel::kEquidistant;
         c->distortion = {0.1, 0.01, 0, 0, 0.001};
       }},
  };
  for (const Case& test : cases) {
    std::vector<RigCamera> rig = FrontAndLeft();
    test.apply(&rig[1]);
    const Status s = ValidateRig(rig);
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << test.fault;
    EXPECT_NE(s.message().find("rig camera 'left'"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find(test.fault), std::string::npos) << s.message();
  }
  std::vector<RigCamera> twice = FrontAndLeft();
  twice[1].name = "front";
  EXPECT_NE(ValidateRig(twice).message().find("'front' is used twice"), std::string::npos);
  std::vector<RigCamera> dots = FrontAndLeft();
  dots[0].name = "..";
  EXPECT_NE(ValidateRig(dots).message().find("not a folder name"), std::string::npos);
  std::vector<RigCamera> spaced = FrontAndLeft();
  spaced[1].name = "left camera";
  EXPECT_NE(ValidateRig(spaced).message().find("camera 1"), std::string::npos);
  EXPECT_EQ(ValidateRig({}).code(), StatusCode::kInvalidArgument);
}

// A keypoint where the lens put a point lands, after undistortion, where the pinhole K puts it.
TEST(CameraRigTest, UndistortedKeypointsFollowThePinholeModel) {
  RigCamera camera = FrontAndLeft()[0];
  camera.distortion = {-0.25, 0.08, 0.001, -0.0005, 0};
  const std::vector<cv::Point3d> points = {{0.3, -0.2, 1.0}, {-0.4, 0.3, 1.5}, {0, 0, 2}};
  std::vector<cv::Point2d> distorted, pinhole;
  cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), camera.K, camera.distortion,
                    distorted);
  cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), camera.K, cv::noArray(),
                    pinhole);
  std::vector<cv::KeyPoint> keypoints;
  for (const cv::Point2d& p : distorted) keypoints.emplace_back(cv::Point2f(p), 7.f);
  UndistortKeypoints(camera, &keypoints);
  for (size_t i = 0; i < points.size(); ++i) {
    EXPECT_NEAR(keypoints[i].pt.x, pinhole[i].x, 0.05) << i;
    EXPECT_NEAR(keypoints[i].pt.y, pinhole[i].y, 0.05) << i;
    EXPECT_EQ(keypoints[i].size, 7.f);
  }
  EXPECT_GT(cv::norm(distorted[0] - pinhole[0]), 1.0) << "the lens moved the point";
  camera.distortion.clear();
  std::vector<cv::KeyPoint> untouched = keypoints;
  UndistortKeypoints(camera, &untouched);
  EXPECT_EQ(untouched[0].pt, keypoints[0].pt);
}

// A fisheye camera (TUM-VI's equidistant calibration): a keypoint where its lens put a point lands
// where the pinhole K puts it, out to 60° off the axis.
TEST(CameraRigTest, EquidistantKeypointsFollowThePinholeModel) {
  RigCamera camera = FrontAndLeft()[0];
  camera.size = {512, 512};
  camera.K = {
      190.97847715128717, 0, 254.93170605935475, 0, 190.9733070521226, 256.8974428996504, 0, 0, 1};
  camera.lens = LensModel::kEquidistant;
  camera.distortion = {0.0034823894022493434, 0.0007150348452162257, -0.0020532361418706202,
                       0.00020293673591811182};
  ASSERT_TRUE(ValidateRig({&camera, 1}).ok());
  const std::vector<cv::Point3d> points = {
      {0.3, -0.2, 1.0}, {-1.2, 0.9, 1.0}, {0, 0, 2}, {1.5, 0.5, 1.0}};  // up to 58° off the axis
  std::vector<cv::Point2d> distorted, pinhole;
  cv::fisheye::projectPoints(points, distorted, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), camera.K,
                             camera.distortion);
  cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), camera.K, cv::noArray(),
                    pinhole);
  std::vector<cv::KeyPoint> keypoints;
  for (const cv::Point2d& p : distorted) keypoints.emplace_back(cv::Point2f(p), 7.f, 30.f);
  UndistortKeypoints(camera, &keypoints);
  for (size_t i = 0; i < points.size(); ++i) {
    EXPECT_NEAR(keypoints[i].pt.x, pinhole[i].x, 0.05) << i;
    EXPECT_NEAR(keypoints[i].pt.y, pinhole[i].y, 0.05) << i;
    EXPECT_EQ(keypoints[i].size, 7.f);
    EXPECT_EQ(keypoints[i].angle, 30.f);
  }
  EXPECT_GT(cv::norm(distorted[1] - pinhole[1]), 50.0) << "the lens moved the point";
}

}  // namespace
}  // namespace recog
