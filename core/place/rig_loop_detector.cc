#include "core/place/rig_loop_detector.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <unordered_map>

#include <opencv2/calib3d.hpp>

#include "core/common/elapsed.h"
#include "core/common/option_checks.h"
#include "core/common/rotation_angle.h"
#include "core/geometry/correspondences.h"
#include "core/geometry/rig_motion.h"

namespace recog {
namespace {

using Clock = std::chrono::steady_clock;

cv::Matx33d SkewMatrix(const cv::Vec3d& v) {
  return {0, -v[2], v[1], v[2], 0, -v[0], -v[1], v[0], 0};
}

// The covariance of a camera pair's pose (rotation vector with a left perturbation, then t) as the
// covariance of the body pose it implies: R_body = A R B, t_body = A t + c - R_body d, so a
// perturbation (dr, dt) of the pair moves the body pose by (A dr, A dt + [R_body d]x A dr).
PoseCovariance6 BodyCovariance(const PoseCovariance6& pair, const cv::Matx33d& A,
                               const cv::Matx33d& body_R, const cv::Vec3d& d) {
  cv::Matx<double, 6, 6> J = cv::Matx<double, 6, 6>::zeros();
  const cv::Matx33d coupling = SkewMatrix(body_R * d) * A;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      J(r, c) = A(r, c);
      J(r + 3, c + 3) = A(r, c);
      J(r + 3, c) = coupling(r, c);
    }
  }
  cv::Matx<double, 6, 6> cov;
  std::copy(pair.begin(), pair.end(), cov.val);
  const cv::Matx<double, 6, 6> body = J * cov * J.t();
  PoseCovariance6 out{};
  std::copy(body.val, body.val + 36, out.begin());
  return out;
}

// A camera pair's inliers as rays of each camera, with the cameras' poses on the body.
RigPairRays PairRays(const RigCamera& query, const RigCamera& match,
                     const std::vector<cv::KeyPoint>& query_keypoints,
                     const std::vector<cv::KeyPoint>& match_keypoints,
                     const std::vector<Match>& inliers) {
  RigPairRays rays;
  rays.query_R = query.body_R_camera;
  rays.query_t = query.body_t_camera;
  rays.match_R = match.body_R_camera;
  rays.match_t = match.body_t_camera;
  rays.focal_px = (query.K(0, 0) + query.K(1, 1) + match.K(0, 0) + match.K(1, 1)) / 4.0;
  const cv::Matx33d query_inverse = query.K.inv(), match_inverse = match.K.inv();
  for (const Match& m : inliers) {
    const cv::Point2f& q = query_keypoints[m.a].pt;
    const cv::Point2f& p = match_keypoints[m.b].pt;
    rays.query.push_back(query_inverse * cv::Vec3d(q.x, q.y, 1.0));
    rays.match.push_back(match_inverse * cv::Vec3d(p.x, p.y, 1.0));
  }
  return rays;
}

// The tag of a rig frame's camera image (EntryMetadata::user_data), and back.
std::string RigTag(uint64_t frame, uint32_t camera) {
  return "rig-frame " + std::to_string(frame) + " camera " + std::to_string(camera);
}
bool ParseRigTag(const std::string& tag, uint64_t* frame, uint32_t* camera) {
  unsigned long long f = 0;
  unsigned c = 0;
  int end = 0;
  if (std::sscanf(tag.c_str(), "rig-frame %llu camera %u%n", &f, &c, &end) != 2 ||
      size_t(end) != tag.size()) {
    return false;
  }
  *frame = f;
  *camera = c;
  return true;
}

}  // namespace

struct RigLoopDetector::Converted {
  std::vector<LoopDetector::ConvertedFrame> cameras;
  std::vector<FrameGeometry> geometry;  // the camera's K, and its points when the frame has them
};

std::string_view RigLoopStatusName(RigLoopStatus status) {
  switch (status) {
    case RigLoopStatus::kLoopDetected:
      return "loop_detected";
    case RigLoopStatus::kTooFewFeatures:
      return "too_few_features";
    case RigLoopStatus::kNoCandidates:
      return "no_candidates";
    case RigLoopStatus::kFailedGeometry:
      return "failed_geometry";
    case RigLoopStatus::kInconsistentCameras:
      return "inconsistent_cameras";
  }
  return "unknown";
}

