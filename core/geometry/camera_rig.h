// A multi-camera rig (thesis §3.3.2: a robot's frontal and lateral cameras, a car's front and
// rear ones): n cameras fixed on one body, each with its pinhole intrinsics, its lens
// (core/geometry/camera_model.h) and its pose in the body frame, given once for every frame the rig
// takes. A loop between two rig frames is a motion of the body; the extrinsics turn what one camera
// pair sees into it.
//
// The body frame is the rig's own (for a robot, x right, y down, z forward is usual). A camera's
// pose is X_body = body_R_camera * X_camera + body_t_camera, in metres.
#pragma once

#include <span>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "core/geometry/camera_model.h"

namespace recog {

struct RigCamera {
  std::string name;  // 1..128 characters of [A-Za-z0-9._-], not only dots; unique in its rig
  cv::Size size;     // of its images, pixels
  cv::Matx33d K = cv::Matx33d::eye();
  std::vector<double> distortion;  // the lens's coefficients (CameraIntrinsics); empty: none
  LensModel lens = LensModel::kRadialTangential;
  cv::Matx33d body_R_camera = cv::Matx33d::eye();
  cv::Vec3d body_t_camera = cv::Vec3d(0, 0, 0);

  // Its K, distortion and lens.
  CameraIntrinsics intrinsics() const {
    return {K(0, 0), K(1, 1), K(0, 2), K(1, 2), distortion, lens};
  }
};

// Largest |R Rᵀ − I| (Frobenius) of a rotation a rig accepts.
inline constexpr double kRigRotationTolerance = 1e-6;

// INVALID_ARGUMENT naming the camera (by name; by index when the name is the problem) for the
// first fault: no camera, a bad or repeated name, an empty size, intrinsics that do not validate
// (CameraIntrinsics::Validate: focal lengths, principal point, the lens's coefficients), a
// non-finite translation, or a body_R_camera that is not a rotation (R Rᵀ ≠ I, or a reflection):
// extrinsics must be rigid transforms.
Status ValidateRig(std::span<const RigCamera> cameras);

// Moves keypoints of `camera`'s images into the pinhole image of its K (ToPinhole), which the
// geometry of a rig's loops assumes. Nothing for a camera without distortion.
void UndistortKeypoints(const RigCamera& camera, std::vector<cv::KeyPoint>* keypoints);

}  // namespace recog
