// RigLoopDetector: loop closure for a multi-camera rig (thesis §3.3.2). A rig frame is one image
// per camera, taken at once by cameras fixed on one body (core/geometry/camera_rig.h); a loop is
// a past rig frame of the same place, and the motion of the body between the two.
//
// The map is one database of camera images: rig frame f's camera c is an entry of its own (with
// c's camera matrix, and 3D points when the camera has depth or a stereo partner), so every
// camera image of a query is searched against every camera image of the map — a robot driving
// back along a corridor finds with its rear camera what its front camera saw. Process(frame):
//  1. each camera image is converted with the map's vocabulary and the database is queried,
//     leaving out the entries of recent rig frames (tau_c of the per-camera parameters: seconds
//     with timestamps, else rig frames);
//  2. the answers are pooled by rig frame: a past frame's score is the sum, over the query's
//     cameras, of the best score any of its camera images got from that camera. Frames under
//     alpha times the best frame's score are dropped;
//  3. the best max_verified_frames frames are verified in order, each query camera against the
//     camera image of the frame it scored best with: correspondences through the direct index,
//     a fundamental matrix with the relocalisation floor of inliers (one frame's evidence, as
//     LoopDetector::Query), then the 3D check where either side has points (PnP: the metric pose);
//  4. verification across the rig: each verified camera pair that fixes a motion (its metric pose,
//     or a rotation from its essential matrix) implies a body motion through the known extrinsics
//     (the pair's relative rotation from its essential matrix, or its metric pose), R_body =
//     body_R_cq * R_pair * body_R_cmᵀ. Pairs must agree within max_rotation_disagreement_deg, else
//     the frame is refused (kInconsistentCameras): two cameras that saw a place from poses the rig
//     cannot take at once were not both looking at it, and a rig whose extrinsics are wrong is
//     caught here. A loop seen by one camera pair alone has that pair's verification only;
//  5. the frame's camera images are added to the database, each tagged with its rig frame and
//     camera (EntryMetadata::user_data), so that the map rebuilds its frames when it is opened
//     again.
// A rig frame's id is the entry id of its first camera image: ids increase in insertion order and
// are never reused, but are not consecutive (n cameras take n entry ids a frame).
// The loop's body-frame pose: with metric pairs, their poses carried into the body frame and fused
// by their covariances (the information-weighted mean); else the rotation of the pair with the
// most epipolar inliers (one camera pair fixes the translation only up to scale). A loop whose
// pairs all hold without fixing a motion (views a pure image shift apart) is a loop without a pose.
//
// Keypoints must be in the pinhole model of their camera's K (distortion removed,
// UndistortKeypoints in core/geometry/camera_rig.h). Thread safety: Process, Add and RemoveFrame
// change the frame table, so they run one at a time and not during a Query; Queries may run
// concurrently with each other (PlaceMap serialises a rig map's calls accordingly). A rig frame is
// committed one camera image at a time: a crash in the middle leaves a frame with fewer cameras,
// which is searched like any other.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/geometry/camera_rig.h"
#include "core/place/loop_detector.h"

namespace recog {

struct RigLoopParams {
  // Per camera image: tau_c (recent_seconds, recent_frames counted in rig frames), alpha (on the
  // pooled frame scores), max_query_results (per camera), matching, epipolar, the relocalisation
  // floor of inliers (16) and the 3D check.
  LoopDetectorParams detector;
  // Candidate rig frames verified per query (default 2: the second best is often the same place
  // seen one frame earlier or later).
  uint32_t max_verified_frames = 2;
  // Largest angle between the body rotations two verified camera pairs imply (default 3°: on the
  // synthetic front + rear drives of tools/evaluation/rig_place_test.cc, true loops disagree by
  // well under 1°, and a rear camera mounted 10° off its calibration makes the pairs disagree by
  // about 20°).
  double max_rotation_disagreement_deg = 3.0;
  // Share of each posed pair's inliers that must lie within the epipolar threshold (the
  // detector's epipolar.threshold_px) of the body motion of the loop (default 0.9; see step 4).
  double min_consistent_ratio = 0.9;

