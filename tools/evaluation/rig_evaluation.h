// Evaluation of the rig loop detector (core/place/rig_loop_detector.h) on a rig sequence with
// ground truth: what `recog eval place --rig` reports — precision and recall over rig frames, the
// camera pairs of each loop, per-stage timings, and with the body's poses the error of each
// loop's body-frame relative pose.
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/features/feature_extractor.h"
#include "core/place/rig_loop_detector.h"
#include "tools/evaluation/ground_truth.h"
#include "tools/evaluation/loop_tally.h"
#include "tools/evaluation/metric_sequence.h"
#include "tools/evaluation/rig_dataset.h"

namespace recog::cli {

struct RigExtractionOptions {
  FeatureOptions features;
  // Depth images (where the dataset has them) give the keypoints 3D points with their camera's K.
  bool use_depth = true;
  double depth_scale = 1.0 / 5000.0;  // metres per unit of a 16-bit depth image (TUM)
  // Only these cameras, by name, in this order (empty: the whole rig): `--cameras front` is the
  // single-camera control.
  std::vector<std::string> cameras;
};

struct RigSequenceFeatures {
  std::vector<RigCamera> cameras;  // the cameras kept
  std::vector<RigFrame> frames;    // keypoints in each camera's pinhole model (undistorted)
  std::vector<double> feature_ms;  // per rig frame: ORB of every camera image (and undistortion)
  std::vector<double> points_ms;   // per rig frame: 3D points from depth; empty without depth
  std::vector<std::string> names;  // per rig frame: its first camera's image
};

// Reads every camera image of the dataset (8-bit grey) and extracts its features, then its 3D
// points from its depth image. INVALID_ARGUMENT naming the camera and the file for an image that
// does not decode or whose size is not its camera's; INVALID_ARGUMENT for an unknown camera name.
// `progress` (may be empty) is told the rig frames done and their total.
StatusOr<RigSequenceFeatures> ExtractRigSequence(
    const RigDataset& dataset, const RigExtractionOptions& options,
    const std::function<void(size_t done, size_t total)>& progress = {});

struct RigDetectedLoop {
  int query = 0, match = 0;  // 0-based rig frames
  RigLoopStatus status = RigLoopStatus::kLoopDetected;
  bool correct = false;  // the ground truth marks the pair
  // "query camera>match camera" per verified pair, e.g. "rear>front".
  std::vector<std::string> camera_pairs;
  uint32_t inliers = 0;  // epipolar inliers over the pairs
  double rotation_disagreement_deg = 0;
  bool posed = false, metric = false;
  // With body poses, for a posed loop: |angle(R R_true^T)|, and for a metric one
  // |t - t_true| / |t_true| in % (the distance between the two body poses).
  std::optional<double> rotation_error_deg, translation_error_pct;
  RigLoopResult result;
};

// The figures over rig frames (statuses by RigLoopStatus name, no ambiguous pairs; timing_ms of
// features, points, conversion, query, verification, insertion, detector and total per rig frame),
// with the loops and the pose errors.
struct RigPlaceEvaluation : LoopFigures {
  std::vector<RigDetectedLoop> loops;  // every frame with a candidate that was verified
  // Over the correct detections, with body poses: medians of the pose errors.
  int posed_correct = 0, metric_correct = 0;
  double median_rotation_error_deg = 0, median_translation_error_pct = 0;
};

struct RigPlaceOptions {
  RigLoopParams detector;
  ScoringType scoring = ScoringType::kL1;
  uint32_t direct_index_levels_up = 2;
};

// Runs a fresh rig detector (in-memory database) over the sequence and scores it against the
// truth (over rig frames). `body_poses` (world_from_body per frame; may be null) adds the pose
// errors. INVALID_ARGUMENT when the truth or the poses do not cover the sequence.
StatusOr<RigPlaceEvaluation> EvaluateRigPlace(const RigSequenceFeatures& sequence,
                                              const GroundTruth& truth,
                                              std::shared_ptr<const Vocabulary> vocabulary,
                                              const RigPlaceOptions& options,
                                              const std::vector<CameraPose>* body_poses = nullptr);

// The body poses of a TUM trajectory file ("timestamp tx ty tz qx qy qz qw" per line, '#'
// comments; what `recog seqgen rig` writes as body_poses.txt), in file order. NOT_FOUND for a
// missing file; INVALID_ARGUMENT naming the file and line for a malformed line or a quaternion
// far from unit length.
StatusOr<std::vector<CameraPose>> ReadTrajectory(const std::string& path);

}  // namespace recog::cli
