// PlaceMap: one place map — a robot session's sequence of frames (a Database in the store) with
// the loop detector that runs on it — and the three things a frame can do to it.
//
//  - Add inserts the frame without querying (LoopDetector::Add: a robot uploading keyframes);
//  - Detect is the loop detector's step, query then add (LoopDetector::Process);
//  - Query looks for the place of the frame and changes nothing (LoopDetector::Query,
//    relocalisation).
// Detect and Query also return, when there is a match whose frame is still stored, the match's
// timestamp and client id (the id the client gave the frame when it was added), and on request:
// the top-k candidates of the database query with their client ids, and three extras that only a
// verified loop (kLoopDetected with RANSAC inliers) has: the fundamental matrix, the inlier
// correspondences (keypoint indices and pixels in both frames), and the relative pose of the two
// cameras recovered from F, which needs the query camera's matrix K.
//
// RemoveFrame removes frames (keyframe culling): a removed frame is never a candidate again, in
// this process or after a restart. Ids are never reused.
//
// A map created with a rig (MapRegistry::Create) is a rig map: its frames are rig frames, one
// image per camera, run by a RigLoopDetector (rig_loop_detector.h) through AddRig, DetectRig and
// QueryRig, and the single-camera calls refuse it (INVALID_ARGUMENT), as the rig calls refuse a
// map without a rig. Its frame ids are rig frame ids; RemoveFrame removes every camera image of a
// rig frame. A rig map's queries take the map's lock (the rig detector's frame table changes with
// every frame added), so they wait for the frame being added instead of running beside it.
//
// Maps are opened, created and deleted by MapRegistry (map_registry.h); holders of a map that the
// registry deleted keep a valid object whose writes fail.
//
// Thread safety: every method may be called from any thread. Add and Detect take the map's lock:
// frames of one map are added one at a time, in the order they get the lock. Query does not take
// it and runs concurrently with them and with other queries (the detector and the database allow
// it). Deletion (by the registry) takes the lock too, so it waits for the frame being added; after
// it, Add and Detect return NOT_FOUND "map '<name>' was deleted". A Query racing a deletion
// answers from what the map held, without the extras whose frame is gone.
// RemoveFrame takes the lock as well; a Query racing it does not fail for it: it answers with or
// without the frame.
#pragma once

#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "core/index/database.h"
#include "core/index/index_store.h"
#include "core/place/loop_detector.h"
#include "core/place/rig_loop_detector.h"

namespace recog {

// What Detect and Query add to the loop result.
struct PlaceResultOptions {
  static constexpr uint32_t kMaxTopK = 50;  // the detector's default max_query_results

  bool include_fundamental = false;
  bool include_relative_pose = false;
  bool include_correspondences = false;
  // The best top_k candidates of the query, 0..kMaxTopK (fewer when the map's max_query_results
  // is lower or the query returns fewer).
  uint32_t top_k = 0;
  // K of the query frame; the relative pose needs it. The matched frame's own camera matrix is
  // used for its side when it was added with one (another robot's camera), else this one.
  std::optional<cv::Matx33d> camera_matrix;

