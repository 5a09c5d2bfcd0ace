// LoopDetector: real-time loop-closure detection over an image sequence (thesis chapter 4), plus
// the two operations a map server needs beside it: adding frames without querying, and one-off
// relocalisation queries.
//
// Process() handles the next frame of the sequence, in order:
//  1. its bag of words and direct-index entry are computed with the map's vocabulary;
//  2. the map's database is queried, leaving out the recent entries (tau_c, in frames or seconds);
//  3. scores are normalised by the score with the previous usable frame, eta = s(v_t, w) /
//     s(v_t, v_t-1) (eq. 3.11), and matches below alpha are dropped; a frame whose score with the
//     previous one is too low is not queried (its eta would be meaningless);
//  4. the remaining matches are grouped into islands of entries close in time, ranked by the sum
//     of their eta (eq. 4.2);
//  5. the best island should be temporally consistent with the best islands of the k previous
//     queries (§4.3.1): consecutive queries whose islands (almost) overlap;
//  6. the best entry of the island is verified geometrically: correspondences through the
//     direct index (Algorithm 2) or exhaustively, then a fundamental matrix with RANSAC and a
//     minimum of inliers (or no check at all). A candidate consistent with k queries needs only
//     that. One consistent with fewer (at least strong_temporal_matches; beyond the thesis, which
//     waits for k in every case and so misses the first frames of each revisit) is verified too,
//     and accepted only when the evidence is strong: at least strong_min_inliers inliers, covering
//     at least strong_min_spread of both images, and not explained by a homography about as well
//     as by F (R_H = S_H / (S_H + S_F) at most strong_max_homography_ratio, ORB-SLAM's model
//     selection): a planar scene or a pure rotation makes F fit without proving a 3D match.
//     Weak evidence waits for k. With verified_candidates > 1, when the best entry is not
//     accepted, the next candidates by score are verified for strong evidence too, and the strong
//     one with the most inliers is the loop. result.acceptance says which rule accepted a loop;
//  7. the frame is added to the database.
// Every frame gets a LoopResult whose status says why there is, or is not, a loop.
//
// Metric loops (thesis §3.3.3 brings the 3D data of a stereo rig into the loop verification, with
// CRF-Matching; this detector uses a PnP check instead, as the metric verification the thesis
// cites there, and returns the metric pose a SLAM needs): a frame may come with a FrameGeometry,
// its camera matrix and the 3D point of each keypoint (from depth or stereo,
// core/geometry/frame_points.h). The entry keeps the points and the camera matrix. When a loop
// passes step 6 and either side has 3D points the other side's camera can see, VerifyMetric checks
// the loop in 3D: PnP RANSAC over the epipolar inliers between the match's points and the query's
// keypoints (query camera), or, when the match has no points (a map without depth), between the
// query's points and the match's keypoints (the match's stored camera matrix), then
// Levenberg-Marquardt on the PnP inliers; the loop must agree in structure (MetricCheckOptions:
// enough inliers, and enough of the 2D-3D correspondences) or its status becomes kFailedGeometry.
// A verified loop carries the metric relative pose and its covariance (LoopResult::metric), in one
// convention whichever side gave the points. Frames without a FrameGeometry, and loops where
// neither side has points with a camera on the other, are handled exactly as before.
//
// Add() is step 7 alone (a robot uploading its keyframes): the frame joins the sequence exactly
// as a processed frame would — it gets the next entry id, becomes the previous usable frame when
// it has enough features, and its timestamp counts for tau_c — but nothing is queried.
//
// Query() asks "where am I in this map?" for one frame, without adding it or changing the
// detector: steps 1, 2, 4 and 6 against every entry of the map (no tau_c), with the scores
// normalised by the best candidate's score instead of the previous frame's (there is none), and
// no temporal consistency (a single query cannot be consistent with anything); step 6 then needs
// relocalisation_min_inliers (16) rather than 12, as one frame's evidence is all there is.
//
// The previous usable frame is the most recent one with enough features: a blank frame (a wall,
// a covered lens) neither gets queried nor breaks the normalisation of the frames after it.
//
// Defaults are thesis Table 4.4 where it gives one (k = 3, alpha = 0.3, direct index level 2,
// 12 RANSAC inliers, minimum score 0.005 with the previous frame, tau_c = 20 s); the others are
// documented on each field. LoopDetectorParams::Thesis() is the thesis's detector exactly (no
// acceptance on strong evidence) and Keyframes() the one for a SLAM's keyframes:
// ParseDetectorPreset names the three presets (default, thesis, keyframes), and
// core/place/detector_settings.h is the table of the settings by name, with their ranges
// (`recog settings` lists each preset's values). One detector per map; independent detectors may
// run at once.
//
// Thread safety: Process and Add change the detector and must be called from one thread at a
// time (per detector, i.e. per map). Query reads nothing they change — only the parameters and
// the database, which is thread-safe — so any number of threads may Query at once, concurrently
// with the thread that Processes or Adds.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include "core/common/feature_set.h"
#include "core/geometry/correspondences.h"
#include "core/geometry/pose_covariance.h"
#include "core/index/database.h"

