// Learning an object model from a recording: many views, one known pose.
//
// A user walks around an object (or turns it) and records it. Only the first frame's pose is
// known (e.g. a CAD model registered to it), yet the model should hold every side the recording
// shows. LearnFromRecording grows the model view by view:
//  1. the model of the views chosen so far (at first the first frame alone) is built with the
//     caller's builder and put in a one-object database;
//  2. an ObjectTracker follows it through the next frames (recognition when it is lost);
//  3. a frame where the object was found with at least `min_inliers` inliers, and seen from a
//     direction more than `min_view_angle_deg` away from every chosen view's, becomes a view with
//     the pose just found, and the model is rebuilt with it (back to 1).
// The direction of a view is the camera centre in the object frame, as a unit vector from the
// object frame's origin. As the object turns, the faces that enter the view are learned while the
// known ones still give the pose, so the model follows the object all the way round.
//
// The poses of the later views are estimates: a wrong pose would put wrong points in the model,
// so only frames with many inliers become views, and the views are spaced by angle, not by time.
// Deterministic (the builder, the tracker and the recogniser are).
#pragma once

#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "core/object/builder/model_builder.h"
#include "core/object/model/object_model.h"
#include "core/object/tracking/object_tracker.h"
#include "core/vocabulary/vocabulary.h"

namespace recog {

struct RecordingLearningOptions {
  // A frame becomes a view when the object's direction differs from every view's by more than
  // this. 15° is 24 views all round a horizontal circle; a larger angle may never be reached, as
  // the tracker loses an object turned too far from the views it knows (visp-cube: 5 views at 15°
  // and the cube found in every frame; 2 at 25°; none at 30°).
  double min_view_angle_deg = 15.0;
  // ... and when its pose was found with at least this many inliers (the tracker's own minimum is
  // 12; a view's points are only as good as its pose).
  size_t min_inliers = 40;
  size_t max_views = 30;  // at most this many views (the first frame included)
  TrackingOptions tracking;

  // OK, or INVALID_ARGUMENT naming the first field out of its range (the tracking's included);
  // `name` names the struct in the message.
  Status Validate(std::string_view name = "RecordingLearningOptions") const;
};

struct RecordingFrame {
  std::string name;  // names the view the frame may become (e.g. the image file's stem)
  cv::Mat image;     // 8-bit
};

// The model of a set of registered views (e.g. ModelBuilder::FromPosedPolygons with the object's
// faces). Each view keeps the name of its frame (`first`'s, or the RecordingFrame's), by which
// the builder can find what else it has of that frame, e.g. its depth image for
// ModelBuilder::FromRgbd. Errors abort the learning.
using ModelFromViews = std::function<StatusOr<ObjectModel>(const std::vector<PosedImage>& views)>;

// Called after every frame: frames done, frames in all, views chosen so far.
using LearningProgress = std::function<void(size_t done, size_t total, size_t views)>;

struct LearnedModel {
  ObjectModel model;                // built from every chosen view
  std::vector<PosedImage> views;    // `first`, then every frame that became a view, with its pose
  std::vector<size_t> view_frames;  // the indices in `frames` of views[1..]
  size_t frames_found = 0;          // frames where the object was found
};

// Learns a model from a registered first frame (`first`: image, camera, pose) and the frames that
// follow it in the recording (`frames`, images of the same camera, in order).
// INVALID_ARGUMENT for an image that is not 8-bit or bad options; the builder's errors as they
// are (among them a view without a point).
StatusOr<LearnedModel> LearnFromRecording(const ModelFromViews& build,
                                          std::shared_ptr<const Vocabulary> vocabulary,
                                          const PosedImage& first,
                                          const std::vector<RecordingFrame>& frames,
                                          const RecordingLearningOptions& options = {},
                                          const LearningProgress& progress = {});

}  // namespace recog
