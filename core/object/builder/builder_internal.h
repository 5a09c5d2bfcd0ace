// Internal to the model builders (model_builder.h is the API): what the builders of every source
// share. ModelBuilder::Accumulator collects (3D point, descriptor) pairs over the views and
// merges them into a model (eq. 5.3); the functions are the view geometry several sources use.
// model_builder.cc defines them; face_images.cc, posed_polygons.cc, rgbd_views.cc and
// roboearth_views.cc each build models from one source.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <unordered_map>
#include <vector>

#include <opencv2/core.hpp>

#include "core/object/builder/model_builder.h"

namespace recog {
namespace builder_internal {

constexpr double kNoDepth = std::numeric_limits<double>::infinity();

// The image as PNG bytes (a model view's image when ModelBuildOptions::keep_images).
std::vector<uint8_t> EncodePng(const cv::Mat& image);
// The ray through a pixel, in camera coordinates (z = 1), the lens distortion undone.
cv::Vec3d PixelRay(const CameraIntrinsics& camera, const cv::Point2f& pixel);
// Fills the convex hull of the projections of `corners` (object frame) into `region`; false when
// a corner is behind the camera.
bool FillProjectedHull(const std::vector<cv::Point3d>& corners, const CameraIntrinsics& camera,
                       const RigidTransform& camera_from_object, cv::Mat* region);

}  // namespace builder_internal

// Collects (3D point, descriptor) pairs, then merges them per point and word into a model.
class ModelBuilder::Accumulator {
 public:
  uint32_t AddPoint(const cv::Point3f& point, int face = -1) {
    points_.push_back(point);
    if (face >= 0) face_of_point_.push_back(uint32_t(face));
    return uint32_t(points_.size() - 1);
  }
  // Like AddPoint, but a point within `radius` of a point that earlier views gave (and this view
  // has not) becomes that point, whose position is the mean of its observations.
  uint32_t AddMergedPoint(const cv::Point3f& point, uint32_t view, double radius) {
    const auto cell = [radius](double x) { return int64_t(std::floor(x / radius)); };
    const int64_t cx = cell(point.x), cy = cell(point.y), cz = cell(point.z);
    int64_t best = -1;
    double best_d2 = radius * radius;
    for (int64_t x = cx - 1; x <= cx + 1; ++x) {
      for (int64_t y = cy - 1; y <= cy + 1; ++y) {
        for (int64_t z = cz - 1; z <= cz + 1; ++z) {
          const auto found = cells_.find(CellKey(x, y, z));
          if (found == cells_.end()) continue;
          for (uint32_t j : found->second) {
            if (last_view_[j] == view) continue;
            const cv::Point3f d = points_[j] - point;
            const double d2 = d.dot(d);
            if (d2 <= best_d2) best_d2 = d2, best = j;
          }
        }
      }
    }
    if (best >= 0) {
      const uint32_t j = uint32_t(best);
      ++observations_[j];
      points_[j] += (point - points_[j]) * (1.0f / float(observations_[j]));
      last_view_[j] = view;
      return j;
    }
    const uint32_t index = AddPoint(point);
    observations_.resize(points_.size(), 1);
    last_view_.resize(points_.size(), view);
    cells_[CellKey(cx, cy, cz)].push_back(index);
    return index;
  }
  void AddFeature(uint32_t point, const uint8_t* descriptor, size_t bytes) {
    point_of_feature_.push_back(point);
    descriptors_.insert(descriptors_.end(), descriptor, descriptor + bytes);
  }
  size_t num_points() const { return points_.size(); }
  size_t num_features() const { return point_of_feature_.size(); }

  // Keeps one descriptor per (point, word): the bitwise majority of that group (ties to 0).
  // Points left without a feature are dropped.
  ObjectModel Finish(const Vocabulary& vocabulary, ObjectModel model) && {
    const size_t bytes = model.descriptor.size_bytes;
    const size_t n = point_of_feature_.size();
    std::vector<std::pair<uint64_t, uint32_t>> keyed(n);  // (point << 32 | word, feature)
    for (size_t i = 0; i < n; ++i) {
      const WordId word = vocabulary.TransformOne(&descriptors_[i * bytes]);
      keyed[i] = {uint64_t(point_of_feature_[i]) << 32 | word, uint32_t(i)};
    }
    std::sort(keyed.begin(), keyed.end());
    std::vector<uint32_t> new_index(points_.size(), UINT32_MAX);
    std::vector<uint8_t> merged;
    std::vector<int> ones(bytes * 8);
    for (size_t begin = 0; begin < n;) {
      size_t end = begin;
      while (end < n && keyed[end].first == keyed[begin].first) ++end;
      std::fill(ones.begin(), ones.end(), 0);
      for (size_t k = begin; k < end; ++k) {
        const uint8_t* d = &descriptors_[size_t(keyed[k].second) * bytes];
        for (size_t bit = 0; bit < bytes * 8; ++bit) ones[bit] += (d[bit / 8] >> (bit % 8)) & 1;
      }
      const int count = int(end - begin);
      for (size_t byte = 0; byte < bytes; ++byte) {
        uint8_t value = 0;
        for (int bit = 0; bit < 8; ++bit) {
          if (2 * ones[byte * 8 + bit] > count) value |= uint8_t(1u << bit);
        }
        merged.push_back(value);
      }
      const uint32_t point = uint32_t(keyed[begin].first >> 32);
      if (new_index[point] == UINT32_MAX) {
        new_index[point] = uint32_t(model.points.size());
        model.points.push_back(points_[point]);
        if (!face_of_point_.empty()) model.face_of_point.push_back(face_of_point_[point]);
      }
      model.point_of_feature.push_back(new_index[point]);
      begin = end;
    }
    model.descriptors = cv::Mat(int(model.point_of_feature.size()), int(bytes), CV_8U);
    if (!merged.empty()) std::copy(merged.begin(), merged.end(), model.descriptors.data);
    return model;
  }

 private:
  static uint64_t CellKey(int64_t x, int64_t y, int64_t z) {
    return (uint64_t(x) & 0x1fffff) << 42 | (uint64_t(y) & 0x1fffff) << 21 |
           (uint64_t(z) & 0x1fffff);
  }

  std::vector<cv::Point3f> points_;
  std::vector<uint32_t> observations_;  // merged points: views seen in, last view
  std::vector<uint32_t> last_view_;
  std::unordered_map<uint64_t, std::vector<uint32_t>> cells_;
  std::vector<uint32_t> face_of_point_;
  std::vector<uint32_t> point_of_feature_;
  std::vector<uint8_t> descriptors_;
};

}  // namespace recog
