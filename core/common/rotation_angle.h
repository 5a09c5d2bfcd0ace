// RotationAngleDeg: how far apart two 3D rotations are — the angle of the rotation that takes one
// to the other — as the loop detectors compare motions and the evaluations score estimated poses
// against true ones.
#pragma once

#include <opencv2/core.hpp>

namespace recog {

// The angle of a * bᵀ (the rotation taking b to a), in degrees, 0 to 180; with b left out, the
// angle of a itself. Rotations a little off orthonormal (rounding) give the nearest angle rather
// than NaN.
double RotationAngleDeg(const cv::Matx33d& a, const cv::Matx33d& b = cv::Matx33d::eye());

}  // namespace recog
