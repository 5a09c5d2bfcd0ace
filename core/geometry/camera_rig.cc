#include "core/geometry/camera_rig.h"

#include <cmath>
#include <set>

#include "core/common/names.h"

namespace recog {
namespace {

Status CameraFault(const RigCamera& camera, const std::string& what) {
  return Status::InvalidArgument("rig camera '" + camera.name + "': " + what);
}

Status ValidateCamera(const RigCamera& c) {
  if (c.size.width <= 0 || c.size.height <= 0) {
    return CameraFault(c, "width and height must be > 0");
  }
  if (Status intrinsics = c.intrinsics().Validate(); !intrinsics.ok()) {
    return CameraFault(c, intrinsics.message());
  }
  const cv::Matx33d& R = c.body_R_camera;
  if (!cv::checkRange(R) || cv::norm(R * R.t() - cv::Matx33d::eye()) > kRigRotationTolerance ||
      cv::determinant(R) < 0.0) {
    return CameraFault(c, "its body rotation is not a rotation (R Rᵀ = I, det R = +1)");
  }
  const cv::Vec3d& t = c.body_t_camera;
  if (!std::isfinite(t[0]) || !std::isfinite(t[1]) || !std::isfinite(t[2])) {
    return CameraFault(c, "its body translation must be finite");
  }
  return Status::Ok();
}

}  // namespace

Status ValidateRig(std::span<const RigCamera> cameras) {
  if (cameras.empty()) return Status::InvalidArgument("a rig needs at least one camera");
  std::set<std::string> names;
  for (size_t i = 0; i < cameras.size(); ++i) {
    const RigCamera& c = cameras[i];
    // Names become folder names: a name of dots only would climb out of the rig's folder.
    Status name = ValidateName("rig camera", c.name);
    if (name.ok() && c.name.find_first_not_of('.') == std::string::npos) {
      name = Status::InvalidArgument("rig camera name '" + c.name + "' is not a folder name");
    }
    if (!name.ok()) return name.WithContext("camera " + std::to_string(i));
    if (!names.insert(c.name).second) {
      return Status::InvalidArgument("rig camera name '" + c.name + "' is used twice");
    }
    RECOG_RETURN_IF_ERROR(ValidateCamera(c));
  }
  return Status::Ok();
}

void UndistortKeypoints(const RigCamera& camera, std::vector<cv::KeyPoint>* keypoints) {
  ToPinhole(camera.intrinsics(), *keypoints);
}

}  // namespace recog