namespace recog {

enum class LoopStatus {
  kLoopDetected,               // a verified loop closure
  kTooFewFeatures,             // fewer than min_features: added, not queried
  kLowScoreWithPrevious,       // s(v_t, v_t-1) below the minimum: added, not queried
  kNoCandidates,               // the query returned nothing (no old enough entry shares a word)
  kLowScore,                   // no candidate reached alpha
  kNoConsistentIsland,         // the candidates formed no island of the minimum size
  kFailedTemporalConsistency,  // the best island is not consistent with the previous queries
  kFailedGeometry,             // too few correspondences or RANSAC inliers (2D, or 3D: metric)
  // Verified, but waiting for the next keyframe(s) to confirm it (keyframe_confirmations): the
  // answer carries the match and its evidence; a client must not act on it yet.
  kCandidate,
};
std::string_view LoopStatusName(LoopStatus status);  // "loop_detected", "too_few_features", ...

enum class GeometryCheck {
  kDirectIndex,  // correspondences through the direct index, then RANSAC (default, thesis DI_l)
  kExhaustive,   // correspondences by comparing every pair, then RANSAC
  kNone,         // accept the temporally consistent candidate as it is
};
std::string_view GeometryCheckName(GeometryCheck check);  // "direct_index", "exhaustive", "none"
StatusOr<GeometryCheck> ParseGeometryCheck(std::string_view name);

// The 3D check of a loop where one side has 3D points (VerifyMetric). Defaults: 2 px as the
// epipolar check's threshold and 12 inliers as its minimum (Table 4.4); 70 % of the 2D-3D
// correspondences (the epipolar inliers with a 3D point): on the synthetic sequences of
// tools/evaluation/metric_sequence_test.cc, true loops keep more (stereo and RGB-D), while a map
// built from a flat picture of the place (a poster: right images, wrong structure) keeps fewer
// and is refused (the shares: docs/places.md, "Metric loops from depth and stereo").
struct MetricCheckOptions {
  double threshold_px = 2.0;  // reprojection error of a PnP inlier
  int max_iterations = 300;   // RANSAC iterations (OpenCV's solvePnPRansac, deterministic)
  double confidence = 0.99;
  uint32_t min_inliers = 12;      // PnP inliers a metric loop needs
  double min_inlier_ratio = 0.7;  // PnP inliers / 2D-3D correspondences
  double min_sigma_px = 0.5;      // floor of the residual sigma of the covariance (pixels)
};

// The calibrated evidence and check of a loop (Verify, when the query and the candidate both
// have a camera matrix: a keyframe client that sends its intrinsics, `recog eval place
// --camera`). The fundamental matrix's inliers are triangulated through the essential matrix
// K_match^T F K_query, which gives LoopEvidence its share in front, parallax and rotation. With
// `enabled`, they must also make physical sense, instead of the uncalibrated spread floor:
//  - they triangulate in front of both cameras (min_in_front; a point whose two rays are
//    parallel counts when they point the same way); or else, without parallax (the inliers'
//    median ray angle under min_parallax_deg), the rotation alone explains them
//    (min_rotation_only of them): a camera that turned on the spot;
//  - the cameras look at most max_rotation_deg apart;
//  - the inliers cover min_spread of both images (InlierSpread, 4 x 4 cells).
// Default off: on the Strecha keyframe walks of shared/data it costs recall and lets through
// false loops the spread floor stops (docs/places.md, "Repeated architecture and wide
// baselines", has the counts and the command): the look-alike façades triangulate in front with
// ample parallax, while true pairs far apart put many of their inliers behind.
struct CalibratedCheckOptions {
  bool enabled = false;  // true: decides instead of the spread floor (see above)
  EssentialOptions essential;
  double min_in_front = 0.9;
  double max_rotation_deg = 90.0;
  double min_parallax_deg = 1.0;
  double min_rotation_only = 0.8;
  double min_spread = 0.125;
};

// What a frame knows of its 3D structure. `K`: the pinhole camera matrix of its keypoints (lens
// distortion removed). `points`: one per keypoint, camera frame, metres, NaN where unknown; or
// empty (a calibrated frame without depth: it can still be checked against entries with points).
struct FrameGeometry {
  cv::Matx33d K = cv::Matx33d::zeros();
  std::vector<cv::Point3f> points;
};

// How a loop was accepted (steps 5 and 6 of the header comment).
enum class LoopAcceptance {
  kNone,                 // no loop
  kTemporalConsistency,  // consistent with k previous queries, then verified (thesis)
  kStrongEvidence,       // consistent with fewer, but a strong geometric verification
  kRelocalisation,       // Query: the verified best candidate (no sequence, no consistency)
};
std::string_view LoopAcceptanceName(LoopAcceptance a);  // "none", "temporal_consistency", ...

// What the scores of a query are normalised by (step 3).
enum class ScoreNormalisation {
  // eta = s(v_t, w) / s(v_t, v_t-1) (eq. 3.11), and a frame whose score with the previous one is
  // under min_score_with_previous is not queried: video, where consecutive frames overlap.
  kPreviousFrame,
  // eta = s(v_t, w) / the best candidate's score (as Query does), and every frame with enough
  // features is queried: keyframes metres apart, whose previous keyframe may share no scene.
  kBestCandidate,
};
std::string_view ScoreNormalisationName(ScoreNormalisation n);  // "previous_frame", ...
StatusOr<ScoreNormalisation> ParseScoreNormalisation(std::string_view name);

// The named parameter sets (ParseDetectorPreset); a map keeps the name of the one it started
// from, and its stored settings are applied over that one.
enum class DetectorPreset { kDefault, kThesis, kKeyframes };
std::string_view DetectorPresetName(DetectorPreset preset);  // "default", "thesis", "keyframes"

struct LoopDetectorParams {
  DetectorPreset preset = DetectorPreset::kDefault;  // the preset these values started from
  uint32_t min_features = 20;                        // fewer features: the frame is not queried
  ScoreNormalisation normalisation = ScoreNormalisation::kPreviousFrame;
  double min_score_with_previous = 0.005;  // thesis Table 4.4 (kPreviousFrame only)
  double alpha = 0.3;                      // minimum normalised score eta (Table 4.4)
  // tau_c: entries added less than this before the frame are not candidates. Frames count when
  // the frame carries no timestamp; with a timestamp (any time, 0.0 included), seconds (Table
  // 4.4: 20 s).
  uint32_t recent_frames = 20;
  double recent_seconds = 20.0;
  uint32_t max_query_results = 50;  // database results considered per query
  // How a query of a large map is bounded (QueryOptions): postings read in full (0: every list),
  // and the best entries on those whose scores are completed.
  size_t query_full_scan_postings = QueryOptions{}.full_scan_postings;
  size_t query_rescored_candidates = QueryOptions{}.rescored_candidates;
  uint32_t island_max_gap = 3;              // entries at most this far apart (ids) join one island
  uint32_t island_min_size = 1;             // smaller islands are dropped
  uint32_t temporal_matches = 3;            // k: consistent previous queries required (Table 4.4)
  uint32_t consistency_max_island_gap = 3;  // ids between consecutive queries' islands
  uint32_t consistency_max_query_gap = 2;   // queries further apart restart the count
  GeometryCheck geometry = GeometryCheck::kDirectIndex;
  MatchOptions matching;              // ratio 0.6 (§4.4.6), max Hamming distance 50
  EpipolarOptions epipolar;           // 2 px, 12 inliers (Table 4.4)
  MetricCheckOptions metric;          // the 3D check, for frames with a FrameGeometry
  CalibratedCheckOptions calibrated;  // evidence (and, enabled, the check) of calibrated frames

