// ObjectSequenceGenerator: synthetic RGB-D sequences of one object with exact ground truth, for
// measuring object recall against apparent size (`recog seqgen objects`, `recog eval sequence
// --truth`).
//
// The object is a planar poster (W x H, one face: front) or a box (W x H x D, faces front, left,
// right and top) whose faces are photos, cropped centrally to the face's aspect ratio. Object frame
// and faces as ModelBuilder::FromFaceImages places them (BoxFace): origin at the box centre, x
// right, y down, z away from the viewer of the front; face image pixel (u, v) is face point
// (u * width / cols, v * height / rows). So `recog model build --planar/--face` with the written
// face images and sizes gives a model whose frame is the ground truth's.
//
// The scene: the object stands in front of a wall, the plane z = D/2 + 1 m of the object frame,
// tiled with 3 x 3 background photos (other photos than the object's; mirrored beyond the tiles).
// A pinhole camera without distortion (fx = fy = focal, cx = (width - 1) / 2, cy = (height - 1) /
// 2, pixel centres at integer coordinates) looks at the object from the front half-space.
//
// The sequence: frame i of N has s = i / (N - 1). The camera moves smoothly: azimuth, elevation
// and roll follow slow sines (seeded phases), the object's centre drifts across the image, and
// twice (seeded times) it drifts past the left or right edge so that the object is partly or
// wholly out of view. The distance is chosen per frame so that the whole projected silhouette
// covers a target fraction of the frame that falls geometrically from max_fraction (s = 0) to
// min_fraction (s = 1). Then blur, illumination (smooth gain, gradient) and noise (seeded per
// frame) as the place generator applies them.
//
// Training views: a separate short walk of `training_views` frames around the object (azimuth
// evenly spread, the object centred at about 15 % of the frame, a different wall), with depth and
// mask and without camera effects, listed in views.txt for `recog model build --rgbd`
// (ReadRgbdViews).
//
// Per frame: the colour image (8-bit BGR), a registered depth image (16-bit, millimetres; the
// object's exact depth rounded to the millimetre, the wall with Gaussian noise of depth_noise_mm,
// 0 in a few small seeded holes), the object's mask (255 on the object) and the truth
// (T_camera<-object, the fraction of the frame the object covers, the fraction of its silhouette
// inside the frame, visible = at least half of it inside).
//
// Determinism: everything follows from the seed (the photos chosen, the trajectory, every frame's
// effects); Frame(i) does not depend on call order.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "core/object/builder/model_builder.h"
#include "core/object/model/object_model.h"

namespace recog::cli {

enum class ObjectShape { kPoster, kBox };
std::string_view ObjectShapeName(ObjectShape shape);  // "poster", "box"
StatusOr<ObjectShape> ParseObjectShape(std::string_view name);

struct ObjectSequenceOptions {
  ObjectShape shape = ObjectShape::kPoster;
  std::string name;  // object name; empty: "synthetic-poster" or "synthetic-box"
  double width = 0.30, height = 0.21, depth = 0.10;  // metres; depth only for boxes
  int frames = 200;
  int training_views = 8;
  int image_width = 640, image_height = 480;
  double focal = 525;                               // fx = fy, pixels
  double max_fraction = 0.30, min_fraction = 0.01;  // of the frame, whole silhouette
  double blur_sigma_max = 1.0, noise_sigma = 3.0, illumination_max = 0.2;
  double depth_noise_mm = 2.0;  // on the wall
  int depth_holes = 4;          // zero-depth discs per frame
  uint64_t seed = 1;

