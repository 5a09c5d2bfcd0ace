#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>
#include "core/object/builder/model_builder.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/names.h"
#include "core/object/formats/roboearth.h"

#include "core/object/builder/builder_internal.h"

namespace recog {

using builder_internal::EncodePng;
using builder_internal::kNoDepth;
using builder_internal::PixelRay;

namespace {

constexpr double kMinTrainingImageSide = 240.0;  // pixels

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

}  // namespace recog
