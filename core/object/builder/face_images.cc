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

}  // namespace recog