  // Acceptance on strong evidence (step 6; not in the thesis): a candidate consistent with fewer
  // than temporal_matches previous queries, but at least strong_temporal_matches, is verified and
  // accepted when its verification is strong. Default on; Thesis() turns it off, and it has no
  // effect with geometry kNone (no verification, no evidence).
  bool strong_acceptance = true;
  // Default 0: a revisit's first frame can close the loop; on the corridor most misses of the
  // thesis detector are those first frames. At most temporal_matches.
  uint32_t strong_temporal_matches = 0;
  // Default 30 inliers: two and a half times the 12 that verify a candidate waiting for k. At
  // least epipolar.min_inliers; RANSAC does not even run with fewer correspondences.
  uint32_t strong_min_inliers = 30;
  // How many candidates are verified for strong evidence: the best island's best entry, then the
  // other candidates of an island, best score first; the strong one with the most inliers is
  // the loop. Default 1 (the best island's best entry only, as the thesis verifies); the
  // keyframes preset 10: on a walk of keyframes metres apart the best score often goes to a
  // look-alike place, and the true one is among the next (docs/places.md, "Repeated
  // architecture and wide baselines").
  uint32_t verified_candidates = 1;
  // Default 0.25: the inliers occupy at least 4 of the 4 x 4 cells over each image's keypoints,
  // in both images (InlierSpread): a match of one small textured patch is not a place.
  double strong_min_spread = 0.25;
  // The spread every verified loop needs (unless the calibrated check, enabled, decides with its
  // own CalibratedCheckOptions::min_spread). Default 0 (video: consecutive queries back a loop);
  // the keyframes preset 0.25: on the Strecha courtyard the look-alike façades' loops kept their
  // inliers on 2 or 3 of the 16 cells, one row of windows.
  double min_spread = 0.0;
  // Default 0.45: above this R_H, a homography explains the correspondences about as well as F
  // (0.5 = equally well), so F's inliers prove no 3D structure (two photos of one screen pass F
  // with 30 inliers). ORB-SLAM's initialisation switches to H at 0.40-0.45.
  double strong_max_homography_ratio = 0.45;
  ModelSelectionOptions model_selection;  // sigma 1 px; H by RANSAC with 2 px as F
  // Query (relocalisation, and searches across maps) accepts a place on one frame's evidence,
  // with no consistent queries behind it: its RANSAC needs at least this many inliers (and at
  // least epipolar.min_inliers). Default 16: robot B's frames looked up in robot A's map
  // (`recog eval place --split`) gave a false loop at the epipolar check's 12 inliers on a seqgen
  // tour and none from 16 on, which the corridor's true loops all reach (docs/places.md, "Queries
  // across maps").
  uint32_t relocalisation_min_inliers = 16;
  // Small frames (a 160x120 or 128x96 robot camera, often a fisheye one): their few features
  // give few inliers, true loops as false ones, and the false loops seen on such a camera had
  // fewer than 20. A frame of at most small_frame_pixels (FeatureSet::image_size; unknown: not
  // small) needs small_frame_min_inliers inliers in every verification. Defaults 320 x 240 and 20:
  // the floor costs the shared corridor downscaled to 160x120 and 128x96 few of its true loops
  // (the counts and the commands: docs/places.md, "Small frames" and "Repeated architecture and
  // wide baselines").
  uint32_t small_frame_pixels = 320 * 240;
  uint32_t small_frame_min_inliers = 20;
  // Keyframe confirmations (beyond the thesis; ORB-SLAM asks as much of its keyframes): with
  // N > 0, a verified loop is first a candidate (kCandidate), and it is accepted when each of the
  // next N queried frames also closes a verified loop next to it: a match at most island_max_gap
  // ids from the previous loop's, at most consistency_max_query_gap frames later, and, when both
  // loops have calibrated evidence (cameras known), a relative motion that agrees with the previous
  // loop's (the rotation the two loops imply between the two query frames within
  // max_motion_disagreement_deg of the one their own matches give, when their matches and the
  // two match frames' fix one: frames too alike or too far apart leave it unchecked). Once
  // confirmed, the loops that go on next to it are accepted at once. Latency: the first loop of a
  // revisit is answered N frames late (as a candidate before). Default 0: accepted at once.
  // At most kMaxKeyframeConfirmations: more would hold every loop back for ever.
  static constexpr uint32_t kMaxKeyframeConfirmations = 100;
  uint32_t keyframe_confirmations = 0;
  double max_motion_disagreement_deg = 15.0;