Status RigLoopParams::Validate(std::string_view name) const {
  OptionChecks check(name);
  check.Member("detector", detector);
  check.AtLeast("max_verified_frames", max_verified_frames, 1);
  check.InRange("max_rotation_disagreement_deg", max_rotation_disagreement_deg,
                RealRange::Above(0));
  check.InRange("min_consistent_ratio", min_consistent_ratio, RealRange::Closed(0, 1));
  return check.status();
}

StatusOr<RigLoopDetector> RigLoopDetector::Create(Database* database, std::vector<RigCamera> rig,
                                                  const RigLoopParams& params) {
  RECOG_RETURN_IF_ERROR(ValidateRig(rig));
  RECOG_RETURN_IF_ERROR(params.Validate());
  RECOG_ASSIGN_OR_RETURN(LoopDetector detector, LoopDetector::Create(database, params.detector));
  RigLoopDetector rig_detector(database, std::move(rig), params, std::move(detector));
  RECOG_RETURN_IF_ERROR(rig_detector.Rebuild());
  return rig_detector;
}

Status RigLoopDetector::Rebuild() {
  return database_->ScanEntries(kEntryMetadata, [&](EntryRecord& entry) -> Status {
    uint64_t frame = 0;
    uint32_t camera = 0;
    const std::string where =
        "map '" + database_->info().config.name + "' entry " + std::to_string(entry.id);
    if (!ParseRigTag(entry.metadata.user_data, &frame, &camera)) {
      return Status::DataLoss(where + " is not tagged with its rig frame and camera");
    }
    if (camera >= rig_.size() || frame > entry.id) {
      return Status::DataLoss(where + " has a rig tag this rig cannot have (frame " +
                              std::to_string(frame) + ", camera " + std::to_string(camera) + ")");
    }
    images_.push_back({entry.id, frame, camera});
    if (frames_.empty() || frames_.back().id != frame) {
      frames_.push_back({frame, entry.metadata.timestamp});
    }
    return Status::Ok();
  });
}

Status RigLoopDetector::CheckFrame(const RigFrame& frame) const {
  if (frame.client_id.size() > kMaxClientIdBytes) {
    return Status::InvalidArgument("a client frame id is at most " +
                                   std::to_string(kMaxClientIdBytes) + " bytes");
  }
  if (frame.cameras.size() != rig_.size()) {
    std::string missing;
    if (frame.cameras.size() < rig_.size()) {
      missing = " (no image for camera '" + rig_[frame.cameras.size()].name + "')";
    }
    return Status::InvalidArgument("a rig frame has " + std::to_string(frame.cameras.size()) +
                                   " camera images for a rig of " + std::to_string(rig_.size()) +
                                   missing);
  }
  if (!frame.points.empty() && frame.points.size() != rig_.size()) {
    return Status::InvalidArgument("a rig frame has 3D points for " +
                                   std::to_string(frame.points.size()) + " cameras of " +
                                   std::to_string(rig_.size()));
  }
  for (size_t c = 0; c < rig_.size(); ++c) {
    const size_t points = frame.points.empty() ? 0 : frame.points[c].size();
    if (points != 0 && points != frame.cameras[c].size()) {
      return Status::InvalidArgument("rig camera '" + rig_[c].name +
                                     "': " + std::to_string(points) + " 3D points for " +
                                     std::to_string(frame.cameras[c].size()) + " keypoints");
    }
    const cv::Size size = rig_[c].size;
    for (const cv::KeyPoint& k : frame.cameras[c].keypoints) {
      if (!(k.pt.x >= -0.5f && k.pt.y >= -0.5f && k.pt.x < float(size.width) - 0.5f &&
            k.pt.y < float(size.height) - 0.5f)) {
        char message[160];
        std::snprintf(message, sizeof(message),
                      "a keypoint at (%.1f, %.1f) is outside its %dx%d images", k.pt.x, k.pt.y,
                      size.width, size.height);
        return Status::InvalidArgument("rig camera '" + rig_[c].name + "': " + message);
      }
    }
  }
  return Status::Ok();
}