  // INVALID_ARGUMENT when top_k is above kMaxTopK.
  Status Validate() const;
};

// The pose of the matched frame's camera relative to the query's, as RelativePoseFromFundamental
// gives it (a = the query frame, b = the match): X_match = R * X_query + t, with |t| = 1 (two views
// fix the translation only up to scale).
struct RelativePose {
  cv::Matx33d R = cv::Matx33d::eye();
  cv::Vec3d t = {0, 0, 0};
};

// A candidate of the query, as a client sees it.
struct PlaceCandidate {
  EntryId frame = kInvalidEntryId;
  std::string client_id;        // what the client gave the frame (empty when nothing)
  double score = 0;             // s(v_t, v_frame)
  double normalized_score = 0;  // eta (below alpha for candidates the detector dropped)
  // RANSAC inliers, for the candidate that was verified geometrically (the loop's match when the
  // check ran); nothing for the others.
  std::optional<uint32_t> inliers;
};

// One inlier correspondence of a verified loop: keypoint `query_index` of the frame at
// `query_pixel` matches keypoint `match_index` of the matched frame (as stored) at `match_pixel`.
struct PlaceCorrespondence {
  uint32_t query_index = 0;
  cv::Point2f query_pixel;
  uint32_t match_index = 0;
  cv::Point2f match_pixel;
};

struct PlaceFrameResult {
  // The detector's result. Add fills only `entry` (the id the frame got); Detect fills everything
  // with `entry` set; Query everything but `entry`.
  LoopResult loop;
  std::optional<double> match_timestamp;   // of loop.match, when it is still stored and has one
  std::string match_client_id;             // of loop.match (empty when none or not given)
  std::vector<PlaceCandidate> candidates;  // asked for: the best top_k, best score first
  std::vector<PlaceCorrespondence> correspondences;  // asked for and verified: the inliers
  std::optional<cv::Matx33d> fundamental;            // asked for and verified
  std::optional<RelativePose> relative_pose;         // asked for, verified, K given and recoverable
};

// What a rig frame did to a rig map: the rig detector's result (AddRig fills only loop.frame),
// with the match's timestamp and client id when it is still stored, and on request the inlier
// correspondences of each camera pair.
struct RigPlaceResult {
  RigLoopResult loop;
  std::optional<double> match_timestamp;
  std::string match_client_id;
  // Asked for: one list per pair of loop.pairs, in its order (query keypoints as given).
  std::vector<std::vector<PlaceCorrespondence>> correspondences;
};

class PlaceMap {
 public:
  // Opens the map `name` of `store` (its database must exist) with its detector parameters, as a
  // rig map when `rig` has cameras. NOT_FOUND when the store has no such map, INVALID_ARGUMENT for
  // bad parameters or a bad rig, DATA_LOSS for a rig map whose frames are not rig frames.
  static StatusOr<std::shared_ptr<PlaceMap>> Open(IndexStore* store, const std::string& name,
                                                  const LoopDetectorParams& params,
                                                  std::shared_ptr<const Vocabulary> vocabulary,
                                                  std::vector<RigCamera> rig = {});

  // Adds the frame (timestamp in seconds, none when unknown) without querying. `client_id` (at most
  // kMaxClientIdBytes) is stored with the frame and returned whenever it is a match. `geometry`
  // (may be null) is the frame's 3D structure (LoopDetector: the frame keeps its points and its
  // loops are checked in 3D, LoopResult::metric).
  StatusOr<PlaceFrameResult> Add(const FeatureSet& features, std::optional<double> timestamp,
                                 std::string_view client_id = {},
                                 const FrameGeometry* geometry = nullptr);
  // Queries the map with the frame, then adds it (loop-closure detection), with `client_id` as
  // for Add. `excluded` frames are never candidates (the client's keyframes covisible with this
  // one; LoopDetector::Process). INVALID_ARGUMENT for bad options (nothing is added then).
  StatusOr<PlaceFrameResult> Detect(const FeatureSet& features, std::optional<double> timestamp,
                                    const PlaceResultOptions& options = {},
                                    std::string_view client_id = {},
                                    const FrameGeometry* geometry = nullptr,
                                    std::span<const EntryId> excluded = {});
  // Looks for the frame's place, leaving out the `excluded` frames; adds nothing and changes
  // nothing (LoopDetector::Query: no tau_c, so no timestamp).
  StatusOr<PlaceFrameResult> Query(const FeatureSet& features,
                                   const PlaceResultOptions& options = {},
                                   const FrameGeometry* geometry = nullptr,
                                   std::span<const EntryId> excluded = {}) const;
  // Query in steps, for a frame looked up in several maps at once (SearchMaps; see
  // LoopDetector::Recognise): the frame converted once by any map that ConvertsLike the others,
  // each map's Shortlist, then Recognise with the best score over the maps, which adds the
  // extras of `options` as Query does.
  Status ConvertForQuery(const FeatureSet& features, LoopDetector::ConvertedFrame* frame) const;
  bool ConvertsLike(const PlaceMap& other) const;
  StatusOr<LoopDetector::Shortlist> Shortlist(const LoopDetector::ConvertedFrame& frame) const;
  StatusOr<PlaceFrameResult> Recognise(const FeatureSet& features,
                                       const LoopDetector::ConvertedFrame& frame,
                                       const LoopDetector::Shortlist& shortlist,
                                       double reference_score,
                                       const PlaceResultOptions& options = {},
                                       const FrameGeometry* geometry = nullptr) const;

