#include "core/geometry/p3p.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

#include "core/common/rotation_angle.h"

namespace recog {
namespace {

// A random pose with the object about 0.3-2 m in front of the camera, and three object points in
// a 20 cm box seen through it.
struct Sample {
  cv::Matx33d R;
  cv::Vec3d t;
  std::array<cv::Vec3d, 3> object;
  std::array<cv::Vec3d, 3> rays;
};

Sample RandomSample(std::mt19937_64& random) {
  std::uniform_real_distribution<double> unit(-1, 1);
  Sample s;
  cv::Rodrigues(cv::Vec3d(unit(random), unit(random), unit(random)) * 1.5, s.R);
  s.t = cv::Vec3d(0.2 * unit(random), 0.2 * unit(random), 1.15 + 0.85 * unit(random));
  for (size_t i = 0; i < 3; ++i) {
    s.object[i] = cv::Vec3d(unit(random), unit(random), unit(random)) * 0.1;
    const cv::Vec3d camera = s.R * s.object[i] + s.t;
    s.rays[i] = camera / camera[2];  // a pinhole pixel without K
  }
  return s;
}

TEST(P3PTest, TheTruePoseIsAmongTheSolutionsAndEverySolutionFitsTheRays) {
  std::mt19937_64 random(7);
  size_t found = 0, samples = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const Sample s = RandomSample(random);
    // Skip nearly collinear triangles: their poses are ill-conditioned for any solver.
    const double area = cv::norm((s.object[1] - s.object[0]).cross(s.object[2] - s.object[0]));
    if (area < 1e-3) continue;
    ++samples;
    std::array<P3PSolution, 4> solutions;
    const size_t count = SolveP3P(s.object, s.rays, &solutions);
    ASSERT_LE(count, 4u);
    bool has_truth = false;
    for (size_t k = 0; k < count; ++k) {
      // 1e-4 of the focal length (0.06 px at f = 600 px): SolveP3P accepts a solution whose
      // squared sides are within 1e-4 of the object's, and near a double root of the quartic
      // rounding leaves that much (trial 1841: 1.4e-5 in an ASan build).
      for (size_t i = 0; i < 3; ++i) {
        const cv::Vec3d camera = solutions[k].R * s.object[i] + solutions[k].t;
        ASSERT_GT(camera[2], 0) << "trial " << trial;
        EXPECT_NEAR(camera[0] / camera[2], s.rays[i][0], 1e-4) << "trial " << trial;
        EXPECT_NEAR(camera[1] / camera[2], s.rays[i][1], 1e-4) << "trial " << trial;
      }
      EXPECT_NEAR(cv::determinant(solutions[k].R), 1.0, 1e-9);
      // The truth within 0.05 degrees and 0.1 mm: what RANSAC's refinement starts from.
      if (RotationAngleDeg(solutions[k].R, s.R) < 0.05 && cv::norm(solutions[k].t - s.t) < 1e-4) {
        has_truth = true;
      }
    }
    found += has_truth ? 1 : 0;
  }
  ASSERT_GT(samples, 1500u);
  // Near-degenerate draws (a double root that rounding turns complex) may lose the true pose;
  // they must stay rare.
  EXPECT_GE(double(found), 0.995 * double(samples)) << found << " of " << samples;
}

TEST(P3PTest, FindsAsManyPosesAsOpenCV) {
  std::mt19937_64 random(11);
  const cv::Matx33d K = cv::Matx33d::eye();
  size_t ours = 0, opencv = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const Sample s = RandomSample(random);
    std::array<P3PSolution, 4> solutions;
    ours += SolveP3P(s.object, s.rays, &solutions);
    std::vector<cv::Point3f> object;
    std::vector<cv::Point2f> pixels;
    for (size_t i = 0; i < 3; ++i) {
      object.emplace_back(float(s.object[i][0]), float(s.object[i][1]), float(s.object[i][2]));
      pixels.emplace_back(float(s.rays[i][0]), float(s.rays[i][1]));
    }
    std::vector<cv::Mat> rvecs, tvecs;
    opencv +=
        size_t(cv::solveP3P(object, pixels, K, cv::noArray(), rvecs, tvecs, cv::SOLVEPNP_P3P));
  }
  // OpenCV works in floats here and drops a few solutions; the counts agree within 5 %.
  EXPECT_NEAR(double(ours), double(opencv), 0.05 * double(opencv)) << ours << " vs " << opencv;
}

TEST(P3PTest, DegenerateSamplesGiveNoSolution) {
  std::array<P3PSolution, 4> solutions;
  const std::array<cv::Vec3d, 3> rays = {cv::Vec3d(0, 0, 1), cv::Vec3d(0.1, 0, 1),
                                         cv::Vec3d(0, 0.1, 1)};
  // Collinear points.
  EXPECT_EQ(
      SolveP3P({cv::Vec3d(0, 0, 0), cv::Vec3d(0.1, 0, 0), cv::Vec3d(0.2, 0, 0)}, rays, &solutions),
      0u);
  // Two coincident points.
  EXPECT_EQ(
      SolveP3P({cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0.1, 0)}, rays, &solutions),
      0u);
  // A zero ray.
  EXPECT_EQ(SolveP3P({cv::Vec3d(0, 0, 0), cv::Vec3d(0.1, 0, 0), cv::Vec3d(0, 0.1, 0)},
                     {cv::Vec3d(0, 0, 0), cv::Vec3d(0.1, 0, 1), cv::Vec3d(0, 0.1, 1)}, &solutions),
            0u);
}

}  // namespace
}  // namespace recog
