#include "core/place/place_map.h"

#include "core/geometry/correspondences.h"

namespace recog {

StatusOr<std::shared_ptr<PlaceMap>> PlaceMap::Open(IndexStore* store, const std::string& name,
                                                   const LoopDetectorParams& params,
                                                   std::shared_ptr<const Vocabulary> vocabulary) {
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<Database> database,
                         Database::Open(store, name, std::move(vocabulary)));
  StatusOr<LoopDetector> detector = LoopDetector::Create(database.get(), params);
  if (!detector.ok()) return detector.status();
  return std::shared_ptr<PlaceMap>(
      new PlaceMap(store, name, params, std::move(database), std::move(detector).value()));
}

StatusOr<PlaceFrameResult> PlaceMap::Add(const FeatureSet& features, double timestamp) {
  PlaceFrameResult result;
  std::lock_guard lock(mutex_);
  if (deleted_) return Status::NotFound("map '" + name_ + "' was deleted");
  RECOG_ASSIGN_OR_RETURN(result.loop.entry, detector_.Add(features, timestamp));
  return result;
}

StatusOr<PlaceFrameResult> PlaceMap::Detect(const FeatureSet& features, double timestamp,
                                            const PlaceResultOptions& options) {
  PlaceFrameResult result;
  {
    std::lock_guard lock(mutex_);
    if (deleted_) return Status::NotFound("map '" + name_ + "' was deleted");
    RECOG_ASSIGN_OR_RETURN(result.loop, detector_.Process(features, timestamp));
  }
  RECOG_RETURN_IF_ERROR(AddExtras(features, options, &result));
  return result;
}

StatusOr<PlaceFrameResult> PlaceMap::Query(const FeatureSet& features, double timestamp,
                                           const PlaceResultOptions& options) const {
  PlaceFrameResult result;
  RECOG_ASSIGN_OR_RETURN(result.loop, detector_.Query(features, timestamp));
  RECOG_RETURN_IF_ERROR(AddExtras(features, options, &result));
  return result;
}

bool PlaceMap::deleted() const {
  std::lock_guard lock(mutex_);
  return deleted_;
}

StatusOr<size_t> PlaceMap::DeleteFrames() {
  std::lock_guard lock(mutex_);  // waits for the frame being added, then stops the others
  const size_t frames = database_->size();
  RECOG_RETURN_IF_ERROR(store_->DeleteMap(name_));
  deleted_ = true;
  return frames;
}

Status PlaceMap::AddExtras(const FeatureSet& features, const PlaceResultOptions& options,
                           PlaceFrameResult* result) const {
  const LoopResult& loop = result->loop;
  if (loop.match == kInvalidEntryId) return Status::Ok();
  const bool verified = loop.status == LoopStatus::kLoopDetected && !loop.inliers.empty();
  const bool pose = options.include_relative_pose && verified && options.camera_matrix.has_value();
  uint32_t parts = kEntryMetadata;
  if (pose) parts |= kEntryFeatures;
  StatusOr<EntryRecord> match = database_->Get(loop.match, parts);
  if (!match.ok()) {
    // The matched frame went away with its map (deleted meanwhile): answer without the extras.
    return match.status().code() == StatusCode::kNotFound ? Status::Ok() : match.status();
  }
  result->match_timestamp = match.value().metadata.timestamp;
  if (options.include_fundamental && verified) result->fundamental = loop.fundamental;
  if (pose) {
    RelativePose relative;
    if (RelativePoseFromFundamental(loop.fundamental, *options.camera_matrix, features.keypoints,
                                    match.value().keypoints, loop.inliers, &relative.R,
                                    &relative.t)) {
      result->relative_pose = relative;
    }
  }
  return Status::Ok();
}

}  // namespace recog
