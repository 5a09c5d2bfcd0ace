// Learning an object model from an RGB-D walk-around (`recog model build --rgbd-recording DIR`):
// the RGB-D counterpart of learning from a recording with a CAD model (recording_learner.h).
//
// The recording is a folder with images/ (the colour frames, 8-bit) and depth/ (16-bit depth
// registered to the colour frames: same size, same camera), paired by the number at the end of
// each file's stem (FrameNumber in frame_poses.h): images/color_image_0007.png goes with
// depth/depth_image_0007.png, and `recog seqgen objects`' images/000007.png with
// depth/000007.png. The frames are taken in the order of their numbers and named by their colour
// image's stem. Only the first frame's pose is known, and the object is given as its 3D box in
// the object frame. LearnFromRecording follows the object through the later frames (read grey, as
// --recording reads them) and every model is built by ModelBuilder::FromRgbd from the views
// chosen so far, each with its frame's depth image (found by the view's name and read when the
// frame becomes a view) and the box: keypoints of the box's projection with a valid depth are
// back-projected, points outside the box dropped.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/object/builder/model_builder.h"
#include "core/object/model/object_model.h"
#include "core/object/tracking/recording_learner.h"

namespace recog::cli {

struct RgbdRecordingFrame {
  int number = 0;
  std::string image, depth;  // paths of the colour and the depth image
};

// The frames of the recording in `dir`, by number. NOT_FOUND when dir/images or dir/depth is
// missing or a colour image has no depth image of its number (depth images without a colour
// image are ignored); INVALID_ARGUMENT for a file name without a number, two colour (or two
// depth) images of one number, or no image.
StatusOr<std::vector<RgbdRecordingFrame>> ListRgbdRecording(const std::string& dir);

struct RgbdRecordingOptions {
  std::string name;             // the object's
  CameraIntrinsics camera;      // of the colour frames (and of the registered depth)
  RigidTransform first_pose;    // T_camera<-object in the first frame
  ObjectBox box;                // the object in its frame
  double depth_scale = 1000.0;  // raw depth units per metre (1000: millimetres)
  RecordingLearningOptions learning;
};

// Learns the model from frames[0] (at options.first_pose) and the frames after it. views[k].name
// is the stem of the view's colour image. INVALID_ARGUMENT without frames, for a depth image
// that cannot be read or is not 16-bit of its colour image's size (naming it), or a depth scale
// that is not positive; the errors of reading the colour images, of LearnFromRecording and of
// FromRgbd as they are. With `view_report`, also FromRgbd's report on the learned model's views
// (a first pose that is off shows there).
StatusOr<LearnedModel> LearnFromRgbdRecording(ModelBuilder* builder,
                                              const std::vector<RgbdRecordingFrame>& frames,
                                              const RgbdRecordingOptions& options,
                                              const LearningProgress& progress = {},
                                              std::vector<RgbdViewReport>* view_report = nullptr);

// The frames numbered `numbers` as RGB-D views (grey image, depth, `camera`, the frame's pose of
// `poses`), in that order, for ModelBuilder::FromRgbd: a model from chosen frames of a recording
// whose every pose is known. NOT_FOUND for a number with no frame or no pose; the errors of
// reading the images as LearnFromRgbdRecording's.
StatusOr<std::vector<RgbdView>> PosedRgbdViews(const std::vector<RgbdRecordingFrame>& frames,
                                               const std::map<int, RigidTransform>& poses,
                                               const CameraIntrinsics& camera, double depth_scale,
                                               const std::vector<int>& numbers);

}  // namespace recog::cli