  // The thesis's detector (Table 4.4): every loop needs k consistent queries
  // (strong_acceptance off).
  static LoopDetectorParams Thesis();
  // For keyframe streams (a SLAM's keyframes, metres apart; chosen on the corridor's every 2nd,
  // 3rd and 4th frame and a seqgen tour of one frame per place, docs/places.md, "Keyframe
  // streams"): the scores normalised by the best candidate, tau_c of 3 keyframes (a loop may close
  // with the keyframe 4 back), consecutive loops consistent only when their islands are at most 1
  // keyframe apart, and a verification for views metres apart (chosen on the Strecha walks of
  // shared/data, docs/places.md, "Repeated architecture and wide baselines"): correspondences from
  // every pair of features with ratio 0.85, 64 bits and the cross check, 45 inliers for any loop,
  // spread over a quarter of both images, and up to 10 candidates verified.
  static LoopDetectorParams Keyframes();
  // OK, or INVALID_ARGUMENT naming the first field out of its range with its value
  // ("LoopDetectorParams.alpha = inf: must be finite and >= 0"); `name` names the struct in the
  // message (a holder passes the member's path, "RigLoopParams.detector"). A setting's range is
  // the settings table's (detector_settings.h) and its message names the setting
  // ("LoopDetectorParams.min_inliers = 7"); the other fields are named by their path
  // ("LoopDetectorParams.metric.min_inliers = 5").
  Status Validate(std::string_view name = "LoopDetectorParams") const;
};

// The preset named `name`: "default" (LoopDetectorParams{}), "thesis" (Thesis()) or "keyframes"
// (Keyframes()).
StatusOr<LoopDetectorParams> ParseDetectorPreset(std::string_view name);

// The figures behind a verified loop, so that a client can gate on its own thresholds (step 6).
struct LoopEvidence {
  uint32_t inliers = 0;  // of the fundamental matrix
  double spread = 0;     // InlierSpread over 4 x 4 cells: the smaller share of the two images
  // Both frames had a camera matrix and the inliers were triangulated through the essential
  // matrix K_match^T F K_query; the fields below are set only then.
  bool calibrated = false;
  double in_front = 0;         // share of the inliers in front of both cameras
  double parallax_deg = 0;     // median angle between an inlier's two rays
  double rotation_deg = 0;     // angle of the relative rotation
  bool pure_rotation = false;  // no parallax, and the rotation alone explains the inliers
  // The relative pose of the essential matrix: X_match = rotation * X_query + translation, the
  // translation of unit length (two views fix it up to scale).
  cv::Matx33d rotation = cv::Matx33d::eye();
  cv::Vec3d translation = cv::Vec3d(0, 0, 0);
  // Keyframes after the first candidate that confirmed the loop (keyframe_confirmations).
  uint32_t confirmations = 0;
};

struct LoopTimings {  // milliseconds spent in each stage for one frame
  double conversion = 0, query = 0, islands = 0, insertion = 0, verification = 0;
  double metric_verification = 0;  // VerifyMetric (0 when it did not run)
  // Candidates whose correspondences and RANSAC `verification` covers (up to verified_candidates;
  // 0 when none was verified).
  uint32_t verified_candidates = 0;
};

// The 3D check of a loop (VerifyMetric) and the metric relative pose it gives.
struct MetricLoop {
  // One side had 3D points and the other a camera matrix: the match's points and the query's
  // camera, or (a match without points) the query's points and the match's stored camera.
  bool checked = false;
  bool verified = false;         // the check passed (the loop agrees in structure)
  uint32_t correspondences = 0;  // epipolar inliers whose feature on that side has a 3D point
  std::vector<Match> inliers;    // PnP inliers (a = query feature, b = match feature)
  double rms_error_px = 0;       // reprojection RMS over the inliers
  // X_query = R * X_match + t: the match's camera frame into the query's, metres (set when
  // verified). The pose of the match's camera seen from the query's camera.
  cv::Matx33d R = cv::Matx33d::eye();
  cv::Vec3d t = cv::Vec3d(0, 0, 0);
  // Covariance of (R, t) as ComputePoseCovariance gives it (core/geometry/pose_covariance.h):
  // rotation vector first (radians, left perturbation of R), then t (metres); row-major. Zeros
  // when the geometry is degenerate.
  PoseCovariance6 covariance{};
};

// One entry of the database query's answer for a frame.
struct LoopCandidate {
  EntryId entry = kInvalidEntryId;
  double score = 0;             // s(v_t, w_entry)
  double normalized_score = 0;  // eta with the query's reference (may be below alpha; 0 if it is 0)
  friend bool operator==(const LoopCandidate&, const LoopCandidate&) = default;
};

struct LoopResult {
  LoopStatus status = LoopStatus::kNoCandidates;
  EntryId entry = kInvalidEntryId;  // id this frame got in the database (none for Query)
  EntryId match = kInvalidEntryId;  // the candidate (or verified loop) entry, when there is one
  double score = 0;                 // s(v_t, w_match)
  double normalized_score = 0;      // eta of the match
  double previous_score = 0;        // s(v_t, v_t-1) (0 for Query and kBestCandidate)
  EntryId island_first = kInvalidEntryId, island_last = kInvalidEntryId;
  double island_score = 0;          // H, the sum of eta over the island
  uint32_t consistent_queries = 0;  // previous queries the island is consistent with
  LoopAcceptance acceptance = LoopAcceptance::kNone;  // how the loop was accepted
  uint32_t correspondences = 0;                       // putative matches given to RANSAC
  std::vector<Match> inliers;  // a = this frame's feature, b = the match's feature
  cv::Matx33d fundamental = cv::Matx33d::zeros();
  // What the database query returned (at most max_query_results entries, best score first, equal
  // scores by increasing id), before alpha and the islands; empty when the frame was not queried.
  std::vector<LoopCandidate> candidates;
  MetricLoop metric;      // the 3D check, for frames with a FrameGeometry
  LoopEvidence evidence;  // of the verification (inliers set whenever step 6 ran)
  LoopTimings timings;
};

// tau_c for one query, as both detectors (this one and RigLoopDetector) give it: every id from
// `first_recent` on (an entry's here, a rig frame's there) is too recent to be a candidate. The
// default, kInvalidEntryId, is the bound of a query for which no stored frame is too recent.
struct RecencyBound {
  EntryId first_recent = kInvalidEntryId;
};

class LoopDetector {
 public:
  // `database` must outlive the detector. Its map fixes the vocabulary, scoring and the level of
  // the direct index. INVALID_ARGUMENT for bad parameters.
  static StatusOr<LoopDetector> Create(Database* database, const LoopDetectorParams& params);

