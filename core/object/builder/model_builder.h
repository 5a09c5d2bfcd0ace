// Building object models from images (thesis §5.2.2, §5.4.2).
//
// Every builder extracts ORB features from each training image over about two octaves (the
// default pyramid: 8 levels at 1.2), gives each keypoint the 3D point it sees, drops keypoints
// without one, and then merges descriptors: per 3D point and visual word only one descriptor is
// kept, the bitwise median (majority) of those that fell into that word (eq. 5.3).
//
// Where the 3D points come from:
//  - RoboEarth `re_vision` folders (roboearth.h), named after the folder (the meta name, which
//    several folders share, becomes the class). 3D models: the dense PMVS cloud
//    (drawing_model.ply, else the union of the per-view clouds) is projected into each view; a
//    point is visible when its normal faces the camera and it is the nearest in its pixel
//    neighbourhood (a coarse z-buffer); a keypoint takes the visible point projecting nearest to
//    it within `association_px` (3 px). Planar models: every view is a fronto-parallel photo of a
//    face at the depth of that view's points; keypoints inside the face rectangle (the bounding
//    box of the view's points) are back-projected onto it, one face per view.
//  - Planar faces from images and physical sizes (a poster: one image, W x H; a cuboid: up to six
//    face images of a W x H x D box, eq. 5.1; the object frame is centred on the box).
//  - Views with known poses and polygonal faces (e.g. a CAD model and one registered frame):
//    keypoints are intersected with the nearest face polygon facing the camera.
//  - RGB-D views with intrinsics and poses: keypoints with a valid depth are back-projected.
//    Depth is registered to the colour image, or comes from its own camera (intrinsics and
//    depth_from_color) and is registered first (core/geometry/depth_registration.h). The object
//    is given by a mask per view, or once by its 3D box (ObjectBox), which is projected into
//    every view; back-projected points must then lie in the box (+ box_margin).
//
// Posed polygons and RGB-D views detect features inside the object's region only (the projected
// faces, the mask or the projected box): each view is cropped to the region's bounding box (+ a
// margin), the crop is enlarged so that its longest side reaches `working_size` (at most
// `max_enlarge` times), ORB runs on it with a region_grid x region_grid grid so that the features
// spread over the object, and only keypoints inside the region are kept (their pixels mapped back
// to the full view, whose camera and distortion are used). RGB-D keypoints at depth
// discontinuities (depth range in a small neighbourhood above discontinuity_ratio x depth) are
// dropped, then points beyond outlier_mads robust deviations from the median on any axis; the
// model's `dimensions` are the extent of the points kept. Points of different views closer than
// merge_radius are one model point (thesis §5.2.2: its descriptors are then merged per visual
// word, eq. 5.3). A view that yields no point is refused (INVALID_ARGUMENT naming the view), and so
// is a model without points.
//
// All builders are deterministic. Each source has its own file beside model_builder.cc (which
// holds the feature extraction and the merging they share): face_images.cc, posed_polygons.cc,
// rgbd_views.cc and roboearth_views.cc.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "core/features/feature_extractor.h"
#include "core/object/model/object_model.h"
#include "core/vocabulary/vocabulary.h"

namespace recog {

struct ModelBuildOptions {
  OrbOptions orb = DefaultModelOrb();
  double association_px = 3.0;  // thesis §5.2.2
  bool keep_images = true;      // store the training images (PNG) in the model
  // RoboEarth: view indices (k of face_k) to leave out, e.g. for leave-one-view-out tests.
  std::vector<int> exclude_views;
  // Detection in the object's region (posed polygons, RGB-D): crop margin (fraction of the
  // region's box on each side, at least 8 px), target longest side of the enlarged crop
  // (pixels; a crop already this large is not shrunk), largest enlargement, ORB grid cells a side.
  double crop_margin = 0.1;
  int working_size = 640;
  double max_enlarge = 4.0;
  int region_grid = 4;
  // RGB-D: a keypoint whose depth range within discontinuity_radius pixels exceeds
  // discontinuity_ratio x its depth lies on an edge (often background) and is dropped.
  int discontinuity_radius = 2;
  double discontinuity_ratio = 0.03;
  // RGB-D: points farther than outlier_mads x 1.4826 x MAD from the median on an axis (and than
  // a tenth of the widest axis's bound, and than merge_radius) are dropped; 0 = keep all.
  double outlier_mads = 5.0;
  // Points of different views closer than this (metres, object frame) are one model point.
  double merge_radius = 0.003;
  // RGB-D with an ObjectBox: points may lie this far outside the box (metres).
  double box_margin = 0.003;

