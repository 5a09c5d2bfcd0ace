// LensWarp: a pinhole image as a lens sees it. A bright dot of the source lands where the lens
// projects its direction; what the source does not show is black; bad cameras are refused.
#include "tools/evaluation/lens_warp.h"

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

namespace recog {
namespace {

const cv::Matx33d kSourceK(300, 0, 159.5, 0, 300, 119.5, 0, 0, 1);
const CameraIntrinsics kFisheye{
    250, 250, 159.5, 119.5, {-0.01, 0.005, 0, 0}, LensModel::kEquidistant};

TEST(LensWarpTest, ADotLandsWhereTheLensProjectsItsDirection) {
  cv::Mat source(240, 320, CV_8UC1, cv::Scalar(0));
  const cv::Point dot(250, 40);
  cv::circle(source, dot, 2, cv::Scalar(255), cv::FILLED);
  auto warp = LensWarp::Create(kSourceK, kFisheye, cv::Size(320, 240));
  ASSERT_TRUE(warp.ok()) << warp.status().ToString();
  const cv::Mat seen = warp->Apply(source);
  cv::Point2d expected;
  const cv::Vec3d direction((dot.x - 159.5) / 300, (dot.y - 119.5) / 300, 1);
  ASSERT_TRUE(ProjectDirection(kFisheye, direction, &expected));
  // The dot's brightest pixel is within a pixel of the projection; the source's dot does not
  // stay where it was (the lens moved it inwards by several pixels).
  cv::Point brightest;
  cv::minMaxLoc(seen, nullptr, nullptr, nullptr, &brightest);
  EXPECT_LE(cv::norm(cv::Point2d(brightest) - expected), 1.5) << brightest << " " << expected;
  EXPECT_GT(cv::norm(cv::Point2d(dot) - expected), 5.0);
}

TEST(LensWarpTest, DirectionsTheSourceDoesNotShowAreBlack) {
  const cv::Mat white(240, 320, CV_8UC1, cv::Scalar(255));
  // A wide fisheye (short focal length) sees beyond the source's field at its corners.
  const CameraIntrinsics wide{100, 100, 159.5, 119.5, {0, 0, 0, 0}, LensModel::kEquidistant};
  auto warp = LensWarp::Create(kSourceK, wide, cv::Size(320, 240));
  ASSERT_TRUE(warp.ok());
  const cv::Mat seen = warp->Apply(white);
  EXPECT_EQ(seen.at<uint8_t>(119, 159), 255);
  EXPECT_EQ(seen.at<uint8_t>(0, 0), 0);
}

TEST(LensWarpTest, BadCamerasAndSizesAreRefused) {
  EXPECT_FALSE(LensWarp::Create(cv::Matx33d::zeros(), kFisheye, cv::Size(320, 240)).ok());
  CameraIntrinsics miscounted = kFisheye;
  miscounted.distortion.pop_back();
  const auto refused = LensWarp::Create(kSourceK, miscounted, cv::Size(320, 240));
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("equidistant"), std::string::npos);
  EXPECT_FALSE(LensWarp::Create(kSourceK, kFisheye, cv::Size(0, 240)).ok());
}

}  // namespace
}  // namespace recog
