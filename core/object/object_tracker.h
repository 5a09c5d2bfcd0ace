// ObjectTracker: follows recognised objects across the frames of one stream, using the previous
// frames' poses as a prior instead of recognising every frame from scratch.
//
// Per frame, for every object being tracked:
//  1. its pose is predicted: the last pose, moved by the last frame-to-frame motion (constant
//     velocity) when the object was tracked in the two previous frames;
//  2. every model feature is projected with the predicted pose; ORB features are extracted in the
//     box of the projections grown by `region_margin_px` (only there, with their own budget, so a
//     small object gets many features), or, for frames given as features, the frame's features
//     are used;
//  3. each projected feature is matched to the keypoints within `window_px` of it (a grid of the
//     keypoints, Hamming distance on 64-bit popcounts, absolute bound and ratio test, then one
//     model feature per keypoint: the closest);
//  4. the pose is solved by RANSAC PnP with few iterations, then Levenberg-Marquardt (the
//     recogniser's own, object_pose.h); with fewer than `min_inliers` inliers the object is lost.
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
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "core/features/feature_extractor.h"
#include "core/object/object_database.h"
#include "core/object/object_recognizer.h"

namespace recog {

struct TrackingOptions {
  OrbOptions orb = DefaultTrackingOrb();  // features in a tracked object's predicted box
  double region_margin_px = 40;           // the box of the projected model grown by this
  double window_px = 24;                  // a projected feature matches keypoints this close
  uint32_t max_distance = 64;             // Hamming bound of a match (of 256 bits)
  double ratio = 0.9;                     // best < ratio * second best in the window
  int ransac_iterations = 30;
  double reprojection_px = 4.0;   // inlier threshold
  size_t min_inliers = 12;        // fewer: the object is lost
  int recognition_interval = 10;  // full recognition every this many frames while tracking; 0 = off
  bool constant_velocity = true;  // predict with the last motion (else the last pose)
  uint64_t seed = 1;              // RANSAC sampling

  static OrbOptions DefaultTrackingOrb() {
    OrbOptions orb;
    orb.max_features = 500;
    orb.levels = 3;
    return orb;
  }
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
  // Follows one object into this frame; true and *detection filled when it is still there.
  bool Follow(const IndexedObject& object, const RigidTransform& predicted, const cv::Mat& image,
              const FeatureSet* features, const CameraIntrinsics& camera,
              const DetectionOptions& extras, Detection* detection);
  // Model features of `object` matched to keypoints_ near their projections into *pairs
  // (model feature, keypoint).
  void MatchInWindows(const IndexedObject& object, const cv::Rect& box,
                      std::vector<std::pair<uint32_t, uint32_t>>* pairs);

  std::shared_ptr<const ObjectDatabase> database_;
  TrackingOptions options_;
  std::unique_ptr<FeatureExtractor> extractor_;
  std::vector<TrackedObject> tracks_;
  int frames_since_recognition_ = 0;
  // Scratch reused across frames (no allocation per feature).
  FeatureSet region_features_;
  const FeatureSet* frame_features_ = nullptr;  // the keypoints being matched (this frame)
  std::vector<cv::Point2f> pinhole_;            // their pixels without lens distortion
  std::vector<cv::Point2f> projected_;          // per model feature
  std::vector<uint32_t> visible_;               // model features projected inside the image
  std::vector<uint32_t> cell_start_, cell_items_;
  std::vector<uint32_t> best_distance_, best_feature_;  // per keypoint
};

}  // namespace recog
