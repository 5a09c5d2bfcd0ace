// The body motion of a front + rear rig from both cameras' correspondences: exact rays give zero
// epipolar error at the true motion, Levenberg-Marquardt recovers it from a start 3° off (where
// one camera alone could trade the error for a sideways step), and extrinsics 10° off leave
// errors no motion removes.
#include "core/geometry/rig_motion.h"

#include <random>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

namespace recog {
namespace {

cv::Matx33d YawDegrees(double degrees) {
  const double a = degrees * CV_PI / 180.0;
  return {std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a)};
}

double AngleDeg(const cv::Matx33d& a, const cv::Matx33d& b) {
  cv::Vec3d w;
  cv::Rodrigues(a * b.t(), w);
  return cv::norm(w) * 180.0 / CV_PI;
}

struct Camera {
  cv::Matx33d R;
  cv::Vec3d t;
};

// The rays of points 2-10 m in front of `match` camera (of the match body), seen by `query`
// (of the query body, X_body_q = R X_body_m + t), with `noise_px` of pixel noise at f = 400.
RigPairRays Rays(const Camera& query, const Camera& match, const cv::Matx33d& R, const cv::Vec3d& t,
                 double noise_px, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(-1, 1), depth(2, 10);
  std::normal_distribution<double> noise(0, noise_px / 400.0);
  RigPairRays rays;
  rays.query_R = query.R;
  rays.query_t = query.t;
  rays.match_R = match.R;
  rays.match_t = match.t;
  rays.focal_px = 400;
  while (rays.query.size() < 150) {
    const double z = depth(rng);
    const cv::Vec3d in_match(unit(rng) * 0.7 * z, unit(rng) * 0.5 * z, z);
    const cv::Vec3d in_body = match.R * in_match + match.t;
    const cv::Vec3d in_query = query.R.t() * (R * in_body + t - query.t);
    if (in_query[2] < 0.5) continue;
    rays.match.push_back({in_match[0] / z + noise(rng), in_match[1] / z + noise(rng), 1});
    rays.query.push_back(
        {in_query[0] / in_query[2] + noise(rng), in_query[1] / in_query[2] + noise(rng), 1});
  }
  return rays;
}

class RigMotionTest : public ::testing::Test {
 protected:
  // The way back of a front + rear rig: turned 183° and 0.2 m away; the query's front camera
  // sees what the match's rear camera saw, and the other way round.
  const Camera front_{cv::Matx33d::eye(), {0, 0, 0.4}};
  const Camera rear_{YawDegrees(180), {0, 0, -0.4}};
  const cv::Matx33d R_ = YawDegrees(183);
  const cv::Vec3d t_{0.15, 0.02, -0.12};

  std::vector<RigPairRays> Pairs(const Camera& rear_as_calibrated, double noise_px) const {
    std::vector<RigPairRays> pairs = {Rays(front_, rear_, R_, t_, noise_px, 1),
                                      Rays(rear_, front_, R_, t_, noise_px, 2)};
    pairs[0].match_R = rear_as_calibrated.R;  // what the rig file says
    pairs[1].query_R = rear_as_calibrated.R;
    return pairs;
  }
};

TEST_F(RigMotionTest, TheTrueMotionPutsEveryRayOnItsEpipolarLine) {
  std::vector<double> errors;
  for (const RigPairRays& pair : Pairs(rear_, 0.0)) {
    RigPairEpipolarErrors(pair, R_, t_, &errors);
    ASSERT_EQ(errors.size(), 150u);
    for (double e : errors) EXPECT_LT(std::abs(e), 1e-6);
    RigPairEpipolarErrors(pair, YawDegrees(1) * R_, t_, &errors);
    double sum = 0;
    for (double e : errors) sum += std::abs(e);
    EXPECT_GT(sum / errors.size(), 1.0) << "1° off moves rays off their lines";
  }
}

TEST_F(RigMotionTest, BothCamerasTogetherRecoverTheRotationFromAStartThreeDegreesOff) {
  const std::vector<RigPairRays> pairs = Pairs(rear_, 0.5);
  const cv::Matx33d start = YawDegrees(3) * R_;
  const cv::Vec3d direction = cv::normalize(front_.R.t() * (t_ + R_ * rear_.t - front_.t));
  cv::Vec3d t = InitialRigTranslation(pairs, 0, direction, start, 2.0);
  cv::Matx33d R = start;
  RefineRigMotion(pairs, 2.0, &R, &t);
  EXPECT_LT(AngleDeg(R, R_), 0.1);
  EXPECT_LT(std::acos(std::clamp(cv::normalize(t).dot(cv::normalize(t_)), -1.0, 1.0)) * 180 / CV_PI,
            3.0);
  std::vector<double> errors;
  for (const RigPairRays& pair : pairs) {
    RigPairEpipolarErrors(pair, R, t, &errors);
    const auto within =
        std::count_if(errors.begin(), errors.end(), [](double e) { return std::abs(e) <= 2.0; });
    EXPECT_GE(double(within) / errors.size(), 0.95);
  }
}

TEST_F(RigMotionTest, ExtrinsicsTenDegreesOffLeaveNoMotionThatFitsBothPairs) {
  const Camera miscalibrated{YawDegrees(10) * rear_.R, rear_.t};
  const std::vector<RigPairRays> pairs = Pairs(miscalibrated, 0.5);
  cv::Matx33d R = R_;
  const cv::Vec3d direction = cv::normalize(front_.R.t() * (t_ + R_ * rear_.t - front_.t));
  cv::Vec3d t = InitialRigTranslation(pairs, 0, direction, R, 2.0);
  RefineRigMotion(pairs, 2.0, &R, &t);
  std::vector<double> errors;
  double worst_share = 1.0;
  for (const RigPairRays& pair : pairs) {
    RigPairEpipolarErrors(pair, R, t, &errors);
    const auto within =
        std::count_if(errors.begin(), errors.end(), [](double e) { return std::abs(e) <= 2.0; });
    worst_share = std::min(worst_share, double(within) / errors.size());
  }
  EXPECT_LT(worst_share, 0.9);
}

}  // namespace
}  // namespace recog
