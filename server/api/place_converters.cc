#include "server/api/place_converters.h"

#include <algorithm>
#include <string>

#include <spdlog/spdlog.h>

#include "core/place/detector_settings.h"
#include "server/api/frame_decoding.h"
#include "server/api/pose_converter.h"
#include "wire/map_settings_text.h"

namespace recog::server {
namespace {

void AddCorrespondences(const std::vector<PlaceCorrespondence>& in,
                        google::protobuf::RepeatedPtrField<pb::Correspondence>* out) {
  for (const PlaceCorrespondence& c : in) {
    pb::Correspondence* correspondence = out->Add();
    correspondence->set_query_index(c.query_index);
    correspondence->set_query_x(c.query_pixel.x);
    correspondence->set_query_y(c.query_pixel.y);
    correspondence->set_match_index(c.match_index);
    correspondence->set_match_x(c.match_pixel.x);
    correspondence->set_match_y(c.match_pixel.y);
  }
}

}  // namespace

// The settings table and MapSettings name the same settings (wire/map_settings_text_test.cc): a
// name of one that the other lacks is a bug here, not the caller's mistake.
Status ApplyMapSettings(const pb::MapSettings& settings, LoopDetectorParams* params) {
  std::vector<NamedSetting> values;
  const std::string unknown = MapSettingsAsText(settings, MapDetectorSettingNames(), &values);
  if (!unknown.empty()) return Status::Internal("MapSettings and the settings table: " + unknown);
  const Status applied = ApplyDetectorSettings(values, params);
  if (!applied.ok()) return applied.WithContext("settings", StatusCode::kInvalidArgument);
  return Status::Ok();
}

void ToProto(const LoopDetectorParams& params, pb::MapSettings* out) {
  for (const auto& [name, text] : MapDetectorSettings(params)) {
    // The text is the table's own, so only a name MapSettings lacks fails; with no status to
    // return, it is logged rather than dropped unseen.
    const std::string error = SetMapSettingFromText(out, name, text);
    if (!error.empty()) spdlog::error("MapSettings and the settings table: {}", error);
  }
}

StatusOr<std::vector<RigCamera>> RigFromProto(const pb::MapSettings& settings) {
  if (settings.rig_size() > 0 && settings.keep_thumbnails()) {
    return Status::InvalidArgument(
        "settings.keep_thumbnails is for single-camera maps, not for a rig map");
  }
  std::vector<RigCamera> rig;
  for (int i = 0; i < settings.rig_size(); ++i) {
    const pb::RigCameraSettings& in = settings.rig(i);
    const std::string field = "settings.rig[" + std::to_string(i) + "] ('" + in.name() + "')";
    RigCamera camera;
    camera.name = in.name();
    camera.size = cv::Size(int(std::min<uint32_t>(in.width(), kMaxImageSide + 1)),
                           int(std::min<uint32_t>(in.height(), kMaxImageSide + 1)));
    // A camera's size is checked as one image would be.
    RECOG_RETURN_IF_ERROR(PixelBudget().Take(in.width(), in.height(), field + " width x height"));
    const pb::CameraIntrinsics& k = in.intrinsics();
    camera.K = cv::Matx33d(k.fx(), 0, k.cx(), 0, k.fy(), k.cy(), 0, 0, 1);
    camera.distortion.assign(k.distortion().begin(), k.distortion().end());
    RECOG_ASSIGN_OR_RETURN(camera.lens, LensFromProto(k.lens(), field + ".intrinsics"));
    const pb::Pose& pose = in.body_pose();
    if (pose.rotation_size() != 0 || pose.translation_size() != 0) {
      if (pose.rotation_size() != 9 || pose.translation_size() != 3) {
        return Status::InvalidArgument(field + ".body_pose needs 9 rotation and 3 translation " +
                                       "values (both empty: the body frame itself)");
      }
      std::copy(pose.rotation().begin(), pose.rotation().end(), camera.body_R_camera.val);
      std::copy(pose.translation().begin(), pose.translation().end(), camera.body_t_camera.val);
    }
    rig.push_back(std::move(camera));
  }
  if (!rig.empty()) {
    const Status valid = ValidateRig(rig);
    if (!valid.ok()) return valid.WithContext("settings.rig", StatusCode::kInvalidArgument);
  }
  return rig;
}

void ToProto(const std::vector<RigCamera>& rig, pb::MapSettings* out) {
  out->clear_rig();
  for (const RigCamera& camera : rig) {
    pb::RigCameraSettings* settings = out->add_rig();
    settings->set_name(camera.name);
    settings->set_width(uint32_t(camera.size.width));
    settings->set_height(uint32_t(camera.size.height));
    pb::CameraIntrinsics* k = settings->mutable_intrinsics();
    k->set_fx(camera.K(0, 0));
    k->set_fy(camera.K(1, 1));
    k->set_cx(camera.K(0, 2));
    k->set_cy(camera.K(1, 2));
    k->mutable_distortion()->Assign(camera.distortion.begin(), camera.distortion.end());
    k->set_lens(pb::LensModel(camera.lens));
    ToProto(camera.body_R_camera, camera.body_t_camera, settings->mutable_body_pose());
  }
}

pb::LoopStatus ToProto(RigLoopStatus status) {
  switch (status) {
    case RigLoopStatus::kLoopDetected:
      return pb::LOOP_STATUS_LOOP_DETECTED;
    case RigLoopStatus::kTooFewFeatures:
      return pb::LOOP_STATUS_TOO_FEW_FEATURES;
    case RigLoopStatus::kNoCandidates:
      return pb::LOOP_STATUS_NO_CANDIDATES;
    case RigLoopStatus::kFailedGeometry:
      return pb::LOOP_STATUS_FAILED_GEOMETRY;
    case RigLoopStatus::kInconsistentCameras:
      return pb::LOOP_STATUS_INCONSISTENT_CAMERAS;
  }
  return pb::LOOP_STATUS_UNSPECIFIED;
}

void ToProto(const RigPlaceResult& result, const std::vector<RigCamera>& rig, pb::LoopResult* out) {
  const RigLoopResult& loop = result.loop;
  out->set_status(ToProto(loop.status));
  if (loop.frame.has_value()) out->set_frame_id(*loop.frame);
  if (loop.match_frame.has_value()) out->set_match_frame_id(*loop.match_frame);
  if (result.match_timestamp.has_value()) out->set_match_timestamp(*result.match_timestamp);
  out->set_match_client_frame_id(result.match_client_id);
  out->set_score(loop.score);
  if (!loop.match_frame.has_value()) return;
  pb::RigLoop* rig_loop = out->mutable_rig();
  uint32_t correspondences = 0, inliers = 0;
  for (size_t p = 0; p < loop.pairs.size(); ++p) {
    const RigCameraMatch& pair = loop.pairs[p];
    pb::RigCameraMatch* match = rig_loop->add_pairs();
    match->set_query_camera(rig[pair.query_camera].name);
    match->set_match_camera(rig[pair.match_camera].name);
    match->set_correspondences(pair.verification.correspondences);
    match->set_inliers(uint32_t(pair.verification.inliers.size()));
    match->set_posed(pair.posed);
    match->set_metric(pair.metric);
    match->set_consistent_ratio(pair.consistent_ratio);
    if (p < result.correspondences.size()) {
      AddCorrespondences(result.correspondences[p], match->mutable_inlier_correspondences());
    }
    correspondences += pair.verification.correspondences;
    inliers += uint32_t(pair.verification.inliers.size());
  }
  out->set_correspondences(correspondences);
  out->set_inliers(inliers);
  rig_loop->set_rotation_disagreement_deg(loop.rotation_disagreement_deg);
  rig_loop->set_posed(loop.posed);
  if (loop.posed) ToProto(loop.R, loop.t, rig_loop->mutable_body_pose());
  rig_loop->set_metric(loop.metric);
  if (loop.metric) {
    rig_loop->mutable_covariance()->Assign(loop.covariance.begin(), loop.covariance.end());
  }
}

pb::LoopStatus ToProto(LoopStatus status) {
  switch (status) {
    case LoopStatus::kLoopDetected:
      return pb::LOOP_STATUS_LOOP_DETECTED;
    case LoopStatus::kTooFewFeatures:
      return pb::LOOP_STATUS_TOO_FEW_FEATURES;
    case LoopStatus::kLowScoreWithPrevious:
      return pb::LOOP_STATUS_LOW_SCORE_WITH_PREVIOUS;
    case LoopStatus::kNoCandidates:
      return pb::LOOP_STATUS_NO_CANDIDATES;
    case LoopStatus::kLowScore:
      return pb::LOOP_STATUS_LOW_SCORE;
    case LoopStatus::kNoConsistentIsland:
      return pb::LOOP_STATUS_NO_CONSISTENT_ISLAND;
    case LoopStatus::kFailedTemporalConsistency:
      return pb::LOOP_STATUS_FAILED_TEMPORAL_CONSISTENCY;
    case LoopStatus::kFailedGeometry:
      return pb::LOOP_STATUS_FAILED_GEOMETRY;
    case LoopStatus::kCandidate:
      return pb::LOOP_STATUS_CANDIDATE;
  }
  return pb::LOOP_STATUS_UNSPECIFIED;
}

void ToProto(const MetricLoop& metric, pb::MetricLoop* out) {
  out->set_checked(metric.checked);
  out->set_verified(metric.verified);
  out->set_correspondences(metric.correspondences);
  out->set_inliers(uint32_t(metric.inliers.size()));
  out->set_rms_error_px(metric.rms_error_px);
  if (!metric.verified) return;
  ToProto(metric.R, metric.t, out->mutable_pose());
  out->mutable_covariance()->Assign(metric.covariance.begin(), metric.covariance.end());
}

void ToProto(const PlaceFrameResult& frame, pb::LoopResult* out) {
  const LoopResult& result = frame.loop;
  out->set_status(ToProto(result.status));
  if (result.entry != kInvalidEntryId) out->set_frame_id(result.entry);
  if (result.match != kInvalidEntryId) out->set_match_frame_id(result.match);
  out->set_score(result.score);
  out->set_normalized_score(result.normalized_score);
  out->set_previous_score(result.previous_score);
  if (result.island_first != kInvalidEntryId) {
    out->set_island_first(result.island_first);
    out->set_island_last(result.island_last);
  }
  out->set_island_score(result.island_score);
  out->set_consistent_queries(result.consistent_queries);
  out->set_correspondences(result.correspondences);
  out->set_inliers(uint32_t(result.inliers.size()));
  if (frame.match_timestamp.has_value()) out->set_match_timestamp(*frame.match_timestamp);
  if (frame.fundamental.has_value()) {
    for (int i = 0; i < 9; ++i) out->add_fundamental(frame.fundamental->val[i]);
  }
  if (frame.relative_pose.has_value()) {
    ToProto(frame.relative_pose->R, frame.relative_pose->t, out->mutable_relative_pose());
  }
  out->set_match_client_frame_id(frame.match_client_id);
  if (result.metric.checked) ToProto(result.metric, out->mutable_metric());
  if (result.correspondences > 0 || !result.inliers.empty()) {
    const LoopEvidence& v = result.evidence;
    pb::LoopEvidence* evidence = out->mutable_evidence();
    evidence->set_inliers(v.inliers);
    evidence->set_spread(v.spread);
    evidence->set_calibrated(v.calibrated);
    evidence->set_in_front(v.in_front);
    evidence->set_parallax_deg(v.parallax_deg);
    evidence->set_rotation_deg(v.rotation_deg);
    evidence->set_pure_rotation(v.pure_rotation);
    evidence->set_confirmations(v.confirmations);
  }
  for (const PlaceCandidate& c : frame.candidates) {
    pb::Candidate* candidate = out->add_candidates();
    candidate->set_frame_id(c.frame);
    candidate->set_client_frame_id(c.client_id);
    candidate->set_score(c.score);
    candidate->set_normalized_score(c.normalized_score);
    if (c.inliers.has_value()) candidate->set_inliers(*c.inliers);
  }
  AddCorrespondences(frame.correspondences, out->mutable_inlier_correspondences());
}

PlaceResultOptions FromProto(const pb::ResultOptions& options,
                             const std::optional<CameraIntrinsics>& intrinsics) {
  PlaceResultOptions out;
  out.include_fundamental = options.include_fundamental();
  out.include_relative_pose = options.include_relative_pose();
  out.include_correspondences = options.include_correspondences();
  out.top_k = options.top_k();
  if (intrinsics.has_value()) out.camera_matrix = intrinsics->K();
  return out;
}

}  // namespace recog::server
