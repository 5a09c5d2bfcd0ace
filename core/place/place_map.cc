#include "core/place/place_map.h"

#include <algorithm>

#include "core/geometry/correspondences.h"

namespace recog {
namespace {

// `entry` of `database` with `parts`, or nullopt when it is no longer stored (removed since the
// query, or its map deleted).
StatusOr<std::optional<EntryRecord>> StoredEntry(const Database& database, EntryId entry,
                                                 uint32_t parts) {
  StatusOr<EntryRecord> record = database.Get(entry, parts);
  if (record.ok()) return std::optional<EntryRecord>(std::move(record).value());
  if (record.status().code() == StatusCode::kNotFound) return std::optional<EntryRecord>();
  return record.status();
}

// The match's timestamp and client id (PlaceFrameResult, RigPlaceResult) from its stored record.
template <typename Result>
void SetMatchMetadata(EntryRecord& match, Result* result) {
  result->match_timestamp = match.metadata.timestamp;
  result->match_client_id = std::move(match.metadata.client_id);
}

// Appends a verified loop's inliers as correspondences: inlier (a, b) pairs keypoint a of the
// query frame with keypoint b of the stored match. INTERNAL for an inlier beyond the keypoints.
Status AppendCorrespondences(const std::vector<Match>& inliers,
                             const std::vector<cv::KeyPoint>& query,
                             const std::vector<cv::KeyPoint>& stored,
                             std::vector<PlaceCorrespondence>* out) {
  out->reserve(out->size() + inliers.size());
  for (const Match& m : inliers) {
    if (m.a >= query.size() || m.b >= stored.size()) {
      return Status::Internal("an inlier of the loop refers to no keypoint");
    }
    out->push_back({m.a, query[m.a].pt, m.b, stored[m.b].pt});
  }
  return Status::Ok();
}

}  // namespace

Status PlaceResultOptions::Validate() const {
  if (top_k > kMaxTopK) {
    return Status::InvalidArgument("top_k is at most " + std::to_string(kMaxTopK) + ", not " +
                                   std::to_string(top_k));
  }
  return Status::Ok();
}

StatusOr<std::shared_ptr<PlaceMap>> PlaceMap::Open(IndexStore* store, const std::string& name,
                                                   const LoopDetectorParams& params,
                                                   std::shared_ptr<const Vocabulary> vocabulary,
                                                   std::vector<RigCamera> rig) {
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<Database> database,
                         Database::Open(store, name, std::move(vocabulary)));
  StatusOr<LoopDetector> detector = LoopDetector::Create(database.get(), params);
  if (!detector.ok()) return detector.status();
  std::optional<RigLoopDetector> rig_detector;
  if (!rig.empty()) {
    RigLoopParams rig_params;
    rig_params.detector = params;
    StatusOr<RigLoopDetector> created =
        RigLoopDetector::Create(database.get(), std::move(rig), rig_params);
    if (!created.ok()) return created.status();
    rig_detector.emplace(std::move(created).value());
  }
  return std::shared_ptr<PlaceMap>(new PlaceMap(store, name, params, std::move(database),
                                                std::move(detector).value(),
                                                std::move(rig_detector)));
}

size_t PlaceMap::frames() const {
  if (!has_rig()) return database_->size();
  std::lock_guard lock(mutex_);
  return rig_detector_->frames();
}

Status PlaceMap::RequireRig(bool rig) const {
  if (rig && !has_rig()) {
    return Status::InvalidArgument("map '" + name_ + "' has no rig: send one image per frame");
  }
  if (!rig && has_rig()) {
    std::string cameras;
    for (const RigCamera& camera : rig_) cameras += (cameras.empty() ? "" : ", ") + camera.name;
    return Status::InvalidArgument("map '" + name_ + "' is a rig map: a frame needs one view per " +
                                   "camera (" + cameras + ")");
  }
  return Status::Ok();
}

