// recog eval place --rig (eval_place.h): the rig detector over a multi-camera rig sequence
// (tools/evaluation/rig_evaluation.h), scored over rig frames, each missed revisit given its
// reason, with the loops' body pose errors when --body-poses gives the body's poses; as JSON or
// as text.
#include <cstdio>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "tools/common/cli_support.h"
#include "tools/evaluation/rig_evaluation.h"
#include "tools/recog/eval_place.h"
#include "tools/recog/eval_place_misses.h"

namespace recog::cli {
namespace {

// --rig's features: every rig frame's images in the cameras kept (--cameras), with the 3D points
// of their depth images unless --no-depth.
StatusOr<RigSequenceFeatures> ExtractRigFeatures(const EvalPlaceArgs& args,
                                                 const RigDataset& dataset, int features) {
  RigExtractionOptions extraction;
  extraction.features = OrbFeatureOptions(args, features);
  extraction.use_depth = !args.no_depth;
  extraction.depth_scale = 1.0 / (args.depth_scale > 0 ? args.depth_scale : 5000.0);
  extraction.cameras = args.rig_cameras;
  ProgressBar progress(!args.quiet);
  auto sequence = ExtractRigSequence(dataset, extraction, [&](size_t done, size_t total) {
    progress.Update("rig frames", done, total);
  });
  progress.Finish();
  return sequence;
}

// --rig --json: the evaluation of the rig sequence with its settings (`parameters`), with the
// pose errors when --body-poses gave the body's poses.
nlohmann::json RigEvaluationJson(const EvalPlaceArgs& args, const RigPlaceEvaluation& e,
                                 RigLayout layout, const std::vector<std::string>& cameras,
                                 bool posed, const std::string& vocabulary_path,
                                 nlohmann::json parameters) {
  nlohmann::json timing, loops = nlohmann::json::array();
  for (const auto& [stage, s] : e.timing_ms) {
    timing[stage] = {{"mean", s.mean}, {"median", s.median}, {"max", s.max}};
  }
  for (const RigDetectedLoop& l : e.loops) {
    nlohmann::json loop = {{"query", l.query + 1},
                           {"match", l.match + 1},
                           {"status", std::string(RigLoopStatusName(l.status))},
                           {"camera_pairs", l.camera_pairs},
                           {"inliers", l.inliers},
                           {"rotation_disagreement_deg", l.rotation_disagreement_deg},
                           {"posed", l.posed},
                           {"metric", l.metric}};
    if (args.has_truth()) loop["correct"] = l.correct;
    if (l.posed) {  // X_body_query = R X_body_match + t
      loop["rotation"] = std::vector<double>(l.result.R.val, l.result.R.val + 9);
      if (l.metric) {
        loop["translation"] = {l.result.t[0], l.result.t[1], l.result.t[2]};
        loop["covariance"] = l.result.covariance;
      }
    }
    if (l.rotation_error_deg) loop["rotation_error_deg"] = *l.rotation_error_deg;
    if (l.translation_error_pct) loop["translation_error_pct"] = *l.translation_error_pct;
    loops.push_back(std::move(loop));
  }
  nlohmann::json out = {{"layout", std::string(RigLayoutName(layout))},
                        {"cameras", cameras},
                        {"frames", e.frames},
                        {"detections", e.detections},
                        {"statuses", e.statuses},
                        {"timing_ms", timing},
                        {"loops", loops},
                        {"vocabulary", vocabulary_path},
                        {"parameters", std::move(parameters)}};
  if (args.has_truth()) {
    out["query_frames_with_truth"] = e.query_frames_with_truth;
    out["correct"] = e.correct;
    out["precision"] = e.precision;
    out["recall"] = e.recall;
    AddMissesJson(e, nullptr, &out);
  }
  if (posed) {
    out["pose_error"] = {{"posed_correct", e.posed_correct},
                         {"metric_correct", e.metric_correct},
                         {"median_rotation_deg", e.median_rotation_error_deg},
                         {"median_translation_pct", e.median_translation_error_pct}};
  }
  return out;
}

// --rig without --json: the evaluation of the rig sequence as text.
void PrintRigEvaluation(const EvalPlaceArgs& args, const RigPlaceEvaluation& e, RigLayout layout,
                        const std::vector<std::string>& cameras, bool posed) {
  std::string joined;
  for (const std::string& c : cameras) joined += (joined.empty() ? "" : ", ") + c;
  std::printf("rig (%s layout): cameras %s; %d rig frames\n",
              std::string(RigLayoutName(layout)).c_str(), joined.c_str(), e.frames);
  if (args.has_truth()) {
    std::printf("query frames with a true match %d\n", e.query_frames_with_truth);
    std::printf("detections %d, correct %d: precision %.1f %%, recall %.1f %%\n", e.detections,
                e.correct, 100 * e.precision, 100 * e.recall);
    PrintMissSummary("", e);
  } else {
    std::printf("detections %d (no ground truth)\n", e.detections);
  }
  if (posed) {
    // A median over no loop is no figure: "none" then.
    const auto median = [](double value, int count, const char* format) {
      char text[32] = "none";
      if (count > 0) std::snprintf(text, sizeof(text), format, value);
      return std::string(text);
    };
    std::printf(
        "body pose of the correct loops: rotation error %s (median over %d posed), "
        "translation error %s of the distance (median over %d metric)\n",
        median(e.median_rotation_error_deg, e.posed_correct, "%.3f deg").c_str(), e.posed_correct,
        median(e.median_translation_error_pct, e.metric_correct, "%.2f %%").c_str(),
        e.metric_correct);
  }
  std::printf("%-13s %8s %8s %8s  (ms per rig frame)\n", "stage", "mean", "median", "max");
  for (const char* stage : {"features", "points", "conversion", "query", "verification",
                            "insertion", "detector", "total"}) {
    if (!e.timing_ms.count(stage)) continue;  // points: with depth images
    const StageStats& s = e.timing_ms.at(stage);
    std::printf("%-13s %8.3f %8.3f %8.3f\n", stage, s.mean, s.median, s.max);
  }
  for (const RigDetectedLoop& l : e.loops) {
    if (l.status != RigLoopStatus::kLoopDetected) continue;
    std::string pairs;
    for (const std::string& p : l.camera_pairs) pairs += (pairs.empty() ? "" : " ") + p;
    std::printf("loop %d -> %d (%s%u inliers; cameras %s)\n", l.query + 1, l.match + 1,
                args.has_truth() ? (l.correct ? "correct, " : "WRONG, ") : "", l.inliers,
                pairs.c_str());
  }
  PrintMisses("", e, [](int frame) { return std::to_string(frame + 1); });
}

// Why each revisit of the rig sequence missed, into e->misses. EvaluateRigPlace keeps the result
// of the rig frames that had a candidate verified (its loops) and, of the others, only the status
// (frame_statuses): too_few_features (kNotQueried) or no_candidates (kNoCandidate). A
// RigLoopResult holds no list of candidates — the rig pools its cameras' answers by rig frame and
// keeps only the frame whose verification gave the status — so a rig miss has no true candidate
// and no rank. That frame is, for failed_geometry, the best pooled one (no camera pair of it
// passed, and the failed pairs' inliers are not kept: no inliers), and for inconsistent_cameras
// the last one refused so (the best pooled one, unless that one failed geometry first; its
// verified pairs' inliers are kept); as neither can say whether a true place was among the
// others, a wrong one there is a kWrongTopCandidate.
void CountRigMisses(const GroundTruth& truth, RigPlaceEvaluation* e) {
  std::map<int, const RigDetectedLoop*> loop_of_frame;
  for (const RigDetectedLoop& l : e->loops) loop_of_frame[l.query] = &l;
  LoopTally tally(e);
  for (int i = 0; i < e->frames; ++i) {
    if (!RevisitsMap(truth, i, {0, e->frames})) continue;
    MissedRevisit miss;
    miss.query = i;
    miss.status = e->frame_statuses[size_t(i)];
    const auto found = loop_of_frame.find(i);
    if (found == loop_of_frame.end()) {
      miss.reason = miss.status == RigLoopStatusName(RigLoopStatus::kTooFewFeatures)
                        ? MissReason::kNotQueried
                        : MissReason::kNoCandidate;
      tally.CountMiss(std::move(miss));
      continue;
    }
    const RigDetectedLoop& l = *found->second;
    if (l.status == RigLoopStatus::kLoopDetected && l.correct) continue;
    miss.candidate = l.match;
    if (l.status != RigLoopStatus::kFailedGeometry) {  // the verified pairs' evidence
      uint32_t correspondences = 0;
      for (const RigCameraMatch& pair : l.result.pairs) {
        correspondences += pair.verification.correspondences;
      }
      miss.inliers = l.inliers;
      miss.correspondences = correspondences;
    }
    miss.reason = l.status == RigLoopStatus::kLoopDetected ? MissReason::kWrongLoop
                  : l.correct                              ? MissReason::kFailedGeometry
                                                           : MissReason::kWrongTopCandidate;
    tally.CountMiss(std::move(miss));
  }
}

}  // namespace

int RunEvalRig(const EvalPlaceArgs& args, const EvalPlaceSettings& settings,
               std::shared_ptr<const Vocabulary> vocabulary, const std::string& vocabulary_path) {
  const PlaceEvaluationOptions& options = settings.options;
  auto dataset = ReadRigDataset(args.rig);
  if (!dataset.ok()) return Fail("eval place", dataset.status());
  auto sequence = ExtractRigFeatures(args, *dataset, settings.features);
  if (!sequence.ok()) return Fail("eval place", sequence.status());
  StatusOr<GroundTruth> truth = NoTrueMatches(sequence->frames.size());
  if (args.has_truth()) {
    truth = ReadGroundTruth(args.ground_truth);
    if (!truth.ok()) return Fail("eval place", truth.status());
  }
  std::optional<std::vector<CameraPose>> poses;
  if (!args.body_poses.empty()) {
    auto read = ReadTrajectory(args.body_poses);
    if (!read.ok()) return Fail("eval place", read.status());
    poses = std::move(read).value();
  }
  RigPlaceOptions rig_options;
  rig_options.detector = settings.rig;
  rig_options.detector.detector = options.detector;
  rig_options.scoring = options.scoring;
  rig_options.direct_index_levels_up = options.direct_index_levels_up;
  auto e = EvaluateRigPlace(*sequence, *truth, std::move(vocabulary), rig_options,
                            poses ? &*poses : nullptr);
  if (!e.ok()) return Fail("eval place", e.status());
  CountRigMisses(*truth, &*e);
  std::vector<std::string> cameras;
  for (const RigCamera& c : sequence->cameras) cameras.push_back(c.name);
  if (args.json) {
    const nlohmann::json out =
        RigEvaluationJson(args, *e, dataset->layout, cameras, poses.has_value(), vocabulary_path,
                          ParametersJson(settings, vocabulary_path, true));
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    std::printf("%s\n", ChangedSettingsLine(options.detector).c_str());
    PrintRigEvaluation(args, *e, dataset->layout, cameras, poses.has_value());
  }
  return 0;
}

}  // namespace recog::cli
