// GuidedMatcher: finds an object again near a pose it is believed to have, by matching its model
// features to the image keypoints close to where that pose projects them.
//
// Given a pose (a tracked object's prediction, or a recognised object's first estimate):
//  1. every model feature is projected with it; those in front of the camera and near the image
//     are kept;
//  2. ORB features are extracted in the box of the projections grown by `region_margin_px`, with
//     their own budget (so a small object gets many features), or, for frames given as features,
//     the frame's features are used;
//  3. each projected feature is matched to the keypoints within `window_px` of it (a grid of the
//     keypoints, Hamming distance on 64-bit popcounts, absolute bound and ratio test, then one
//     model feature per keypoint: the closest);
//  4. the pose is solved by RANSAC PnP with few iterations, then Levenberg-Marquardt (the
//     recogniser's own, object_pose.h); fewer than `min_inliers` inliers = not found.
// Matching by position as well as appearance finds far more correspondences than the appearance
// alone (the direct index and the ratio test over the whole model), so the pose rests on many more
// inliers.
//
// The tracker follows objects with it (object_tracker.h); the recogniser refines its detections
// with it (object_recognizer.h). Not thread-safe (scratch memory is reused): one per thread.
// Deterministic: RANSAC is seeded.
#pragma once

#include <memory>
#include <string_view>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "core/features/feature_extractor.h"
#include "core/object/recognition/detection.h"
#include "core/object/recognition/object_database.h"

namespace recog {

struct GuidedMatchOptions {
  OrbOptions orb = DefaultOrb();  // features in the object's box
  double region_margin_px = 40;   // the box of the projected model grown by this
  double window_px = 24;          // a projected feature matches keypoints this close
  uint32_t max_distance = 64;     // Hamming bound of a match (of 256 bits)
  double ratio = 0.9;             // best < ratio * second best in the window
  int ransac_iterations = 30;
  double reprojection_px = 4.0;  // inlier threshold
  size_t min_inliers = 12;       // fewer: not found
  uint64_t seed = 1;             // RANSAC sampling

  // OK, or INVALID_ARGUMENT naming the first field out of its range; `name` names the struct in
  // the message (a holder passes the member's path, "TrackingOptions.matching").
  Status Validate(std::string_view name = "GuidedMatchOptions") const;

  static OrbOptions DefaultOrb() {
    OrbOptions orb;
    orb.max_features = 500;
    orb.levels = 3;
    return orb;
  }
};

class GuidedMatcher {
 public:
  explicit GuidedMatcher(GuidedMatchOptions options = {});

  // Looks for `object` near `pose` in `image` (8-bit), or among `features` when the frame is
  // given as features (then `image` is empty). True and *detection filled (pose, inliers,
  // outline and the extras asked for) when found with at least min_inliers inliers.
  bool Match(const IndexedObject& object, const RigidTransform& pose, const cv::Mat& image,
             const FeatureSet* features, const CameraIntrinsics& camera,
             const DetectionOptions& extras, Detection* detection);

  const GuidedMatchOptions& options() const { return options_; }

 private:
  // Model features of `object` matched to frame_features_ near their projections into *pairs
  // (model feature, keypoint).
  void MatchInWindows(const IndexedObject& object, const cv::Rect& box,
                      std::vector<std::pair<uint32_t, uint32_t>>* pairs);

  GuidedMatchOptions options_;
  std::unique_ptr<FeatureExtractor> extractor_;
  // Scratch reused across calls (no allocation per feature).
  FeatureSet region_features_;
  const FeatureSet* frame_features_ = nullptr;  // the keypoints being matched
  std::vector<cv::Point2f> pinhole_;            // their pixels without lens distortion
  std::vector<cv::Point2f> projected_;          // per model feature
  std::vector<uint32_t> visible_;               // model features projected near the image
  std::vector<uint32_t> cell_start_, cell_items_;
  std::vector<uint32_t> best_distance_, best_feature_;  // per keypoint
  std::vector<std::pair<uint32_t, uint32_t>> pairs_;
};

}  // namespace recog