StatusOr<RigPlaceResult> PlaceMap::AddRig(const RigFrame& frame) {
  RECOG_RETURN_IF_ERROR(RequireRig(true));
  RigPlaceResult result;
  std::lock_guard lock(mutex_);
  if (deleted_) return Status::NotFound("map '" + name_ + "' was deleted");
  RECOG_ASSIGN_OR_RETURN(result.loop.frame, rig_detector_->Add(frame));
  return result;
}

StatusOr<RigPlaceResult> PlaceMap::DetectRig(const RigFrame& frame, bool correspondences,
                                             std::span<const uint64_t> excluded) {
  RECOG_RETURN_IF_ERROR(RequireRig(true));
  RigPlaceResult result;
  std::lock_guard lock(mutex_);
  if (deleted_) return Status::NotFound("map '" + name_ + "' was deleted");
  RECOG_ASSIGN_OR_RETURN(result.loop, rig_detector_->Process(frame, excluded));
  RECOG_RETURN_IF_ERROR(AddRigExtras(frame, correspondences, &result));
  return result;
}

StatusOr<RigPlaceResult> PlaceMap::QueryRig(const RigFrame& frame, bool correspondences,
                                            std::span<const uint64_t> excluded) const {
  RECOG_RETURN_IF_ERROR(RequireRig(true));
  RigPlaceResult result;
  std::lock_guard lock(mutex_);
  if (deleted_) return Status::NotFound("map '" + name_ + "' was deleted");
  RECOG_ASSIGN_OR_RETURN(result.loop, rig_detector_->Query(frame, excluded));
  RECOG_RETURN_IF_ERROR(AddRigExtras(frame, correspondences, &result));
  return result;
}

Status PlaceMap::AddRigExtras(const RigFrame& frame, bool correspondences,
                              RigPlaceResult* result) const {
  const RigLoopResult& loop = result->loop;
  if (!loop.match_frame.has_value()) return Status::Ok();
  // Any stored camera image of the match carries its timestamp and client id.
  const EntryId any_image =
      loop.pairs.empty() ? EntryId(*loop.match_frame) : loop.pairs.front().entry;
  RECOG_ASSIGN_OR_RETURN(std::optional<EntryRecord> match,
                         StoredEntry(*database_, any_image, kEntryMetadata));
  if (match.has_value()) SetMatchMetadata(*match, result);  // none for a partial frame
  if (!correspondences || loop.status != RigLoopStatus::kLoopDetected) return Status::Ok();
  for (const RigCameraMatch& pair : loop.pairs) {
    RECOG_ASSIGN_OR_RETURN(const EntryRecord stored, database_->Get(pair.entry, kEntryFeatures));
    RECOG_RETURN_IF_ERROR(
        AppendCorrespondences(pair.verification.inliers, frame.cameras[pair.query_camera].keypoints,
                              stored.keypoints, &result->correspondences.emplace_back()));
  }
  return Status::Ok();
}

StatusOr<PlaceFrameResult> PlaceMap::Add(const FeatureSet& features,
                                         std::optional<double> timestamp,
                                         std::string_view client_id,
                                         const FrameGeometry* geometry) {
  RECOG_RETURN_IF_ERROR(RequireRig(false));
  PlaceFrameResult result;
  std::lock_guard lock(mutex_);
  if (deleted_) return Status::NotFound("map '" + name_ + "' was deleted");
  RECOG_ASSIGN_OR_RETURN(result.loop.entry,
                         detector_.Add(features, timestamp, client_id, geometry));
  return result;
}

StatusOr<PlaceFrameResult> PlaceMap::Detect(
    const FeatureSet& features, std::optional<double> timestamp, const PlaceResultOptions& options,
    std::string_view client_id, const FrameGeometry* geometry, std::span<const EntryId> excluded) {
  RECOG_RETURN_IF_ERROR(RequireRig(false));
  RECOG_RETURN_IF_ERROR(options.Validate());
  PlaceFrameResult result;
  {
    std::lock_guard lock(mutex_);
    if (deleted_) return Status::NotFound("map '" + name_ + "' was deleted");
    RECOG_ASSIGN_OR_RETURN(result.loop,
                           detector_.Process(features, timestamp, client_id, geometry, excluded));
  }
  RECOG_RETURN_IF_ERROR(AddExtras(features, options, &result));
  return result;
}

