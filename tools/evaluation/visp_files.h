// Readers for the ViSP files that describe the visp-cube sequence: a CAD model (.cao, "V1" format:
// points, then faces given by point indices) and a pose file (.pos: tx ty tz thetaux thetauy
// thetauz, the object's pose in the camera frame, rotation as an axis-angle vector).
#pragma once

#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/object/builder/model_builder.h"

namespace recog::cli {

// The faces built from points ("3D faces from points"); lines, cylinders and circles are not
// supported (INVALID_ARGUMENT when present). '#' starts a comment.
StatusOr<std::vector<FacePolygon>> ReadCaoFaces(const std::string& path);
// T_camera<-object.
StatusOr<RigidTransform> ReadVispPose(const std::string& path);

}  // namespace recog::cli