  // Processes the next frame of the sequence (timestamp in seconds, none when unknown) and adds it
  // to the database, with the client's id of the frame (stored in its metadata, at most
  // kMaxClientIdBytes). Errors are only for bad input (e.g. descriptors of another format) or a
  // failing store; "no loop" is a result.
  // With `geometry` (may be null), the entry keeps its points and camera matrix, and a loop is
  // checked in 3D.
  // `excluded`: entries that are never candidates for this frame, beside tau_c's recent ones —
  // the client's own keyframes covisible with this one (ORB-SLAM leaves out the keyframes
  // connected to the query), which share its scene without being a revisit. Any order; ids the
  // map does not hold are ignored.
  StatusOr<LoopResult> Process(const FeatureSet& features,
                               std::optional<double> timestamp = std::nullopt,
                               std::string_view client_id = {},
                               const FrameGeometry* geometry = nullptr,
                               std::span<const EntryId> excluded = {});

  // Adds the next frame of the sequence (timestamp in seconds, none when unknown) to the database
  // without querying, and returns its entry id. The detector's state moves on as Process would
  // move it for a frame that is not queried: the frame counts in the sequence (and so in the gap
  // between queries for temporal consistency), is the previous usable frame when it has enough
  // features, and its timestamp bounds tau_c. The client id and the errors are as for Process.
  // With `geometry` (may be null), the entry keeps its 3D points and camera matrix.
  StatusOr<EntryId> Add(const FeatureSet& features, std::optional<double> timestamp = std::nullopt,
                        std::string_view client_id = {}, const FrameGeometry* geometry = nullptr);

