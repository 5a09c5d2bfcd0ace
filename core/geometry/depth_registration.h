// RegisterDepth: a depth image taken by its own camera, re-expressed in a colour camera's pixels.
//
// Real RGB-D sensors deliver depth from a separate camera: its own intrinsics (and distortion)
// and a rigid transform to the colour camera, X_depth = R * X_colour + t. Every depth pixel with a
// depth is back-projected in the depth camera, moved into the colour frame and projected into the
// colour image (with the colour camera's distortion); it fills the colour pixels its footprint
// covers (about colour focal / depth focal pixels a side), and where several land on one pixel
// the nearest wins. Colour pixels that nothing lands on stay 0 (no depth).
#pragma once

#include <vector>

#include <opencv2/core.hpp>

namespace recog {

struct DepthCamera {
  cv::Matx33d K = cv::Matx33d::eye();
  std::vector<double> distortion;  // OpenCV order (k1, k2, p1, p2[, k3]); empty = none
};

// `depth_m`: CV_32F metres in the depth camera (0 or non-finite = none). Returns CV_32F metres of
// `color_size`, the depth along the colour camera's z axis.
cv::Mat RegisterDepth(const cv::Mat& depth_m, const DepthCamera& depth_camera,
                      const cv::Matx33d& depth_from_color_R, const cv::Vec3d& depth_from_color_t,
                      const DepthCamera& color_camera, cv::Size color_size);

}  // namespace recog