Status RigLoopDetector::Convert(const RigFrame& frame, Converted* converted) const {
  converted->cameras.resize(rig_.size());
  converted->geometry.resize(rig_.size());
  for (size_t c = 0; c < rig_.size(); ++c) {
    converted->geometry[c].K = rig_[c].K;
    if (!frame.points.empty()) converted->geometry[c].points = frame.points[c];
    const Status status = detector_.ConvertForQuery(frame.cameras[c], &converted->cameras[c]);
    if (!status.ok()) return status.WithContext("rig camera '" + rig_[c].name + "'");
  }
  return Status::Ok();
}

RecencyBound RigLoopDetector::RecencyBoundFor(std::optional<double> timestamp) const {
  const LoopDetectorParams& p = params_.detector;
  size_t first_recent = frames_.size();
  if (!timestamp.has_value()) {
    first_recent = first_recent > p.recent_frames ? first_recent - p.recent_frames : 0;
  } else {
    const double limit = *timestamp - p.recent_seconds;
    while (first_recent > 0 && frames_[first_recent - 1].timestamp.has_value() &&
           *frames_[first_recent - 1].timestamp > limit) {
      --first_recent;
    }
  }
  if (first_recent == frames_.size()) return {};
  return {EntryId(frames_[first_recent].id)};
}

std::optional<std::pair<uint64_t, uint32_t>> RigLoopDetector::FrameOf(EntryId entry) const {
  const auto it = std::lower_bound(images_.begin(), images_.end(), entry,
                                   [](const StoredImage& i, EntryId e) { return i.entry < e; });
  if (it == images_.end() || it->entry != entry) return std::nullopt;
  return std::make_pair(it->frame, it->camera);
}

std::vector<EntryId> RigLoopDetector::EntriesOf(std::span<const uint64_t> frames) const {
  std::vector<EntryId> entries;
  for (const uint64_t id : frames) {
    auto it = std::lower_bound(images_.begin(), images_.end(), id,
                               [](const StoredImage& i, uint64_t f) { return i.frame < f; });
    for (; it != images_.end() && it->frame == id; ++it) entries.push_back(it->entry);
  }
  std::sort(entries.begin(), entries.end());
  return entries;
}

