#include "core/object/model/object_model.h"

#include "core/common/names.h"
#include "core/common/text.h"

#include <cmath>

namespace recog {
namespace {

bool FinitePoint(const cv::Point3f& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

}  // namespace

std::string_view ObjectTypeName(ObjectType type) {
  return type == ObjectType::kPlanar ? "planar" : "3D";
}

StatusOr<ObjectType> ParseObjectType(std::string_view name) {
  if (name == "planar") return ObjectType::kPlanar;
  if (name == "3D" || name == "3d") return ObjectType::k3D;
  return Status::InvalidArgument("unknown object type '" + std::string(name) +
                                 "' (expected planar or 3D)");
}

cv::Point3d RigidTransform::Apply(const cv::Point3d& x) const {
  const cv::Vec3d y = R * cv::Vec3d(x.x, x.y, x.z) + t;
  return {y[0], y[1], y[2]};
}

RigidTransform RigidTransform::Inverse() const {
  RigidTransform inverse;
  inverse.R = R.t();
  inverse.t = -(inverse.R * t);
  return inverse;
}

RigidTransform RigidTransform::operator*(const RigidTransform& other) const {
  RigidTransform out;
  out.R = R * other.R;
  out.t = R * other.t + t;
  return out;
}

cv::Matx44d RigidTransform::Matrix() const {
  return {R(0, 0), R(0, 1), R(0, 2), t[0], R(1, 0), R(1, 1), R(1, 2), t[1],
          R(2, 0), R(2, 1), R(2, 2), t[2], 0,       0,       0,       1};
}

RigidTransform RigidTransform::FromMatrix(const cv::Matx44d& m) {
  RigidTransform out;
  out.R = m.get_minor<3, 3>(0, 0);
  out.t = {m(0, 3), m(1, 3), m(2, 3)};
  return out;
}

bool ProjectPoint(const CameraIntrinsics& camera, const RigidTransform& camera_from_object,
                  const cv::Point3d& x, cv::Point2d* pixel) {
  const cv::Point3d c = camera_from_object.Apply(x);
  if (c.z <= 1e-9) return false;
  *pixel = {camera.fx * c.x / c.z + camera.cx, camera.fy * c.y / c.z + camera.cy};
  return true;
}

Status ObjectModel::Validate() const {
  RECOG_RETURN_IF_ERROR(ValidateName("object", metadata.name));
  const std::string where = "object model '" + metadata.name + "': ";
  // Its text goes into API answers and JSON, which must be UTF-8.
  const auto text = [&](const std::string& value, const std::string& field) {
    return IsValidUtf8(value) ? Status::Ok()
                              : Status::InvalidArgument(where + field + " is not UTF-8 text");
  };
  RECOG_RETURN_IF_ERROR(text(metadata.object_class, "the class"));
  RECOG_RETURN_IF_ERROR(text(metadata.units, "the units"));
  RECOG_RETURN_IF_ERROR(text(metadata.source, "the source"));
  for (const TrainingView& view : views) {
    RECOG_RETURN_IF_ERROR(text(view.name, "a view's name"));
  }
  if (descriptor.type != DescriptorType::kBinary) {
    return Status::InvalidArgument(where + "only binary descriptors are supported");
  }
  const size_t n = point_of_feature.size();
  if (n > 0 && (descriptors.type() != CV_8U || size_t(descriptors.rows) != n ||
                size_t(descriptors.cols) != descriptor.size_bytes)) {
    return Status::InvalidArgument(where + "descriptors must be " + std::to_string(n) + " x " +
                                   std::to_string(descriptor.size_bytes) + " CV_8U");
  }
  if (n == 0 && !descriptors.empty()) {
    return Status::InvalidArgument(where + "descriptors without points");
  }
  for (uint32_t p : point_of_feature) {
    if (p >= points.size()) return Status::InvalidArgument(where + "feature of a missing point");
  }
  for (const cv::Point3f& p : points) {
    if (!FinitePoint(p)) return Status::InvalidArgument(where + "a point is not finite");
  }
  if (metadata.type == ObjectType::kPlanar) {
    if (faces.empty()) return Status::InvalidArgument(where + "a planar model needs faces");
    if (face_of_point.size() != points.size()) {
      return Status::InvalidArgument(where + "every point of a planar model needs a face");
    }
    for (uint32_t f : face_of_point) {
      if (f >= faces.size()) return Status::InvalidArgument(where + "point of a missing face");
    }
    for (const PlanarFace& face : faces) {
      if (!(face.width > 0) || !(face.height > 0)) {
        return Status::InvalidArgument(where + "faces need a positive width and height");
      }
    }
  } else if (!face_of_point.empty()) {
    return Status::InvalidArgument(where + "a 3D model has no faces");
  }
  for (const TrainingView& view : views) {
    RECOG_RETURN_IF_ERROR(view.camera.Validate());
  }
  return Status::Ok();
}

}  // namespace recog
