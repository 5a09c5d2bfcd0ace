// Pose solving shared by the object recogniser and the object tracker: reprojection errors, the
// RANSAC PnP of 3D objects (P3P on minimal samples, seeded, then Levenberg-Marquardt on the
// inliers) and the detection's fields that follow from a solved pose (inliers, mean error,
// optional 2D-3D inliers and covariance, outline).
//
// Every pixel given to these functions is a pinhole pixel (lens distortion removed) except
// `keypoints` in CompleteDetection, which are the keypoints as detected.
#pragma once

#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

#include "core/object/recognition/detection.h"
#include "core/object/recognition/object_database.h"

namespace recog {

// Squared reprojection error of `x` under pose (R, t), or infinity behind the camera.
double SquaredReprojectionError(const cv::Matx33d& K, const cv::Matx33d& R, const cv::Vec3d& t,
                                const cv::Point3f& x, const cv::Point2f& pixel);

// The transform of a Rodrigues rotation vector and a translation.
RigidTransform PoseFromRodrigues(const cv::Vec3d& rvec, const cv::Vec3d& tvec);

// Indices of the correspondences that `pose` reprojects within `threshold_px`.
void ReprojectionInliers(const cv::Matx33d& K, const RigidTransform& pose,
                         const std::vector<cv::Point3f>& object,
                         const std::vector<cv::Point2f>& image, double threshold_px,
                         std::vector<uint32_t>* inliers);

// Refines a pose on correspondences with Levenberg-Marquardt (OpenCV's iterative PnP).
RigidTransform RefinePose(const cv::Matx33d& K, const RigidTransform& pose,
                          const std::vector<cv::Point3f>& object,
                          const std::vector<cv::Point2f>& image);

// RANSAC over P3P on minimal samples of 3 correspondences (every solution of a sample is scored),
// seeded, stopping adaptively (99 % confidence) and after `iterations` at most; then LM on the
// inliers, twice. False with fewer than 5 inliers. P3P rather than the thesis's EPnP: a 3-point
// sample is all inliers far more often (at 30 % inliers, 2.7 % of samples against 0.24 %), which is
// what a small object in clutter has; and a hypothesis of SolveP3P (core/geometry/p3p.h) is far
// cheaper than one of OpenCV's solveP3P or EPnP (docs/evaluation.md, "Benchmarks").
bool RansacPnp(const cv::Matx33d& K, const std::vector<cv::Point3f>& object,
               const std::vector<cv::Point2f>& image, int iterations, double threshold_px,
               uint64_t seed, RigidTransform* pose, std::vector<uint32_t>* inliers);

// Fills the fields of `detection` that follow from `pose` and its inliers: the object's metadata,
// the pose, inliers, correspondences (= object_points.size()), the mean reprojection error,
// inlier_pixels, the extras `extras` asks for and the outline. object_points[i] (model feature
// model_features[i]) matched pinhole[i], detected at keypoints[i]; `inliers` index them.
void CompleteDetection(const IndexedObject& object, const CameraIntrinsics& camera,
                       const RigidTransform& pose, const std::vector<uint32_t>& inliers,
                       const std::vector<uint32_t>& model_features,
                       const std::vector<cv::Point3f>& object_points,
                       const std::vector<cv::Point2f>& pinhole,
                       const std::vector<cv::Point2f>& keypoints, const DetectionOptions& extras,
                       Detection* detection);

}  // namespace recog
