#include "tools/recog/loop_json.h"

#include "tools/common/remote_support.h"

namespace recog::cli {
namespace {

using Json = nlohmann::ordered_json;

// The correspondences as [{query_index, query: [x, y], match_index, match: [x, y]}].
Json CorrespondencesJson(const google::protobuf::RepeatedPtrField<pb::Correspondence>& in) {
  Json pairs = Json::array();
  for (const pb::Correspondence& c : in) {
    pairs.push_back({{"query_index", c.query_index()},
                     {"query", {c.query_x(), c.query_y()}},
                     {"match_index", c.match_index()},
                     {"match", {c.match_x(), c.match_y()}}});
  }
  return pairs;
}

}  // namespace

std::string StatusLabel(pb::LoopStatus status) {
  return EnumLabel(pb::LoopStatus_Name(status), "LOOP_STATUS_");
}

Json LoopJson(const pb::LoopResult& r) {
  Json out = {{"status", StatusLabel(r.status())}, {"score", r.score()}};
  if (!r.has_rig()) {  // a rig map's scores are pooled over cameras, without islands
    out.update({{"normalized_score", r.normalized_score()},
                {"previous_score", r.previous_score()},
                {"island", {{"first", r.island_first()}, {"last", r.island_last()}}},
                {"island_score", r.island_score()},
                {"consistent_queries", r.consistent_queries()}});
  }
  out["correspondences"] = r.correspondences();
  out["inliers"] = r.inliers();
  if (r.has_evidence()) {
    const pb::LoopEvidence& e = r.evidence();
    out["evidence"] = {{"inliers", e.inliers()},
                       {"spread", e.spread()},
                       {"calibrated", e.calibrated()},
                       {"in_front", e.in_front()},
                       {"parallax_deg", e.parallax_deg()},
                       {"rotation_deg", e.rotation_deg()},
                       {"pure_rotation", e.pure_rotation()},
                       {"confirmations", e.confirmations()}};
  }
  if (r.has_frame_id()) out["frame"] = r.frame_id();
  if (r.has_match_frame_id()) {
    out["match"] = r.match_frame_id();
    out["match_client_frame_id"] = r.match_client_frame_id();
  }
  if (r.candidates_size() > 0) {
    Json candidates = Json::array();
    for (const pb::Candidate& c : r.candidates()) {
      Json candidate = {{"frame", c.frame_id()},
                        {"client_frame_id", c.client_frame_id()},
                        {"score", c.score()},
                        {"normalized_score", c.normalized_score()}};
      if (c.has_inliers()) candidate["inliers"] = c.inliers();
      candidates.push_back(std::move(candidate));
    }
    out["candidates"] = std::move(candidates);
  }
  if (r.inlier_correspondences_size() > 0) {
    out["inlier_correspondences"] = CorrespondencesJson(r.inlier_correspondences());
  }
  if (r.has_relative_pose()) {
    const pb::Pose& pose = r.relative_pose();
    out["relative_pose"] = {
        {"rotation", std::vector<double>(pose.rotation().begin(), pose.rotation().end())},
        {"translation", std::vector<double>(pose.translation().begin(), pose.translation().end())}};
  }
  if (r.has_rig()) {
    const pb::RigLoop& rig = r.rig();
    Json pairs = Json::array();
    for (const pb::RigCameraMatch& pair : rig.pairs()) {
      pairs.push_back({{"query_camera", pair.query_camera()},
                       {"match_camera", pair.match_camera()},
                       {"correspondences", pair.correspondences()},
                       {"inliers", pair.inliers()},
                       {"posed", pair.posed()},
                       {"metric", pair.metric()},
                       {"consistent_ratio", pair.consistent_ratio()}});
      if (pair.inlier_correspondences_size() > 0) {
        pairs.back()["inlier_correspondences"] = CorrespondencesJson(pair.inlier_correspondences());
      }
    }
    Json rig_json = {{"pairs", std::move(pairs)},
                     {"rotation_disagreement_deg", rig.rotation_disagreement_deg()},
                     {"posed", rig.posed()},
                     {"metric", rig.metric()}};
    if (rig.posed()) {
      // X_body_query = R X_body_match + t; t in metres when metric, else zero
      const pb::Pose& body = rig.body_pose();
      rig_json["body_pose"] = {
          {"rotation", std::vector<double>(body.rotation().begin(), body.rotation().end())},
          {"translation",
           std::vector<double>(body.translation().begin(), body.translation().end())}};
    }
    if (rig.metric()) {
      rig_json["covariance"] =
          std::vector<double>(rig.covariance().begin(), rig.covariance().end());
    }
    out["rig"] = std::move(rig_json);
  }
  if (r.has_metric()) {
    const pb::MetricLoop& m = r.metric();
    Json metric = {{"checked", m.checked()},
                   {"verified", m.verified()},
                   {"correspondences", m.correspondences()},
                   {"inliers", m.inliers()},
                   {"rms_error_px", m.rms_error_px()}};
    if (m.verified()) {
      metric["pose"] = {
          // X_query = R X_match + t, metres
          {"rotation", std::vector<double>(m.pose().rotation().begin(), m.pose().rotation().end())},
          {"translation",
           std::vector<double>(m.pose().translation().begin(), m.pose().translation().end())}};
      metric["covariance"] = std::vector<double>(m.covariance().begin(), m.covariance().end());
    }
    out["metric"] = std::move(metric);
  }
  return out;
}

Json TimingJson(const pb::Timing& t) {
  return {{"decode", t.decode_ms()},
          {"features", t.features_ms()},
          {"recognition", t.recognition_ms()},
          {"queue", t.queue_ms()}};
}

}  // namespace recog::cli
