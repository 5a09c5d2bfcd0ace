#include <algorithm>
#include <cmath>
#include <string>
#include <vector>
#include "core/object/builder/model_builder.h"

#include <opencv2/imgproc.hpp>

#include "core/common/names.h"

#include "core/object/builder/builder_internal.h"

namespace recog {

using builder_internal::EncodePng;
using builder_internal::FillProjectedHull;
using builder_internal::kNoDepth;
using builder_internal::PixelRay;

namespace {

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

}  // namespace

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

}  // namespace recog