  // INVALID_ARGUMENT naming the first value out of range.
  Status Validate() const;
  std::string ObjectName() const;
};

// Ground truth of one frame.
struct ObjectTruthFrame {
  std::string image;  // file name in images/
  RigidTransform camera_from_object;
  double area_fraction = 0;  // object pixels / frame pixels
  double in_view = 0;        // object pixels / pixels of the whole projected silhouette (<= 1)
  bool visible = false;      // in_view >= 0.5
};

struct ObjectSequenceTruth {
  std::string object;
  CameraIntrinsics camera;
  int width = 0, height = 0;
  std::vector<ObjectTruthFrame> frames;
};

// truth.txt: '#' comments, then the lines
//   object NAME
//   camera fx fy cx cy
//   image_size WIDTH HEIGHT
//   frame IMAGE VISIBLE(0/1) AREA_FRACTION IN_VIEW r11 r12 r13 r21 r22 r23 r31 r32 r33 t1 t2 t3
// (pose T_camera<-object, metres). Read: NOT_FOUND when missing, INVALID_ARGUMENT naming the line.
Status WriteObjectSequenceTruth(const ObjectSequenceTruth& truth, const std::string& path);
StatusOr<ObjectSequenceTruth> ReadObjectSequenceTruth(const std::string& path);

struct RenderedObjectFrame {
  cv::Mat image;  // CV_8UC3
  cv::Mat depth;  // CV_16U, millimetres, 0 = none
  cv::Mat mask;   // CV_8U, 255 on the object
  ObjectTruthFrame truth;
};

// A face of the object and the photo it shows.
struct ObjectFace {
  BoxSide side = BoxSide::kFront;
  std::string photo;
  cv::Mat image;  // the cropped photo (8-bit BGR), as written to faces/
};

class ObjectSequenceGenerator {
 public:
  // The object's faces come from `object_photos`, the walls from `background_photos` (seeded
  // choices). INVALID_ARGUMENT for bad options or too few photos (a box needs 4 object photos);
  // errors of reading the chosen photos as they are.
  static StatusOr<ObjectSequenceGenerator> Create(const std::vector<std::string>& object_photos,
                                                  const std::vector<std::string>& background_photos,
                                                  const ObjectSequenceOptions& options);

  const ObjectSequenceOptions& options() const { return options_; }
  int num_frames() const { return options_.frames; }
  const CameraIntrinsics& camera() const { return camera_; }
  const std::vector<ObjectFace>& faces() const { return faces_; }

  // Sequence frame i / training view k; INVALID_ARGUMENT when out of range.
  StatusOr<RenderedObjectFrame> Frame(int i) const;
  StatusOr<RenderedObjectFrame> TrainingView(int k) const;

 private:
  struct Scene;
  struct Shot {
    RigidTransform camera_from_object;
    int walk = 0;  // 0: the sequence, 1: the training walk
    uint64_t effects_seed = 0;
    double gain = 1, gradient_x = 0, gradient_y = 0;
    bool effects = true;
  };
  ObjectSequenceGenerator() = default;
  StatusOr<RenderedObjectFrame> Render(const Shot& shot) const;

  ObjectSequenceOptions options_;
  CameraIntrinsics camera_;
  std::vector<ObjectFace> faces_;
  std::vector<PlanarFace> geometry_;  // by face
  std::shared_ptr<const Scene> scene_;
  std::vector<Shot> frames_, training_;
};

struct ObjectSequenceWriteResult {
  std::string truth_path, views_path, readme_path;
  int frames = 0, visible_frames = 0;
  double min_fraction = 0, max_fraction = 0;  // over visible frames
};

// Writes out_dir/{images,depth,masks}/000001.png ..., truth.txt, faces/<side>.png,
// train/{rgb,depth,mask}_01.png ..., views.txt and README.txt (every file and the commands to
// build the model and evaluate). Creates out_dir; INVALID_ARGUMENT when it exists and is not an
// empty folder; INTERNAL when a file cannot be written. `progress` gets (written, total) images.
StatusOr<ObjectSequenceWriteResult> WriteObjectSequence(
    const ObjectSequenceGenerator& generator, const std::string& out_dir,
    const std::function<void(uint64_t, uint64_t)>& progress = {});

}  // namespace recog::cli
