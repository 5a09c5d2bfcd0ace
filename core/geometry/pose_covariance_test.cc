#include "core/geometry/pose_covariance.h"

#include <random>

#include <gtest/gtest.h>
#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <opencv2/calib3d.hpp>

namespace recog {
namespace {

using RowMajor6 = Eigen::Matrix<double, 6, 6, Eigen::RowMajor>;

struct Scene {
  cv::Matx33d K = {500, 0, 320, 0, 500, 240, 0, 0, 1};
  cv::Vec3d rvec = {0.2, -0.3, 0.1};
  cv::Vec3d t = {0.05, -0.02, 1.5};
  cv::Matx33d R;
  std::vector<cv::Point3f> points;
  std::vector<cv::Point2f> pixels;  // projections plus Gaussian noise of `noise_px`
};

Scene MakeScene(size_t n, double noise_px) {
  Scene scene;
  cv::Rodrigues(scene.rvec, scene.R);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> box(-0.2f, 0.2f);
  for (size_t i = 0; i < n; ++i) scene.points.emplace_back(box(rng), box(rng), box(rng));
  cv::projectPoints(scene.points, scene.rvec, scene.t, scene.K, cv::noArray(), scene.pixels);
  std::normal_distribution<float> noise(0.0f, float(noise_px));
  for (cv::Point2f& p : scene.pixels) p += cv::Point2f(noise(rng), noise(rng));
  return scene;
}

double Trace(const PoseCovariance6& c) {
  double trace = 0;
  for (int i = 0; i < 6; ++i) trace += c[size_t(i * 7)];
  return trace;
}

TEST(PoseCovarianceTest, IsSymmetricPositiveDefiniteAndShrinksWithMorePoints) {
  const Scene scene = MakeScene(200, 1.0);
  PoseCovariance6 all, few;
  ASSERT_TRUE(
      ComputePoseCovariance(scene.K, scene.R, scene.t, scene.points, scene.pixels, 0.5, &all));
  const std::vector<cv::Point3f> points(scene.points.begin(), scene.points.begin() + 20);
  const std::vector<cv::Point2f> pixels(scene.pixels.begin(), scene.pixels.begin() + 20);
  ASSERT_TRUE(ComputePoseCovariance(scene.K, scene.R, scene.t, points, pixels, 0.5, &few));
  for (const PoseCovariance6* c : {&all, &few}) {
    const RowMajor6 m = Eigen::Map<const RowMajor6>(c->data());
    EXPECT_LT((m - m.transpose()).norm(), 1e-12 * m.norm());
    EXPECT_EQ(Eigen::LLT<RowMajor6>(m).info(), Eigen::Success);
  }
  EXPECT_GT(Trace(few), 2 * Trace(all));
}

TEST(PoseCovarianceTest, TranslationBlockMatchesOpenCvJacobian) {
  // The translation block does not depend on how the rotation is parametrised, so it must equal
  // the one from OpenCV's Jacobian (Rodrigues vector, then t).
  const Scene scene = MakeScene(50, 0.0);
  PoseCovariance6 covariance;
  ASSERT_TRUE(ComputePoseCovariance(scene.K, scene.R, scene.t, scene.points, scene.pixels, 0.5,
                                    &covariance));
  std::vector<cv::Point2f> projected;
  cv::Mat jacobian;
  cv::projectPoints(scene.points, scene.rvec, scene.t, scene.K, cv::noArray(), projected, jacobian);
  const cv::Mat j6 = jacobian.colRange(0, 6);
  cv::Mat inverse;
  cv::invert(j6.t() * j6, inverse, cv::DECOMP_CHOLESKY);
  // An exact fit: sigma² is the floor, 0.5².
  for (int r = 3; r < 6; ++r) {
    for (int c = 3; c < 6; ++c) {
      const double expected = 0.25 * inverse.at<double>(r, c);
      EXPECT_NEAR(covariance[size_t(r * 6 + c)], expected,
                  1e-6 * std::abs(inverse.at<double>(r, r)))
          << r << "," << c;
    }
  }
}

TEST(PoseCovarianceTest, LargerResidualsGiveALargerCovariance) {
  const Scene exact = MakeScene(100, 0.0), noisy = MakeScene(100, 3.0);
  PoseCovariance6 a, b;
  ASSERT_TRUE(
      ComputePoseCovariance(exact.K, exact.R, exact.t, exact.points, exact.pixels, 0.5, &a));
  ASSERT_TRUE(
      ComputePoseCovariance(noisy.K, noisy.R, noisy.t, noisy.points, noisy.pixels, 0.5, &b));
  EXPECT_GT(Trace(a), 0);  // the floor: an exact fit is not certain
  EXPECT_GT(Trace(b), 10 * Trace(a));
}

TEST(PoseCovarianceTest, RejectsTooFewPointsAndPointsBehindTheCamera) {
  Scene scene = MakeScene(10, 0.5);
  PoseCovariance6 covariance{};
  const std::vector<cv::Point3f> three(scene.points.begin(), scene.points.begin() + 3);
  const std::vector<cv::Point2f> three_pixels(scene.pixels.begin(), scene.pixels.begin() + 3);
  EXPECT_FALSE(
      ComputePoseCovariance(scene.K, scene.R, scene.t, three, three_pixels, 0.5, &covariance));
  EXPECT_FALSE(ComputePoseCovariance(scene.K, scene.R, scene.t, scene.points, three_pixels, 0.5,
                                     &covariance));
  EXPECT_FALSE(ComputePoseCovariance(scene.K, scene.R, -scene.t, scene.points, scene.pixels, 0.5,
                                     &covariance));
  EXPECT_EQ(Trace(covariance), 0);  // untouched
}

// Perturbations drawn from a pose's covariance, pushed through the exact inversion, have the
// covariance InversePoseCovariance predicts (small perturbations: first order holds).
TEST(PoseCovarianceTest, InverseMatchesSampledInversions) {
  const Scene scene = MakeScene(1, 0);
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
  const double sigmas[6] = {2e-3, 1e-3, 3e-3, 4e-3, 1e-3, 2e-3};
  for (int i = 0; i < 6; ++i) covariance(i, i) = sigmas[i] * sigmas[i];
  covariance(0, 4) = covariance(4, 0) = 0.5 * sigmas[0] * sigmas[4];
  PoseCovariance6 given;
  Eigen::Map<RowMajor6>(given.data()) = covariance;
  const PoseCovariance6 predicted = InversePoseCovariance(scene.R, scene.t, given);

  const Eigen::Matrix<double, 6, 6> L = covariance.llt().matrixL();
  const cv::Matx33d R_inverse = scene.R.t();
  const cv::Vec3d t_inverse = -(R_inverse * scene.t);
  std::mt19937 rng(11);
  std::normal_distribution<double> normal;
  const int samples = 20000;
  Eigen::Matrix<double, 6, 6> sampled = Eigen::Matrix<double, 6, 6>::Zero();
  for (int s = 0; s < samples; ++s) {
    Eigen::Matrix<double, 6, 1> z;
    for (int i = 0; i < 6; ++i) z(i) = normal(rng);
    const Eigen::Matrix<double, 6, 1> d = L * z;
    cv::Matx33d rotation_delta;
    cv::Rodrigues(cv::Vec3d(d(0), d(1), d(2)), rotation_delta);
    const cv::Matx33d R = rotation_delta * scene.R;
    const cv::Vec3d t = scene.t + cv::Vec3d(d(3), d(4), d(5));
    // The inverse of the perturbed pose, as a perturbation of the exact inverse.
    const cv::Matx33d R_perturbed_inverse = R.t();
    cv::Vec3d delta;
    cv::Rodrigues(R_perturbed_inverse * R_inverse.t(), delta);
    const cv::Vec3d dt = -(R_perturbed_inverse * t) - t_inverse;
    Eigen::Matrix<double, 6, 1> e;
    e << delta[0], delta[1], delta[2], dt[0], dt[1], dt[2];
    sampled += e * e.transpose();
  }
  sampled /= samples;
  const RowMajor6 expected = Eigen::Map<const RowMajor6>(predicted.data());
  EXPECT_LT((sampled - expected).norm(), 0.05 * expected.norm()) << "sampled\n"
                                                                 << sampled << "\npredicted\n"
                                                                 << expected;
  // Inverting twice gives the covariance back.
  const PoseCovariance6 twice = InversePoseCovariance(R_inverse, t_inverse, predicted);
  for (size_t i = 0; i < 36; ++i) EXPECT_NEAR(twice[i], given[i], 1e-12);
}

}  // namespace
}  // namespace recog
