#include "core/geometry/camera_rig.h"

#include <cmath>
#include <set>

#include <opencv2/calib3d.hpp>

#include "core/common/names.h"

namespace recog {
namespace {

bool Finite(double v) { return std::isfinite(v); }

Status CameraFault(const RigCamera& camera, const std::string& what) {
  return Status::InvalidArgument("rig camera '" + camera.name + "': " + what);
}

Status ValidateCamera(const RigCamera& c) {
  if (c.size.width <= 0 || c.size.height <= 0) {
    return CameraFault(c, "width and height must be > 0");
  }
  if (!(c.K(0, 0) > 0.0) || !(c.K(1, 1) > 0.0) || !Finite(c.K(0, 0)) || !Finite(c.K(1, 1))) {
    return CameraFault(c, "fx and fy must be finite and > 0");
  }
  if (!Finite(c.K(0, 2)) || !Finite(c.K(1, 2))) return CameraFault(c, "cx and cy must be finite");
  const size_t d = c.distortion.size();
  if (d != 0 && d != 4 && d != 5 && d != 8) {
    return CameraFault(c, "distortion has " + std::to_string(d) + " values (0, 4, 5 or 8)");
  }
  for (double v : c.distortion) {
    if (!Finite(v)) return CameraFault(c, "distortion values must be finite");
  }
  const cv::Matx33d& R = c.body_R_camera;
  if (!cv::checkRange(R) || cv::norm(R * R.t() - cv::Matx33d::eye()) > kRigRotationTolerance ||
      cv::determinant(R) < 0.0) {
    return CameraFault(c, "its body rotation is not a rotation (R Rᵀ = I, det R = +1)");
  }
  const cv::Vec3d& t = c.body_t_camera;
  if (!Finite(t[0]) || !Finite(t[1]) || !Finite(t[2])) {
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
  if (camera.distortion.empty() || keypoints->empty()) return;
  std::vector<cv::Point2f> pixels(keypoints->size());
  for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = (*keypoints)[i].pt;
  cv::undistortPoints(pixels, pixels, camera.K, camera.distortion, cv::noArray(), camera.K);
  for (size_t i = 0; i < pixels.size(); ++i) (*keypoints)[i].pt = pixels[i];
}

}  // namespace recog
