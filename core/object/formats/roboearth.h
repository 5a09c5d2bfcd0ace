// Reading and writing RoboEarth `re_vision` object model folders.
//
// A folder holds, per training view k (three-digit index): face_k.png (the photo), face_k.txt (the
// camera in Bundler "bundle.out" form, OpenCV axes: a comment line, "1 0", "f k1 k2", three rows
// of R, then t; the principal point is the image centre), face_k.ply (the sparse points seen in
// that view) and face_k.key.gz (old SURF keys, ignored); drawing_model.ply (the dense PMVS cloud
// of the whole object, ASCII PLY with x y z [nx ny nz] [colour]); and meta.xml:
//
//   <model><name>lion</name><type>3D</type><faces>20</faces>
//     <dimensions><scale>1</scale> ... or, for planar models, <width> <height> <depth> and per
//     face <face><index>0</index><width>..</width><height>..</height>
//     <oTf>16 numbers, row-major</oTf></face></dimensions></model>
//
// Readers validate everything they read and return INVALID_ARGUMENT / DATA_LOSS naming the file
// and line for malformed input, NOT_FOUND for a missing folder or file.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "core/object/formats/ply_file.h"  // the point clouds of a folder
#include "core/object/model/object_model.h"

namespace recog {

// A Bundler camera as RoboEarth stores it.
struct BundleCamera {
  double focal = 0, k1 = 0, k2 = 0;
  RigidTransform camera_from_object;
};
StatusOr<BundleCamera> ReadBundleCamera(const std::string& path);
Status WriteBundleCamera(const std::string& path, const BundleCamera& camera);

struct RoboEarthFace {  // planar models only
  int index = 0;
  double width = 0, height = 0;
  RigidTransform object_from_face;  // oTf
};

struct RoboEarthMeta {
  std::string name;
  ObjectType type = ObjectType::k3D;
  int num_faces = 0;
  double scale = 1;                         // 3D models
  double width = 0, height = 0, depth = 0;  // planar models: overall size
  std::vector<RoboEarthFace> faces;         // planar models, by index
};
StatusOr<RoboEarthMeta> ReadRoboEarthMeta(const std::string& path);
Status WriteRoboEarthMeta(const std::string& path, const RoboEarthMeta& meta);

struct RoboEarthView {
  int index = 0;
  std::string image_path;  // face_k.png
  BundleCamera camera;
  std::string points_path;  // face_k.ply ("" when absent)
};

struct RoboEarthFolder {
  std::string path;
  RoboEarthMeta meta;
  std::vector<RoboEarthView> views;  // by increasing index
  std::string dense_cloud_path;      // drawing_model.ply ("" when absent)
};
// Lists a model folder: meta.xml plus every face_k.png that has its face_k.txt.
StatusOr<RoboEarthFolder> ReadRoboEarthFolder(const std::string& dir);

// Writes `model` as a RoboEarth folder that ModelBuilder::FromRoboEarth reads back: meta.xml
// (planar models: their size and one <face> per PlanarFace; 3D models: scale 1 and one face per
// view, as the real folders count them), drawing_model.ply (the model points, without normals)
// and, per training view k in order (face_000, face_001, ...), the image, its camera and the model
// points that project into it in front of the camera; for planar models only those of the face the
// view looks at most directly, since the reader takes a planar view's points as its face.
// Everything is checked before anything is written:
//  - FAILED_PRECONDITION when the model has no point, no view, or a view without its image;
//  - INVALID_ARGUMENT naming the view when its camera is one the format cannot express (one focal
//    length, the principal point at the image centre, no distortion): fx != fy or a principal
//    point off the centre by more than half a pixel anywhere in the image, or any distortion;
//    also for a model that fails Validate() or whose metadata meta.xml cannot hold;
//  - DATA_LOSS when a view's image cannot be decoded;
//  - ALREADY_EXISTS when `dir` exists and is not an empty folder.
// `dir` is created when missing. An I/O error part way leaves the files written so far.
Status ExportRoboEarthFolder(const ObjectModel& model, const std::string& dir);

}  // namespace recog
