#include "core/object/model_builder.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numeric>
#include <sstream>
#include <unordered_map>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/names.h"
#include "core/geometry/depth_registration.h"
#include "core/object/roboearth.h"

namespace recog {
namespace {

constexpr double kNoDepth = std::numeric_limits<double>::infinity();
constexpr double kMinTrainingImageSide = 240.0;  // pixels

std::vector<uint8_t> EncodePng(const cv::Mat& image) {
  std::vector<uint8_t> png;
  cv::imencode(".png", image, png);
  return png;
}

// The ray through a pixel, in camera coordinates (z = 1), the lens distortion undone.
cv::Vec3d PixelRay(const CameraIntrinsics& camera, const cv::Point2f& pixel) {
  if (camera.distortion.empty()) {
    return {(pixel.x - camera.cx) / camera.fx, (pixel.y - camera.cy) / camera.fy, 1.0};
  }
  std::vector<cv::Point2f> undistorted;
  cv::undistortPoints(std::vector<cv::Point2f>{pixel}, undistorted, cv::Mat(camera.K()),
                      cv::Mat(camera.distortion));
  return {undistorted[0].x, undistorted[0].y, 1.0};
}

// Fills the convex hull of the projections of `corners` (object frame) into `region`; false when
// a corner is behind the camera.
bool FillProjectedHull(const std::vector<cv::Point3d>& corners, const CameraIntrinsics& camera,
                       const RigidTransform& camera_from_object, cv::Mat* region) {
  std::vector<cv::Point> pixels;
  for (const cv::Point3d& x : corners) {
    cv::Point2d uv;
    if (!ProjectPoint(camera, camera_from_object, x, &uv)) return false;
    // Far outside the image: clamp so that the integer polygon stays well-defined.
    pixels.emplace_back(int(std::lround(std::clamp(uv.x, -1e5, 1e5))),
                        int(std::lround(std::clamp(uv.y, -1e5, 1e5))));
  }
  std::vector<cv::Point> hull;
  cv::convexHull(pixels, hull);
  cv::fillConvexPoly(*region, hull, cv::Scalar(255));
  return true;
}

// The 8 corners of a box in the object frame.
std::vector<cv::Point3d> BoxCorners(const ObjectBox& box) {
  std::vector<cv::Point3d> corners;
  for (int k = 0; k < 8; ++k) {
    corners.emplace_back(box.centre[0] + ((k & 1) ? 0.5 : -0.5) * box.size[0],
                         box.centre[1] + ((k & 2) ? 0.5 : -0.5) * box.size[1],
                         box.centre[2] + ((k & 4) ? 0.5 : -0.5) * box.size[2]);
  }
  return corners;
}

// The depth image of an RGB-D view in metres (CV_32F), registered to its colour image.
cv::Mat RegisteredDepthMetres(const RgbdView& rgbd) {
  cv::Mat metres;
  if (rgbd.depth.type() == CV_16U) {
    rgbd.depth.convertTo(metres, CV_32F, 1.0 / rgbd.depth_scale);
  } else {
    metres = rgbd.depth;
  }
  if (!(rgbd.depth_camera.fx > 0)) return metres;
  const CameraIntrinsics& color = rgbd.view.camera;
  return RegisterDepth(metres, {rgbd.depth_camera.K(), rgbd.depth_camera.distortion},
                       rgbd.depth_from_color.R, rgbd.depth_from_color.t,
                       {color.K(), color.distortion}, rgbd.view.image.size());
}

// True when the depth range among the valid depths within `radius` of (u, v) exceeds ratio * z.
bool AtDepthDiscontinuity(const cv::Mat& depth, int u, int v, int radius, double ratio, double z) {
  float low = float(z), high = float(z);
  for (int y = std::max(0, v - radius); y <= std::min(depth.rows - 1, v + radius); ++y) {
    const float* row = depth.ptr<float>(y);
    for (int x = std::max(0, u - radius); x <= std::min(depth.cols - 1, u + radius); ++x) {
      if (!(row[x] > 0) || !std::isfinite(row[x])) continue;
      low = std::min(low, row[x]);
      high = std::max(high, row[x]);
    }
  }
  return high - low > ratio * z;
}

// Indices of the points within `mads` robust deviations (1.4826 x MAD) of the median on every
// axis; an axis's bound is at least `floor` and a tenth of the widest axis's (a flat object is no
// reason to cut its depth noise). mads <= 0 keeps every point.
std::vector<size_t> RobustInliers(const std::vector<cv::Point3f>& points, double mads,
                                  double floor) {
  std::vector<size_t> kept;
  if (!(mads > 0)) {
    kept.resize(points.size());
    std::iota(kept.begin(), kept.end(), size_t{0});
    return kept;
  }
  const auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  cv::Vec3d centre, bound;
  for (int axis = 0; axis < 3; ++axis) {
    std::vector<double> values(points.size());
    for (size_t i = 0; i < points.size(); ++i) values[i] = (&points[i].x)[axis];
    centre[axis] = median(values);
    for (double& v : values) v = std::abs(v - centre[axis]);
    bound[axis] = mads * 1.4826 * median(values);
  }
  const double least = std::max(floor, 0.1 * std::max({bound[0], bound[1], bound[2]}));
  for (size_t i = 0; i < points.size(); ++i) {
    bool inside = true;
    for (int axis = 0; axis < 3; ++axis) {
      inside =
          inside && std::abs((&points[i].x)[axis] - centre[axis]) <= std::max(least, bound[axis]);
    }
    if (inside) kept.push_back(i);
  }
  return kept;
}

cv::Vec3d ToVec(const cv::Point3d& p) { return {p.x, p.y, p.z}; }

// True when `p` (on the polygon's plane) lies inside the convex polygon whose corners turn
// counter-clockwise about `normal`.
bool InsideConvexPolygon(const std::vector<cv::Vec3d>& corners, const cv::Vec3d& normal,
                         const cv::Vec3d& p) {
  for (size_t i = 0; i < corners.size(); ++i) {
    const cv::Vec3d& a = corners[i];
    const cv::Vec3d& b = corners[(i + 1) % corners.size()];
    if ((b - a).cross(p - a).dot(normal) < -1e-12) return false;
  }
  return true;
}

// Projections of the cloud points that a view sees: normal facing the camera and nearest in a
// coarse z-buffer. Looked up by pixel cell.
class VisiblePoints {
 public:
  VisiblePoints(const std::vector<cv::Point3f>& points, const std::vector<cv::Vec3f>& normals,
                const CameraIntrinsics& camera, const RigidTransform& pose, cv::Size size,
                double cell_px)
      : cell_(cell_px),
        cols_(int(std::ceil(size.width / cell_px)) + 1),
        rows_(int(std::ceil(size.height / cell_px)) + 1) {
    constexpr int kZCell = 4;  // z-buffer cell, pixels
    const int zcols = size.width / kZCell + 1;
    const int zrows = size.height / kZCell + 1;
    std::vector<double> zbuffer(size_t(zcols) * zrows, kNoDepth);
    std::vector<cv::Point2d> pixel(points.size());
    std::vector<double> depth(points.size(), kNoDepth);
    for (size_t i = 0; i < points.size(); ++i) {
      const cv::Point3d c = pose.Apply(cv::Point3d(points[i]));
      if (c.z <= 0) continue;
      if (!normals.empty()) {
        const cv::Vec3d n = pose.R * cv::Vec3d(normals[i]);
        if (n.dot(cv::Vec3d(-c.x, -c.y, -c.z)) <= 0) continue;  // faces away
      }
      const cv::Point2d uv(camera.fx * c.x / c.z + camera.cx, camera.fy * c.y / c.z + camera.cy);
      if (uv.x < 0 || uv.y < 0 || uv.x >= size.width || uv.y >= size.height) continue;
      pixel[i] = uv;
      depth[i] = c.z;
      double& z = zbuffer[size_t(int(uv.y) / kZCell) * zcols + int(uv.x) / kZCell];
      z = std::min(z, c.z);
    }
    cells_.resize(size_t(cols_) * rows_);
    for (size_t i = 0; i < points.size(); ++i) {
      if (depth[i] == kNoDepth) continue;
      // Occluded when clearly behind the nearest point of its neighbourhood.
      double nearest = kNoDepth;
      const int zx = int(pixel[i].x) / kZCell, zy = int(pixel[i].y) / kZCell;
      for (int y = std::max(0, zy - 1); y <= std::min(zrows - 1, zy + 1); ++y) {
        for (int x = std::max(0, zx - 1); x <= std::min(zcols - 1, zx + 1); ++x) {
          nearest = std::min(nearest, zbuffer[size_t(y) * zcols + x]);
        }
      }
      if (depth[i] > nearest * 1.02) continue;
      cells_[Cell(pixel[i])].push_back({pixel[i], uint32_t(i)});
    }
  }

