// ObjectTracker: follows recognised objects across the frames of one stream, using the previous
// frames' poses as a prior instead of recognising every frame from scratch.
//
// Per frame, for every object being tracked:
//  1. its pose is predicted: the last pose, moved by the last frame-to-frame motion (constant
//     velocity) when the object was tracked in the two previous frames;
//  2. it is looked for near that pose by guided matching (guided_matcher.h: ORB in the box of the
//     projected model, each projected model feature matched to the keypoints in a window around
//     it, RANSAC PnP + Levenberg-Marquardt); with fewer than `matching.min_inliers` inliers the
//     object is lost.
//
// Recognition policy: the ObjectRecognizer searches the whole frame (a) on every frame while
// nothing is tracked, (b) on a frame where a tracked object was lost (so it is re-recognised at
// once when it is still in view), and (c) every `recognition_interval` frames (default 10) while
// objects are tracked, to find objects that entered the view; 0 turns (c) off. Objects found by
// recognition that are already tracked keep their tracked detection. Detections say which way
// they were found (Detection::tracked) and come best first (most inliers).
//
// The tracker holds the state of one stream (the tracks and its scratch memory); the recogniser
// is passed per call, because in recogd it belongs to the worker thread that runs the frame while
// the tracker belongs to the stream. Not thread-safe: one frame at a time. Deterministic: RANSAC
// is seeded.
#pragma once

#include <memory>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "core/object/recognition/guided_matcher.h"
#include "core/object/recognition/object_database.h"
#include "core/object/recognition/object_recognizer.h"

namespace recog {

struct TrackingOptions {
  GuidedMatchOptions matching;    // how a tracked object is found near its predicted pose
  int recognition_interval = 10;  // full recognition every this many frames while tracking; 0 = off
  bool constant_velocity = true;  // predict with the last motion (else the last pose)

  // OK, or INVALID_ARGUMENT naming the first field out of its range (its matching's included);
  // `name` names the struct in the message (a holder passes the member's path).
  Status Validate(std::string_view name = "TrackingOptions") const;
};

// Milliseconds spent on one frame.
struct TrackingTiming {
  double tracking = 0;     // every tracked object: features in its box, matching, PnP
  double recognition = 0;  // the full recognition, when it ran
  double total = 0;
  bool recognized = false;  // whether the full recognition ran on this frame
  size_t tracked = 0;       // objects tracked in this frame
  size_t lost = 0;          // tracked objects lost in this frame
};

class ObjectTracker {
 public:
  // `options` as TrackingOptions::Validate accepts them.
  explicit ObjectTracker(std::shared_ptr<const ObjectDatabase> database,
                         TrackingOptions options = {});

  // Tracks and recognises the filter's objects in the next frame of the stream. The recogniser
  // must use the same database. INVALID_ARGUMENT for an empty or non-8-bit image or invalid
  // intrinsics (the tracks are kept).
  Status Track(ObjectRecognizer& recognizer, const cv::Mat& image, const CameraIntrinsics& camera,
               std::vector<Detection>* detections, TrackingTiming* timing = nullptr,
               const ObjectFilter& filter = {}, const DetectionOptions& extras = {});
  // The same for a frame given as features (in the database's descriptor format).
  Status TrackFeatures(ObjectRecognizer& recognizer, const FeatureSet& features,
                       const CameraIntrinsics& camera, std::vector<Detection>* detections,
                       TrackingTiming* timing = nullptr, const ObjectFilter& filter = {},
                       const DetectionOptions& extras = {});

  // Forgets every track: the next frame is recognised.
  void Reset();
  size_t tracked_objects() const { return tracks_.size(); }
  const TrackingOptions& options() const { return options_; }

 private:
  struct TrackedObject {
    EntryId id = kInvalidEntryId;
    RigidTransform pose;      // in the last frame
    RigidTransform motion;    // pose(last) * pose(the frame before)^-1
    bool has_motion = false;  // tracked in the two last frames
  };

  // The frame's step after validation; `image` is empty for a frame given as features.
  Status Run(ObjectRecognizer& recognizer, const cv::Mat& image, const FeatureSet* features,
             const CameraIntrinsics& camera, const ObjectFilter& filter,
             const DetectionOptions& extras, std::vector<Detection>* detections,
             TrackingTiming* timing);

  std::shared_ptr<const ObjectDatabase> database_;
  TrackingOptions options_;
  GuidedMatcher matcher_;
  std::vector<TrackedObject> tracks_;
  int frames_since_recognition_ = 0;
};

}  // namespace recog
