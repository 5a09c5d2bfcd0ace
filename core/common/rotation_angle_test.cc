#include "core/common/rotation_angle.h"

#include <cmath>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

namespace recog {
namespace {

cv::Matx33d Turn(const cv::Vec3d& axis_angle) {
  cv::Matx33d R;
  cv::Rodrigues(axis_angle, R);
  return R;
}

TEST(RotationAngleTest, TheAngleOfOneRotation) {
  EXPECT_NEAR(RotationAngleDeg(Turn({0, 0.3, 0})), 0.3 * 180 / CV_PI, 1e-9);
  EXPECT_NEAR(RotationAngleDeg(Turn({0, 0, -2.0})), 2.0 * 180 / CV_PI, 1e-9);
  EXPECT_EQ(RotationAngleDeg(cv::Matx33d::eye()), 0.0);
  EXPECT_NEAR(RotationAngleDeg(cv::Matx33d(-1, 0, 0, 0, 1, 0, 0, 0, -1)), 180.0, 1e-9);
}

TEST(RotationAngleTest, TheAngleBetweenTwoRotationsEitherWayRound) {
  const cv::Matx33d a = Turn({0.1, 0.2, 0.0}), b = Turn({0.1, 0.2, 0.0}) * Turn({0, 0, 0.25});
  EXPECT_NEAR(RotationAngleDeg(a, b), 0.25 * 180 / CV_PI, 1e-9);
  EXPECT_NEAR(RotationAngleDeg(b, a), 0.25 * 180 / CV_PI, 1e-9);
  EXPECT_NEAR(RotationAngleDeg(a, a), 0.0, 1e-5);  // acos near 1 keeps ~1e-8 rad
}

TEST(RotationAngleTest, RoundingOffOrthonormalGivesAnAngleNotNan) {
  const cv::Matx33d slightly_large = cv::Matx33d::eye() * (1 + 1e-9);
  EXPECT_EQ(RotationAngleDeg(slightly_large), 0.0);
  const cv::Matx33d half_turn = cv::Matx33d(-1, 0, 0, 0, -1, 0, 0, 0, 1) * (1 + 1e-9);
  EXPECT_NEAR(RotationAngleDeg(half_turn), 180.0, 1e-6);
}

}  // namespace
}  // namespace recog