StatusOr<RigLoopResult> RigLoopDetector::Search(const RigFrame& frame, const Converted& converted,
                                                RecencyBound bound,
                                                std::span<const uint64_t> excluded_frames) const {
  RigLoopResult result;
  const size_t n = rig_.size();
  const std::vector<EntryId> excluded = EntriesOf(excluded_frames);
  // Steps 1-2: per camera shortlists, pooled by rig frame.
  struct CameraBest {
    double score = 0;
    EntryId entry = kInvalidEntryId;
    uint32_t camera = 0;
  };
  struct FrameVotes {
    uint64_t frame = 0;
    double total = 0;
    std::vector<CameraBest> best;  // per query camera
  };
  std::vector<FrameVotes> votes;
  std::unordered_map<uint64_t, size_t> slot_of_frame;
  bool queried = false;
  for (size_t c = 0; c < n; ++c) {
    result.timings.conversion += converted.cameras[c].conversion_ms;
    if (frame.cameras[c].size() < params_.detector.min_features) continue;
    queried = true;
    RECOG_ASSIGN_OR_RETURN(const LoopDetector::Shortlist shortlist,
                           detector_.ShortlistFor(converted.cameras[c], excluded, bound));
    result.timings.query += shortlist.query_ms;
    for (const QueryResult& r : shortlist.results) {
      const auto where = FrameOf(r.id);
      if (!where.has_value()) continue;
      const auto [it, added] = slot_of_frame.try_emplace(where->first, votes.size());
      if (added) votes.push_back({where->first, 0, std::vector<CameraBest>(n)});
      CameraBest& best = votes[it->second].best[c];
      if (r.score > best.score) best = {r.score, r.id, where->second};
    }
  }
  if (!queried) {
    result.status = RigLoopStatus::kTooFewFeatures;
    return result;
  }
  for (FrameVotes& v : votes) {
    for (const CameraBest& b : v.best) v.total += b.score;
  }
  std::sort(votes.begin(), votes.end(), [](const FrameVotes& a, const FrameVotes& b) {
    return a.total != b.total ? a.total > b.total : a.frame < b.frame;
  });
  if (votes.empty() || !(votes.front().total > 0.0)) return result;  // kNoCandidates

  // Steps 3-4: verify the best frames in order.
  const auto start = Clock::now();
  std::optional<RigLoopResult> refused;
  const size_t tries = std::min<size_t>(votes.size(), params_.max_verified_frames);
  for (size_t i = 0; i < tries; ++i) {
    const FrameVotes& candidate = votes[i];
    if (candidate.total < params_.detector.alpha * votes.front().total) break;
    RigLoopResult attempt;
    attempt.match_frame = candidate.frame;
    attempt.score = candidate.total;
    for (uint32_t c = 0; c < n; ++c) {
      const CameraBest& best = candidate.best[c];
      if (best.entry == kInvalidEntryId) continue;
      RECOG_ASSIGN_OR_RETURN(LoopResult verification,
                             detector_.VerifyEntry(frame.cameras[c], converted.cameras[c],
                                                   best.entry, &converted.geometry[c]));
      if (verification.status != LoopStatus::kLoopDetected) continue;
      RigCameraMatch pair;
      pair.query_camera = c;
      pair.match_camera = best.camera;
      pair.entry = best.entry;
      pair.verification = std::move(verification);
      attempt.pairs.push_back(std::move(pair));
    }
    CheckAcrossRig(frame, &attempt);
    if (attempt.status == RigLoopStatus::kLoopDetected) {
      attempt.timings = result.timings;
      attempt.timings.verification = MillisecondsSince(start);
      return attempt;
    }
    if (!refused.has_value() || attempt.status == RigLoopStatus::kInconsistentCameras) {
      refused = std::move(attempt);
    }
  }
  if (!refused.has_value()) return result;  // the best frame was under alpha: cannot happen
  refused->timings = result.timings;
  refused->timings.verification = MillisecondsSince(start);
  return *std::move(refused);
}