  // OK, or INVALID_ARGUMENT naming the first field out of its range (the detector's included,
  // "RigLoopParams.detector.alpha = ..."); `name` names the struct in the message.
  Status Validate(std::string_view name = "RigLoopParams") const;
};

// One rig frame: camera c's features (keypoints in its pinhole model) and, optionally, the 3D
// point of each keypoint (camera frame, metres, NaN where unknown; frame_points.h).
struct RigFrame {
  std::vector<FeatureSet> cameras;               // one per camera of the rig, in rig order
  std::vector<std::vector<cv::Point3f>> points;  // empty, or one list per camera (each empty or
                                                 // one point per keypoint)
  std::optional<double> timestamp;               // seconds; none when unknown
  std::string client_id;  // the client's own id, stored with every camera image (kMaxClientIdBytes)
};

enum class RigLoopStatus {
  kLoopDetected,         // a verified loop, consistent across the rig
  kTooFewFeatures,       // no camera image had min_features: added, not queried
  kNoCandidates,         // nothing old enough shares a word with any camera image
  kFailedGeometry,       // no camera pair of the candidates passed verification
  kInconsistentCameras,  // camera pairs verified, but the body motions they imply disagree
};
std::string_view RigLoopStatusName(RigLoopStatus status);  // "loop_detected", ...

// A camera pair of a loop: the query's camera `query_camera` saw what the match's `match_camera`
// saw.
struct RigCameraMatch {
  uint32_t query_camera = 0, match_camera = 0;
  EntryId entry = kInvalidEntryId;  // the match's camera image
  LoopResult verification;          // inliers (a = query feature, b = match feature), F, metric
  // The body motion this pair implies: X_body_query = body_R * X_body_match (+ body_t when
  // metric).
  cv::Matx33d body_R = cv::Matx33d::eye();
  cv::Vec3d body_t = cv::Vec3d(0, 0, 0);
  bool metric = false;                // the pair passed the 3D check: body_t is metres
  PoseCovariance6 body_covariance{};  // of (body_R, body_t), when metric
  // body_R is known: the pair passed the 3D check, or its essential matrix fixed a rotation (it
  // does not for views that differ by a pure image shift, where F holds but says no motion).
  bool posed = false;
  // Share of the pair's inliers within the epipolar threshold of the loop's body motion (step 4).
  double consistent_ratio = 0;
};

struct RigLoopTimings {  // milliseconds for one rig frame, all cameras
  double conversion = 0, query = 0, verification = 0, insertion = 0;
};

struct RigLoopResult {
  RigLoopStatus status = RigLoopStatus::kNoCandidates;
  std::optional<uint64_t> frame;         // the id this rig frame got (Process); none for Query
  std::optional<uint64_t> match_frame;   // the loop's (or last refused candidate's) rig frame id
  double score = 0;                      // the match frame's pooled score
  std::vector<RigCameraMatch> pairs;     // the match frame's verified camera pairs
  double rotation_disagreement_deg = 0;  // largest angle between the posed pairs' body rotations
  // X_body_query = R * X_body_match + t (the match's body frame into the query's), when `posed`
  // (some pair is); t is metres when `metric`, else zero.
  bool posed = false;
  cv::Matx33d R = cv::Matx33d::eye();
  cv::Vec3d t = cv::Vec3d(0, 0, 0);
  bool metric = false;
  PoseCovariance6 covariance{};  // of (R, t) as MetricLoop's, when metric
  RigLoopTimings timings;
};

class RigLoopDetector {
 public:
  // `database` must outlive the detector and hold only this rig's frames (it is a map of its
  // own); the frames it already holds are read back from their tags (a map opened again).
  // INVALID_ARGUMENT for a rig that does not validate, or bad parameters; DATA_LOSS for a stored
  // entry without a rig tag or with a camera the rig does not have.
  static StatusOr<RigLoopDetector> Create(Database* database, std::vector<RigCamera> rig,
                                          const RigLoopParams& params);

