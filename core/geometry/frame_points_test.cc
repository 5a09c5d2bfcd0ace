#include "core/geometry/frame_points.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/features/feature_extractor.h"
#include "tests/testing/data_paths.h"

namespace recog {
namespace {

const cv::Matx33d kK(500, 0, 320, 0, 500, 240, 0, 0, 1);

bool IsNaN(const cv::Point3f& p) { return std::isnan(p.x) && std::isnan(p.y) && std::isnan(p.z); }

TEST(PointsFromDepthTest, MillimetresAndMetresBackProjectWithTheCameraMatrix) {
  cv::Mat mm(480, 640, CV_16U, cv::Scalar(2000));
  mm(cv::Rect(100, 100, 50, 50)).setTo(0);  // a hole
  mm.at<uint16_t>(300, 400) = 0;            // one missing pixel, neighbours 2000 and 1500
  mm.at<uint16_t>(299, 400) = 1500;
  const std::vector<cv::KeyPoint> keypoints = {{cv::Point2f(420.0f, 140.0f), 7},
                                               {cv::Point2f(125.0f, 125.0f), 7},
                                               {cv::Point2f(400.2f, 299.8f), 7},
                                               {cv::Point2f(400.0f, 300.0f), 7},
                                               {cv::Point2f(700.0f, 10.0f), 7}};
  std::vector<cv::Point3f> points;
  ASSERT_TRUE(PointsFromDepth(keypoints, mm.size(), kK, mm, 0.001, &points).ok());
  ASSERT_EQ(points.size(), keypoints.size());
  EXPECT_FLOAT_EQ(points[0].z, 2.0f);
  EXPECT_FLOAT_EQ(points[0].x, float((420.0 - 320.0) * 2.0 / 500.0));
  EXPECT_FLOAT_EQ(points[0].y, float((140.0 - 240.0) * 2.0 / 500.0));
  EXPECT_TRUE(IsNaN(points[1]));       // inside the hole: no neighbour has a depth
  EXPECT_FLOAT_EQ(points[2].z, 1.5f);  // its own pixel
  EXPECT_FLOAT_EQ(points[3].z, 1.5f);  // no depth: the nearest neighbour (the foreground)
  EXPECT_TRUE(IsNaN(points[4]));       // outside the image

  cv::Mat metres;
  mm.convertTo(metres, CV_32F, 0.001);
  metres.at<float>(0, 0) = std::numeric_limits<float>::quiet_NaN();
  std::vector<cv::Point3f> from_metres;
  ASSERT_TRUE(PointsFromDepth(keypoints, mm.size(), kK, metres, 123.0, &from_metres).ok());
  for (size_t i = 0; i < points.size(); ++i) {
    if (IsNaN(points[i])) {
      EXPECT_TRUE(IsNaN(from_metres[i])) << i;
    } else {
      EXPECT_NEAR(from_metres[i].z, points[i].z, 1e-6) << i;
    }
  }
  // Another scale: decimetres.
  ASSERT_TRUE(PointsFromDepth(keypoints, mm.size(), kK, mm, 0.01, &points).ok());
  EXPECT_FLOAT_EQ(points[0].z, 20.0f);
}

TEST(PointsFromDepthTest, BadDepthIsInvalidArgument) {
  const std::vector<cv::KeyPoint> keypoints = {{cv::Point2f(10, 10), 7}};
  std::vector<cv::Point3f> points;
  const cv::Mat mm(480, 640, CV_16U, cv::Scalar(1000));
  auto s = PointsFromDepth(keypoints, cv::Size(320, 240), kK, mm, 0.001, &points);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("640x480"), std::string::npos) << s.ToString();
  s = PointsFromDepth(keypoints, mm.size(), kK, cv::Mat(480, 640, CV_8U), 0.001, &points);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("CV_16U"), std::string::npos) << s.ToString();
  EXPECT_EQ(
      PointsFromDepth(keypoints, mm.size(), kK, cv::Mat(480, 640, CV_32FC2), 1, &points).code(),
      StatusCode::kInvalidArgument);
  EXPECT_EQ(PointsFromDepth(keypoints, mm.size(), kK, cv::Mat(), 0.001, &points).code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(PointsFromDepth(keypoints, mm.size(), kK, mm, 0.0, &points).code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(
      PointsFromDepth(keypoints, mm.size(), cv::Matx33d::eye() * 0.0, mm, 0.001, &points).code(),
      StatusCode::kInvalidArgument);
}

class PointsFromStereoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    cv::Mat photo = cv::imread(testing::ProjectTestData("corridor/20.jpg"), cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(photo.empty());
    cv::resize(photo, left_, cv::Size(640, 480), 0, 0, cv::INTER_LINEAR);
    UseLeft(left_, FeatureOptions{});
  }

  // Makes `left` the left image, described with `options` (the right images too).
  void UseLeft(const cv::Mat& left, const FeatureOptions& options) {
    left_ = left;
    auto extractor = CreateFeatureExtractor(options);
    ASSERT_TRUE(extractor.ok());
    extractor_ = std::move(extractor).value();
    ASSERT_TRUE(extractor_->Extract(left_, &features_).ok());
  }

  // PointsFromStereo with `right` described by the left image's extractor.
  Status Points(const cv::Mat& right, double baseline, const StereoOptions& options,
                std::vector<cv::Point3f>* points) const {
    FeatureSet right_features;
    if (!right.empty()) RECOG_RETURN_IF_ERROR(extractor_->Extract(right, &right_features));
    return PointsFromStereo(features_, left_, right_features, right, kK, baseline, options, points);
  }

  // The right image of a fronto-parallel plane: the left image moved `disparity` px left
  // (and `rows` px down).
  cv::Mat Right(double disparity, double rows = 0) const {
    cv::Mat right;
    const cv::Matx23d shift(1, 0, -disparity, 0, 1, rows);
    cv::warpAffine(left_, right, shift, left_.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
    return right;
  }

  cv::Mat left_;
  std::unique_ptr<FeatureExtractor> extractor_;
  FeatureSet features_;
};

TEST_F(PointsFromStereoTest, DepthOfAFrontoParallelPlaneFromItsDisparity) {
  constexpr double kBaseline = 0.12, kDisparity = 12.3;
  const double expected_z = kK(0, 0) * kBaseline / kDisparity;  // 4.878 m
  std::vector<cv::Point3f> points;
  ASSERT_TRUE(Points(Right(kDisparity), kBaseline, {}, &points).ok());
  ASSERT_EQ(points.size(), features_.size());
  std::vector<double> errors;
  for (size_t i = 0; i < points.size(); ++i) {
    if (IsNaN(points[i])) continue;
    errors.push_back(std::abs(points[i].z - expected_z) / expected_z);
    const cv::Point2f& p = features_.keypoints[i].pt;
    EXPECT_NEAR(points[i].x, (p.x - 320.0) * points[i].z / 500.0, 1e-4);
  }
  // Most keypoints away from the borders find their match; their depth is right within 1 %.
  EXPECT_GT(errors.size(), features_.size() / 2);
  std::nth_element(errors.begin(), errors.begin() + long(errors.size() / 2), errors.end());
  EXPECT_LT(errors[errors.size() / 2], 0.01);
}

TEST_F(PointsFromStereoTest, ASmallPairEnlargedBeforeOrbGetsItsDepthInItsOwnPixels) {
  // A 160x120 pair described with the place features (enlarged to a 352-pixel short side before
  // ORB, keypoints mapped back): the right image's features come from the same enlargement, so
  // octaves and row tolerances agree and the depth is that of the 160x120 disparity.
  cv::Mat small;
  cv::resize(left_, small, cv::Size(160, 120), 0, 0, cv::INTER_AREA);
  UseLeft(small, PlaceFeatureOptions());
  ASSERT_GT(features_.size(), 100u) << "the enlarged frame has corners";
  constexpr double kBaseline = 0.12, kDisparity = 3.4;
  const double expected_z = kK(0, 0) * kBaseline / kDisparity;
  std::vector<cv::Point3f> points;
  ASSERT_TRUE(Points(Right(kDisparity), kBaseline, {}, &points).ok());
  std::vector<double> errors;
  for (size_t i = 0; i < points.size(); ++i) {
    EXPECT_LT(features_.keypoints[i].pt.x, 160.f) << "keypoints are in the frame's own pixels";
    if (!IsNaN(points[i])) errors.push_back(std::abs(points[i].z - expected_z) / expected_z);
  }
  EXPECT_GT(errors.size(), features_.size() / 3);
  std::nth_element(errors.begin(), errors.begin() + long(errors.size() / 2), errors.end());
  EXPECT_LT(errors[errors.size() / 2], 0.05);
}

TEST_F(PointsFromStereoTest, MatchesStayOnTheirRowAndInFrontOfTheCamera) {
  std::vector<cv::Point3f> points;
  // The right image 10 px lower (more than the row tolerance of any octave): the true
  // counterparts are off the row; a few features of the corridor's repeated texture may still
  // find a look-alike on their row.
  ASSERT_TRUE(Points(Right(12.0, 10.0), 0.1, {}, &points).ok());
  const auto with_depth = [&] {
    return std::count_if(points.begin(), points.end(),
                         [](const cv::Point3f& p) { return !IsNaN(p); });
  };
  EXPECT_LT(with_depth(), long(features_.size() / 20)) << "of " << features_.size();
  // A negative disparity (the right image moved right) is behind the camera: no depth.
  ASSERT_TRUE(Points(Right(-12.0), 0.1, {}, &points).ok());
  EXPECT_LT(with_depth(), long(features_.size() / 20)) << "of " << features_.size();
}

TEST_F(PointsFromStereoTest, BadInputIsInvalidArgument) {
  std::vector<cv::Point3f> points;
  const cv::Mat right = Right(10);
  auto s = Points(right, 0.0, {}, &points);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("baseline"), std::string::npos) << s.ToString();
  EXPECT_EQ(Points(right, -0.1, {}, &points).code(), StatusCode::kInvalidArgument);
  cv::Mat small;
  cv::resize(right, small, cv::Size(320, 240));
  s = Points(small, 0.1, {}, &points);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("320x240"), std::string::npos) << s.ToString();
  EXPECT_EQ(Points(cv::Mat(), 0.1, {}, &points).code(), StatusCode::kInvalidArgument);
  FeatureSet float_features = features_;
  features_.descriptors.convertTo(float_features.descriptors, CV_32F);
  FeatureSet right_features;
  ASSERT_TRUE(extractor_->Extract(right, &right_features).ok());
  EXPECT_EQ(
      PointsFromStereo(float_features, left_, right_features, right, kK, 0.1, {}, &points).code(),
      StatusCode::kInvalidArgument);
  EXPECT_EQ(PointsFromStereo(features_, left_, float_features, right, kK, 0.1, {}, &points).code(),
            StatusCode::kInvalidArgument)
      << "the right features must be ORB too";
  StereoOptions even_window;
  even_window.window = 10;
  EXPECT_EQ(Points(right, 0.1, even_window, &points).code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace recog