  static OrbOptions DefaultModelOrb() {
    OrbOptions orb;
    orb.max_features = 2000;
    orb.levels = 8;  // 1.2^7 = 3.6: about two octaves
    return orb;
  }
};

// Which side of a W x H x D box a face image shows (viewed from outside, upright).
enum class BoxSide { kFront, kBack, kLeft, kRight, kTop, kBottom };
StatusOr<BoxSide> ParseBoxSide(std::string_view name);  // "front", "back", ...

// The face of a W x H x D box that `side` shows (width, height and object_from_face): the object
// frame is at the box centre, x right, y down, z away from the viewer of the front; the front
// face lies at z = -D/2. FromFaceImages places its faces so.
PlanarFace BoxFace(BoxSide side, double width, double height, double depth);

struct FaceImage {
  BoxSide side = BoxSide::kFront;
  cv::Mat image;  // 8-bit grey or BGR, showing the whole face and nothing else
};

// A polygonal face of a 3D model in the object frame (corners in order around the face).
struct FacePolygon {
  std::vector<cv::Point3d> corners;  // at least 3, coplanar
};

// A registered training image: the object frame as seen by this camera.
struct PosedImage {
  std::string name;
  cv::Mat image;
  CameraIntrinsics camera;
  RigidTransform camera_from_object;
};

struct RgbdView {
  PosedImage view;
  cv::Mat depth;  // CV_16U (units of 1 / depth_scale metres) or CV_32F (metres); 0 = none
  double depth_scale = 1000.0;
  cv::Mat mask;  // optional CV_8U of the image's size, non-zero on the object
  // Depth from its own camera: when depth_camera.fx > 0, `depth` is that camera's image (any
  // size) and depth_from_color places it (X_depth = R * X_colour + t, metres). Otherwise depth is
  // registered to the colour image already (and has its size).
  CameraIntrinsics depth_camera;
  RigidTransform depth_from_color;
};

// The object's 3D box in the object frame: it spans centre +- size / 2 along the object's axes
// (a box centred on the object frame by default).
struct ObjectBox {
  cv::Vec3d size = {0, 0, 0};  // width (x), height (y), depth (z), metres, all > 0
  cv::Vec3d centre = {0, 0, 0};
};

// What FromRgbd made of one view, for a caller checking its inputs. With a box, a view's features
// that have a depth land in the box when its pose is right; when the pose is off, the region
// (the projected box) and the depth miss each other and many land outside: on visp-rbt-cube the
// frames whose given pose is off by a centimetre or more have clearly fewer inside, which `recog
// model build` warns of (the shares and their command are in docs/objects.md, "visp-rbt-cube: a
// small object in real clutter").
struct RgbdViewReport {
  std::string name;
  size_t features = 0;    // extracted in the view's region
  size_t with_depth = 0;  // of them with a usable depth (valid, not at a depth discontinuity)
  size_t in_box = 0;      // of those, inside the box (all of them without a box)

  // Fewer than kMinInBoxShare of at least kMinWithDepth features with a depth are in the box.
  static constexpr double kMinInBoxShare = 0.7;
  static constexpr size_t kMinWithDepth = 20;
  bool LooksMisposed() const {
    return with_depth >= kMinWithDepth && double(in_box) < kMinInBoxShare * double(with_depth);
  }
};

class ModelBuilder {
 public:
  // The vocabulary is the object vocabulary the model's descriptors are merged with.
  ModelBuilder(std::shared_ptr<const Vocabulary> vocabulary, ModelBuildOptions options = {});

  StatusOr<ObjectModel> FromRoboEarth(const std::string& dir);
  // One face image: a planar poster of width x height; several (up to 6, distinct sides): a box
  // of width x height x depth. Sizes in metres.
  StatusOr<ObjectModel> FromFaceImages(const std::string& name, const std::vector<FaceImage>& faces,
                                       double width, double height, double depth = 0);
  StatusOr<ObjectModel> FromPosedPolygons(const std::string& name,
                                          const std::vector<FacePolygon>& polygons,
                                          const std::vector<PosedImage>& views);
  // With `box`, views without a mask take the projected box as their region, and points outside
  // the box are dropped. With `report`, also what became of each view's features (one entry per
  // view, in order; filled as far as the build went when it fails).
  StatusOr<ObjectModel> FromRgbd(const std::string& name, const std::vector<RgbdView>& views,
                                 const std::optional<ObjectBox>& box = std::nullopt,
                                 std::vector<RgbdViewReport>* report = nullptr);

  const std::shared_ptr<const Vocabulary>& vocabulary() const { return vocabulary_; }

 private:
  class Accumulator;
  Status Extract(const cv::Mat& image, FeatureSet* features);
  // Features inside `region` (CV_8U of the image's size, non-zero inside), detected on the
  // enlarged crop; keypoint positions are pixels of `image`.
  Status ExtractInRegion(const cv::Mat& image, const cv::Mat& region, FeatureSet* features);

  std::shared_ptr<const Vocabulary> vocabulary_;
  ModelBuildOptions options_;
  std::unique_ptr<FeatureExtractor> extractor_;
  // The extractor of the last region: pyramid levels and feature budget.
  std::unique_ptr<FeatureExtractor> region_extractor_;
  int region_levels_ = 0, region_budget_ = 0;
};

// Reads an RGB-D view list: a text file whose lines (besides # comments) are
//   rgb depth fx fy cx cy depth_scale r11 r12 r13 r21 r22 r23 r31 r32 r33 t1 t2 t3 [mask]
// with paths relative to the file and the pose T_camera<-object.
StatusOr<std::vector<RgbdView>> ReadRgbdViews(const std::string& list_path);

}  // namespace recog