  // Rig maps: RigLoopDetector::Add, Process and Query under the map's lock, with the match's
  // timestamp and client id and, with `correspondences`, each pair's inliers. `excluded` rig
  // frames are never candidates. INVALID_ARGUMENT for a map without a rig, or a frame that does
  // not fit the rig (naming the camera; nothing is added).
  StatusOr<RigPlaceResult> AddRig(const RigFrame& frame);
  StatusOr<RigPlaceResult> DetectRig(const RigFrame& frame, bool correspondences = false,
                                     std::span<const uint64_t> excluded = {});
  StatusOr<RigPlaceResult> QueryRig(const RigFrame& frame, bool correspondences = false,
                                    std::span<const uint64_t> excluded = {}) const;

  // Removes frame `id` (keyframe culling). NOT_FOUND when the map has no such frame (never added,
  // or removed already) or was deleted.
  Status RemoveFrame(EntryId id);
  // Removes every frame whose client id is `client_id` (non-empty) and returns their ids, in
  // increasing order. It reads the metadata of every frame of the map (linear in the map's size;
  // RemoveFrame by id is constant time). NOT_FOUND when no frame has that client id.
  StatusOr<std::vector<EntryId>> RemoveFramesByClientId(const std::string& client_id);

  // Writes the map's index snapshot (Database::SaveSnapshot), which the next open loads instead
  // of reading every frame; returns the bytes written, 0 when it is already current. Frames being
  // added wait for it; queries do not. NOT_FOUND once the map is deleted.
  StatusOr<uint64_t> SaveIndexSnapshot();
  // How opening the map built its index.
  const DatabaseOpenReport& open_report() const { return database_->open_report(); }

  const std::string& name() const { return name_; }
  // The map group it was created in (MapRegistry::Create; empty for none).
  const std::string& group() const { return group_; }
  const LoopDetectorParams& params() const { return params_; }
  const MapInfo& info() const { return database_->info(); }
  const Vocabulary& vocabulary() const { return database_->vocabulary(); }
  // Frames stored (rig frames for a rig map), and the id the next one will get.
  size_t frames() const;
  EntryId next_frame_id() const { return database_->next_entry_id(); }
  bool deleted() const;
  // The rig of a rig map; empty for a single-camera map.
  const std::vector<RigCamera>& rig() const { return rig_; }
  bool has_rig() const { return !rig_.empty(); }

 private:
  friend class MapRegistry;

  PlaceMap(IndexStore* store, std::string name, const LoopDetectorParams& params,
           std::unique_ptr<Database> database, LoopDetector detector,
           std::optional<RigLoopDetector> rig_detector)
      : store_(store),
        name_(std::move(name)),
        params_(params),
        database_(std::move(database)),
        detector_(std::move(detector)),
        rig_detector_(std::move(rig_detector)) {
    if (rig_detector_.has_value()) rig_ = rig_detector_->rig();
  }

  // INVALID_ARGUMENT unless the map is (`rig`) or is not a rig map.
  Status RequireRig(bool rig) const;
  // The rig extras of `result` (RigPlaceResult); requires the lock.
  Status AddRigExtras(const RigFrame& frame, bool correspondences, RigPlaceResult* result) const;

  // Deletes the map's frames from the store and marks the map deleted, under the lock (for
  // MapRegistry::Delete). Returns how many frames it had.
  StatusOr<size_t> DeleteFrames();
  // Fills the match timestamp and client id, and the extras `options` asks for.
  Status AddExtras(const FeatureSet& features, const PlaceResultOptions& options,
                   PlaceFrameResult* result) const;

  IndexStore* const store_;
  const std::string name_;
  std::string group_;  // set by MapRegistry before it publishes the map, then never changed
  const LoopDetectorParams params_;
  const std::unique_ptr<Database> database_;  // declared before the detector, which points to it
  mutable std::mutex mutex_;  // guards detector_'s Add/Process, rig_detector_ and deleted_
  LoopDetector detector_;     // single-camera maps
  std::optional<RigLoopDetector> rig_detector_;  // rig maps
  std::vector<RigCamera> rig_;                   // rig maps: rig_detector_'s cameras
  bool deleted_ = false;
};

}  // namespace recog