void RigLoopDetector::CheckAcrossRig(const RigFrame& frame, RigLoopResult* result) const {
  if (result->pairs.empty()) {
    result->status = RigLoopStatus::kFailedGeometry;
    return;
  }
  // Each pair's relative pose (X_query_camera = R X_match_camera + t), then the body motion it
  // implies; and its inliers as rays, for the check across the rig.
  std::vector<RigCameraMatch*> posed;
  std::vector<RigPairRays> rays;
  std::vector<cv::Vec3d> directions;  // camera translation direction of each non-metric pair
  for (RigCameraMatch& pair : result->pairs) {
    const RigCamera& query = rig_[pair.query_camera];
    const RigCamera& match = rig_[pair.match_camera];
    const LoopResult& v = pair.verification;
    auto record = database_->Get(pair.entry, kEntryFeatures);
    if (!record.ok()) continue;
    const std::vector<cv::KeyPoint>& query_keypoints = frame.cameras[pair.query_camera].keypoints;
    cv::Matx33d R;
    cv::Vec3d t(0, 0, 0), direction(0, 0, 0);
    if (v.metric.verified) {
      R = v.metric.R;
      t = v.metric.t;
      pair.metric = true;
    } else {
      cv::Matx33d R_match_query;
      cv::Vec3d t_match_query;
      if (!RelativePoseFromMatches(query.K, match.K, query_keypoints, record->keypoints, v.inliers,
                                   params_.detector.epipolar.threshold_px, &R_match_query,
                                   &t_match_query)) {
        continue;  // F holds but fixes no motion (e.g. a pure image shift): not posed
      }
      R = R_match_query.t();
      direction = -(R * t_match_query);
    }
    const cv::Matx33d& A = query.body_R_camera;
    pair.body_R = A * R * match.body_R_camera.t();
    if (pair.metric) {
      pair.body_t = A * t + query.body_t_camera - pair.body_R * match.body_t_camera;
      pair.body_covariance =
          BodyCovariance(v.metric.covariance, A, pair.body_R, match.body_t_camera);
    }
    pair.posed = true;
    posed.push_back(&pair);
    directions.push_back(direction);
    rays.push_back(PairRays(query, match, query_keypoints, record->keypoints, v.inliers));
  }
  for (size_t i = 0; i < posed.size(); ++i) {
    for (size_t j = i + 1; j < posed.size(); ++j) {
      result->rotation_disagreement_deg = std::max(
          result->rotation_disagreement_deg, RotationAngleDeg(posed[i]->body_R, posed[j]->body_R));
    }
  }
  result->status = RigLoopStatus::kLoopDetected;
  if (posed.empty()) return;
  result->posed = true;
  const double threshold_px = params_.detector.epipolar.threshold_px;
  const auto most_inliers = [&](bool metric) {
    size_t best = posed.size();
    for (size_t i = 0; i < posed.size(); ++i) {
      if (posed[i]->metric != metric) continue;
      const auto inliers = [&](size_t k) {
        return metric ? posed[k]->verification.metric.inliers.size()
                      : posed[k]->verification.inliers.size();
      };
      if (best == posed.size() || inliers(i) > inliers(best)) best = i;
    }
    return best;
  };
  cv::Vec3d body_t(0, 0, 0);
  const size_t metric_reference = most_inliers(true);
  if (metric_reference < posed.size()) {
    // Metric pairs: their body poses must agree, and are fused by their covariances.
    for (size_t i = 0; i < posed.size(); ++i) {
      if (posed[i]->metric && RotationAngleDeg(posed[i]->body_R, posed[metric_reference]->body_R) >
                                  params_.max_rotation_disagreement_deg) {
        result->status = RigLoopStatus::kInconsistentCameras;
        return;
      }
    }
    FuseMetricPairs(posed, *posed[metric_reference], result);
    body_t = result->t;
  } else {
    // Monocular pairs: the one body motion that fits all their epipolar geometries.
    const size_t reference = most_inliers(false);
    result->R = posed[reference]->body_R;
    if (posed.size() == 1) return;  // one pair: nothing to check it against
    body_t = InitialRigTranslation(rays, reference, directions[reference], result->R, threshold_px);
    RefineRigMotion(rays, threshold_px, &result->R, &body_t);
  }
  // Every pair's correspondences must lie on the epipolar lines of the body motion.
  std::vector<double> errors;
  for (size_t i = 0; i < posed.size(); ++i) {
    RigPairEpipolarErrors(rays[i], result->R, body_t, &errors);
    const auto agreeing = std::count_if(errors.begin(), errors.end(),
                                        [&](double e) { return std::abs(e) <= threshold_px; });
    posed[i]->consistent_ratio = errors.empty() ? 0.0 : double(agreeing) / double(errors.size());
    if (posed[i]->consistent_ratio < params_.min_consistent_ratio) {
      result->status = RigLoopStatus::kInconsistentCameras;
    }
  }
}

void RigLoopDetector::FuseMetricPairs(const std::vector<RigCameraMatch*>& posed,
                                      const RigCameraMatch& reference,
                                      RigLoopResult* result) const {
  result->metric = true;
  result->R = reference.body_R;
  result->t = reference.body_t;
  result->covariance = reference.body_covariance;
  // The information-weighted mean, in the tangent space of the reference's pose (pairs whose
  // covariance is degenerate are left out).
  cv::Matx66d information = cv::Matx66d::zeros();
  cv::Vec6d weighted(0, 0, 0, 0, 0, 0);
  for (const RigCameraMatch* pair : posed) {
    if (!pair->metric) continue;
    cv::Matx66d pair_information;
    if (!cv::invert(cv::Matx66d(pair->body_covariance.data()), pair_information,
                    cv::DECOMP_CHOLESKY)) {
      continue;
    }
    cv::Vec3d rotation;
    cv::Rodrigues(pair->body_R * reference.body_R.t(), rotation);
    const cv::Vec3d translation = pair->body_t - reference.body_t;
    const cv::Vec6d offset(rotation[0], rotation[1], rotation[2], translation[0], translation[1],
                           translation[2]);
    information += pair_information;
    weighted += pair_information * offset;
  }
  cv::Matx66d fused;
  if (!cv::invert(information, fused, cv::DECOMP_CHOLESKY)) return;
  const cv::Vec6d offset = fused * weighted;
  cv::Matx33d rotation;
  cv::Rodrigues(cv::Vec3d(offset[0], offset[1], offset[2]), rotation);
  result->R = rotation * reference.body_R;
  result->t = reference.body_t + cv::Vec3d(offset[3], offset[4], offset[5]);
  std::copy(fused.val, fused.val + 36, result->covariance.begin());
}

