// ObjectModel: what the system knows about one object it can recognise (thesis §5.4.2, eq. 5.3).
//
// A model is a set of 3D points in the object's own frame, each described by one or more binary
// descriptors seen from different views and scales (at most one per point and visual word: the
// median of the descriptors that fell in that word). Recognition matches image features against
// these descriptors and solves the pose from the 2D-3D pairs.
//
// Besides the points a model carries its metadata (name, class, planar or 3D, size, units, where
// it came from, version), for planar objects the faces (rectangles placed in the object frame by
// oTf, used for the homography check and the outline), and optionally the training views it was
// built from (camera, pose and the encoded image), so that a model file is self-contained and can
// be exported back to a RoboEarth folder.
//
// Frames and units: X_camera = R * X_object + t (OpenCV axes: x right, y down, z forward).
// Coordinates are in the model's `units` (metres for everything this project builds; RoboEarth
// 3D models come from structure from motion with an arbitrary scale, recorded as units "sfm").
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/descriptor.h"
#include "core/common/status.h"
#include "core/geometry/camera_model.h"

namespace recog {

enum class ObjectType : uint8_t { kPlanar = 0, k3D = 1 };
std::string_view ObjectTypeName(ObjectType type);  // "planar", "3D"
StatusOr<ObjectType> ParseObjectType(std::string_view name);

// A rigid transform T_a<-b: X_a = R * X_b + t.
struct RigidTransform {
  cv::Matx33d R = cv::Matx33d::eye();
  cv::Vec3d t = {0, 0, 0};
  cv::Point3d Apply(const cv::Point3d& x) const;
  RigidTransform Inverse() const;
  RigidTransform operator*(const RigidTransform& other) const;  // composition
  cv::Matx44d Matrix() const;
  static RigidTransform FromMatrix(const cv::Matx44d& m);
};

// Projects an object-frame point with a camera pose T_camera<-object; false when behind the camera.
bool ProjectPoint(const CameraIntrinsics& camera, const RigidTransform& camera_from_object,
                  const cv::Point3d& x, cv::Point2d* pixel);

struct ObjectMetadata {
  std::string name;          // unique in a database: 1..128 of [A-Za-z0-9._-]
  std::string object_class;  // free text ("box", "toy", ...), may be empty
  ObjectType type = ObjectType::k3D;
  cv::Vec3d dimensions = {0, 0, 0};  // width, height, depth in `units` (0 = unknown)
  std::string units = "m";
  std::string source;    // how it was built ("roboearth:/path", "planar:poster.png", ...)
  uint32_t version = 1;  // bumped by the database when a model is replaced
  friend bool operator==(const ObjectMetadata&, const ObjectMetadata&) = default;
};

// A planar face: a width x height rectangle. In face coordinates the face spans x in [0, width]
// and y in [0, height] (x right, y down as in its image, z = 0, normal -z towards the viewer);
// object_from_face places it in the object frame (RoboEarth's oTf).
struct PlanarFace {
  double width = 0, height = 0;
  RigidTransform object_from_face;
};

// One image the model was built from.
struct TrainingView {
  std::string name;         // "face_003"
  CameraIntrinsics camera;  // of this image
  RigidTransform camera_from_object;
  std::vector<uint8_t> image_png;  // the encoded image (may be empty when not kept)
};

struct ObjectModel {
  ObjectMetadata metadata;
  DescriptorFormat descriptor = DescriptorFormat::Orb();
  std::vector<cv::Point3f> points;  // 3D points in the object frame
  // Features: one descriptor row each, describing point point_of_feature[i].
  cv::Mat descriptors;  // CV_8U, one row per feature
  std::vector<uint32_t> point_of_feature;
  // Planar objects: the face each point lies on (index into faces); empty for 3D objects.
  std::vector<PlanarFace> faces;
  std::vector<uint32_t> face_of_point;
  std::vector<TrainingView> views;

  size_t num_features() const { return point_of_feature.size(); }
  // OK when sizes agree, indices are in range, points are finite and the metadata is valid.
  Status Validate() const;
};

}  // namespace recog