  // The visible point projecting nearest to `p` within `radius` pixels (radius <= cell), or -1.
  int64_t Nearest(const cv::Point2f& p, double radius) const {
    const int cx = int(p.x / cell_), cy = int(p.y / cell_);
    double best = radius * radius;
    int64_t found = -1;
    for (int y = std::max(0, cy - 1); y <= std::min(rows_ - 1, cy + 1); ++y) {
      for (int x = std::max(0, cx - 1); x <= std::min(cols_ - 1, cx + 1); ++x) {
        for (const auto& [uv, index] : cells_[size_t(y) * cols_ + x]) {
          const double d = (uv.x - p.x) * (uv.x - p.x) + (uv.y - p.y) * (uv.y - p.y);
          if (d <= best) {
            best = d;
            found = index;
          }
        }
      }
    }
    return found;
  }

 private:
  size_t Cell(const cv::Point2d& uv) const {
    return size_t(int(uv.y / cell_)) * cols_ + size_t(int(uv.x / cell_));
  }
  double cell_;
  int cols_, rows_;
  std::vector<std::vector<std::pair<cv::Point2d, uint32_t>>> cells_;
};

}  // namespace

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

ModelBuilder::ModelBuilder(std::shared_ptr<const Vocabulary> vocabulary, ModelBuildOptions options)
    : vocabulary_(std::move(vocabulary)), options_(std::move(options)) {}

Status ModelBuilder::Extract(const cv::Mat& image, FeatureSet* features) {
  if (!extractor_) {
    FeatureOptions feature_options;
    feature_options.orb = options_.orb;
    RECOG_ASSIGN_OR_RETURN(extractor_, CreateFeatureExtractor(feature_options));
  }
  return extractor_->Extract(image, features);
}

Status ModelBuilder::ExtractInRegion(const cv::Mat& image, const cv::Mat& region,
                                     FeatureSet* features) {
  features->keypoints.clear();
  features->descriptors = cv::Mat();
  const cv::Rect box = cv::boundingRect(region);
  if (box.empty()) return Status::Ok();
  // ORB keeps edge_threshold pixels of every pyramid level free: the crop keeps that much
  // context around the region at the coarsest level of the view's own pyramid.
  const double context = options_.orb.edge_threshold *
                         std::pow(double(options_.orb.scale_factor), options_.orb.levels - 1);
  const int margin =
      int(std::ceil(std::max(context, options_.crop_margin * std::max(box.width, box.height))));
  const cv::Rect crop =
      cv::Rect(box.x - margin, box.y - margin, box.width + 2 * margin, box.height + 2 * margin) &
      cv::Rect(0, 0, image.cols, image.rows);
  const double scale = std::clamp(double(options_.working_size) / std::max(crop.width, crop.height),
                                  1.0, std::max(1.0, options_.max_enlarge));
  cv::Mat patch = image(crop);
  if (scale > 1.0) cv::resize(patch, patch, cv::Size(), scale, scale, cv::INTER_CUBIC);
  // The pyramid gets the levels the enlargement added, so that it still reaches down as far as
  // it does on the view itself (recognition sees the object at the view's scale).
  const int levels =
      options_.orb.levels +
      int(std::ceil(std::log(scale) / std::log(double(options_.orb.scale_factor)) - 1e-9));
  // The grid's cells outside the region leave their share unused: the budget grows with the
  // crop's area over the region's (at most 8 times), so that the region gets about max_features.
  const int budget = int(std::lround(
      options_.orb.max_features *
      std::min(8.0, double(crop.area()) / std::max(1, cv::countNonZero(region(crop))))));
  if (!region_extractor_ || region_levels_ != levels || region_budget_ != budget) {
    FeatureOptions feature_options;
    feature_options.orb = options_.orb;
    feature_options.orb.levels = levels;
    feature_options.orb.max_features = budget;
    feature_options.orb.grid_rows = feature_options.orb.grid_cols = options_.region_grid;
    RECOG_ASSIGN_OR_RETURN(region_extractor_, CreateFeatureExtractor(feature_options));
    region_levels_ = levels;
    region_budget_ = budget;
  }
  FeatureSet found;
  RECOG_RETURN_IF_ERROR(region_extractor_->Extract(patch, &found));
  std::vector<int> rows;
  for (size_t i = 0; i < found.size(); ++i) {
    cv::KeyPoint keypoint = found.keypoints[i];
    // resize maps pixel centres: crop pixel x = (patch pixel x + 0.5) / scale - 0.5.
    keypoint.pt = {float((keypoint.pt.x + 0.5) / scale - 0.5 + crop.x),
                   float((keypoint.pt.y + 0.5) / scale - 0.5 + crop.y)};
    keypoint.size = float(keypoint.size / scale);
    const int u = std::clamp(int(std::lround(keypoint.pt.x)), 0, image.cols - 1);
    const int v = std::clamp(int(std::lround(keypoint.pt.y)), 0, image.rows - 1);
    if (region.at<uint8_t>(v, u) == 0) continue;
    features->keypoints.push_back(keypoint);
    rows.push_back(int(i));
  }
  features->descriptors =
      cv::Mat(int(rows.size()), found.descriptors.cols, found.descriptors.type());
  for (size_t k = 0; k < rows.size(); ++k)
    found.descriptors.row(rows[k]).copyTo(features->descriptors.row(int(k)));
  return Status::Ok();
}

StatusOr<BoxSide> ParseBoxSide(std::string_view name) {
  static constexpr std::pair<std::string_view, BoxSide> kSides[] = {
      {"front", BoxSide::kFront}, {"back", BoxSide::kBack}, {"left", BoxSide::kLeft},
      {"right", BoxSide::kRight}, {"top", BoxSide::kTop},   {"bottom", BoxSide::kBottom}};
  for (const auto& [text, side] : kSides) {
    if (name == text) return side;
  }
  return Status::InvalidArgument("unknown box side '" + std::string(name) +
                                 "' (front, back, left, right, top, bottom)");
}

PlanarFace BoxFace(BoxSide side, double w, double h, double d) {
  PlanarFace face;
  // Columns of R are the face's x, y and z axes in the object frame; t is its top-left corner.
  cv::Vec3d x, y, origin;
  switch (side) {
    case BoxSide::kFront:
      x = {1, 0, 0}, y = {0, 1, 0}, origin = {-w / 2, -h / 2, -d / 2};
      face.width = w, face.height = h;
      break;
    case BoxSide::kBack:
      x = {-1, 0, 0}, y = {0, 1, 0}, origin = {w / 2, -h / 2, d / 2};
      face.width = w, face.height = h;
      break;
    case BoxSide::kLeft:
      x = {0, 0, -1}, y = {0, 1, 0}, origin = {-w / 2, -h / 2, d / 2};
      face.width = d, face.height = h;
      break;
    case BoxSide::kRight:
      x = {0, 0, 1}, y = {0, 1, 0}, origin = {w / 2, -h / 2, -d / 2};
      face.width = d, face.height = h;
      break;
    case BoxSide::kTop:
      x = {1, 0, 0}, y = {0, 0, -1}, origin = {-w / 2, -h / 2, d / 2};
      face.width = w, face.height = d;
      break;
    case BoxSide::kBottom:
      x = {1, 0, 0}, y = {0, 0, 1}, origin = {-w / 2, h / 2, -d / 2};
      face.width = w, face.height = d;
      break;
  }
  const cv::Vec3d z = x.cross(y);
  face.object_from_face.R = {x[0], y[0], z[0], x[1], y[1], z[1], x[2], y[2], z[2]};
  face.object_from_face.t = origin;
  return face;
}

namespace {

// A camera looking straight at a face so that its image spans the whole face: face point
// (x, y) maps to pixel (x * cols / width, y * rows / height); the camera sits at depth 1.
void FrontalCamera(const PlanarFace& face, cv::Size image, CameraIntrinsics* camera,
                   RigidTransform* camera_from_object) {
  camera->fx = image.width / face.width;
  camera->fy = image.height / face.height;
  camera->cx = camera->cy = 0;
  RigidTransform camera_from_face;
  camera_from_face.t = {0, 0, 1};
  *camera_from_object = camera_from_face * face.object_from_face.Inverse();
}

}  // namespace

StatusOr<ObjectModel> ModelBuilder::FromFaceImages(const std::string& name,
                                                   const std::vector<FaceImage>& faces,
                                                   double width, double height, double depth) {
  if (faces.empty() || faces.size() > 6) {
    return Status::InvalidArgument("a planar model needs 1 to 6 face images, got " +
                                   std::to_string(faces.size()));
  }
  if (!(width > 0) || !(height > 0) || !(depth >= 0) || !std::isfinite(width + height + depth)) {
    return Status::InvalidArgument("planar model sizes must be positive (depth may be 0)");
  }
  if (faces.size() > 1 && !(depth > 0)) {
    return Status::InvalidArgument("a box of several faces needs a positive depth");
  }
  for (size_t i = 0; i < faces.size(); ++i) {
    for (size_t j = 0; j < i; ++j) {
      if (faces[i].side == faces[j].side) {
        return Status::InvalidArgument("two face images for the same side of the box");
      }
    }
  }
  ObjectModel model;
  model.metadata.name = name;
  model.metadata.type = ObjectType::kPlanar;
  model.metadata.dimensions = {width, height, depth};
  model.metadata.source = faces.size() == 1 ? "planar" : "box";
  RECOG_RETURN_IF_ERROR(ValidateName("object", name));
  Accumulator accumulator;
  FeatureSet features;
  for (const FaceImage& face_image : faces) {
    if (face_image.image.empty()) return Status::InvalidArgument("empty face image");
    const PlanarFace face = BoxFace(face_image.side, width, height, depth);
    const int face_index = int(model.faces.size());
    model.faces.push_back(face);
    RECOG_RETURN_IF_ERROR(Extract(face_image.image, &features));
    const double sx = face.width / face_image.image.cols;
    const double sy = face.height / face_image.image.rows;
    for (size_t i = 0; i < features.size(); ++i) {
      const cv::Point2f& p = features.keypoints[i].pt;
      const cv::Point3d x = face.object_from_face.Apply({p.x * sx, p.y * sy, 0.0});
      accumulator.AddFeature(accumulator.AddPoint(cv::Point3f(x), face_index),
                             features.descriptors.ptr(int(i)), features.descriptors.cols);
    }
    TrainingView view;
    view.name = "face_" + std::to_string(face_index);
    FrontalCamera(face, face_image.image.size(), &view.camera, &view.camera_from_object);
    if (options_.keep_images) view.image_png = EncodePng(face_image.image);
    model.views.push_back(std::move(view));
  }
  model = std::move(accumulator).Finish(*vocabulary_, std::move(model));
  RECOG_RETURN_IF_ERROR(model.Validate());
  return model;
}

StatusOr<ObjectModel> ModelBuilder::FromPosedPolygons(const std::string& name,
                                                      const std::vector<FacePolygon>& polygons,
                                                      const std::vector<PosedImage>& views) {
  RECOG_RETURN_IF_ERROR(ValidateName("object", name));
  if (polygons.empty() || views.empty()) {
    return Status::InvalidArgument("a model from posed images needs faces and views");
  }
  struct Plane {
    std::vector<cv::Vec3d> corners;
    cv::Vec3d normal;
  };
  std::vector<Plane> planes;
  cv::Vec3d low(1e300, 1e300, 1e300), high(-1e300, -1e300, -1e300);
  for (const FacePolygon& polygon : polygons) {
    if (polygon.corners.size() < 3) return Status::InvalidArgument("a face needs 3 corners");
    Plane plane;
    for (const cv::Point3d& c : polygon.corners) {
      plane.corners.push_back(ToVec(c));
      for (int k = 0; k < 3; ++k) {
        low[k] = std::min(low[k], plane.corners.back()[k]);
        high[k] = std::max(high[k], plane.corners.back()[k]);
      }
    }
    plane.normal = (plane.corners[1] - plane.corners[0]).cross(plane.corners[2] - plane.corners[0]);
    const double norm = cv::norm(plane.normal);
    if (norm < 1e-12) return Status::InvalidArgument("a face has collinear corners");
    plane.normal /= norm;
    planes.push_back(std::move(plane));
  }
  ObjectModel model;
  model.metadata.name = name;
  model.metadata.type = ObjectType::k3D;
  model.metadata.dimensions = high - low;
  model.metadata.source = "posed-polygons";
  Accumulator accumulator;
  FeatureSet features;
  for (size_t view_index = 0; view_index < views.size(); ++view_index) {
    const PosedImage& posed = views[view_index];
    RECOG_RETURN_IF_ERROR(posed.camera.Validate());
    if (posed.image.empty()) return Status::InvalidArgument("view '" + posed.name + "' is empty");
    // The region: the projected faces.
    cv::Mat region(posed.image.size(), CV_8U, cv::Scalar(0));
    for (const FacePolygon& polygon : polygons) {
      FillProjectedHull(polygon.corners, posed.camera, posed.camera_from_object, &region);
    }
    RECOG_RETURN_IF_ERROR(ExtractInRegion(posed.image, region, &features));
    const RigidTransform object_from_camera = posed.camera_from_object.Inverse();
    const cv::Vec3d centre = object_from_camera.t;
    const size_t points_before = accumulator.num_features();
    for (size_t i = 0; i < features.size(); ++i) {
      const cv::Vec3d ray = object_from_camera.R * PixelRay(posed.camera, features.keypoints[i].pt);
      double nearest = kNoDepth;
      for (const Plane& plane : planes) {
        const double facing = ray.dot(plane.normal);
        if (std::abs(facing) < 1e-12) continue;
        const double s = (plane.corners[0] - centre).dot(plane.normal) / facing;
        if (s <= 0 || s >= nearest) continue;
        if (InsideConvexPolygon(plane.corners, plane.normal, centre + s * ray)) {
          nearest = s;
        }
      }
      if (nearest == kNoDepth) continue;
      const cv::Vec3d x = centre + nearest * ray;
      accumulator.AddFeature(
          accumulator.AddMergedPoint(cv::Point3f(float(x[0]), float(x[1]), float(x[2])),
                                     uint32_t(view_index), options_.merge_radius),
          features.descriptors.ptr(int(i)), features.descriptors.cols);
    }
    if (accumulator.num_features() == points_before) {
      return Status::InvalidArgument("view '" + posed.name +
                                     "' gives no object point (do the faces project into it?)");
    }
    model.views.push_back({posed.name, posed.camera, posed.camera_from_object,
                           options_.keep_images ? EncodePng(posed.image) : std::vector<uint8_t>{}});
  }
  model = std::move(accumulator).Finish(*vocabulary_, std::move(model));
  RECOG_RETURN_IF_ERROR(model.Validate());
  return model;
}

StatusOr<ObjectModel> ModelBuilder::FromRgbd(const std::string& name,
                                             const std::vector<RgbdView>& views,
                                             const std::optional<ObjectBox>& box) {
  RECOG_RETURN_IF_ERROR(ValidateName("object", name));
  if (views.empty()) return Status::InvalidArgument("an RGB-D model needs views");
  if (box && !(box->size[0] > 0 && box->size[1] > 0 && box->size[2] > 0 &&
               std::isfinite(box->size[0] + box->size[1] + box->size[2] + box->centre[0] +
                             box->centre[1] + box->centre[2]))) {
    return Status::InvalidArgument("the object box needs a positive width, height and depth");
  }
  ObjectModel model;
  model.metadata.name = name;
  model.metadata.type = ObjectType::k3D;
  model.metadata.source = "rgbd";
  // Every back-projected keypoint, before the outliers are dropped and the views merged.
  std::vector<cv::Point3f> points;
  std::vector<uint32_t> view_of_point;
  std::vector<uint8_t> descriptors;
  int descriptor_bytes = 0;
  FeatureSet features;
  for (size_t view_index = 0; view_index < views.size(); ++view_index) {
    const RgbdView& rgbd = views[view_index];
    const PosedImage& posed = rgbd.view;
    const std::string where = "view '" + posed.name + "'";
    RECOG_RETURN_IF_ERROR(posed.camera.Validate());
    if (posed.image.empty()) return Status::InvalidArgument(where + ": empty image");
    const bool own_camera = rgbd.depth_camera.fx > 0;
    if (own_camera) RECOG_RETURN_IF_ERROR(rgbd.depth_camera.Validate());
    if (rgbd.depth.empty() || (!own_camera && rgbd.depth.size() != posed.image.size()) ||
        (rgbd.depth.type() != CV_16U && rgbd.depth.type() != CV_32F)) {
      return Status::InvalidArgument(
          where +
          ": depth must be CV_16U or CV_32F, of the image's size unless it has its own "
          "camera");
    }
    if (!rgbd.mask.empty() &&
        (rgbd.mask.size() != posed.image.size() || rgbd.mask.type() != CV_8U)) {
      return Status::InvalidArgument(where + ": mask must be CV_8U of the image's size");
    }
    if (rgbd.depth.type() == CV_16U && !(rgbd.depth_scale > 0)) {
      return Status::InvalidArgument(where + ": depth scale must be positive");
    }
    const cv::Mat depth = RegisteredDepthMetres(rgbd);
    cv::Mat region;
    if (!rgbd.mask.empty()) {
      region = rgbd.mask != 0;
    } else {
      region = cv::Mat(posed.image.size(), CV_8U, cv::Scalar(box ? 0 : 255));
      if (box &&
          !FillProjectedHull(BoxCorners(*box), posed.camera, posed.camera_from_object, &region)) {
        region.setTo(255);  // the camera is inside the box's extent: the box test alone decides
      }
    }
    RECOG_RETURN_IF_ERROR(ExtractInRegion(posed.image, region, &features));
    descriptor_bytes = features.descriptors.cols;
    const RigidTransform object_from_camera = posed.camera_from_object.Inverse();
    const size_t points_before = points.size();
    for (size_t i = 0; i < features.size(); ++i) {
      const cv::Point2f& p = features.keypoints[i].pt;
      const int u = std::clamp(int(std::lround(p.x)), 0, depth.cols - 1);
      const int v = std::clamp(int(std::lround(p.y)), 0, depth.rows - 1);
      const double z = depth.at<float>(v, u);
      if (!(z > 0) || !std::isfinite(z)) continue;
      if (AtDepthDiscontinuity(depth, u, v, options_.discontinuity_radius,
                               options_.discontinuity_ratio, z)) {
        continue;
      }
      const cv::Vec3d c = z * PixelRay(posed.camera, p);
      const cv::Point3d x = object_from_camera.Apply({c[0], c[1], c[2]});
      if (box) {
        bool inside = true;
        for (int k = 0; k < 3; ++k) {
          inside = inside &&
                   std::abs((&x.x)[k] - box->centre[k]) <= box->size[k] / 2 + options_.box_margin;
        }
        if (!inside) continue;
      }
      points.emplace_back(x);
      view_of_point.push_back(uint32_t(view_index));
      const uint8_t* d = features.descriptors.ptr(int(i));
      descriptors.insert(descriptors.end(), d, d + descriptor_bytes);
    }
    if (points.size() == points_before) {
      return Status::InvalidArgument(
          where +
          " gives no object point (empty mask or box region, no depth on the object, or "
          "a wrong pose?)");
    }
    model.views.push_back({posed.name, posed.camera, posed.camera_from_object,
                           options_.keep_images ? EncodePng(posed.image) : std::vector<uint8_t>{}});
  }
  Accumulator accumulator;
  cv::Vec3d low(1e300, 1e300, 1e300), high(-1e300, -1e300, -1e300);
  for (size_t i : RobustInliers(points, options_.outlier_mads, options_.merge_radius)) {
    for (int k = 0; k < 3; ++k) {
      low[k] = std::min(low[k], double((&points[i].x)[k]));
      high[k] = std::max(high[k], double((&points[i].x)[k]));
    }
    accumulator.AddFeature(
        accumulator.AddMergedPoint(points[i], view_of_point[i], options_.merge_radius),
        &descriptors[i * size_t(descriptor_bytes)], size_t(descriptor_bytes));
  }
  if (accumulator.num_points() == 0) {
    return Status::InvalidArgument("RGB-D model '" + name + "' has no point");
  }
  model.metadata.dimensions = high - low;
  model = std::move(accumulator).Finish(*vocabulary_, std::move(model));
  RECOG_RETURN_IF_ERROR(model.Validate());
  return model;
}

StatusOr<ObjectModel> ModelBuilder::FromRoboEarth(const std::string& dir) {
  RECOG_ASSIGN_OR_RETURN(RoboEarthFolder folder, ReadRoboEarthFolder(dir));
  ObjectModel model;
  // Several RoboEarth folders share a meta name (bottle1_big, bottle1_medium and bottle1_small
  // are all "bottle1"), and names are unique in a database: the folder names the model, and the
  // meta name becomes its class.
  model.metadata.name = std::filesystem::path(dir).filename().string();
  if (model.metadata.name.empty()) {
    model.metadata.name = std::filesystem::path(dir).parent_path().filename().string();
  }
  model.metadata.object_class = folder.meta.name;
  model.metadata.type = folder.meta.type;
  model.metadata.source = "roboearth:" + std::filesystem::path(dir).filename().string();
  model.metadata.units = folder.meta.type == ObjectType::kPlanar ? "m" : "sfm";
  model.metadata.dimensions = {folder.meta.width, folder.meta.height, folder.meta.depth};
  RECOG_RETURN_IF_ERROR(ValidateName("object", model.metadata.name));

  // 3D models: one cloud for every view (the dense one, else the union of the views' clouds).
  PointCloud cloud;
  if (folder.meta.type == ObjectType::k3D) {
    if (!folder.dense_cloud_path.empty()) {
      RECOG_ASSIGN_OR_RETURN(cloud, ReadPly(folder.dense_cloud_path));
    } else {
      for (const RoboEarthView& view : folder.views) {
        if (view.points_path.empty()) continue;
        RECOG_ASSIGN_OR_RETURN(PointCloud part, ReadPly(view.points_path));
        if (part.normals.empty() != cloud.normals.empty() && !cloud.points.empty()) {
          part.normals.clear();
          cloud.normals.clear();
        }
        cloud.points.insert(cloud.points.end(), part.points.begin(), part.points.end());
        cloud.normals.insert(cloud.normals.end(), part.normals.begin(), part.normals.end());
      }
    }
    if (cloud.points.empty()) {
      return Status::InvalidArgument("RoboEarth model '" + dir + "' has no 3D points");
    }
  }

  Accumulator accumulator;
  std::vector<int64_t> point_of_cloud(cloud.points.size(), -1);
  FeatureSet features;
  for (const RoboEarthView& view : folder.views) {
    if (std::find(options_.exclude_views.begin(), options_.exclude_views.end(), view.index) !=
        options_.exclude_views.end()) {
      continue;
    }
    RECOG_ASSIGN_OR_RETURN(cv::Mat image, ReadGrayImage(view.image_path));
    // Some planar faces are stored as small crops (a 51 x 125 bottle label): enlarge them so that
    // ORB, which needs a 31-pixel border, finds features at all.
    const double enlarge = std::max(1.0, kMinTrainingImageSide / std::min(image.cols, image.rows));
    if (enlarge > 1.0) cv::resize(image, image, cv::Size(), enlarge, enlarge, cv::INTER_CUBIC);
    CameraIntrinsics camera;
    camera.fx = camera.fy = view.camera.focal * enlarge;
    camera.cx = image.cols / 2.0;
    camera.cy = image.rows / 2.0;
    RECOG_RETURN_IF_ERROR(camera.Validate());
    const RigidTransform& pose = view.camera.camera_from_object;
    RECOG_RETURN_IF_ERROR(Extract(image, &features));

    if (folder.meta.type == ObjectType::k3D) {
      const VisiblePoints visible(cloud.points, cloud.normals, camera, pose, image.size(),
                                  std::max(1.0, options_.association_px));
      for (size_t i = 0; i < features.size(); ++i) {
        const int64_t p = visible.Nearest(features.keypoints[i].pt, options_.association_px);
        if (p < 0) continue;
        if (point_of_cloud[size_t(p)] < 0) {
          point_of_cloud[size_t(p)] = accumulator.AddPoint(cloud.points[size_t(p)]);
        }
        accumulator.AddFeature(uint32_t(point_of_cloud[size_t(p)]),
                               features.descriptors.ptr(int(i)), features.descriptors.cols);
      }
    } else {
      // A planar view is a fronto-parallel photo of one face: the face lies at the depth of the
      // view's points, within their bounding box.
      if (view.points_path.empty()) continue;
      RECOG_ASSIGN_OR_RETURN(PointCloud points, ReadPly(view.points_path));
      double depth = 0;
      cv::Point2d low(1e300, 1e300), high(-1e300, -1e300);
      size_t in_front = 0;
      for (const cv::Point3f& x : points.points) {
        cv::Point2d uv;
        if (!ProjectPoint(camera, pose, cv::Point3d(x), &uv)) continue;
        depth += pose.Apply(cv::Point3d(x)).z;
        low = {std::min(low.x, uv.x), std::min(low.y, uv.y)};
        high = {std::max(high.x, uv.x), std::max(high.y, uv.y)};
        ++in_front;
      }
      const cv::Rect2d box(low, high);
      if (in_front < 3 || box.width <= 0 || box.height <= 0) continue;
      depth /= double(in_front);
      PlanarFace face;
      face.width = box.width * depth / camera.fx;
      face.height = box.height * depth / camera.fy;
      RigidTransform camera_from_face;
      camera_from_face.t = depth * PixelRay(camera, cv::Point2f(box.tl()));
      face.object_from_face = pose.Inverse() * camera_from_face;
      const int face_index = int(model.faces.size());
      model.faces.push_back(face);
      for (size_t i = 0; i < features.size(); ++i) {
        const cv::Point2f& p = features.keypoints[i].pt;
        if (!box.contains(cv::Point2d(p))) continue;
        const cv::Vec3d c = depth * PixelRay(camera, p);
        const cv::Point3d x = pose.Inverse().Apply({c[0], c[1], c[2]});
        accumulator.AddFeature(accumulator.AddPoint(cv::Point3f(x), face_index),
                               features.descriptors.ptr(int(i)), features.descriptors.cols);
      }
    }
    char name[16];
    std::snprintf(name, sizeof(name), "face_%03d", view.index);
    model.views.push_back(
        {name, camera, pose, options_.keep_images ? EncodePng(image) : std::vector<uint8_t>{}});
  }
  if (accumulator.num_points() == 0) {
    return Status::InvalidArgument("RoboEarth model '" + dir + "' gave no feature with a 3D point");
  }
  model = std::move(accumulator).Finish(*vocabulary_, std::move(model));
  if (model.metadata.type == ObjectType::k3D) {
    cv::Vec3d low(1e300, 1e300, 1e300), high(-1e300, -1e300, -1e300);
    for (const cv::Point3f& p : model.points) {
      low = {std::min(low[0], double(p.x)), std::min(low[1], double(p.y)),
             std::min(low[2], double(p.z))};
      high = {std::max(high[0], double(p.x)), std::max(high[1], double(p.y)),
              std::max(high[2], double(p.z))};
    }
    model.metadata.dimensions = high - low;
  }
  RECOG_RETURN_IF_ERROR(model.Validate());
  return model;
}

StatusOr<std::vector<RgbdView>> ReadRgbdViews(const std::string& list_path) {
  std::ifstream in(list_path);
  if (!in) return Status::NotFound("cannot open RGB-D view list '" + list_path + "'");
  const std::filesystem::path base = std::filesystem::path(list_path).parent_path();
  std::vector<RgbdView> views;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    const std::string where = list_path + ":" + std::to_string(number);
    std::string rgb, depth, mask;
    RgbdView view;
    CameraIntrinsics& camera = view.view.camera;
    cv::Matx33d& R = view.view.camera_from_object.R;
    cv::Vec3d& t = view.view.camera_from_object.t;
    fields >> rgb >> depth >> camera.fx >> camera.fy >> camera.cx >> camera.cy >> view.depth_scale;
    for (int k = 0; k < 9; ++k) fields >> R.val[k];
    for (int k = 0; k < 3; ++k) fields >> t[k];
    if (!fields) return Status::InvalidArgument(where + ": expected 19 fields");
    fields >> mask;
    RECOG_RETURN_IF_ERROR(camera.Validate());
    if (cv::norm(R.t() * R - cv::Matx33d::eye()) > 1e-3 || cv::determinant(R) <= 0) {
      return Status::InvalidArgument(where + ": the rotation is not a rotation matrix");
    }
    view.view.name = std::filesystem::path(rgb).stem().string();
    RECOG_ASSIGN_OR_RETURN(view.view.image, ReadGrayImage((base / rgb).string()));
    view.depth = cv::imread((base / depth).string(), cv::IMREAD_ANYDEPTH);
    if (view.depth.empty()) return Status::InvalidArgument(where + ": cannot read depth " + depth);
    if (!mask.empty()) {
      view.mask = cv::imread((base / mask).string(), cv::IMREAD_GRAYSCALE);
      if (view.mask.empty()) return Status::InvalidArgument(where + ": cannot read mask " + mask);
    }
    views.push_back(std::move(view));
  }
  if (views.empty()) return Status::InvalidArgument(list_path + " lists no view");
  return views;
}

}  // namespace recog
