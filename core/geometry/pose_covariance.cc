#include "core/geometry/pose_covariance.h"

#include <algorithm>

#include <Eigen/Cholesky>
#include <Eigen/Core>

namespace recog {

bool ComputePoseCovariance(const cv::Matx33d& K, const cv::Matx33d& R, const cv::Vec3d& t,
                           const std::vector<cv::Point3f>& points,
                           const std::vector<cv::Point2f>& pixels, double min_sigma_px,
                           PoseCovariance6* covariance) {
  const size_t n = points.size();
  if (n < 4 || pixels.size() != n) return false;
  using Matrix6 = Eigen::Matrix<double, 6, 6>;
  Matrix6 normal = Matrix6::Zero();
  double squared_residuals = 0;
  const double fx = K(0, 0), fy = K(1, 1);
  for (size_t i = 0; i < n; ++i) {
    const cv::Vec3d c = R * cv::Vec3d(points[i].x, points[i].y, points[i].z) + t;
    if (c[2] <= 1e-9) return false;
    const double iz = 1.0 / c[2];
    const double u = fx * c[0] * iz + K(0, 2);
    const double v = fy * c[1] * iz + K(1, 2);
    squared_residuals +=
        (u - pixels[i].x) * (u - pixels[i].x) + (v - pixels[i].y) * (v - pixels[i].y);
    // d(u, v)/dc, and dc/d(δ, t) = [−[c − t]×, I] (the perturbation rotates R X = c − t).
    Eigen::Matrix<double, 2, 3> dpixel;
    dpixel << fx * iz, 0, -fx * c[0] * iz * iz, 0, fy * iz, -fy * c[1] * iz * iz;
    const Eigen::Vector3d r(c[0] - t[0], c[1] - t[1], c[2] - t[2]);
    Eigen::Matrix3d minus_skew;
    minus_skew << 0, r.z(), -r.y(), -r.z(), 0, r.x(), r.y(), -r.x(), 0;
    Eigen::Matrix<double, 2, 6> jacobian;
    jacobian.leftCols<3>() = dpixel * minus_skew;
    jacobian.rightCols<3>() = dpixel;
    normal.noalias() += jacobian.transpose() * jacobian;
  }
  const double sigma2 =
      std::max(squared_residuals / double(2 * n - 6), min_sigma_px * min_sigma_px);
  const Eigen::LLT<Matrix6> llt(normal);
  if (llt.info() != Eigen::Success) return false;
  const Matrix6 inverse = llt.solve(Matrix6::Identity());
  if (!inverse.allFinite()) return false;
  const Matrix6 result = sigma2 * 0.5 * (inverse + inverse.transpose());
  Eigen::Map<Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(covariance->data()) = result;
  return true;
}

PoseCovariance6 InversePoseCovariance(const cv::Matx33d& R, const cv::Vec3d& t,
                                      const PoseCovariance6& covariance) {
  using RowMajor6 = Eigen::Matrix<double, 6, 6, Eigen::RowMajor>;
  Eigen::Matrix3d rotation_transposed;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) rotation_transposed(r, c) = R(c, r);
  }
  Eigen::Matrix3d skew_t;
  skew_t << 0, -t[2], t[1], t[2], 0, -t[0], -t[1], t[0], 0;
  RowMajor6 jacobian = RowMajor6::Zero();
  jacobian.topLeftCorner<3, 3>() = -rotation_transposed;
  jacobian.bottomLeftCorner<3, 3>() = -rotation_transposed * skew_t;
  jacobian.bottomRightCorner<3, 3>() = -rotation_transposed;
  const RowMajor6 result =
      jacobian * Eigen::Map<const RowMajor6>(covariance.data()) * jacobian.transpose();
  PoseCovariance6 out;
  Eigen::Map<RowMajor6>(out.data()) = 0.5 * (result + result.transpose());
  return out;
}

}  // namespace recog