StatusOr<uint64_t> RigLoopDetector::Insert(const RigFrame& frame, const Converted& converted) {
  const uint64_t id = database_->next_entry_id();
  for (uint32_t c = 0; c < rig_.size(); ++c) {
    EntryMetadata metadata;
    metadata.timestamp = frame.timestamp;
    metadata.client_id = frame.client_id;
    metadata.user_data = RigTag(id, c);
    const FrameGeometry& geometry = converted.geometry[c];
    RECOG_ASSIGN_OR_RETURN(const EntryId entry,
                           database_->AddConverted(
                               converted.cameras[c].bow, converted.cameras[c].direct,
                               frame.cameras[c], std::move(metadata), geometry.points, geometry.K));
    if (frames_.empty() || frames_.back().id != id) frames_.push_back({id, frame.timestamp});
    images_.push_back({entry, id, c});
  }
  return id;
}

StatusOr<RigLoopResult> RigLoopDetector::Process(const RigFrame& frame,
                                                 std::span<const uint64_t> excluded) {
  RECOG_RETURN_IF_ERROR(CheckFrame(frame));
  Converted converted;
  RECOG_RETURN_IF_ERROR(Convert(frame, &converted));
  RECOG_ASSIGN_OR_RETURN(RigLoopResult result,
                         Search(frame, converted, RecencyBoundFor(frame.timestamp), excluded));
  const auto start = Clock::now();
  RECOG_ASSIGN_OR_RETURN(result.frame, Insert(frame, converted));
  result.timings.insertion = MillisecondsSince(start);
  return result;
}

StatusOr<uint64_t> RigLoopDetector::Add(const RigFrame& frame) {
  RECOG_RETURN_IF_ERROR(CheckFrame(frame));
  Converted converted;
  RECOG_RETURN_IF_ERROR(Convert(frame, &converted));
  return Insert(frame, converted);
}

StatusOr<RigLoopResult> RigLoopDetector::Query(const RigFrame& frame,
                                               std::span<const uint64_t> excluded) const {
  RECOG_RETURN_IF_ERROR(CheckFrame(frame));
  Converted converted;
  RECOG_RETURN_IF_ERROR(Convert(frame, &converted));
  return Search(frame, converted, RecencyBound{}, excluded);
}

Status RigLoopDetector::RemoveFrame(uint64_t id) {
  const auto frame = std::lower_bound(frames_.begin(), frames_.end(), id,
                                      [](const StoredFrame& f, uint64_t i) { return f.id < i; });
  if (frame == frames_.end() || frame->id != id) {
    return Status::NotFound("map '" + database_->info().config.name + "' has no rig frame " +
                            std::to_string(id));
  }
  const uint64_t ids[] = {id};
  for (const EntryId entry : EntriesOf(ids)) {
    RECOG_RETURN_IF_ERROR(database_->Remove(entry));
    images_.erase(std::lower_bound(images_.begin(), images_.end(), entry,
                                   [](const StoredImage& i, EntryId e) { return i.entry < e; }));
  }
  frames_.erase(frame);
  return Status::Ok();
}

StatusOr<std::vector<uint64_t>> RigLoopDetector::FramesWithClientId(
    std::string_view client_id) const {
  std::vector<uint64_t> ids;
  RECOG_RETURN_IF_ERROR(database_->ScanEntries(kEntryMetadata, [&](EntryRecord& entry) -> Status {
    const auto where = FrameOf(entry.id);
    if (entry.metadata.client_id == client_id && where.has_value() &&
        (ids.empty() || ids.back() != where->first)) {
      ids.push_back(where->first);
    }
    return Status::Ok();
  }));
  return ids;
}

}  // namespace recog
