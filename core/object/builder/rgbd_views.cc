#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>
#include "core/object/builder/model_builder.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/names.h"
#include "core/geometry/depth_registration.h"

#include "core/object/builder/builder_internal.h"

namespace recog {

using builder_internal::EncodePng;
using builder_internal::FillProjectedHull;
using builder_internal::PixelRay;

namespace {

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

}  // namespace

StatusOr<ObjectModel> ModelBuilder::FromRgbd(const std::string& name,
                                             const std::vector<RgbdView>& views,
                                             const std::optional<ObjectBox>& box,
                                             std::vector<RgbdViewReport>* report) {
  if (report) report->clear();
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
    RgbdViewReport view_report{posed.name, features.size()};
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
      ++view_report.with_depth;
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
      ++view_report.in_box;
      points.emplace_back(x);
      view_of_point.push_back(uint32_t(view_index));
      const uint8_t* d = features.descriptors.ptr(int(i));
      descriptors.insert(descriptors.end(), d, d + descriptor_bytes);
    }
    if (report) report->push_back(view_report);
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
