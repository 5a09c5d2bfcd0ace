// Synthetic RGB-D and stereo sequences with exactly known geometry, for the metric loops of the
// place detector (thesis §3.3.3): a scene of textured planes at known depths seen by a pinhole
// camera along a known path.
//
// Each plane is a photo stretched over a rectangle of the world (centre, two unit axes along the
// photo's x and y, width and height in metres). A frame is rendered by casting the ray of every
// pixel onto each plane (the plane-induced homography of that plane: pixel -> photo position),
// keeping the nearest hit, and sampling the photo bilinearly (cv::remap); pixels that see no
// plane are black and have no depth. The depth image holds the exact depth of each pixel's hit
// along the camera's z axis, CV_16U millimetres (0 = none). The right image of a rectified
// stereo pair is the same render from the camera moved by the baseline along its own +x axis.
//
// Poses: world_from_camera R (the camera's axes in the world) and centre c, so that
// X_camera = Rᵀ (X_world − c); camera axes x right, y down, z forward.
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "tools/evaluation/camera_trajectory.h"

namespace recog::cli {

struct TexturedPlane {
  cv::Mat texture;  // 8-bit grey
  cv::Vec3d center;
  cv::Vec3d axis_x, axis_y;      // unit vectors of the world along the photo's columns and rows
  double width = 1, height = 1;  // metres the photo spans
};

struct RenderedFrame {
  cv::Mat image;     // 8-bit grey
  cv::Mat depth_mm;  // CV_16U millimetres, 0 = no depth
  cv::Mat right;     // 8-bit grey, the right image of the stereo pair (empty without a baseline)
};

// The rotation of `degrees` about the world's y axis (a pan).
cv::Matx33d Yaw(double degrees);

// Renders the scene from `pose` with camera matrix K into an image of `size`; with
// baseline_m > 0 also the right image. INVALID_ARGUMENT for an empty or non-grey texture, a
// plane of non-positive size or with axes that are not unit and orthogonal, a K without positive
// focal lengths, an empty size or a negative baseline.
StatusOr<RenderedFrame> RenderPlanes(const std::vector<TexturedPlane>& planes, const cv::Matx33d& K,
                                     cv::Size size, const CameraPose& pose, double baseline_m);

// The true relative pose LoopResult::metric reports between a query frame and a matched frame:
// X_query = R X_match + t.
void RelativePose(const CameraPose& query, const CameraPose& match, cv::Matx33d* R, cv::Vec3d* t);

}  // namespace recog::cli
