#include "core/place/loop_detector.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include <opencv2/calib3d.hpp>

#include "core/common/elapsed.h"
#include "core/common/option_checks.h"
#include "core/common/rotation_angle.h"
#include "core/place/detector_settings.h"

namespace recog {
namespace {

using Clock = std::chrono::steady_clock;

// The query's answer as candidates, eta = s / reference (0 when the reference is 0).
std::vector<LoopCandidate> Candidates(const std::vector<QueryResult>& results, double reference) {
  std::vector<LoopCandidate> candidates;
  candidates.reserve(results.size());
  for (const QueryResult& r : results) {
    candidates.push_back({r.id, r.score, reference > 0.0 ? r.score / reference : 0.0});
  }
  return candidates;
}

// The reference of eta when there is no previous frame to normalise by: the best candidate's
// score (the results come best first), 0 without candidates.
double BestScore(const std::vector<QueryResult>& results) {
  return results.empty() ? 0.0 : results.front().score;
}

// Before the frame changes the detector's state (Database::AddConverted checks it too late).
Status CheckClientId(std::string_view client_id) {
  if (client_id.size() <= kMaxClientIdBytes) return Status::Ok();
  return Status::InvalidArgument("a frame's client id is at most " +
                                 std::to_string(kMaxClientIdBytes) + " bytes");
}

// INVALID_ARGUMENT unless `geometry` (when given) has a usable camera matrix and one point per
// keypoint (or none).
Status CheckGeometry(const FeatureSet& features, const FrameGeometry* geometry) {
  if (geometry == nullptr) return Status::Ok();
  const cv::Matx33d& K = geometry->K;
  if (!(K(0, 0) > 0.0) || !(K(1, 1) > 0.0) || !std::isfinite(K(0, 2)) || !std::isfinite(K(1, 2))) {
    return Status::InvalidArgument("frame geometry needs a camera matrix with fx, fy > 0");
  }
  if (!geometry->points.empty() && geometry->points.size() != features.size()) {
    return Status::InvalidArgument("frame geometry has " + std::to_string(geometry->points.size()) +
                                   " 3D points for " + std::to_string(features.size()) +
                                   " keypoints");
  }
  return Status::Ok();
}

// The query's camera matrix for the calibrated check, when it has one.
const cv::Matx33d* CameraOf(const FrameGeometry* geometry) {
  return geometry != nullptr ? &geometry->K : nullptr;
}

bool IsUsablePoint(const cv::Point3f& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z) && p.z > 0.0f;
}

// The grid of InlierSpread for strong evidence: 4 x 4 cells over each image.
constexpr int kSpreadGrid = 4;

// Whether the inliers of `essential` make a physical two-view geometry (CalibratedCheckOptions):
// in front of both cameras, or a pure rotation the rotation alone explains; `pure_rotation`, when
// not null, says which.
bool PhysicallyPlausible(const EssentialResult& essential, const CalibratedCheckOptions& options,
                         bool* pure_rotation = nullptr) {
  const double inliers = double(essential.inliers.size());
  const bool rotation = essential.parallax_deg < options.min_parallax_deg &&
                        essential.rotation_only >= options.min_rotation_only * inliers;
  if (pure_rotation != nullptr) *pure_rotation = rotation;
  return inliers > 0 && (essential.in_front >= options.min_in_front * inliers || rotation);
}

// The calibrated evidence of a loop between the query (a: camera K_query) and a candidate (b:
// K_match), given the fundamental matrix fitted to their matches (`fitted`, verified): how its
// inliers triangulate through the essential matrix K_match^T F K_query. Fills `evidence` and says
// whether they make physical sense (CalibratedCheckOptions).
bool MeasureCalibrated(const cv::Matx33d& K_query, const cv::Matx33d& K_match,
                       const std::vector<cv::KeyPoint>& query_keypoints,
                       const std::vector<cv::KeyPoint>& match_keypoints,
                       const EpipolarResult& fitted, double threshold_px,
                       const CalibratedCheckOptions& options, LoopEvidence* evidence) {
  const EssentialResult essential =
      MeasureEssential(K_match.t() * fitted.fundamental * K_query, K_query, K_match,
                       query_keypoints, match_keypoints, fitted.inliers, threshold_px);
  if (!essential.found) return false;
  evidence->calibrated = true;
  const bool geometry = PhysicallyPlausible(essential, options, &evidence->pure_rotation);
  evidence->in_front = essential.in_front / double(fitted.inliers.size());
  evidence->parallax_deg = essential.parallax_deg;
  evidence->rotation_deg = RotationAngleDeg(essential.R);
  evidence->rotation = essential.R;
  evidence->translation = essential.t;
  return geometry && evidence->rotation_deg <= options.max_rotation_deg &&
         evidence->spread >= options.min_spread;
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
    case LoopStatus::kCandidate:
      return "candidate";
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

std::string_view LoopAcceptanceName(LoopAcceptance a) {
  switch (a) {
    case LoopAcceptance::kNone:
      return "none";
    case LoopAcceptance::kTemporalConsistency:
      return "temporal_consistency";
    case LoopAcceptance::kStrongEvidence:
      return "strong_evidence";
    case LoopAcceptance::kRelocalisation:
      return "relocalisation";
  }
  return "unknown";
}

std::string_view ScoreNormalisationName(ScoreNormalisation n) {
  switch (n) {
    case ScoreNormalisation::kPreviousFrame:
      return "previous_frame";
    case ScoreNormalisation::kBestCandidate:
      return "best_candidate";
  }
  return "unknown";
}

StatusOr<ScoreNormalisation> ParseScoreNormalisation(std::string_view name) {
  for (ScoreNormalisation n :
       {ScoreNormalisation::kPreviousFrame, ScoreNormalisation::kBestCandidate}) {
    if (name == ScoreNormalisationName(n)) return n;
  }
  return Status::InvalidArgument("unknown score normalisation '" + std::string(name) +
                                 "' (previous_frame or best_candidate)");
}

std::string_view DetectorPresetName(DetectorPreset preset) {
  switch (preset) {
    case DetectorPreset::kDefault:
      return "default";
    case DetectorPreset::kThesis:
      return "thesis";
    case DetectorPreset::kKeyframes:
      return "keyframes";
  }
  return "unknown";
}

LoopDetectorParams LoopDetectorParams::Thesis() {
  LoopDetectorParams params;
  params.preset = DetectorPreset::kThesis;
  params.strong_acceptance = false;
  return params;
}

LoopDetectorParams LoopDetectorParams::Keyframes() {
  LoopDetectorParams params;
  params.preset = DetectorPreset::kKeyframes;
  params.normalisation = ScoreNormalisation::kBestCandidate;
  params.recent_frames = 3;
  params.consistency_max_island_gap = 1;
  params.min_spread = 0.25;
  params.geometry = GeometryCheck::kExhaustive;
  params.matching = {.ratio = 0.85, .max_distance = 64, .mutual = true};
  params.epipolar.min_inliers = 45;
  params.strong_min_inliers = 45;
  params.verified_candidates = 10;
  return params;
}

StatusOr<LoopDetectorParams> ParseDetectorPreset(std::string_view name) {
  if (name == "default") return LoopDetectorParams{};
  if (name == "thesis") return LoopDetectorParams::Thesis();
  if (name == "keyframes") return LoopDetectorParams::Keyframes();
  return Status::InvalidArgument("unknown detector preset '" + std::string(name) +
                                 "' (default, thesis or keyframes)");
}

Status LoopDetectorParams::Validate(std::string_view name) const {
  OptionChecks check(name);
  // The range of every setting is the settings table's, named as the setting.
  CheckDetectorSettingRanges(*this, &check);
  // The fields that are not settings. PnP of the metric check needs 6 correspondences.
  check.InRange("metric.threshold_px", metric.threshold_px, RealRange::Above(0));
  check.InRange("metric.confidence", metric.confidence, RealRange::Open(0, 1));
  check.AtLeast("metric.max_iterations", metric.max_iterations, 1);
  check.AtLeast("metric.min_inliers", metric.min_inliers, 6);
  check.InRange("metric.min_inlier_ratio", metric.min_inlier_ratio, RealRange::Closed(0, 1));
  check.InRange("metric.min_sigma_px", metric.min_sigma_px, RealRange::AtLeast(0));
  check.InRange("calibrated.essential.threshold_px", calibrated.essential.threshold_px,
                RealRange::Above(0));
  check.InRange("calibrated.essential.confidence", calibrated.essential.confidence,
                RealRange::Open(0, 1));
  check.AtLeast("calibrated.essential.max_iterations", calibrated.essential.max_iterations, 1);
  check.InRange("calibrated.min_parallax_deg", calibrated.min_parallax_deg, RealRange::AtLeast(0));
  check.InRange("calibrated.min_rotation_only", calibrated.min_rotation_only,
                RealRange::Closed(0, 1));
  check.InRange("model_selection.sigma_px", model_selection.sigma_px, RealRange::Above(0));
  check.InRange("model_selection.threshold_px", model_selection.threshold_px, RealRange::Above(0));
  check.InRange("model_selection.confidence", model_selection.confidence, RealRange::Open(0, 1));
  check.AtLeast("model_selection.max_iterations", model_selection.max_iterations, 1);
  // The rules between settings, which no range can say.
  check.Require(strong_temporal_matches <= temporal_matches, "strong_temporal_matches",
                strong_temporal_matches,
                "<= temporal_matches (" + std::to_string(temporal_matches) + ")");
  check.Require(strong_min_inliers >= epipolar.min_inliers, "strong_min_inliers",
                strong_min_inliers,
                ">= min_inliers (" + std::to_string(epipolar.min_inliers) + ")");
  return check.status();
}

StatusOr<LoopDetector> LoopDetector::Create(Database* database, const LoopDetectorParams& params) {
  if (database == nullptr) return Status::InvalidArgument("a loop detector needs a database");
  RECOG_RETURN_IF_ERROR(params.Validate());
  return LoopDetector(database, params);
}

RecencyBound LoopDetector::RecencyBoundFor(std::optional<double> timestamp) const {
  if (!timestamp.has_value()) {
    const EntryId next = database_->next_entry_id();
    if (params_.recent_frames == 0) return {};
    return {next > params_.recent_frames ? next - params_.recent_frames : 0};
  }
  // Entries this detector added after (timestamp - recent_seconds) are too recent; entries from
  // before this detector existed are older than all of them.
  const double limit = *timestamp - params_.recent_seconds;
  const auto it = std::upper_bound(entry_timestamps_.begin(), entry_timestamps_.end(), limit);
  if (it == entry_timestamps_.end()) return {};
  return {entry_ids_[size_t(it - entry_timestamps_.begin())]};
}

Status LoopDetector::Convert(const FeatureSet& features, BowVector* bow,
                             FeatureVector* direct) const {
  const MapConfig& map = database_->info().config;
  return database_->vocabulary().Transform(features.descriptors, bow, direct,
                                           int(map.direct_index_levels_up),
                                           TraitsOf(map.scoring).normalization);
}

bool LoopDetector::FindIslands(const std::vector<QueryResult>& results, double reference,
                               LoopResult* result, std::vector<Island>* islands) const {
  struct Candidate {
    EntryId id;
    double eta, score;
  };
  std::vector<Candidate> candidates;
  for (const QueryResult& r : results) {
    const double eta = r.score / reference;
    if (eta >= params_.alpha) candidates.push_back({r.id, eta, r.score});
  }
  if (results.empty()) {
    result->status = LoopStatus::kNoCandidates;
    return false;
  }
  if (candidates.empty()) {
    result->status = LoopStatus::kLowScore;
    return false;
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& a, const Candidate& b) { return a.id < b.id; });
  islands->clear();
  size_t island_size = 0;
  for (size_t i = 0; i < candidates.size(); ++i) {
    const Candidate& c = candidates[i];
    if (i == 0 || c.id - islands->back().last > params_.island_max_gap) {
      if (i > 0 && island_size < params_.island_min_size) islands->pop_back();
      islands->push_back({c.id, c.id, 0.0, c.id, 0.0, 0.0});
      island_size = 0;
    }
    Island& island = islands->back();
    island.last = c.id;
    island.score += c.eta;
    if (c.eta > island.best_eta) {
      island.best_eta = c.eta;
      island.best_score = c.score;
      island.best = c.id;
    }
    ++island_size;
  }
  if (island_size < params_.island_min_size) islands->pop_back();
  if (islands->empty()) {
    result->status = LoopStatus::kNoConsistentIsland;
    return false;
  }
  // By H; on a tie, the older one first.
  std::stable_sort(islands->begin(), islands->end(),
                   [](const Island& a, const Island& b) { return a.score > b.score; });
  SetIsland(islands->front(), result);
  return true;
}

void LoopDetector::SetIsland(const Island& island, LoopResult* result) {
  result->island_first = island.first;
  result->island_last = island.last;
  result->island_score = island.score;
  result->match = island.best;
  result->normalized_score = island.best_eta;
  result->score = island.best_score;
}

Status LoopDetector::QueryDatabase(const BowVector& bow, RecencyBound bound,
                                   std::span<const EntryId> excluded,
                                   std::vector<QueryResult>* results) const {
  // Asks for as many more results as entries are left out, so that max_query_results remain.
  RECOG_RETURN_IF_ERROR(
      database_->Query(bow,
                       {.max_results = params_.max_query_results + excluded.size(),
                        .max_entry_id = bound.first_recent,
                        .full_scan_postings = params_.query_full_scan_postings,
                        .rescored_candidates = params_.query_rescored_candidates},
                       results));
  if (!excluded.empty()) {
    std::erase_if(*results, [&](const QueryResult& r) {
      return std::find(excluded.begin(), excluded.end(), r.id) != excluded.end();
    });
  }
  if (results->size() > params_.max_query_results) results->resize(params_.max_query_results);
  return Status::Ok();
}

StatusOr<LoopResult> LoopDetector::Process(const FeatureSet& features,
                                           std::optional<double> timestamp,
                                           std::string_view client_id,
                                           const FrameGeometry* geometry,
                                           std::span<const EntryId> excluded) {
  RECOG_RETURN_IF_ERROR(CheckClientId(client_id));
  RECOG_RETURN_IF_ERROR(CheckGeometry(features, geometry));
  LoopResult result;
  const uint64_t frame = frames_seen_++;

  auto start = Clock::now();
  BowVector bow;
  FeatureVector direct;
  RECOG_RETURN_IF_ERROR(Convert(features, &bow, &direct));
  result.timings.conversion = MillisecondsSince(start);

  const bool enough_features = HasEnoughFeatures(features);
  if (!enough_features) {
    result.status = LoopStatus::kTooFewFeatures;
  } else if (params_.normalisation == ScoreNormalisation::kBestCandidate) {
    // Every frame with enough features is queried; eta is relative to the best candidate.
  } else if (previous_bow_.has_value()) {
    result.previous_score = Score(database_->info().config.scoring, bow, *previous_bow_);
    if (result.previous_score < params_.min_score_with_previous) {
      result.status = LoopStatus::kLowScoreWithPrevious;
    }
  } else {
    result.status = LoopStatus::kLowScoreWithPrevious;  // the first frame has nothing to compare
  }

  const bool query = enough_features && result.status != LoopStatus::kLowScoreWithPrevious;
  if (query) {
    start = Clock::now();
    RECOG_RETURN_IF_ERROR(
        QueryDatabase(bow, RecencyBoundFor(timestamp), excluded, &query_results_));
    result.timings.query = MillisecondsSince(start);
    const double reference = params_.normalisation == ScoreNormalisation::kBestCandidate
                                 ? BestScore(query_results_)
                                 : result.previous_score;
    result.candidates = Candidates(query_results_, reference);

    start = Clock::now();
    if (FindIslands(query_results_, reference, &result, &islands_)) {
      // Temporal consistency with the previous query's island.
      uint32_t consistent = 0;
      if (previous_match_.has_value() &&
          frame - previous_match_->frame <= params_.consistency_max_query_gap) {
        const PreviousMatch& p = *previous_match_;
        const bool close =
            result.island_first <= uint64_t(p.last) + params_.consistency_max_island_gap &&
            p.first <= uint64_t(result.island_last) + params_.consistency_max_island_gap;
        if (close) consistent = p.consistent + 1;
      }
      previous_match_ = PreviousMatch{frame, result.island_first, result.island_last, consistent};
      result.consistent_queries = consistent;
      result.status = consistent >= params_.temporal_matches
                          ? LoopStatus::kLoopDetected
                          : LoopStatus::kFailedTemporalConsistency;
    }
    result.timings.islands = MillisecondsSince(start);

    const bool strong_allowed = params_.strong_acceptance &&
                                params_.geometry != GeometryCheck::kNone &&
                                result.consistent_queries >= params_.strong_temporal_matches;
    if (result.status == LoopStatus::kLoopDetected) {
      RECOG_RETURN_IF_ERROR(
          Verify(features, direct, CameraOf(geometry), params_.epipolar, &result));
      if (result.status == LoopStatus::kLoopDetected) {
        result.acceptance = LoopAcceptance::kTemporalConsistency;
      } else if (strong_allowed && params_.verified_candidates > 1) {
        // The consistent candidate failed: the next ones may still be strong evidence.
        RECOG_RETURN_IF_ERROR(AcceptStrongest(features, direct, CameraOf(geometry), reference,
                                              /*best_verified=*/true, &result));
      }
    } else if (result.status == LoopStatus::kFailedTemporalConsistency && strong_allowed) {
      // Too few consistent queries for a weak candidate: a strong one is accepted now.
      RECOG_RETURN_IF_ERROR(AcceptStrongest(features, direct, CameraOf(geometry), reference,
                                            /*best_verified=*/false, &result));
    }
    if (result.status == LoopStatus::kLoopDetected && geometry != nullptr) {
      RECOG_RETURN_IF_ERROR(VerifyMetric(features, *geometry, &result));
    }
    if (result.status == LoopStatus::kLoopDetected && params_.keyframe_confirmations > 0) {
      RECOG_RETURN_IF_ERROR(Confirm(features, direct, CameraOf(geometry), frame, &result));
    }
  }

  start = Clock::now();
  RECOG_ASSIGN_OR_RETURN(result.entry,
                         Insert(features, bow, direct, timestamp, client_id, geometry));
  result.timings.insertion = MillisecondsSince(start);
  if (result.status == LoopStatus::kLoopDetected || result.status == LoopStatus::kCandidate) {
    const LoopEvidence& evidence = result.evidence;
    last_loop_ = LastLoop{frame, result.entry, result.match,
                          evidence.calibrated ? std::optional(evidence.rotation) : std::nullopt,
                          evidence.confirmations};
  }
  return result;
}

StatusOr<EntryId> LoopDetector::Add(const FeatureSet& features, std::optional<double> timestamp,
                                    std::string_view client_id, const FrameGeometry* geometry) {
  RECOG_RETURN_IF_ERROR(CheckClientId(client_id));
  RECOG_RETURN_IF_ERROR(CheckGeometry(features, geometry));
  ++frames_seen_;
  BowVector bow;
  FeatureVector direct;
  RECOG_RETURN_IF_ERROR(Convert(features, &bow, &direct));
  return Insert(features, bow, direct, timestamp, client_id, geometry);
}

StatusOr<LoopResult> LoopDetector::Query(const FeatureSet& features, const FrameGeometry* geometry,
                                         std::span<const EntryId> excluded) const {
  RECOG_RETURN_IF_ERROR(CheckGeometry(features, geometry));
  ConvertedFrame frame;
  RECOG_RETURN_IF_ERROR(ConvertForQuery(features, &frame));
  RECOG_ASSIGN_OR_RETURN(const Shortlist shortlist, ShortlistFor(frame, excluded));
  return Recognise(features, frame, shortlist, shortlist.best_score, geometry);
}

Status LoopDetector::ConvertForQuery(const FeatureSet& features, ConvertedFrame* frame) const {
  const auto start = Clock::now();
  RECOG_RETURN_IF_ERROR(Convert(features, &frame->bow, &frame->direct));
  frame->conversion_ms = MillisecondsSince(start);
  return Status::Ok();
}

StatusOr<LoopDetector::Shortlist> LoopDetector::ShortlistFor(const ConvertedFrame& frame,
                                                             std::span<const EntryId> excluded,
                                                             RecencyBound bound) const {
  Shortlist shortlist;
  const auto start = Clock::now();
  // The whole map, without tau_c: entry_ids_/entry_timestamps_ belong to Process and Add.
  // (Not query_results_: Process may be using it.)
  RECOG_RETURN_IF_ERROR(QueryDatabase(frame.bow, bound, excluded, &shortlist.results));
  shortlist.best_score = BestScore(shortlist.results);
  shortlist.query_ms = MillisecondsSince(start);
  return shortlist;
}

StatusOr<LoopResult> LoopDetector::Recognise(const FeatureSet& features,
                                             const ConvertedFrame& frame,
                                             const Shortlist& shortlist, double reference_score,
                                             const FrameGeometry* geometry) const {
  RECOG_RETURN_IF_ERROR(CheckGeometry(features, geometry));
  LoopResult result;
  if (!StartAlone(features, frame, &result)) return result;
  result.timings.query = shortlist.query_ms;

  const auto start = Clock::now();
  result.candidates = Candidates(shortlist.results, reference_score);
  std::vector<Island> islands;
  const bool found = FindIslands(shortlist.results, reference_score, &result, &islands);
  if (found) result.status = LoopStatus::kLoopDetected;
  result.timings.islands = MillisecondsSince(start);

  if (found) RECOG_RETURN_IF_ERROR(VerifyAlone(features, frame, geometry, &result));
  return result;
}

StatusOr<LoopResult> LoopDetector::VerifyEntry(const FeatureSet& features,
                                               const ConvertedFrame& frame, EntryId entry,
                                               const FrameGeometry* geometry) const {
  RECOG_RETURN_IF_ERROR(CheckGeometry(features, geometry));
  LoopResult result;
  if (!StartAlone(features, frame, &result)) return result;
  result.status = LoopStatus::kLoopDetected;
  result.match = entry;
  RECOG_RETURN_IF_ERROR(VerifyAlone(features, frame, geometry, &result));
  return result;
}

bool LoopDetector::StartAlone(const FeatureSet& features, const ConvertedFrame& frame,
                              LoopResult* result) const {
  result->timings.conversion = frame.conversion_ms;
  if (HasEnoughFeatures(features)) return true;
  result->status = LoopStatus::kTooFewFeatures;
  return false;
}

Status LoopDetector::VerifyAlone(const FeatureSet& features, const ConvertedFrame& frame,
                                 const FrameGeometry* geometry, LoopResult* result) const {
  // One frame's evidence, with no consistent queries behind it: a higher floor of inliers.
  EpipolarOptions epipolar = params_.epipolar;
  epipolar.min_inliers = std::max<size_t>(epipolar.min_inliers, params_.relocalisation_min_inliers);
  RECOG_RETURN_IF_ERROR(Verify(features, frame.direct, CameraOf(geometry), epipolar, result));
  if (result->status != LoopStatus::kLoopDetected) return Status::Ok();
  result->acceptance = LoopAcceptance::kRelocalisation;
  if (geometry != nullptr) RECOG_RETURN_IF_ERROR(VerifyMetric(features, *geometry, result));
  return Status::Ok();
}

StatusOr<EntryId> LoopDetector::Insert(const FeatureSet& features, const BowVector& bow,
                                       const FeatureVector& direct, std::optional<double> timestamp,
                                       std::string_view client_id, const FrameGeometry* geometry) {
  if (HasEnoughFeatures(features)) previous_bow_ = bow;
  EntryMetadata metadata;
  metadata.timestamp = timestamp;
  metadata.client_id = client_id;
  std::vector<cv::Point3f> points;
  cv::Matx33d camera = cv::Matx33d::zeros();
  if (geometry != nullptr) {
    points = geometry->points;
    camera = geometry->K;
  }
  RECOG_ASSIGN_OR_RETURN(const EntryId id,
                         database_->AddConverted(bow, direct, features, std::move(metadata),
                                                 std::move(points), camera));
  if (timestamp.has_value()) {
    entry_timestamps_.push_back(
        entry_timestamps_.empty() ? *timestamp : std::max(*timestamp, entry_timestamps_.back()));
    entry_ids_.push_back(id);
  }
  return id;
}

Status LoopDetector::AcceptStrongest(const FeatureSet& features, const FeatureVector& direct,
                                     const cv::Matx33d* camera, double reference,
                                     bool best_verified, LoopResult* result) const {
  // The best island's best entry, then the other candidates of an island, best score first
  // (query_results_ comes so), each with its island.
  struct Trial {
    const QueryResult* candidate;
    const Island* island;
  };
  std::vector<Trial> trials;
  for (const QueryResult& r : query_results_) {
    if (trials.size() + 1 >= params_.verified_candidates) break;
    if (r.id == result->match || r.score < params_.alpha * reference) continue;
    const auto island = std::find_if(islands_.begin(), islands_.end(), [&](const Island& x) {
      return x.first <= r.id && r.id <= x.last;
    });
    if (island != islands_.end()) trials.push_back({&r, &*island});
  }
  // RANSAC runs only when there are correspondences enough for strong_min_inliers.
  EpipolarOptions epipolar = params_.epipolar;
  epipolar.min_inliers = params_.strong_min_inliers;
  std::optional<LoopResult> strongest;
  double verification_ms = result->timings.verification;
  uint32_t verified = result->timings.verified_candidates;
  for (size_t i = best_verified ? 1 : 0; i <= trials.size(); ++i) {
    LoopResult trial = *result;
    trial.timings.verification = 0;
    trial.timings.verified_candidates = 0;
    if (i > 0) {
      const QueryResult& r = *trials[i - 1].candidate;
      SetIsland(*trials[i - 1].island, &trial);
      trial.match = r.id;
      trial.score = r.score;
      trial.normalized_score = r.score / reference;
    }
    bool strong = false;
    RECOG_RETURN_IF_ERROR(Verify(features, direct, camera, epipolar, &trial, &strong));
    verification_ms += trial.timings.verification;
    verified += trial.timings.verified_candidates;
    if (strong && (!strongest || trial.evidence.inliers > strongest->evidence.inliers)) {
      strongest = std::move(trial);
    }
  }
  if (strongest.has_value()) {
    *result = *std::move(strongest);
    result->status = LoopStatus::kLoopDetected;
    result->acceptance = LoopAcceptance::kStrongEvidence;
  }
  result->timings.verification = verification_ms;
  result->timings.verified_candidates = verified;
  return Status::Ok();
}

Status LoopDetector::Verify(const FeatureSet& features, const FeatureVector& direct,
                            const cv::Matx33d* camera, const EpipolarOptions& epipolar_options,
                            LoopResult* result, bool* strong) const {
  // epipolar_options with the floor of small frames (below).
  if (params_.geometry == GeometryCheck::kNone) return Status::Ok();
  const auto start = Clock::now();
  RECOG_ASSIGN_OR_RETURN(EntryRecord candidate,
                         database_->Get(result->match, kEntryDirect | kEntryFeatures));
  std::vector<Match> matches;
  RECOG_RETURN_IF_ERROR(
      Correspondences(kInvalidEntryId, features.descriptors, direct, candidate, &matches));
  result->correspondences = uint32_t(matches.size());
  EpipolarOptions epipolar = epipolar_options;
  const int64_t pixels = int64_t(features.image_size.area());
  if (pixels > 0 && pixels <= int64_t(params_.small_frame_pixels)) {
    epipolar.min_inliers = std::max<size_t>(epipolar.min_inliers, params_.small_frame_min_inliers);
  }
  LoopEvidence& evidence = result->evidence;
  EpipolarResult fitted =
      VerifyEpipolar(features.keypoints, candidate.keypoints, matches, epipolar);
  result->fundamental = fitted.fundamental;
  evidence.inliers = uint32_t(fitted.inliers.size());
  evidence.spread =
      InlierSpread(features.keypoints, candidate.keypoints, fitted.inliers, kSpreadGrid);
  // With both cameras known, the evidence says how the inliers triangulate; the calibrated check,
  // when enabled, then decides instead of the uncalibrated spread floor.
  const bool plausible =
      fitted.verified && camera != nullptr && candidate.has_camera() &&
      MeasureCalibrated(*camera, candidate.camera, features.keypoints, candidate.keypoints, fitted,
                        epipolar.threshold_px, params_.calibrated, &evidence);
  const bool checked_calibrated = params_.calibrated.enabled && evidence.calibrated;
  const bool verified =
      fitted.verified && (checked_calibrated ? plausible : evidence.spread >= params_.min_spread);
  result->inliers = std::move(fitted.inliers);
  if (!verified) result->status = LoopStatus::kFailedGeometry;
  if (strong != nullptr) {
    // The calibrated check itself has ruled out what R_H guards against (no parallax, points
    // behind a camera); otherwise the homography's RANSAC runs only when still needed.
    *strong = verified && evidence.spread >= params_.strong_min_spread &&
              (checked_calibrated
                   ? !evidence.pure_rotation
                   : SelectTwoViewModel(features.keypoints, candidate.keypoints, result->inliers,
                                        result->fundamental, params_.model_selection)
                             .homography_ratio <= params_.strong_max_homography_ratio);
  }
  result->timings.verification = MillisecondsSince(start);
  result->timings.verified_candidates = 1;
  return Status::Ok();
}

Status LoopDetector::Correspondences(EntryId a_entry, const cv::Mat& a_descriptors,
                                     const FeatureVector& a_direct, const EntryRecord& b,
                                     std::vector<Match>* matches) const {
  const Status matched =
      params_.geometry == GeometryCheck::kDirectIndex
          ? MatchByDirectIndex(a_direct, a_descriptors, b.direct, b.descriptors, params_.matching,
                               matches)
          : MatchExhaustive(a_descriptors, b.descriptors, params_.matching, matches);
  if (matched.ok()) return matched;
  // The matcher calls the two sides A and B: say which frames they are (a damaged entry's
  // direct index is DATA_LOSS).
  const std::string a_name =
      a_entry == kInvalidEntryId ? "the frame" : "entry " + std::to_string(a_entry);
  return matched.WithContext("matching " + a_name + " (A) with entry " + std::to_string(b.id) +
                             " (B)");
}

StatusOr<std::optional<cv::Matx33d>> LoopDetector::RotationBetween(
    EntryId a_entry, const std::vector<cv::KeyPoint>& a_keypoints, const cv::Mat& a_descriptors,
    const FeatureVector& a_direct, const cv::Matx33d& a_camera, EntryId b) const {
  RECOG_ASSIGN_OR_RETURN(EntryRecord entry, database_->Get(b, kEntryDirect | kEntryFeatures));
  if (!entry.has_camera()) return std::optional<cv::Matx33d>();
  std::vector<Match> matches;
  RECOG_RETURN_IF_ERROR(Correspondences(a_entry, a_descriptors, a_direct, entry, &matches));
  const EssentialResult essential = VerifyEssential(
      a_camera, entry.camera, a_keypoints, entry.keypoints, matches, params_.calibrated.essential);
  const bool held = essential.found && essential.inliers.size() >= params_.epipolar.min_inliers &&
                    PhysicallyPlausible(essential, params_.calibrated);
  return held ? std::optional(essential.R) : std::nullopt;
}

Status LoopDetector::Confirm(const FeatureSet& features, const FeatureVector& direct,
                             const cv::Matx33d* camera, uint64_t frame, LoopResult* result) const {
  uint32_t confirmations = 0;
  const auto distance = [](EntryId x, EntryId y) { return x > y ? x - y : y - x; };
  if (last_loop_.has_value() && frame - last_loop_->frame <= params_.consistency_max_query_gap &&
      distance(result->match, last_loop_->match) <= params_.island_max_gap) {
    bool agrees = true;
    if (result->evidence.calibrated && last_loop_->rotation.has_value() && camera != nullptr) {
      // X_match = R X_query for both loops; the two query frames and the two matches by their own
      // matches: predicted R_now = R_matches * R_before * R_queries.
      RECOG_ASSIGN_OR_RETURN(
          const std::optional<cv::Matx33d> queries,
          RotationBetween(kInvalidEntryId, features.keypoints, features.descriptors, direct,
                          *camera, last_loop_->query));
      std::optional<cv::Matx33d> matches = cv::Matx33d::eye();
      if (result->match != last_loop_->match) {
        RECOG_ASSIGN_OR_RETURN(EntryRecord before,
                               database_->Get(last_loop_->match, kEntryDirect | kEntryFeatures));
        RECOG_ASSIGN_OR_RETURN(
            matches, RotationBetween(before.id, before.keypoints, before.descriptors, before.direct,
                                     before.camera, result->match));
      }
      // Frames too alike (or too far apart) to fix a rotation between them leave the motion
      // unchecked: the neighbourhood alone confirms then.
      agrees = !queries.has_value() || !matches.has_value() ||
               RotationAngleDeg(result->evidence.rotation,
                                *matches * *last_loop_->rotation * *queries) <=
                   params_.max_motion_disagreement_deg;
    }
    if (agrees) confirmations = last_loop_->confirmations + 1;
  }
  result->evidence.confirmations = confirmations;
  if (confirmations < params_.keyframe_confirmations) {
    result->status = LoopStatus::kCandidate;
  }
  return Status::Ok();
}

Status LoopDetector::VerifyMetric(const FeatureSet& features, const FrameGeometry& geometry,
                                  LoopResult* result) const {
  if (params_.geometry == GeometryCheck::kNone) return Status::Ok();
  const auto start = Clock::now();
  RECOG_ASSIGN_OR_RETURN(EntryRecord candidate, database_->Get(result->match, kEntryFeatures));
  // The 3D points come from the match, seen by the query's camera; or, when the match has none,
  // from the query, seen by the match's camera (stored when the match came with intrinsics). The
  // pose is then solved the other way round and inverted.
  const bool points_of_match = !candidate.points.empty();
  if (!points_of_match && (geometry.points.empty() || !candidate.has_camera())) {
    return Status::Ok();
  }
  const std::vector<cv::Point3f>& points = points_of_match ? candidate.points : geometry.points;
  const std::vector<cv::KeyPoint>& keypoints =
      points_of_match ? features.keypoints : candidate.keypoints;
  const cv::Matx33d& K = points_of_match ? geometry.K : candidate.camera;
  MetricLoop& metric = result->metric;
  metric.checked = true;
  std::vector<Match> pairs;
  std::vector<cv::Point3f> object;
  std::vector<cv::Point2f> image;
  for (const Match& m : result->inliers) {
    const uint32_t point = points_of_match ? m.b : m.a;
    const uint32_t pixel = points_of_match ? m.a : m.b;
    if (point >= points.size() || !IsUsablePoint(points[point])) continue;
    pairs.push_back(m);
    object.push_back(points[point]);
    image.push_back(keypoints[pixel].pt);
  }
  metric.correspondences = uint32_t(pairs.size());
  const MetricCheckOptions& options = params_.metric;
  cv::Vec3d rvec, tvec;
  std::vector<int> ransac_inliers;
  const bool solved = pairs.size() >= options.min_inliers &&
                      cv::solvePnPRansac(object, image, K, cv::noArray(), rvec, tvec, false,
                                         options.max_iterations, float(options.threshold_px),
                                         options.confidence, ransac_inliers, cv::SOLVEPNP_EPNP);
  std::vector<cv::Point3f> inlier_object;
  std::vector<cv::Point2f> inlier_image;
  if (solved && ransac_inliers.size() >= 6) {
    for (int i : ransac_inliers) {
      inlier_object.push_back(object[size_t(i)]);
      inlier_image.push_back(image[size_t(i)]);
    }
    cv::solvePnPRefineLM(inlier_object, inlier_image, K, cv::noArray(), rvec, tvec);
    // The inliers of the refined pose.
    std::vector<cv::Point2f> projected;
    cv::projectPoints(object, rvec, tvec, K, cv::noArray(), projected);
    inlier_object.clear();
    inlier_image.clear();
    cv::Matx33d R;
    cv::Rodrigues(rvec, R);
    double squared_sum = 0;
    const double threshold2 = options.threshold_px * options.threshold_px;
    for (size_t i = 0; i < pairs.size(); ++i) {
      const cv::Point2f d = projected[i] - image[i];
      const double e2 = double(d.x) * d.x + double(d.y) * d.y;
      const cv::Vec3d x(object[i].x, object[i].y, object[i].z);
      if ((R * x + tvec)[2] <= 0.0 || e2 > threshold2) continue;
      metric.inliers.push_back(pairs[i]);
      inlier_object.push_back(object[i]);
      inlier_image.push_back(image[i]);
      squared_sum += e2;
    }
    if (!metric.inliers.empty()) {
      metric.rms_error_px = std::sqrt(squared_sum / double(metric.inliers.size()));
    }
  }
  const size_t inliers = metric.inliers.size();
  metric.verified = inliers >= options.min_inliers &&
                    double(inliers) >= options.min_inlier_ratio * double(pairs.size());
  if (metric.verified) {
    cv::Matx33d R;
    cv::Rodrigues(rvec, R);
    if (!ComputePoseCovariance(K, R, tvec, inlier_object, inlier_image, options.min_sigma_px,
                               &metric.covariance)) {
      metric.covariance.fill(0.0);
    }
    if (points_of_match) {
      metric.R = R;
      metric.t = tvec;
    } else {  // solved as X_match = R X_query + t
      metric.R = R.t();
      metric.t = -(R.t() * tvec);
      metric.covariance = InversePoseCovariance(R, tvec, metric.covariance);
    }
  } else {
    result->status = LoopStatus::kFailedGeometry;
    result->acceptance = LoopAcceptance::kNone;
  }
  result->timings.metric_verification = MillisecondsSince(start);
  return Status::Ok();
}

}  // namespace recog