  // Looks for the place of a single frame in the map, without adding the frame or changing the
  // detector (relocalisation). Every entry the map holds when the query runs is a candidate:
  // tau_c, which keeps a sequence from matching its own recent past, does not apply (so a query
  // takes no timestamp). As there is no previous frame, each candidate's score is normalised by
  // the best candidate's, eta = s / s_best, so alpha still keeps the candidates within a fraction
  // of a reference score; candidates are grouped into islands as by Process, and the best entry
  // of the best island is verified with the geometry check of the parameters. The status is
  // kLoopDetected when the place is recognised, else kTooFewFeatures, kNoCandidates, kLowScore
  // (only when alpha > 1 or every score is 0, as the best candidate's eta is 1),
  // kNoConsistentIsland or kFailedGeometry. `entry` stays kInvalidEntryId, `previous_score` and
  // `consistent_queries` 0, and the insertion time 0; a recognised place has acceptance
  // kRelocalisation.
  // Errors are only for bad input or a failing store. Safe to call from any number of threads,
  // concurrently with Process and Add.
  // With `geometry` (may be null), a recognised place is checked in 3D and gets the metric pose
  // when its entry has 3D points, or the query has them and the entry a camera matrix. `excluded`
  // as for Process.
  StatusOr<LoopResult> Query(const FeatureSet& features, const FrameGeometry* geometry = nullptr,
                             std::span<const EntryId> excluded = {}) const;