StatusOr<PlaceFrameResult> PlaceMap::Query(const FeatureSet& features,
                                           const PlaceResultOptions& options,
                                           const FrameGeometry* geometry,
                                           std::span<const EntryId> excluded) const {
  RECOG_RETURN_IF_ERROR(RequireRig(false));
  RECOG_RETURN_IF_ERROR(options.Validate());
  PlaceFrameResult result;
  StatusOr<LoopResult> loop = detector_.Query(features, geometry, excluded);
  if (loop.status().code() == StatusCode::kNotFound && !deleted()) {
    // A frame removed (RemoveFrame) between the detector's query and its geometric check.
    // deleted() took the map's lock, which RemoveFrame holds until the frame has left the index
    // too, so the query runs again without it.
    loop = detector_.Query(features, geometry, excluded);
  }
  if (!loop.ok()) return loop.status();
  result.loop = std::move(loop).value();
  RECOG_RETURN_IF_ERROR(AddExtras(features, options, &result));
  return result;
}

Status PlaceMap::ConvertForQuery(const FeatureSet& features,
                                 LoopDetector::ConvertedFrame* frame) const {
  return detector_.ConvertForQuery(features, frame);
}

bool PlaceMap::ConvertsLike(const PlaceMap& other) const {
  const MapConfig &mine = info().config, &theirs = other.info().config;
  return mine.vocabulary_checksum == theirs.vocabulary_checksum && mine.scoring == theirs.scoring &&
         mine.direct_index_levels_up == theirs.direct_index_levels_up;
}

StatusOr<LoopDetector::Shortlist> PlaceMap::Shortlist(
    const LoopDetector::ConvertedFrame& frame) const {
  RECOG_RETURN_IF_ERROR(RequireRig(false));
  return detector_.ShortlistFor(frame);
}

StatusOr<PlaceFrameResult> PlaceMap::Recognise(const FeatureSet& features,
                                               const LoopDetector::ConvertedFrame& frame,
                                               const LoopDetector::Shortlist& shortlist,
                                               double reference_score,
                                               const PlaceResultOptions& options,
                                               const FrameGeometry* geometry) const {
  RECOG_RETURN_IF_ERROR(options.Validate());
  PlaceFrameResult result;
  StatusOr<LoopResult> loop =
      detector_.Recognise(features, frame, shortlist, reference_score, geometry);
  if (loop.status().code() == StatusCode::kNotFound && !deleted()) {
    // A frame removed meanwhile, as in Query: shortlisted again without it.
    RECOG_ASSIGN_OR_RETURN(const LoopDetector::Shortlist again, detector_.ShortlistFor(frame));
    loop = detector_.Recognise(features, frame, again, reference_score, geometry);
  }
  if (!loop.ok()) return loop.status();
  result.loop = std::move(loop).value();
  RECOG_RETURN_IF_ERROR(AddExtras(features, options, &result));
  return result;
}

bool PlaceMap::deleted() const {
  std::lock_guard lock(mutex_);
  return deleted_;
}

StatusOr<uint64_t> PlaceMap::SaveIndexSnapshot() {
  {
    std::lock_guard lock(mutex_);
    if (deleted_) return Status::NotFound("map '" + name_ + "' was deleted");
  }
  // A deletion from here on makes the store refuse the snapshot.
  return database_->SaveSnapshot();
}

StatusOr<size_t> PlaceMap::DeleteFrames() {
  std::lock_guard lock(mutex_);  // waits for the frame being added, then stops the others
  const size_t frames = has_rig() ? rig_detector_->frames() : database_->size();
  RECOG_RETURN_IF_ERROR(store_->DeleteMap(name_));
  deleted_ = true;
  return frames;
}

Status PlaceMap::RemoveFrame(EntryId id) {
  std::lock_guard lock(mutex_);  // not in the middle of the detector's step
  if (deleted_) return Status::NotFound("map '" + name_ + "' was deleted");
  if (has_rig()) return rig_detector_->RemoveFrame(id);
  const Status removed = database_->Remove(id);
  if (removed.code() == StatusCode::kNotFound) {
    return Status::NotFound("map '" + name_ + "' has no frame " + std::to_string(id));
  }
  return removed;
}

