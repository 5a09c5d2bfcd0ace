// A camera's intrinsics and its lens: how a direction in the camera frame (x right, y down,
// z forward) becomes a pixel, and back. Four lens models cover what robots carry and what
// calibration tools write:
//  - pinhole: no distortion, u = fx x/z + cx, v = fy y/z + cy (an empty `distortion`, whatever the
//    lens says);
//  - radial-tangential: OpenCV's family (ROS `plumb_bob` with 5 coefficients, `rational_polynomial`
//    with 8; EuRoC/Kalibr `radtan` with 4): k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tx ty]]]],
//    the order of cv::projectPoints; valid in front of the camera (z > 0);
//  - equidistant (Kannala–Brandt as OpenCV's cv::fisheye, ROS `equidistant`, Kalibr `equi`):
//    r = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸), θ the angle off the optical axis, r on the
//    normalised plane (u = fx r x/ρ + cx, ρ = √(x² + y²)); valid up to where r(θ) stops growing
//    (at most 180°);
//  - double sphere (Usenko, Demmel and Cremers 2018; Kalibr `ds`): xi and alpha; fields of view
//    beyond 180°, points behind the camera's plane included.
// Unproject turns a pixel into a unit bearing (the inverse of Project inside the model's valid
// image); Project turns a direction back into a pixel. The geometry of loops works in the pinhole
// image of K (core/geometry/correspondences.h): ToPinhole moves keypoints there once per frame,
// those whose bearing is within kMaxPinholeAngleDeg of the axis exactly, those beyond (a
// fisheye's rim) in their direction at that angle, where RANSAC treats them as the outliers they
// then are.
#pragma once

#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"

namespace recog {

enum class LensModel : uint8_t {
  kRadialTangential = 0,  // also the pinhole: no coefficients
  kEquidistant = 1,
  kDoubleSphere = 2,
};

// "radtan", "equidistant", "double_sphere": the names of the --camera syntax, rig files and
// reports.
std::string_view LensModelName(LensModel lens);
// Also takes the names calibration files use: ROS `plumb_bob` and `rational_polynomial`, Kalibr
// `radtan` and `radial-tangential` (radtan); `equi`, `fisheye` and `kannala_brandt`
// (equidistant); `ds` (double_sphere). INVALID_ARGUMENT listing the known names otherwise.
StatusOr<LensModel> ParseLensModel(std::string_view name);

// Bearings further than this from the optical axis are put at this angle by ToPinhole.
inline constexpr double kMaxPinholeAngleDeg = 80.0;

// Pinhole intrinsics, in pixels, and a lens model with its coefficients.
struct CameraIntrinsics {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  std::vector<double> distortion;  // the lens's coefficients; empty = a pinhole camera
  LensModel lens = LensModel::kRadialTangential;

  cv::Matx33d K() const { return {fx, 0, cx, 0, fy, cy, 0, 0, 1}; }
  // True without coefficients, or with radtan coefficients that are all 0.
  bool IsPinhole() const;
  // OK, or INVALID_ARGUMENT naming the fault: fx, fy not finite and > 0; cx, cy not finite; a
  // number of coefficients the lens does not take (radtan 0, 4, 5, 8, 12 or 14; equidistant 0 or
  // 4; double sphere 0 or 2); a coefficient that is not finite; double sphere's alpha outside
  // [0, 1].
  Status Validate() const;
  // "equidistant fx=… fy=… cx=… cy=… [k1 k2 k3 k4]": for logs and reports.
  std::string Describe() const;
  friend bool operator==(const CameraIntrinsics&, const CameraIntrinsics&) = default;
};

// The pixel of direction `point` (any length) seen by `camera` (valid: Validate() is OK). False
// when the lens cannot see it (behind a radtan camera; beyond the equidistant or double sphere
// model's valid angle).
bool ProjectDirection(const CameraIntrinsics& camera, const cv::Vec3d& point, cv::Point2d* pixel);
// The unit bearing of `pixel`. False when no direction maps to it (outside the lens's image
// circle, or where an iterative inverse does not converge).
bool UnprojectPixel(const CameraIntrinsics& camera, const cv::Point2d& pixel, cv::Vec3d* bearing);

// Moves `keypoints` (pixels of `camera`) into the pinhole image of camera.K(): exactly for
// bearings within kMaxPinholeAngleDeg of the axis, at that angle beyond it; a pixel with no
// bearing stays where it is. Nothing for a pinhole camera.
void ToPinhole(const CameraIntrinsics& camera, std::span<cv::KeyPoint> keypoints);
void ToPinhole(const CameraIntrinsics& camera, std::span<cv::Point2f> pixels);

// The --camera syntax of the command-line tools (docs/cli.md, "Cameras"):
//   fx,fy,cx,cy                          a pinhole camera (rectified images)
//   fx,fy,cx,cy,k1,k2,p1,p2[,k3…]        radial-tangential, OpenCV's order (as before)
//   LENS:fx,fy,cx,cy[,coefficients]      LENS one of ParseLensModel's names, e.g.
//                                        equidistant:190.9,190.9,254.9,256.9,0.0034,0.0007,-0.0029,0.0003
//                                        ds:156.1,155.7,254.6,256.4,-0.24,0.57
// INVALID_ARGUMENT, prefixed with `flag`, naming what is wrong (Validate's faults included).
StatusOr<CameraIntrinsics> ParseCameraText(std::string_view flag, std::string_view text);

}  // namespace recog