  // Query in three steps, for a frame looked up in several maps of one vocabulary at once
  // (SearchMaps): ConvertForQuery once for all the maps, Shortlist in each, then Recognise in
  // each with `reference_score` the best score over all of them. Scores are then normalised as
  // if the maps were one: a map whose candidates all score under alpha times the best map's is
  // not verified (kLowScore). Query is the three steps with the map's own best score. Thread
  // safety as Query.
  struct ConvertedFrame {
    BowVector bow;
    FeatureVector direct;
    double conversion_ms = 0;
  };
  struct Shortlist {
    std::vector<QueryResult> results;  // the map's best max_query_results entries
    double best_score = 0;
    double query_ms = 0;
  };
  Status ConvertForQuery(const FeatureSet& features, ConvertedFrame* frame) const;
  // `bound` leaves the recent entries out (RigLoopDetector's tau_c); by default none is.
  StatusOr<Shortlist> ShortlistFor(const ConvertedFrame& frame,
                                   std::span<const EntryId> excluded = {},
                                   RecencyBound bound = {}) const;
  StatusOr<LoopResult> Recognise(const FeatureSet& features, const ConvertedFrame& frame,
                                 const Shortlist& shortlist, double reference_score,
                                 const FrameGeometry* geometry = nullptr) const;

  // Step 6 alone, as Recognise runs it, against a given entry of the map (a multi-camera rig
  // picks its candidates across cameras, core/place/rig_loop_detector.h): the relocalisation
  // floor of inliers, then the 3D check with `geometry`. `match` is `entry`; the status is
  // kLoopDetected, kTooFewFeatures or kFailedGeometry. NOT_FOUND for an entry the map does not
  // hold. Thread safety as Query.
  StatusOr<LoopResult> VerifyEntry(const FeatureSet& features, const ConvertedFrame& frame,
                                   EntryId entry, const FrameGeometry* geometry = nullptr) const;

  const LoopDetectorParams& params() const { return params_; }

 private:
  struct PreviousMatch {
    uint64_t frame = 0;  // index of the query frame in this detector's sequence
    EntryId first = 0, last = 0;
    uint32_t consistent = 0;
  };
  // The last verified loop (keyframe confirmations).
  struct LastLoop {
    uint64_t frame = 0;               // index of its query frame in the sequence
    EntryId query = kInvalidEntryId;  // the entry its query frame became
    EntryId match = kInvalidEntryId;
    std::optional<cv::Matx33d> rotation;  // X_match = R X_query, when the evidence is calibrated
    uint32_t confirmations = 0;
  };

