// Rig files: the cameras of a multi-camera rig (core/geometry/camera_rig.h), given once for a
// whole sequence.
//
// A rig file is YAML with one key, `cameras`, a list of cameras, each with
//   name: front                  # 1..128 characters of [A-Za-z0-9._-], unique in the rig
//   width: 640, height: 480      # pixels
//   fx, fy, cx, cy               # the pinhole intrinsics, pixels; fx, fy > 0
//   distortion: [k1, k2, p1, p2[, k3[, k4, k5, k6]]]   # the lens's coefficients; [] for none
//   lens: equidistant            # optional: radtan (the default: OpenCV's order above),
//                                # equidistant [k1, k2, k3, k4] or double_sphere [xi, alpha]
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
#include "core/geometry/camera_rig.h"
#include "tools/evaluation/metric_sequence.h"

namespace YAML {
class Node;
}

namespace recog::cli {

// Reads and validates a rig file. NOT_FOUND when it does not exist; INVALID_ARGUMENT naming the
// file (and the camera) for YAML that does not parse, a missing or mistyped key (an unknown lens
// name too), or a rig that does not validate (ValidateRig).
StatusOr<std::vector<RigCamera>> ReadRigFile(const std::string& path);

// Writes a rig that validates (INVALID_ARGUMENT otherwise); INTERNAL when the file cannot be
// written. ReadRigFile gives the cameras back exactly.
Status WriteRigFile(const std::vector<RigCamera>& cameras, const std::string& path);

// The numbers of YAML sequence `node` of `count` numbers (any count when 0); throws a
// YAML::Exception naming `key` otherwise (rig files and EuRoC sensor.yaml files).
std::vector<double> YamlNumbers(const YAML::Node& node, size_t count, const std::string& key);

// The pose of `camera` in the world when the body is at `body` (world_from_camera).
CameraPose CameraInWorld(const CameraPose& body, const RigCamera& camera);

}  // namespace recog::cli
