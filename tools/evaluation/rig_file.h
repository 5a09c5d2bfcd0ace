// Rig files: the cameras of a multi-camera rig (thesis §3.3.2), given once for a whole sequence.
//
// A rig file is YAML with one key, `cameras`, a list of cameras, each with
//   name: front                  # 1..64 characters of [A-Za-z0-9_-], unique in the rig
//   width: 640, height: 480      # pixels
//   fx, fy, cx, cy               # the pinhole intrinsics, pixels; fx, fy > 0
//   distortion: [k1, k2, p1, p2[, k3[, k4, k5, k6]]]   # OpenCV's order; [] for none
//   body_from_camera:            # the camera's pose on the body, X_body = R X_camera + t
//     rotation: [9 numbers, row-major]    # a rotation: R Rᵀ = I (within 1e-6) and det R = +1
//     translation: [tx, ty, tz]           # metres
// The body frame is the rig's own (for a robot: x right, y down, z forward is usual); every pose
// of the rig and every loop between rig frames is given in it.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "tools/evaluation/metric_sequence.h"

namespace recog::cli {

struct RigCamera {
  std::string name;
  cv::Size size;
  cv::Matx33d K = cv::Matx33d::eye();
  std::vector<double> distortion;  // empty, 4, 5 or 8 values
  // X_body = body_from_camera.world_from_camera * X_camera + body_from_camera.center.
  CameraPose body_from_camera;
};

// INVALID_ARGUMENT naming the camera (by name, or by index when the name is the problem) for the
// first fault: no camera, a bad or repeated name, an empty size, non-positive focal lengths, a
// non-finite principal point or translation, a distortion of another length, or a
// body_from_camera rotation that is not a rotation (R Rᵀ ≠ I, or a reflection).
Status ValidateRig(const std::vector<RigCamera>& cameras);

// Reads and validates a rig file. NOT_FOUND when it does not exist; INVALID_ARGUMENT naming the
// file (and the camera) for YAML that does not parse, a missing or mistyped key, or a rig that
// does not validate.
StatusOr<std::vector<RigCamera>> ReadRigFile(const std::string& path);

// Writes a rig that validates (INVALID_ARGUMENT otherwise); INTERNAL when the file cannot be
// written. ReadRigFile gives the cameras back exactly.
Status WriteRigFile(const std::vector<RigCamera>& cameras, const std::string& path);

// The pose of `camera` in the world when the body is at `body` (world_from_camera).
CameraPose CameraInWorld(const CameraPose& body, const RigCamera& camera);

}  // namespace recog::cli