  LoopDetector(Database* database, const LoopDetectorParams& params)
      : database_(database), params_(params) {}
  bool HasEnoughFeatures(const FeatureSet& features) const {
    return features.size() >= params_.min_features;
  }
  // Step 1: the frame's bag of words and direct-index entry, as the map wants them.
  Status Convert(const FeatureSet& features, BowVector* bow, FeatureVector* direct) const;
  // tau_c for a frame at `timestamp`: by time when the frame has one, else by frames.
  RecencyBound RecencyBoundFor(std::optional<double> timestamp) const;
  // Step 2: the best max_query_results entries below `bound` that are not `excluded`.
  Status QueryDatabase(const BowVector& bow, RecencyBound bound, std::span<const EntryId> excluded,
                       std::vector<QueryResult>* results) const;
  // Candidates close in id (eq. 4.2): H is the sum of their eta, `best` the one with the highest.
  struct Island {
    EntryId first = 0, last = 0;
    double score = 0;  // H
    EntryId best = 0;
    double best_eta = 0, best_score = 0;
  };
  // Steps 3 and 4: normalises the scores of `results` by `reference` (eta = s / reference), keeps
  // those reaching alpha, groups them into `islands`, best H first (on a tie, the older first),
  // and fills the match, score, eta and island of `result` with the best. False, with the status
  // that says why, when no island is left.
  bool FindIslands(const std::vector<QueryResult>& results, double reference, LoopResult* result,
                   std::vector<Island>* islands) const;
  // The match, score, eta and island of `result` from `island`.
  static void SetIsland(const Island& island, LoopResult* result);
  // Acceptance on strong evidence (step 6): verifies the verified_candidates first candidates of
  // Process's query (the best island's best entry, unless `best_verified` says it has just failed
  // a weaker floor, then the other candidates of an island, with eta relative to `reference`) with
  // strong_min_inliers; the strong one with the most inliers becomes the loop
  // (kStrongEvidence), with the island it is in. Without one, `result` is kept as it is; its
  // verification time adds every trial's.
  Status AcceptStrongest(const FeatureSet& features, const FeatureVector& direct,
                         const cv::Matx33d* camera, double reference, bool best_verified,
                         LoopResult* result) const;
  // The 3D check (§3.3.3), after Verify passed: when one side has 3D points (see above), fills
  // result->metric (PnP RANSAC over the epipolar inliers with a 3D point, LM refinement, the
  // covariance) and sets kFailedGeometry when the loop does not agree in structure. Nothing when
  // neither side has points the other's camera can see, or the geometry check is kNone.
  Status VerifyMetric(const FeatureSet& features, const FrameGeometry& geometry,
                      LoopResult* result) const;
  // Step 6: verifies `result->match` with the geometry check of the parameters (nothing for
  // kNone) and `epipolar`, filling correspondences, inliers, fundamental matrix and verification
  // time; the status becomes kFailedGeometry when the check fails. With `strong`, also sets
  // *strong to whether a verified match is strong evidence (inliers, spread, R_H). With a
  // `camera` for the query (may be null) and a candidate stored with one, the calibrated evidence
  // (and, enabled, check).
  Status Verify(const FeatureSet& features, const FeatureVector& direct, const cv::Matx33d* camera,
                const EpipolarOptions& epipolar, LoopResult* result, bool* strong = nullptr) const;
  // Keyframe confirmations for a verified loop of frame `frame` (status kLoopDetected): counts the
  // loops before it that confirm it into result->evidence.confirmations and makes it a
  // kCandidate while they are fewer than keyframe_confirmations.
  Status Confirm(const FeatureSet& features, const FeatureVector& direct, const cv::Matx33d* camera,
                 uint64_t frame, LoopResult* result) const;
  // The rotation X_b = R X_a between two frames from their own matches (the five-point essential
  // matrix, CalibratedCheckOptions::essential; nullopt when they do not hold one with
  // epipolar.min_inliers inliers): `a` is the frame being processed (a_entry kInvalidEntryId) or
  // entry a_entry, `b` an entry of the map.
  StatusOr<std::optional<cv::Matx33d>> RotationBetween(
      EntryId a_entry, const std::vector<cv::KeyPoint>& a_keypoints, const cv::Mat& a_descriptors,
      const FeatureVector& a_direct, const cv::Matx33d& a_camera, EntryId b) const;
  // The putative matches of step 6 (the geometry check's matcher) between features a (the frame
  // being processed, a_entry kInvalidEntryId, or entry a_entry) and entry b's. An error names
  // both: DATA_LOSS for a stored entry whose direct index does not fit its features.
  Status Correspondences(EntryId a_entry, const cv::Mat& a_descriptors,
                         const FeatureVector& a_direct, const EntryRecord& b,
                         std::vector<Match>* matches) const;
  // The start of a one-frame result (Recognise, VerifyEntry): its conversion time; false, with
  // kTooFewFeatures, when the frame has too few features to be looked up.
  bool StartAlone(const FeatureSet& features, const ConvertedFrame& frame,
                  LoopResult* result) const;
  // Verify with the relocalisation floor of inliers (one frame's evidence), then VerifyMetric
  // with `geometry` (may be null); acceptance kRelocalisation when the loop holds.
  Status VerifyAlone(const FeatureSet& features, const ConvertedFrame& frame,
                     const FrameGeometry* geometry, LoopResult* result) const;
  // Step 7: adds the converted frame to the database and moves the detector's state on (the
  // previous usable frame, the timestamps for tau_c). Returns the frame's entry id.
  StatusOr<EntryId> Insert(const FeatureSet& features, const BowVector& bow,
                           const FeatureVector& direct, std::optional<double> timestamp,
                           std::string_view client_id, const FrameGeometry* geometry);

  Database* database_;
  LoopDetectorParams params_;
  uint64_t frames_seen_ = 0;
  std::optional<BowVector> previous_bow_;  // of the last frame with enough features
  std::optional<PreviousMatch> previous_match_;
  std::optional<LastLoop> last_loop_;
  // The timestamps of the timestamped entries this detector added (never decreasing), and their
  // ids, in id order.
  std::vector<double> entry_timestamps_;
  std::vector<EntryId> entry_ids_;
  std::vector<QueryResult> query_results_;  // reused by Process (Query uses its own)
  std::vector<Island> islands_;             // of Process's query, best H first
};

}  // namespace recog