StatusOr<std::vector<EntryId>> PlaceMap::RemoveFramesByClientId(const std::string& client_id) {
  if (client_id.empty()) return Status::InvalidArgument("the client frame id to remove is empty");
  std::lock_guard lock(mutex_);
  if (deleted_) return Status::NotFound("map '" + name_ + "' was deleted");
  std::vector<EntryId> ids;
  if (has_rig()) {
    RECOG_ASSIGN_OR_RETURN(const std::vector<uint64_t> frames,
                           rig_detector_->FramesWithClientId(client_id));
    ids.assign(frames.begin(), frames.end());
  } else {
    RECOG_RETURN_IF_ERROR(database_->ScanEntries(kEntryMetadata, [&](EntryRecord& entry) -> Status {
      if (entry.metadata.client_id == client_id) ids.push_back(entry.id);
      return Status::Ok();
    }));
  }
  if (ids.empty()) {
    return Status::NotFound("map '" + name_ + "' has no frame with client id '" + client_id + "'");
  }
  for (EntryId id : ids) {
    RECOG_RETURN_IF_ERROR(has_rig() ? rig_detector_->RemoveFrame(id) : database_->Remove(id));
  }
  return ids;
}

Status PlaceMap::AddExtras(const FeatureSet& features, const PlaceResultOptions& options,
                           PlaceFrameResult* result) const {
  const LoopResult& loop = result->loop;
  // The match went through the geometric check (whether it passed or not).
  const bool checked =
      params_.geometry != GeometryCheck::kNone &&
      (loop.status == LoopStatus::kLoopDetected || loop.status == LoopStatus::kFailedGeometry);
  const size_t top_k = std::min<size_t>(options.top_k, loop.candidates.size());
  for (size_t i = 0; i < top_k; ++i) {
    const LoopCandidate& candidate = loop.candidates[i];
    RECOG_ASSIGN_OR_RETURN(std::optional<EntryRecord> entry,
                           StoredEntry(*database_, candidate.entry, kEntryMetadata));
    if (!entry.has_value()) continue;  // no longer a candidate
    PlaceCandidate out{candidate.entry, std::move(entry->metadata.client_id), candidate.score,
                       candidate.normalized_score, std::nullopt};
    if (checked && candidate.entry == loop.match) out.inliers = uint32_t(loop.inliers.size());
    result->candidates.push_back(std::move(out));
  }

  if (loop.match == kInvalidEntryId) return Status::Ok();
  const bool verified = loop.status == LoopStatus::kLoopDetected && !loop.inliers.empty();
  const bool pose = options.include_relative_pose && verified && options.camera_matrix.has_value();
  const bool correspondences = options.include_correspondences && verified;
  uint32_t parts = kEntryMetadata;
  if (pose || correspondences) parts |= kEntryFeatures;
  RECOG_ASSIGN_OR_RETURN(std::optional<EntryRecord> match,
                         StoredEntry(*database_, loop.match, parts));
  // The matched frame went away with its map (deleted meanwhile): answer without the extras.
  if (!match.has_value()) return Status::Ok();
  SetMatchMetadata(*match, result);
  if (options.include_fundamental && verified) result->fundamental = loop.fundamental;
  if (correspondences) {
    RECOG_RETURN_IF_ERROR(AppendCorrespondences(loop.inliers, features.keypoints, match->keypoints,
                                                &result->correspondences));
  }
  if (pose) {
    RelativePose relative;
    // The matched frame's own camera when it came with one (another robot's), else the query's.
    const cv::Matx33d& match_camera = match->has_camera() ? match->camera : *options.camera_matrix;
    if (RelativePoseFromFundamental(loop.fundamental, *options.camera_matrix, match_camera,
                                    features.keypoints, match->keypoints, loop.inliers, &relative.R,
                                    &relative.t)) {
      result->relative_pose = relative;
    }
  }
  return Status::Ok();
}

}  // namespace recog
