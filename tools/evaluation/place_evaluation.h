// Evaluation of the loop detector on a recorded sequence with ground truth: what
// `recog eval place` reports (precision, recall, per-stage timings, the detections) and the
// pieces it is made of, usable from benchmarks too.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/features/feature_extractor.h"
#include "core/geometry/camera_model.h"
#include "core/geometry/frame_points.h"
#include "core/place/loop_detector.h"
#include "tools/evaluation/camera_trajectory.h"
#include "tools/evaluation/dataset_layouts.h"
#include "tools/evaluation/ground_truth.h"
#include "tools/evaluation/loop_tally.h"
#include "tools/evaluation/ros_bag.h"
#include "tools/evaluation/video_input.h"

namespace recog::cli {

// The frames of a sequence: a folder of images (natural order of names), a dataset folder in a
// public layout with timestamps (TUM RGB-D, EuRoC, KITTI: dataset_layouts.h), a text file listing
// one image path per line (relative paths are relative to the list), a video file, a live
// camera, "camera:N" (the Video4Linux device /dev/videoN, read until the caller stops), or the
// image topic of a ROS 1 bag with its depth or right images (OpenBag, ros_bag.h).
class FrameSource {
 public:
  // A folder is read in `layout`; without one, in the layout DetectDatasetLayout finds. A layout
  // for anything but a folder is INVALID_ARGUMENT; errors of ReadDatasetFrames as they are.
  static StatusOr<FrameSource> Open(const std::string& spec,
                                    std::optional<DatasetLayout> layout = std::nullopt);
  // The frames of a ROS 1 bag's `topics.image`, in stamp order, with their stamps as timestamps
  // and their depth and right images; every error of RosBagReader::Open, before any frame.
  static StatusOr<FrameSource> OpenBag(const std::string& path, const BagTopics& topics,
                                       const BagReadOptions& options = {});
  // The next frame as 8-bit grey; false at the end. Undecodable images are INVALID_ARGUMENT
  // (the next call goes on with the following image). `name` is the image's path, or
  // "<video file name>#<frame number from 1>" ("camera:N#<frame number>" for a camera,
  // "<bag file name>#<frame number from 1>" for a bag).
  StatusOr<bool> Next(cv::Mat* gray, std::string* name);
  // Timestamp (seconds) of the frame Next() returned last; none when the source has none.
  std::optional<double> timestamp() const;
  // The depth image (TUM, a bag's depth topic) and the right image (EuRoC, KITTI, a bag's right
  // topic) files of the frame Next() returned last; empty when it has none, and for a bag.
  std::string depth_path() const;
  std::string right_path() const;
  // Those images of the frame Next() returned last; empty when it has none. A depth image is
  // CV_16UC1 (TUM: 1/5000 m; a bag's 16UC1: millimetres) or CV_32FC1 (metres); a right image
  // 8-bit grey. A file that cannot be read is INVALID_ARGUMENT (depth) or ReadGrayImage's error.
  StatusOr<cv::Mat> depth() const;
  StatusOr<cv::Mat> right() const;
  // The dataset layout read (kFolder for anything without timestamps, and for a bag).
  DatasetLayout layout() const { return layout_; }
  // True for a video or a camera, whose frames have no file of their own.
  bool is_video() const { return video_ != nullptr; }
  // True for a bag (whose frames have no file of their own either); bag() is then its reader
  // (its cameras), else null.
  bool is_bag() const { return bag_ != nullptr; }
  const RosBagReader* bag() const { return bag_.get(); }
  // Frames in the sequence: exact for images and bags, the container's count for a video (0:
  // unknown, and for a camera).
  size_t size() const;

