// PoseCovariance: the uncertainty of a camera pose solved from 2D-3D correspondences (PnP).
//
// First-order propagation at the solution: Cov = sigma² (JᵀJ)⁻¹, where J is the 2N×6 Jacobian of
// the pinhole reprojections of the N points with respect to the pose parameters and sigma² the
// residual variance, sum of squared reprojection residuals / (2N − 6), floored at min_sigma_px²
// so that an exact fit does not claim a zero uncertainty. The parameters, in this order, are a
// rotation vector δ perturbing R on the left (R ← exp([δ]×) R, radians, camera frame) and the
// translation t (in the units of the points). The result is 6×6, row-major, symmetric.
//
// The pixels must be pinhole pixels (no lens distortion), as the pose was solved with.
#pragma once

#include <array>
#include <vector>

#include <opencv2/core.hpp>

namespace recog {

using PoseCovariance6 = std::array<double, 36>;

// The covariance of the pose X_camera = R X + t fitted to points[i] ↔ pixels[i] with camera
// matrix K. False (and *covariance untouched) with fewer than 4 points, a point on or behind the
// camera plane, mismatched sizes, or degenerate geometry (JᵀJ not positive definite).
bool ComputePoseCovariance(const cv::Matx33d& K, const cv::Matx33d& R, const cv::Vec3d& t,
                           const std::vector<cv::Point3f>& points,
                           const std::vector<cv::Point2f>& pixels, double min_sigma_px,
                           PoseCovariance6* covariance);

// The covariance of the inverse pose, X = Rᵀ X_camera − Rᵀ t, in the same parametrisation, from
// the covariance of (R, t): first order, Cov' = J Cov Jᵀ with J = [[−Rᵀ, 0], [−Rᵀ[t]×, −Rᵀ]].
// For a pose solved the other way round (the 3D points on the other side of a loop).
PoseCovariance6 InversePoseCovariance(const cv::Matx33d& R, const cv::Vec3d& t,
                                      const PoseCovariance6& covariance);

}  // namespace recog
