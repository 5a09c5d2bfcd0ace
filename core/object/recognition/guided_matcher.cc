#include "core/object/recognition/guided_matcher.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/calib3d.hpp>

#include "core/common/descriptor.h"
#include "core/common/option_checks.h"
#include "core/object/recognition/object_pose.h"

namespace recog {
namespace {

constexpr uint32_t kNoMatch = std::numeric_limits<uint32_t>::max();

}  // namespace

Status GuidedMatchOptions::Validate(std::string_view name) const {
  OptionChecks check(name);
  check.Member("orb", orb);
  check.InRange("region_margin_px", region_margin_px, RealRange::AtLeast(0));
  check.InRange("window_px", window_px, RealRange::Above(0));
  check.InRange("ratio", ratio, RealRange::OpenClosed(0, 1));
  check.AtLeast("ransac_iterations", ransac_iterations, 1);
  check.InRange("reprojection_px", reprojection_px, RealRange::Above(0));
  check.AtLeast("min_inliers", min_inliers, 1);
  return check.status();
}

GuidedMatcher::GuidedMatcher(GuidedMatchOptions options) : options_(std::move(options)) {}

bool GuidedMatcher::Match(const IndexedObject& object, const RigidTransform& pose,
                          const cv::Mat& image, const FeatureSet* features,
                          const CameraIntrinsics& camera, const DetectionOptions& extras,
                          Detection* detection) {
  // Project every model feature; keep those in front of the camera (and in the image).
  const cv::Matx33d K = camera.K();
  const size_t n = object.points.size();
  projected_.resize(n);
  visible_.clear();
  const float slack = float(options_.window_px);
  float min_x = INFINITY, min_y = INFINITY, max_x = -INFINITY, max_y = -INFINITY;
  for (size_t f = 0; f < n; ++f) {
    const cv::Point3f& x = object.points[f];
    const cv::Vec3d c = pose.R * cv::Vec3d(x.x, x.y, x.z) + pose.t;
    if (c[2] <= 1e-9) continue;
    const cv::Point2f p(float(K(0, 0) * c[0] / c[2] + K(0, 2)),
                        float(K(1, 1) * c[1] / c[2] + K(1, 2)));
    if (!image.empty() && (p.x < -slack || p.y < -slack || p.x > float(image.cols) + slack ||
                           p.y > float(image.rows) + slack)) {
      continue;
    }
    projected_[f] = p;
    visible_.push_back(uint32_t(f));
    min_x = std::min(min_x, p.x);
    min_y = std::min(min_y, p.y);
    max_x = std::max(max_x, p.x);
    max_y = std::max(max_y, p.y);
  }
  if (visible_.size() < options_.min_inliers) return false;
  const float margin = float(options_.region_margin_px);
  cv::Rect box(cv::Point(int(std::floor(min_x - margin)), int(std::floor(min_y - margin))),
               cv::Point(int(std::ceil(max_x + margin)), int(std::ceil(max_y + margin))));

  // The keypoints to match: ORB in the box, or the frame's own.
  if (!image.empty()) {
    box &= cv::Rect(0, 0, image.cols, image.rows);
    if (box.empty()) return false;
    if (!extractor_) {
      FeatureOptions feature_options;
      feature_options.orb = options_.orb;
      auto extractor = CreateFeatureExtractor(feature_options);
      if (!extractor.ok()) return false;
      extractor_ = std::move(*extractor);
    }
    if (!extractor_->Extract(image(box), &region_features_).ok()) return false;
    for (cv::KeyPoint& k : region_features_.keypoints) {
      k.pt.x += float(box.x);
      k.pt.y += float(box.y);
    }
    frame_features_ = &region_features_;
  } else {
    frame_features_ = features;
  }
  const size_t m = frame_features_->size();
  if (m < options_.min_inliers) return false;
  pinhole_.resize(m);
  for (size_t k = 0; k < m; ++k) pinhole_[k] = frame_features_->keypoints[k].pt;
  ToPinhole(camera, pinhole_);

  std::vector<std::pair<uint32_t, uint32_t>>& pairs = pairs_;
  MatchInWindows(object, box, &pairs);
  if (pairs.size() < options_.min_inliers) return false;
  std::vector<uint32_t> model_features(pairs.size());
  std::vector<cv::Point3f> object_points(pairs.size());
  std::vector<cv::Point2f> image_points(pairs.size()), keypoints(pairs.size());
  for (size_t i = 0; i < pairs.size(); ++i) {
    model_features[i] = pairs[i].first;
    object_points[i] = object.points[pairs[i].first];
    image_points[i] = pinhole_[pairs[i].second];
    keypoints[i] = frame_features_->keypoints[pairs[i].second].pt;
  }
  RigidTransform solved;
  std::vector<uint32_t> inliers;
  if (!RansacPnp(K, object_points, image_points, options_.ransac_iterations,
                 options_.reprojection_px, options_.seed, &solved, &inliers) ||
      inliers.size() < options_.min_inliers) {
    return false;
  }
  CompleteDetection(object, camera, solved, inliers, model_features, object_points, image_points,
                    keypoints, extras, detection);
  return true;
}

void GuidedMatcher::MatchInWindows(const IndexedObject& object, const cv::Rect& box,
                                   std::vector<std::pair<uint32_t, uint32_t>>* pairs) {
  // Bucket the keypoints in a grid of window-sized cells over the box (a counting sort), so a
  // window touches at most 3x3 cells.
  const float cell = float(std::max(options_.window_px, 1.0));
  const int cols = std::max(1, int(std::ceil(float(box.width) / cell)));
  const int rows = std::max(1, int(std::ceil(float(box.height) / cell)));
  const size_t m = pinhole_.size();
  auto cell_of = [&](const cv::Point2f& p) -> int {
    const int cx = int(std::floor((p.x - float(box.x)) / cell));
    const int cy = int(std::floor((p.y - float(box.y)) / cell));
    if (cx < 0 || cy < 0 || cx >= cols || cy >= rows) return -1;
    return cy * cols + cx;
  };
  cell_start_.assign(size_t(cols * rows) + 1, 0);
  for (size_t k = 0; k < m; ++k) {
    if (const int c = cell_of(pinhole_[k]); c >= 0) ++cell_start_[size_t(c) + 1];
  }
  for (size_t c = 1; c < cell_start_.size(); ++c) cell_start_[c] += cell_start_[c - 1];
  cell_items_.resize(cell_start_.back());
  best_distance_.assign(cell_start_.size(), 0);  // fill positions per cell, reused below
  for (size_t k = 0; k < m; ++k) {
    if (const int c = cell_of(pinhole_[k]); c >= 0) {
      cell_items_[cell_start_[size_t(c)] + best_distance_[size_t(c)]++] = uint32_t(k);
    }
  }

  // Each visible model feature against the keypoints in its window; one feature per keypoint.
  best_distance_.assign(m, kNoMatch);
  best_feature_.assign(m, kNoMatch);
  const cv::Mat& model = object.descriptors;
  const cv::Mat& frame = frame_features_->descriptors;
  const size_t bytes = size_t(model.cols);
  const float window = float(options_.window_px);
  const float window2 = window * window;
  for (uint32_t f : visible_) {
    const cv::Point2f p = projected_[f];
    const int x0 = std::max(0, int(std::floor((p.x - window - float(box.x)) / cell)));
    const int x1 = std::min(cols - 1, int(std::floor((p.x + window - float(box.x)) / cell)));
    const int y0 = std::max(0, int(std::floor((p.y - window - float(box.y)) / cell)));
    const int y1 = std::min(rows - 1, int(std::floor((p.y + window - float(box.y)) / cell)));
    const uint8_t* descriptor = model.ptr<uint8_t>(int(f));
    uint32_t best = kNoMatch, second = kNoMatch, best_k = kNoMatch;
    for (int cy = y0; cy <= y1; ++cy) {
      for (int cx = x0; cx <= x1; ++cx) {
        const size_t c = size_t(cy * cols + cx);
        for (uint32_t i = cell_start_[c]; i < cell_start_[c + 1]; ++i) {
          const uint32_t k = cell_items_[i];
          const cv::Point2f d = pinhole_[k] - p;
          if (d.x * d.x + d.y * d.y > window2) continue;
          const uint8_t* other = frame.ptr<uint8_t>(int(k));
          const uint32_t distance = bytes == 32 ? Hamming256(descriptor, other)
                                                : HammingDistance(descriptor, other, bytes);
          if (distance < best) {
            second = best;
            best = distance;
            best_k = k;
          } else if (distance < second) {
            second = distance;
          }
        }
      }
    }
    if (best > options_.max_distance) continue;
    if (second != kNoMatch && double(best) >= options_.ratio * double(second)) continue;
    if (best < best_distance_[best_k]) {
      best_distance_[best_k] = best;
      best_feature_[best_k] = f;
    }
  }
  pairs->clear();
  for (size_t k = 0; k < m; ++k) {
    if (best_feature_[k] != kNoMatch) pairs->emplace_back(best_feature_[k], uint32_t(k));
  }
}

}  // namespace recog