 private:
  std::vector<std::string> files_;
  std::vector<double> timestamps_;            // per file, for a dataset layout; empty otherwise
  std::vector<std::string> depths_, rights_;  // per file, for a dataset layout; empty otherwise
  DatasetLayout layout_ = DatasetLayout::kFolder;
  size_t next_ = 0;
  std::shared_ptr<VideoInput> video_;  // a video file or a camera
  std::string video_name_;
  std::shared_ptr<RosBagReader> bag_;
  BagFrame bag_frame_;  // the frame Next() returned last, of a bag
};

// 3D points for the frames of a dataset that has depth images (TUM) or right images (EuRoC,
// KITTI): the loop detector then checks loops in 3D and gives their metric relative pose
// (LoopResult::metric, thesis §3.3.3). A camera with a lens distortion has its frames' keypoints
// moved into the pinhole image of its K (ToPinhole) once their points are known, and loops are
// checked there; its depth is aligned with the distorted image; right images need a rectified,
// distortion-free pair.
struct SequenceGeometryOptions {
  CameraIntrinsics camera;  // of the (left) images
  // Metres per unit of a 16-bit depth image (TUM: 1/5000; millimetres: 0.001). Float depth
  // images are metres.
  double depth_scale = 1.0 / 5000.0;
  double baseline_m = 0;  // the right camera's offset along x; needed for right images
  StereoOptions stereo;
};

struct SequenceFeatures {
  std::vector<FeatureSet> features;
  // Per frame, with SequenceGeometryOptions: K and the keypoints' 3D points (empty points for a
  // frame without depth or right image); empty without.
  std::vector<FrameGeometry> geometry;
  std::vector<double> points_ms;  // time to compute the 3D points, per frame (with geometry)
  std::vector<std::string> names;
  // Seconds, per frame (none: unknown, tau_c then counts frames); empty when none has one.
  std::vector<std::optional<double>> timestamps;
  std::vector<double> feature_ms;  // extraction time per frame
  std::vector<cv::Mat> images;     // kept only when asked (for drawing)
};

// Reads every frame and extracts its features (single thread, timed per frame); with `geometry`,
// also the 3D points of frames that have a depth or right image (errors of PointsFromDepth /
// PointsFromStereo, e.g. a right image without a baseline, name the frame).
StatusOr<SequenceFeatures> ExtractSequence(
    FrameSource& source, const FeatureOptions& options, bool keep_images,
    const std::function<void(size_t)>& progress = nullptr,
    const std::optional<SequenceGeometryOptions>& geometry = std::nullopt);

struct DetectedLoop {
  int query = 0;  // 0-based frame index
  int match = 0;  // 0-based frame index of the matched frame
  LoopStatus status = LoopStatus::kLoopDetected;
  // The ground truth marks the pair and, with a trajectory, the loop's inliers agree with the true
  // geometry (`geometry->agrees`).
  bool correct = false;
  // The pair is listed as ambiguous (and, with a trajectory, the inliers agree with the true
  // geometry): left out of precision.
  bool ambiguous = false;
  double normalized_score = 0;
  uint32_t inliers = 0;
  LoopAcceptance acceptance = LoopAcceptance::kNone;  // how the detector accepted it
  MetricLoop metric;                                  // the 3D check, for frames with 3D points
  LoopEvidence evidence;                              // the detector's own figures
  std::optional<LoopGeometryTruth> geometry;          // with a trajectory: what the poses say
};

// The figures over the sequence (statuses by LoopStatus name; timing_ms of features, points,
// conversion, query, islands, insertion, verification, metric_verification and total), with the
// loops and the misses (ExplainMiss).
struct PlaceEvaluation : LoopFigures {
  std::vector<DetectedLoop> loops;  // every frame that had a candidate match
};

// The frames of one map as the sequence numbers them: the map holds frames [first, end), and its
// entry e is frame first + e (a map built from those frames in order).
struct MapFrames {
  int first = 0, end = 0;
};

// True when the truth matches frame `query` to a frame of `map`: the frame revisits that map.
bool RevisitsMap(const GroundTruth& truth, int query, MapFrames map);

// Why frame `query`, a revisit of `map` whose loop there is not counted correct, was missed, from
// its LoopResult in that map. A candidate is a true place when the truth matches the query to its
// frame (GroundTruth::Matches, as a loop is judged). By the result's status, then its candidates:
//  - too_few_features, low_score_with_previous: kNotQueried;
//  - loop_detected: kWrongLoop (the caller judged the loop not correct);
//  - otherwise no true place among `candidates` (none at all for no_candidates): kNoCandidate;
//  - low_score, no_consistent_island (no best candidate was chosen): kLowScore;
//  - the best candidate (`match`) not a true place: kWrongTopCandidate;
//  - else, a true best candidate: failed_geometry is kFailedGeometry (with failed_metric when the
//    2D check passed and the 3D one refused it); failed_temporal_consistency, and candidate
//    (verified, awaiting keyframe confirmations), are kNotConsistent.
// The rank of the first true candidate is set whenever one is among the candidates; the
// verification's inliers and correspondences whenever the status says one ran (failed_geometry,
// candidate, loop_detected), the consistent queries for failed_temporal_consistency.
MissedRevisit ExplainMiss(const LoopResult& result, int query, MapFrames map,
                          const GroundTruth& truth);

struct PlaceEvaluationOptions {
  LoopDetectorParams detector;
  ScoringType scoring = ScoringType::kL1;
  uint32_t direct_index_levels_up = 2;
};

// Runs a fresh detector (in-memory database) over the sequence in order: every frame's
// LoopResult, in order (what a recogd map with the same parameters answers frame for frame).
StatusOr<std::vector<LoopResult>> DetectLoops(const SequenceFeatures& sequence,
                                              std::shared_ptr<const Vocabulary> vocabulary,
                                              const PlaceEvaluationOptions& options);

// DetectLoops, scored against the ground truth. `results`, when not null, receives every frame's
// LoopResult. With `trajectory` (one pose per frame), each loop is also scored by its inliers
// (ScoreLoopGeometry): one whose inliers do not agree with the true geometry is false whatever
// the ground truth says. INVALID_ARGUMENT when the trajectory has another number of frames.
StatusOr<PlaceEvaluation> EvaluatePlace(const SequenceFeatures& sequence, const GroundTruth& truth,
                                        std::shared_ptr<const Vocabulary> vocabulary,
                                        const PlaceEvaluationOptions& options,
                                        std::vector<LoopResult>* results = nullptr,
                                        const CameraTrajectory* trajectory = nullptr);

// Two robots sharing a sequence's places (a fleet's maps, or one robot's two sessions): frames
// [0, split) are robot A's map (added, no query); frames [split, n) stream into robot B's own
// map (LoopDetector::Process, its own loops) and are looked up in A's map with A in B's search
// set (LoopDetector::Query: relocalisation, every frame alone, no tau_c and no temporal
// consistency). Frame indices are the sequence's, as in the ground truth; a query frame counts
// as a revisit of A (inter_map.query_frames_with_truth) when the truth matches it to a frame
// before `split`, and of B (own_map) when to one from `split` on. Timings of inter_map are the
// lookup in A alone (the features are counted in own_map).
struct AcrossMapsEvaluation {
  PlaceEvaluation inter_map;  // B's frames looked up in A
  PlaceEvaluation own_map;    // B's frames in B's own map
};
// INVALID_ARGUMENT when the split leaves no frame to one robot, or the truth does not cover the
// sequence.
StatusOr<AcrossMapsEvaluation> EvaluateAcrossMaps(const SequenceFeatures& sequence,
                                                  const GroundTruth& truth, int split,
                                                  std::shared_ptr<const Vocabulary> vocabulary,
                                                  const PlaceEvaluationOptions& options);

// Two robots' own sequences as one for EvaluateAcrossMaps (`recog eval place --robot-b`): robot
// B's frames numbered after robot A's, as a ground truth across the two sequences numbers them
// (split = A's frame count). Per-frame data that only one of them has (timestamps, 3D points,
// images) is left empty for the other's frames; each robot keeps its own clock.
void AppendSequence(SequenceFeatures robot_b, SequenceFeatures* robot_a);

}  // namespace recog::cli