  // Steps 1-5 for the next rig frame; the `excluded` rig frames (ids; unknown ones are ignored)
  // are never candidates for it, beside tau_c's recent ones. INVALID_ARGUMENT naming the camera
  // for a frame without an image for every camera, keypoints outside a camera's image size, or a
  // points list of the wrong length, and for a client id that is too long; nothing is added then.
  // "No loop" is a result.
  StatusOr<RigLoopResult> Process(const RigFrame& frame, std::span<const uint64_t> excluded = {});
  // Step 5 alone (a robot uploading its keyframes); returns the frame's id.
  StatusOr<uint64_t> Add(const RigFrame& frame);
  // Steps 1-4 against every frame of the map (no tau_c) but the `excluded` ones, without adding
  // the frame.
  StatusOr<RigLoopResult> Query(const RigFrame& frame,
                                std::span<const uint64_t> excluded = {}) const;
  // Removes rig frame `id` (every camera image of it): it is never a candidate again. NOT_FOUND
  // when the map holds no such frame.
  Status RemoveFrame(uint64_t id);
  // The ids of the stored rig frames added with `client_id`, increasing (reads every entry's
  // metadata: linear in the map's size).
  StatusOr<std::vector<uint64_t>> FramesWithClientId(std::string_view client_id) const;

  const std::vector<RigCamera>& rig() const { return rig_; }
  uint64_t frames() const { return frames_.size(); }  // rig frames stored
  EntryId next_frame_id() const { return database_->next_entry_id(); }

 private:
  struct Converted;  // a frame's camera images, converted

  RigLoopDetector(Database* database, std::vector<RigCamera> rig, const RigLoopParams& params,
                  LoopDetector detector)
      : database_(database),
        rig_(std::move(rig)),
        params_(params),
        detector_(std::move(detector)) {}
  Status CheckFrame(const RigFrame& frame) const;
  Status Convert(const RigFrame& frame, Converted* converted) const;
  // Steps 1-4 with the entries of the frames `bound` leaves out, and of the `excluded` frames,
  // left out.
  StatusOr<RigLoopResult> Search(const RigFrame& frame, const Converted& converted,
                                 RecencyBound bound, std::span<const uint64_t> excluded) const;
  // Step 4 for one candidate frame: the pairs' body motions and whether they agree.
  void CheckAcrossRig(const RigFrame& frame, RigLoopResult* result) const;
  // The metric pairs' body poses fused by their covariances into result's R, t and covariance.
  void FuseMetricPairs(const std::vector<RigCameraMatch*>& posed, const RigCameraMatch& reference,
                       RigLoopResult* result) const;
  StatusOr<uint64_t> Insert(const RigFrame& frame, const Converted& converted);
  // Reads the stored frames back from their entries' tags (Create).
  Status Rebuild();
  // tau_c for a rig frame at `timestamp`, by rig frame ids.
  RecencyBound RecencyBoundFor(std::optional<double> timestamp) const;
  // The rig frame and camera of a stored entry (nullopt for others).
  std::optional<std::pair<uint64_t, uint32_t>> FrameOf(EntryId entry) const;
  // The entries of the `frames` this detector stores, increasing.
  std::vector<EntryId> EntriesOf(std::span<const uint64_t> frames) const;

  struct StoredImage {
    EntryId entry;
    uint64_t frame;
    uint32_t camera;
  };
  struct StoredFrame {
    uint64_t id;
    std::optional<double> timestamp;
  };

  Database* database_;
  std::vector<RigCamera> rig_;
  RigLoopParams params_;
  LoopDetector detector_;            // per camera image
  std::vector<StoredImage> images_;  // by increasing entry id
  std::vector<StoredFrame> frames_;  // by increasing id
};

}  // namespace recog
