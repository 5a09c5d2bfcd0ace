#include "core/object/recognition/object_pose.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <random>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "core/geometry/p3p.h"
#include "core/geometry/pose_covariance.h"

namespace recog {
namespace {

// Floor of the residual standard deviation in a pose covariance: keypoints are not located more
// precisely than this, however well the inliers fit.
constexpr double kCovarianceMinSigmaPx = 0.5;

template <class T>
std::vector<T> Select(const std::vector<T>& values, const std::vector<uint32_t>& indices) {
  std::vector<T> out;
  out.reserve(indices.size());
  for (uint32_t i : indices) out.push_back(values[i]);
  return out;
}

}  // namespace

double SquaredReprojectionError(const cv::Matx33d& K, const cv::Matx33d& R, const cv::Vec3d& t,
                                const cv::Point3f& x, const cv::Point2f& pixel) {
  const cv::Vec3d c = R * cv::Vec3d(x.x, x.y, x.z) + t;
  if (c[2] <= 1e-9) return INFINITY;
  const double u = K(0, 0) * c[0] / c[2] + K(0, 2);
  const double v = K(1, 1) * c[1] / c[2] + K(1, 2);
  return (u - pixel.x) * (u - pixel.x) + (v - pixel.y) * (v - pixel.y);
}

RigidTransform PoseFromRodrigues(const cv::Vec3d& rvec, const cv::Vec3d& tvec) {
  RigidTransform pose;
  cv::Rodrigues(rvec, pose.R);
  pose.t = tvec;
  return pose;
}

void ReprojectionInliers(const cv::Matx33d& K, const RigidTransform& pose,
                         const std::vector<cv::Point3f>& object,
                         const std::vector<cv::Point2f>& image, double threshold_px,
                         std::vector<uint32_t>* inliers) {
  inliers->clear();
  const double bound = threshold_px * threshold_px;
  for (size_t i = 0; i < object.size(); ++i) {
    if (SquaredReprojectionError(K, pose.R, pose.t, object[i], image[i]) <= bound) {
      inliers->push_back(uint32_t(i));
    }
  }
}

RigidTransform RefinePose(const cv::Matx33d& K, const RigidTransform& pose,
                          const std::vector<cv::Point3f>& object,
                          const std::vector<cv::Point2f>& image) {
  cv::Vec3d rvec, tvec = pose.t;
  cv::Rodrigues(pose.R, rvec);
  cv::solvePnP(object, image, K, cv::noArray(), rvec, tvec, true, cv::SOLVEPNP_ITERATIVE);
  return PoseFromRodrigues(rvec, tvec);
}

bool RansacPnp(const cv::Matx33d& K, const std::vector<cv::Point3f>& object,
               const std::vector<cv::Point2f>& image, int iterations, double threshold_px,
               uint64_t seed, RigidTransform* pose, std::vector<uint32_t>* inliers) {
  constexpr int kSample = 3;
  constexpr size_t kMinInliers = 5;
  const size_t n = object.size();
  if (n < kMinInliers) return false;
  std::mt19937_64 rng(seed);
  std::array<cv::Vec3d, kSample> sample_object, sample_rays;
  std::array<P3PSolution, 4> solutions;
  std::vector<uint32_t> candidate;
  inliers->clear();
  // Adaptive stop: enough iterations to draw, with 99 % confidence, one all-inlier sample at the
  // best inlier ratio seen so far; never more than `iterations`.
  int needed = iterations;
  for (int iteration = 0; iteration < needed; ++iteration) {
    uint32_t picked[kSample];
    for (int k = 0; k < kSample; ++k) {
      bool fresh = false;
      while (!fresh) {
        picked[k] = uint32_t(rng() % n);
        fresh = std::find(picked, picked + k, picked[k]) == picked + k;
      }
      const cv::Point3f& x = object[picked[k]];
      const cv::Point2f& pixel = image[picked[k]];
      sample_object[size_t(k)] = cv::Vec3d(x.x, x.y, x.z);
      sample_rays[size_t(k)] =
          cv::Vec3d((pixel.x - K(0, 2)) / K(0, 0), (pixel.y - K(1, 2)) / K(1, 1), 1.0);
    }
    const size_t solved = SolveP3P(sample_object, sample_rays, &solutions);
    bool improved = false;
    for (size_t s = 0; s < solved; ++s) {
      const RigidTransform hypothesis{solutions[s].R, solutions[s].t};
      ReprojectionInliers(K, hypothesis, object, image, threshold_px, &candidate);
      if (candidate.size() > inliers->size()) {
        inliers->swap(candidate);
        *pose = hypothesis;
        improved = true;
      }
    }
    if (improved) {
      const double all_inliers = std::pow(double(inliers->size()) / double(n), kSample);
      if (all_inliers >= 1.0) break;
      // In doubles first: with a handful of inliers the count overflows an int.
      needed =
          int(std::min(double(iterations), std::ceil(std::log(0.01) / std::log1p(-all_inliers))));
    }
  }
  if (inliers->size() < kMinInliers) return false;
  // Refine on the inliers, then once more on the inliers of the refined pose.
  for (int round = 0; round < 2; ++round) {
    const RigidTransform refined =
        RefinePose(K, *pose, Select(object, *inliers), Select(image, *inliers));
    ReprojectionInliers(K, refined, object, image, threshold_px, &candidate);
    if (candidate.size() < inliers->size()) break;
    *pose = refined;
    inliers->swap(candidate);
  }
  return true;
}

void CompleteDetection(const IndexedObject& object, const CameraIntrinsics& camera,
                       const RigidTransform& pose, const std::vector<uint32_t>& inliers,
                       const std::vector<uint32_t>& model_features,
                       const std::vector<cv::Point3f>& object_points,
                       const std::vector<cv::Point2f>& pinhole,
                       const std::vector<cv::Point2f>& keypoints, const DetectionOptions& extras,
                       Detection* detection) {
  const cv::Matx33d K = camera.K();
  detection->id = object.id;
  detection->name = object.metadata.name;
  detection->version = object.metadata.version;
  detection->type = object.metadata.type;
  detection->object_class = object.metadata.object_class;
  detection->units = object.metadata.units;
  detection->camera_from_object = pose;
  detection->inliers = inliers.size();
  detection->correspondences = object_points.size();
  detection->inlier_pixels.clear();
  detection->inliers_2d3d.clear();
  detection->covariance.clear();
  double error = 0;
  for (uint32_t i : inliers) {
    error += std::sqrt(SquaredReprojectionError(K, pose.R, pose.t, object_points[i], pinhole[i]));
    detection->inlier_pixels.push_back(keypoints[i]);
    if (extras.include_inliers) {
      detection->inliers_2d3d.push_back({keypoints[i], model_features[i], object_points[i]});
    }
  }
  detection->reprojection_error_px = inliers.empty() ? 0 : error / double(inliers.size());
  if (extras.include_covariance) {
    // The pose was solved on the pinhole pixels, so its uncertainty is too.
    PoseCovariance6 covariance;
    if (ComputePoseCovariance(K, pose.R, pose.t, Select(object_points, inliers),
                              Select(pinhole, inliers), kCovarianceMinSigmaPx, &covariance)) {
      detection->covariance.assign(covariance.begin(), covariance.end());
    }
  }

  std::vector<cv::Point3f> outline3d;
  if (object.metadata.type == ObjectType::kPlanar) {
    for (const PlanarFace& face : object.faces) {
      for (const cv::Point2d corner :
           {cv::Point2d(0, 0), cv::Point2d(face.width, 0), cv::Point2d(face.width, face.height),
            cv::Point2d(0, face.height)}) {
        outline3d.emplace_back(face.object_from_face.Apply({corner.x, corner.y, 0.0}));
      }
    }
  } else {
    outline3d = object.outline_points;
  }
  std::vector<cv::Point2f> projected;  // the outline's points the camera sees
  for (const cv::Point3f& x : outline3d) {
    const cv::Point3d c = pose.Apply(cv::Point3d(x));
    cv::Point2d pixel;
    if (c.z > 1e-9 && ProjectDirection(camera, cv::Vec3d(c.x, c.y, c.z), &pixel)) {
      projected.emplace_back(pixel);
    }
  }
  detection->outline.clear();
  if (projected.size() >= 3) cv::convexHull(projected, detection->outline);
}

}  // namespace recog
