#include "core/place/loop_detector.h"

#include <algorithm>
#include <chrono>

namespace recog {
namespace {

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

}  // namespace

std::string_view LoopStatusName(LoopStatus status) {
  switch (status) {
    case LoopStatus::kLoopDetected:
      return "loop_detected";
    case LoopStatus::kTooFewFeatures:
      return "too_few_features";
    case LoopStatus::kLowScoreWithPrevious:
      return "low_score_with_previous";
    case LoopStatus::kNoCandidates:
      return "no_candidates";
    case LoopStatus::kLowScore:
      return "low_score";
    case LoopStatus::kNoConsistentIsland:
      return "no_consistent_island";
    case LoopStatus::kFailedTemporalConsistency:
      return "failed_temporal_consistency";
    case LoopStatus::kFailedGeometry:
      return "failed_geometry";
  }
  return "unknown";
}

std::string_view GeometryCheckName(GeometryCheck check) {
  switch (check) {
    case GeometryCheck::kDirectIndex:
      return "direct_index";
    case GeometryCheck::kExhaustive:
      return "exhaustive";
    case GeometryCheck::kNone:
      return "none";
  }
  return "unknown";
}

StatusOr<GeometryCheck> ParseGeometryCheck(std::string_view name) {
  for (GeometryCheck c :
       {GeometryCheck::kDirectIndex, GeometryCheck::kExhaustive, GeometryCheck::kNone}) {
    if (name == GeometryCheckName(c)) return c;
  }
  return Status::InvalidArgument("unknown geometry check '" + std::string(name) +
                                 "' (direct_index, exhaustive or none)");
}

Status LoopDetectorParams::Validate() const {
  if (!(alpha >= 0.0)) return Status::InvalidArgument("alpha must be >= 0");
  if (!(min_score_with_previous >= 0.0)) {
    return Status::InvalidArgument("min_score_with_previous must be >= 0");
  }
  if (!(recent_seconds >= 0.0)) return Status::InvalidArgument("recent_seconds must be >= 0");
  if (max_query_results == 0) return Status::InvalidArgument("max_query_results must be >= 1");
  if (island_min_size == 0) return Status::InvalidArgument("island_min_size must be >= 1");
  if (!(matching.ratio > 0.0 && matching.ratio <= 1.0)) {
    return Status::InvalidArgument("matching ratio must be in (0, 1]");
  }
  if (!(epipolar.threshold_px > 0.0) || !(epipolar.confidence > 0.0 && epipolar.confidence < 1.0) ||
      epipolar.max_iterations < 1 || epipolar.min_inliers < 8) {
    return Status::InvalidArgument(
        "RANSAC needs a threshold > 0, a confidence in (0, 1), iterations >= 1 and at least 8 "
        "inliers");
  }
  return Status::Ok();
}

StatusOr<LoopDetector> LoopDetector::Create(Database* database, const LoopDetectorParams& params) {
  if (database == nullptr) return Status::InvalidArgument("a loop detector needs a database");
  RECOG_RETURN_IF_ERROR(params.Validate());
  return LoopDetector(database, params);
}

EntryId LoopDetector::QueryBound(double timestamp) const {
  const EntryId next = database_->next_entry_id();
  if (timestamp <= 0.0) {
    return next > params_.recent_frames ? next - params_.recent_frames : 0;
  }
  // Entries this detector added after (timestamp - recent_seconds) are too recent; entries from
  // before this detector existed are older than all of them.
  const double limit = timestamp - params_.recent_seconds;
  const auto it = std::upper_bound(entry_timestamps_.begin(), entry_timestamps_.end(), limit);
  if (it == entry_timestamps_.end()) return next;
  return entry_ids_[size_t(it - entry_timestamps_.begin())];
}

StatusOr<LoopResult> LoopDetector::Process(const FeatureSet& features, double timestamp) {
  LoopResult result;
  const uint64_t frame = frames_seen_++;
  const MapConfig& map = database_->info().config;

  auto start = Clock::now();
  BowVector bow;
  FeatureVector direct;
  RECOG_RETURN_IF_ERROR(database_->vocabulary().Transform(features.descriptors, &bow, &direct,
                                                          int(map.direct_index_levels_up),
                                                          TraitsOf(map.scoring).normalization));
  result.timings.conversion = MsSince(start);

  const bool enough_features = features.size() >= params_.min_features;
  if (!enough_features) {
    result.status = LoopStatus::kTooFewFeatures;
  } else if (previous_bow_.has_value()) {
    result.previous_score = Score(map.scoring, bow, *previous_bow_);
    if (result.previous_score < params_.min_score_with_previous) {
      result.status = LoopStatus::kLowScoreWithPrevious;
    }
  } else {
    result.status = LoopStatus::kLowScoreWithPrevious;  // the first frame has nothing to compare
  }

  const bool query = enough_features && result.status != LoopStatus::kLowScoreWithPrevious;
  if (query) {
    start = Clock::now();
    RECOG_RETURN_IF_ERROR(database_->Query(
        bow, {.max_results = params_.max_query_results, .max_entry_id = QueryBound(timestamp)},
        &query_results_));
    result.timings.query = MsSince(start);

    start = Clock::now();
    // Normalised scores, then islands of entries close in id.
    const std::vector<QueryResult>& kept = query_results_;
    std::vector<std::pair<EntryId, std::pair<double, double>>> candidates;  // id -> (eta, score)
    for (const QueryResult& r : kept) {
      const double eta = r.score / result.previous_score;
      if (eta >= params_.alpha) candidates.push_back({r.id, {eta, r.score}});
    }
    if (kept.empty()) {
      result.status = LoopStatus::kNoCandidates;
    } else if (candidates.empty()) {
      result.status = LoopStatus::kLowScore;
    } else {
      std::sort(candidates.begin(), candidates.end());
      std::vector<Island> islands;
      size_t island_size = 0;
      for (size_t i = 0; i < candidates.size(); ++i) {
        const auto& [id, scores] = candidates[i];
        if (i == 0 || id - islands.back().last > params_.island_max_gap) {
          if (i > 0 && island_size < params_.island_min_size) islands.pop_back();
          islands.push_back({id, id, 0.0, id, 0.0, 0.0});
          island_size = 0;
        }
        Island& island = islands.back();
        island.last = id;
        island.score += scores.first;
        if (scores.first > island.best_eta) {
          island.best_eta = scores.first;
          island.best_score = scores.second;
          island.best = id;
        }
        ++island_size;
      }
      if (island_size < params_.island_min_size) islands.pop_back();
      if (islands.empty()) {
        result.status = LoopStatus::kNoConsistentIsland;
      } else {
        // Best island by H; on a tie, the older one.
        const Island& best =
            *std::max_element(islands.begin(), islands.end(),
                              [](const Island& a, const Island& b) { return a.score < b.score; });
        result.island_first = best.first;
        result.island_last = best.last;
        result.island_score = best.score;
        result.match = best.best;
        result.normalized_score = best.best_eta;
        result.score = best.best_score;

        // Temporal consistency with the previous query's island.
        uint32_t consistent = 0;
        if (previous_match_.has_value() &&
            frame - previous_match_->frame <= params_.consistency_max_query_gap) {
          const PreviousMatch& p = *previous_match_;
          const bool close = best.first <= uint64_t(p.last) + params_.consistency_max_island_gap &&
                             p.first <= uint64_t(best.last) + params_.consistency_max_island_gap;
          if (close) consistent = p.consistent + 1;
        }
        previous_match_ = PreviousMatch{frame, best.first, best.last, consistent};
        result.consistent_queries = consistent;
        result.status = consistent >= params_.temporal_matches
                            ? LoopStatus::kLoopDetected
                            : LoopStatus::kFailedTemporalConsistency;
      }
    }
    result.timings.islands = MsSince(start);

    if (result.status == LoopStatus::kLoopDetected && params_.geometry != GeometryCheck::kNone) {
      start = Clock::now();
      RECOG_RETURN_IF_ERROR(Verify(features, direct, &result));
      result.timings.verification = MsSince(start);
    }
  }
  if (enough_features) previous_bow_ = bow;

  start = Clock::now();
  EntryMetadata metadata;
  metadata.timestamp = timestamp;
  RECOG_ASSIGN_OR_RETURN(result.entry,
                         database_->AddConverted(bow, direct, features, std::move(metadata)));
  if (timestamp > 0.0) {
    entry_timestamps_.push_back(
        entry_timestamps_.empty() ? timestamp : std::max(timestamp, entry_timestamps_.back()));
    entry_ids_.push_back(result.entry);
  }
  result.timings.insertion = MsSince(start);
  return result;
}

Status LoopDetector::Verify(const FeatureSet& features, const FeatureVector& direct,
                            LoopResult* result) {
  RECOG_ASSIGN_OR_RETURN(EntryRecord candidate,
                         database_->Get(result->match, kEntryDirect | kEntryFeatures));
  std::vector<Match> matches;
  if (params_.geometry == GeometryCheck::kDirectIndex) {
    RECOG_RETURN_IF_ERROR(MatchByDirectIndex(direct, features.descriptors, candidate.direct,
                                             candidate.descriptors, params_.matching, &matches));
  } else {
    RECOG_RETURN_IF_ERROR(
        MatchExhaustive(features.descriptors, candidate.descriptors, params_.matching, &matches));
  }
  result->correspondences = uint32_t(matches.size());
  EpipolarResult epipolar =
      VerifyEpipolar(features.keypoints, candidate.keypoints, matches, params_.epipolar);
  result->fundamental = epipolar.fundamental;
  result->inliers = std::move(epipolar.inliers);
  if (!epipolar.verified) result->status = LoopStatus::kFailedGeometry;
  return Status::Ok();
}

}  // namespace recog
