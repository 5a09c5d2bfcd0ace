// The camera poses that put three known 3D points on three observed viewing rays (P3P), solved
// in closed form: Grunert's formulation (Haralick et al. 1994, "Review and analysis of solutions
// of the three point perspective pose estimation problem") gives a quartic in the ratio of two
// depths, solved by Ferrari's method and polished by Newton steps; each real, positive root gives
// the three depths, and the rotation and translation follow from the two triangles (the points
// in the object frame and in the camera frame).
//
// It is the inner step of RANSAC PnP, run up to hundreds of times per image, so it allocates
// nothing, and it is far cheaper than OpenCV 4.6's cv::solveP3P with its conversions to cv::Mat
// (`bench_objects --benchmark_filter=P3P` times both on the same samples; the figures are in
// docs/evaluation.md, "Benchmarks").
#pragma once

#include <array>
#include <cstddef>

#include <opencv2/core.hpp>

namespace recog {

// One pose: X_camera = R X_object + t.
struct P3PSolution {
  cv::Matx33d R;
  cv::Vec3d t;
};

// Up to four poses that map object[i] onto the ray through rays[i] (a direction in the camera
// frame, any length, pointing in front of the camera: (x, y, 1) for a pinhole pixel with K
// removed). Returns how many it wrote to *solutions; 0 for a degenerate sample (collinear or
// coincident points, parallel rays).
size_t SolveP3P(const std::array<cv::Vec3d, 3>& object, const std::array<cv::Vec3d, 3>& rays,
                std::array<P3PSolution, 4>* solutions);

}  // namespace recog
