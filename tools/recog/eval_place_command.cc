// recog eval place: runs the loop detector over a sequence (a folder, a TUM RGB-D / EuRoC / KITTI
// dataset folder with timestamps, a list, a video or a ROS bag (1 or 2); or with --rig a
// multi-camera rig sequence) and reports the detections and per-stage timings, with a ground truth
// also precision, recall and why each missed revisit was missed (eval_place_misses.h); --sweep
// alpha draws the PR curve.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <yaml-cpp/yaml.h>
#include <nlohmann/json.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/place/detector_settings.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tools/common/cli_support.h"
#include "tools/evaluation/camera_calibration.h"
#include "tools/evaluation/place_evaluation.h"
#include "tools/evaluation/plot.h"
#include "tools/evaluation/rig_evaluation.h"
#include "tools/recog/bag_flags.h"
#include "tools/recog/commands.h"
#include "tools/recog/eval_place_misses.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

struct EvalPlaceArgs {
  std::string images, ground_truth, vocabulary, params_file, draw_dir, sweep;
  std::string preset = "default";
  std::string deprecated_mode;  // --mode, the old name of --preset
  std::string layout = "auto";
  // fx,fy,cx,cy: the frames' camera matrix (the calibrated check of loops), and 3D points from
  // the dataset's depth or right images
  std::string camera;
  std::string poses;  // with --camera: every frame's pose (CameraTrajectory), loops judged by it
  std::string ambiguous;                                            // pairs left out of precision
  std::string trajectory_plot = "recog_eval_place_trajectory.png";  // with --poses
  double depth_scale = 0, baseline = 0;
  std::string plot = "recog_eval_place_pr.png";
  int features = 1000;
  int min_short_side = kPlaceMinShortSide;
  int split = 0;  // > 0: frames 1..split are robot A's map, the rest robot B's (EvaluateAcrossMaps)
  std::string robot_b;     // robot B's own sequence: A's frames (--images) are then A's map
  std::string rig;         // a rig sequence (rig_dataset.h) instead of --images
  std::string body_poses;  // with --rig: the body's poses, for the loops' pose errors
  std::vector<std::string> rig_cameras;  // with --rig: only these cameras
  bool no_depth = false;                 // with --rig: ignore the cameras' depth images
  BagFlags bag;                          // --bag and its topics, instead of --images
  bool json = false;
  bool quiet = false;

  // With --ground-truth: precision and recall are reported.
  bool has_truth() const { return !ground_truth.empty(); }
  // --split or --robot-b: two robots, each with a map of its own (EvaluateAcrossMaps).
  bool two_robots() const { return split > 0 || !robot_b.empty(); }
};

// --preset, or --mode (its old name) when that was given.
const std::string& PresetFlag(const EvalPlaceArgs& args) {
  return args.deprecated_mode.empty() ? args.preset : args.deprecated_mode;
}

// The name of a sequence for a title: its folder, or the folder above an "images" folder; a
// bag's file name.
std::string SequenceTitle(const EvalPlaceArgs& args) {
  if (args.bag.given()) return fs::path(args.bag.bag).filename().string();
  const std::string& images = args.images;
  fs::path shown = fs::path(images).lexically_normal();
  if (shown.filename().empty()) shown = shown.parent_path();      // a trailing slash
  if (shown.filename() == "images") shown = shown.parent_path();  // name the data set
  return shown.filename().string();
}

// Reads detector parameters from a YAML file: the settings table's names
// (core/place/detector_settings.h; a `preset` among them applies first), and the evaluation's own
// `features`, `direct_index_levels_up` and `scoring`. Unknown keys are an error (typos must not
// pass silently).
Status ReadParams(const std::string& path, PlaceEvaluationOptions* options, int* features) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    return Status::NotFound("parameter file '" + path + "' cannot be read");
  } catch (const YAML::Exception& e) {
    return Status::InvalidArgument("parameter file '" + path + "': " + e.what());
  }
  if (!root.IsMap()) return Status::InvalidArgument("parameter file '" + path + "' is not a map");
  const std::string context = "parameter file '" + path + "'";
  std::vector<NamedSetting> settings;
  try {
    for (const auto& item : root) {
      const std::string key = item.first.as<std::string>();
      const YAML::Node& value = item.second;
      if (!value.IsScalar()) {
        return Status::InvalidArgument(context + ": '" + key + "' is not a single value");
      }
      if (key == "direct_index_levels_up") {
        options->direct_index_levels_up = value.as<uint32_t>();
      } else if (key == "features") {
        *features = value.as<int>();
      } else if (key == "scoring") {
        RECOG_ASSIGN_OR_RETURN(options->scoring, ParseScoring(value.Scalar()));
      } else {
        settings.emplace_back(key, value.Scalar());
      }
    }
  } catch (const YAML::Exception& e) {
    return Status::InvalidArgument(context + ": " + e.what());
  }
  const Status applied = ApplyDetectorSettings(settings, &options->detector);
  return applied.ok() ? applied : applied.WithContext(context);
}

nlohmann::json ToJson(const PlaceEvaluation& e, const SequenceFeatures& seq) {
  nlohmann::json timing;
  for (const auto& [stage, s] : e.timing_ms) {
    timing[stage] = {{"mean", s.mean}, {"median", s.median}, {"max", s.max}};
  }
  nlohmann::json loops = nlohmann::json::array();
  for (const DetectedLoop& l : e.loops) {
    nlohmann::json loop = {{"query", l.query + 1},
                           {"match", l.match + 1},
                           {"query_file", seq.names[size_t(l.query)]},
                           {"match_file", seq.names[size_t(l.match)]},
                           {"status", std::string(LoopStatusName(l.status))},
                           {"acceptance", std::string(LoopAcceptanceName(l.acceptance))},
                           {"correct", l.correct},
                           {"normalized_score", l.normalized_score},
                           {"inliers", l.inliers}};
    if (l.status == LoopStatus::kLoopDetected || l.inliers > 0) {
      const LoopEvidence& v = l.evidence;
      loop["evidence"] = {{"inliers", v.inliers},
                          {"spread", v.spread},
                          {"calibrated", v.calibrated},
                          {"in_front", v.in_front},
                          {"parallax_deg", v.parallax_deg},
                          {"rotation_deg", v.rotation_deg},
                          {"pure_rotation", v.pure_rotation},
                          {"confirmations", v.confirmations}};
    }
    if (l.ambiguous) loop["ambiguous"] = true;
    if (l.geometry.has_value()) {
      loop["true_geometry"] = {{"distance_m", l.geometry->distance_m},
                               {"angle_deg", l.geometry->angle_deg},
                               {"agreeing_inliers", l.geometry->agreeing},
                               {"agrees", l.geometry->agrees}};
    }
    if (l.metric.checked) {
      // X_query = R X_match + t, metres.
      loop["metric"] = {{"verified", l.metric.verified},
                        {"inliers", l.metric.inliers.size()},
                        {"correspondences", l.metric.correspondences},
                        {"rotation", std::vector<double>(l.metric.R.val, l.metric.R.val + 9)},
                        {"translation", {l.metric.t[0], l.metric.t[1], l.metric.t[2]}},
                        {"covariance", l.metric.covariance}};
    }
    loops.push_back(std::move(loop));
  }
  nlohmann::json out = {
      {"frames", e.frames},         {"query_frames_with_truth", e.query_frames_with_truth},
      {"detections", e.detections}, {"correct", e.correct},
      {"ambiguous", e.ambiguous},   {"precision", e.precision},
      {"recall", e.recall},         {"statuses", e.statuses},
      {"timing_ms", timing},        {"loops", loops}};
  AddMissesJson(e, &seq.names, &out);
  return out;
}

// Side-by-side images of each detection with its inlier correspondences.
Status DrawDetections(const std::string& dir, const SequenceFeatures& seq,
                      const std::vector<LoopResult>& results) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Status::InvalidArgument("cannot create '" + dir + "': " + ec.message());
  for (size_t q = 0; q < results.size(); ++q) {
    const LoopResult& r = results[q];
    if (r.status != LoopStatus::kLoopDetected) continue;
    std::vector<cv::DMatch> matches;
    for (const Match& m : r.inliers) matches.emplace_back(int(m.a), int(m.b), float(m.distance));
    cv::Mat canvas;
    cv::drawMatches(seq.images[q], seq.features[q].keypoints, seq.images[r.match],
                    seq.features[r.match].keypoints, matches, canvas, cv::Scalar(0, 255, 0),
                    cv::Scalar(0, 0, 255), {}, cv::DrawMatchesFlags::NOT_DRAW_SINGLE_POINTS);
    const std::string path = (fs::path(dir) / ("loop_" + std::to_string(q + 1) + "_" +
                                               std::to_string(r.match + 1) + ".png"))
                                 .string();
    if (!cv::imwrite(path, canvas)) return Status::Internal("cannot write '" + path + "'");
  }
  return Status::Ok();
}

// --split (or --robot-b, after A's frames): robot A's map from the first `split` frames, robot B
// streaming the rest with A in its search set; B's revisits of A's places are inter-map loops,
// the others B's own.
int ReportAcrossMaps(const EvalPlaceArgs& args, int split, const SequenceFeatures& sequence,
                     const GroundTruth& truth, std::shared_ptr<const Vocabulary> vocabulary,
                     const PlaceEvaluationOptions& options, nlohmann::json parameters) {
  auto evaluation = EvaluateAcrossMaps(sequence, truth, split, std::move(vocabulary), options);
  if (!evaluation.ok()) return Fail("eval place", evaluation.status());
  const int frames = int(sequence.features.size());
  if (args.json) {
    const nlohmann::json out = {{"robot_a_frames", {1, split}},
                                {"robot_b_frames", {split + 1, frames}},
                                {"inter_map", ToJson(evaluation->inter_map, sequence)},
                                {"own_map", ToJson(evaluation->own_map, sequence)},
                                {"parameters", std::move(parameters)},
                                {"ground_truth", args.ground_truth}};
    std::printf("%s\n", out.dump(2).c_str());
    return 0;
  }
  std::printf(
      "robot A: frames 1-%d (its map); robot B: frames %d-%d (its own map, A's in its "
      "search set)\n",
      split, split + 1, frames);
  const auto report = [&](const char* what, const char* label, const PlaceEvaluation& e) {
    std::printf(
        "%s: B's frames with a true match there %d, detections %d, correct %d: precision "
        "%.1f %%, recall %.1f %%\n",
        what, e.query_frames_with_truth, e.detections, e.correct, 100 * e.precision,
        100 * e.recall);
    PrintMissSummary(label, e);
  };
  report("inter-map loops (in A's map)", "inter-map", evaluation->inter_map);
  report("own loops (in B's map)", "own", evaluation->own_map);
  const StageStats& lookup = evaluation->inter_map.timing_ms.at("total");
  std::printf("lookup in A's map: %.3f ms median, %.3f ms max per frame (features excluded)\n",
              lookup.median, lookup.max);
  const std::pair<const char*, const PlaceEvaluation*> maps[] = {
      {"inter-map", &evaluation->inter_map}, {"own", &evaluation->own_map}};
  for (const auto& [label, e] : maps) {
    for (const DetectedLoop& l : e->loops) {
      if (l.status != LoopStatus::kLoopDetected) continue;
      std::printf("%s loop %s -> %s (%s, %u inliers)\n", label,
                  sequence.names[size_t(l.query)].c_str(), sequence.names[size_t(l.match)].c_str(),
                  l.correct ? "correct" : "WRONG", l.inliers);
    }
  }
  for (const auto& [label, e] : maps) {
    PrintMisses(label, *e, [&](int frame) { return sequence.names[size_t(frame)]; });
  }
  return 0;
}

// The ORB options of --features (or the features of --params) and --min-short-side.
FeatureOptions OrbFeatureOptions(const EvalPlaceArgs& args, int features) {
  FeatureOptions options = PlaceFeatureOptions();
  options.orb.max_features = features;
  options.orb.min_short_side = args.min_short_side;
  return options;
}

// The ground truth of a sequence of `frames` frames without --ground-truth: no frame has a true
// match, so detections are counted and precision and recall are not reported.
GroundTruth NoTrueMatches(size_t frames) {
  GroundTruth truth;
  truth.frames = int(frames);
  truth.matches.resize(frames);
  return truth;
}

// ---- --rig ----

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

// --rig --json: the evaluation of the rig sequence, with the pose errors when --body-poses gave
// the body's poses.
nlohmann::json RigEvaluationJson(const EvalPlaceArgs& args, const RigPlaceEvaluation& e,
                                 RigLayout layout, const std::vector<std::string>& cameras,
                                 bool posed, const std::string& vocabulary_path) {
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
                        {"vocabulary", vocabulary_path}};
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

// --rig: the rig detector over a rig sequence (every camera image searched against every camera
// image of the map, loops verified across the rig), scored over rig frames.
int RunEvalRig(const EvalPlaceArgs& args, const PlaceEvaluationOptions& options, int features,
               std::shared_ptr<const Vocabulary> vocabulary, const std::string& vocabulary_path) {
  auto dataset = ReadRigDataset(args.rig);
  if (!dataset.ok()) return Fail("eval place", dataset.status());
  auto sequence = ExtractRigFeatures(args, *dataset, features);
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
        RigEvaluationJson(args, *e, dataset->layout, cameras, poses.has_value(), vocabulary_path);
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    PrintRigEvaluation(args, *e, dataset->layout, cameras, poses.has_value());
  }
  return 0;
}

// ---- --images ----

// --images' frames with their features (followed with --robot-b by robot B's), what they are
// judged by, and where robot A's frames end.
struct PlaceSequence {
  SequenceFeatures features;
  GroundTruth truth;                              // NoTrueMatches without --ground-truth
  std::optional<CameraTrajectory> trajectory;     // --poses
  DatasetLayout layout = DatasetLayout::kFolder;  // --images' own (detected unless --layout)
  bool bag = false;                               // read from --bag
  int split = 0;  // > 0: frames 1..split are robot A's map, the rest robot B's
};

// The layout a report names: the dataset layout of --images, or "bag".
std::string LayoutName(const PlaceSequence& sequence) {
  return sequence.bag ? "bag" : std::string(DatasetLayoutName(sequence.layout));
}

// --ground-truth, with the pairs of --ambiguous; an empty truth without --ground-truth.
StatusOr<GroundTruth> ReadTruth(const EvalPlaceArgs& args) {
  GroundTruth truth;
  if (args.has_truth()) {
    RECOG_ASSIGN_OR_RETURN(truth, ReadGroundTruth(args.ground_truth));
  }
  if (!args.ambiguous.empty()) {
    if (!args.has_truth()) return Status::InvalidArgument("--ambiguous needs --ground-truth");
    RECOG_RETURN_IF_ERROR(ReadAmbiguousPairs(args.ambiguous, &truth));
  }
  return truth;
}

// The frames' camera: --camera, or a bag's camera info (--camera-info-topic); none without
// either.
StatusOr<std::optional<CameraIntrinsics>> FramesCamera(const EvalPlaceArgs& args,
                                                       const FrameSource& source) {
  if (!args.camera.empty()) {
    RECOG_ASSIGN_OR_RETURN(const CameraIntrinsics camera, ParseCameraFlag("--camera", args.camera));
    return std::optional<CameraIntrinsics>(camera);
  }
  if (source.bag() != nullptr) return source.bag()->FrameCamera();
  return std::optional<CameraIntrinsics>();
}

// --poses (with the frames' camera): every frame's pose, which the loops are judged by; none
// without it.
StatusOr<std::optional<CameraTrajectory>> ReadTrajectoryFlags(
    const EvalPlaceArgs& args, const std::optional<CameraIntrinsics>& camera) {
  if (args.poses.empty()) return std::optional<CameraTrajectory>();
  if (!camera.has_value()) {
    return Status::InvalidArgument("--poses needs --camera (or a bag's --camera-info-topic)");
  }
  RECOG_ASSIGN_OR_RETURN(std::vector<CameraPose> poses, ReadCameraPoses(args.poses));
  return std::optional<CameraTrajectory>(CameraTrajectory{std::move(poses), camera->K()});
}

// The frames' camera, --depth-scale and --baseline: the camera matrix, and how 3D points come
// from the depth or right images of `source` (a dataset or a bag); none without a camera. A bag's
// stereo baseline comes from its right camera info unless --baseline gives one; its 16UC1 depth
// is in millimetres.
StatusOr<std::optional<SequenceGeometryOptions>> ReadGeometryFlags(
    const EvalPlaceArgs& args, const FrameSource& source,
    const std::optional<CameraIntrinsics>& camera) {
  if (!camera.has_value()) {
    if (args.depth_scale > 0 || args.baseline > 0) {
      return Status::InvalidArgument(
          "--depth-scale and --baseline need --camera (or a bag's --camera-info-topic)");
    }
    if (!args.bag.topics.depth.empty() || !args.bag.topics.right.empty()) {
      return Status::InvalidArgument(
          "--depth-topic and --right-topic need the frames' camera: --camera-info-topic or "
          "--camera");
    }
    return std::optional<SequenceGeometryOptions>();
  }
  SequenceGeometryOptions geometry;
  geometry.camera = *camera;
  // --depth-scale is in units per metre, as in recog query and the model builder's views.
  const double units_per_metre = args.depth_scale > 0
                                     ? args.depth_scale
                                     : (source.layout() == DatasetLayout::kTum ? 5000.0 : 1000.0);
  geometry.depth_scale = 1.0 / units_per_metre;
  geometry.baseline_m = args.baseline;
  if (geometry.baseline_m <= 0 && source.bag() != nullptr) {
    RECOG_ASSIGN_OR_RETURN(const std::optional<double> baseline, source.bag()->StereoBaseline());
    if (baseline.has_value()) geometry.baseline_m = *baseline;
  }
  return std::optional<SequenceGeometryOptions>(geometry);
}

// --robot-b: robot B's frames with their features, appended to robot A's in *sequence (as the
// ground truth numbers them).
Status AppendRobotB(const EvalPlaceArgs& args, std::optional<DatasetLayout> layout,
                    const FeatureOptions& orb,
                    const std::optional<SequenceGeometryOptions>& geometry,
                    SequenceFeatures* sequence) {
  RECOG_ASSIGN_OR_RETURN(FrameSource source, FrameSource::Open(args.robot_b, layout));
  ProgressBar progress(!args.quiet);
  auto robot_b = ExtractSequence(
      source, orb, false,
      [&](size_t n) { progress.Update("robot B's features", n, source.size()); }, geometry);
  progress.Finish();
  RECOG_RETURN_IF_ERROR(robot_b.status());
  AppendSequence(std::move(robot_b).value(), sequence);
  return Status::Ok();
}

// Reads --images (in `layout`, detected when none) or --bag and what goes with it, and extracts
// the frames' features.
StatusOr<PlaceSequence> ReadPlaceSequence(const EvalPlaceArgs& args,
                                          std::optional<DatasetLayout> layout, int features) {
  RECOG_ASSIGN_OR_RETURN(FrameSource source, args.bag.given()
                                                 ? args.bag.Open()
                                                 : FrameSource::Open(args.images, layout));
  PlaceSequence sequence;
  sequence.layout = source.layout();
  sequence.bag = source.is_bag();
  RECOG_ASSIGN_OR_RETURN(sequence.truth, ReadTruth(args));
  RECOG_ASSIGN_OR_RETURN(const std::optional<CameraIntrinsics> camera, FramesCamera(args, source));
  RECOG_ASSIGN_OR_RETURN(sequence.trajectory, ReadTrajectoryFlags(args, camera));
  RECOG_ASSIGN_OR_RETURN(const std::optional<SequenceGeometryOptions> geometry,
                         ReadGeometryFlags(args, source, camera));
  const FeatureOptions orb = OrbFeatureOptions(args, features);
  const uint64_t frames = args.has_truth() ? uint64_t(sequence.truth.frames) : source.size();
  ProgressBar progress(!args.quiet);
  auto extracted = ExtractSequence(
      source, orb, !args.draw_dir.empty(),
      [&](size_t n) { progress.Update("features", n, frames); }, geometry);
  progress.Finish();
  RECOG_ASSIGN_OR_RETURN(sequence.features, std::move(extracted));
  sequence.split = args.split;
  if (!args.robot_b.empty()) {
    sequence.split = int(sequence.features.features.size());
    RECOG_RETURN_IF_ERROR(AppendRobotB(args, layout, orb, geometry, &sequence.features));
  }
  if (!args.has_truth()) sequence.truth = NoTrueMatches(sequence.features.features.size());
  return sequence;
}

// The settings that the results are reported with.
nlohmann::json ParametersJson(const PlaceEvaluationOptions& options, int features,
                              const std::string& vocabulary_path) {
  return {{"preset", std::string(DetectorPresetName(options.detector.preset))},
          {"strong_acceptance", options.detector.strong_acceptance},
          {"alpha", options.detector.alpha},
          {"temporal_matches", options.detector.temporal_matches},
          {"geometry", std::string(GeometryCheckName(options.detector.geometry))},
          {"direct_index_levels_up", options.direct_index_levels_up},
          {"features", features},
          {"vocabulary", vocabulary_path}};
}

// The results of one map (ToJson) with the settings, the layout and the ground truth; without a
// ground truth, none of its figures (precision, recall, each loop's verdict).
nlohmann::json EvaluationJson(const EvalPlaceArgs& args, const PlaceEvaluation& evaluation,
                              const PlaceSequence& sequence, nlohmann::json parameters) {
  nlohmann::json out = ToJson(evaluation, sequence.features);
  out["parameters"] = std::move(parameters);
  out["layout"] = LayoutName(sequence);
  out["ground_truth"] =
      args.has_truth() ? nlohmann::json(args.ground_truth) : nlohmann::json(nullptr);
  if (!args.has_truth()) {
    for (const char* key :
         {"query_frames_with_truth", "correct", "precision", "recall", "misses", "miss_reasons"}) {
      out.erase(key);
    }
    for (nlohmann::json& loop : out["loops"]) loop.erase("correct");
  }
  return out;
}

// One curve of --sweep alpha: precision and recall at alpha 0, 0.05, ..., 1 with the geometric
// check `geometry`; each point is also appended to *sweep.
StatusOr<PlotSeries> SweepAlphaCurve(const PlaceSequence& sequence,
                                     const std::shared_ptr<const Vocabulary>& vocabulary,
                                     const PlaceEvaluationOptions& options, GeometryCheck geometry,
                                     const cv::Scalar& color, nlohmann::json* sweep) {
  PlotSeries series;
  series.label = "geometry: " + std::string(GeometryCheckName(geometry));
  series.color = color;
  for (int a = 0; a <= 20; ++a) {
    PlaceEvaluationOptions o = options;
    o.detector.alpha = a * 0.05;
    o.detector.geometry = geometry;
    RECOG_ASSIGN_OR_RETURN(const PlaceEvaluation e,
                           EvaluatePlace(sequence.features, sequence.truth, vocabulary, o));
    sweep->push_back({{"geometry", std::string(GeometryCheckName(geometry))},
                      {"alpha", o.detector.alpha},
                      {"precision", e.precision},
                      {"recall", e.recall},
                      {"detections", e.detections}});
    series.points.push_back({e.recall, e.precision});
    char label[16];
    std::snprintf(label, sizeof(label), "%.1f", o.detector.alpha);
    series.point_labels.push_back(a % 4 == 0 ? label : "");
  }
  return series;
}

// --sweep alpha: two precision-recall curves, with the configured geometric check and without any
// (thesis Fig. 4.7), which shows what the normalised score and the temporal consistency achieve
// on their own; their points go to out["sweep"], their plot to --plot.
Status SweepAlpha(const EvalPlaceArgs& args, const PlaceSequence& sequence,
                  const std::shared_ptr<const Vocabulary>& vocabulary,
                  const PlaceEvaluationOptions& options, nlohmann::json* out) {
  nlohmann::json sweep = nlohmann::json::array();
  std::vector<PlotSeries> curves;
  for (const GeometryCheck geometry : {options.detector.geometry, GeometryCheck::kNone}) {
    if (!curves.empty() && geometry == options.detector.geometry) break;
    const cv::Scalar color = curves.empty() ? cv::Scalar(200, 80, 20) : cv::Scalar(40, 40, 220);
    RECOG_ASSIGN_OR_RETURN(PlotSeries curve,
                           SweepAlphaCurve(sequence, vocabulary, options, geometry, color, &sweep));
    curves.push_back(std::move(curve));
  }
  (*out)["sweep"] = sweep;
  PlotOptions plot;
  plot.title =
      "Loop detection on " + SequenceTitle(args) + ": precision vs recall, alpha from 0 to 1";
  plot.x_label = "recall";
  plot.y_label = "precision";
  RECOG_RETURN_IF_ERROR(WritePlot(args.plot, plot, curves));
  (*out)["plot"] = args.plot;
  return Status::Ok();
}

// --poses: the PNG of the detected loops over the trajectory, each correct, false or ambiguous;
// its name goes to out["trajectory_plot"].
Status PlotLoopsOverTrajectory(const EvalPlaceArgs& args, const CameraTrajectory& trajectory,
                               const PlaceEvaluation& evaluation, nlohmann::json* out) {
  std::vector<DrawnLoop> drawn;
  for (const DetectedLoop& l : evaluation.loops) {
    if (l.status != LoopStatus::kLoopDetected) continue;
    drawn.push_back({l.query, l.match,
                     l.ambiguous ? DrawnLoop::Verdict::kAmbiguous
                     : l.correct ? DrawnLoop::Verdict::kCorrect
                                 : DrawnLoop::Verdict::kFalse});
  }
  char title[160];
  std::snprintf(title, sizeof(title), "%s, --preset %s: %d loops, %d correct, %d ambiguous",
                SequenceTitle(args).c_str(), PresetFlag(args).c_str(), evaluation.detections,
                evaluation.correct, evaluation.ambiguous);
  RECOG_RETURN_IF_ERROR(WriteTrajectoryPlot(trajectory.poses, drawn, title, args.trajectory_plot));
  (*out)["trajectory_plot"] = args.trajectory_plot;
  return Status::Ok();
}

// A detected loop as the text report lists it: its two frames, its verdict (with a ground truth),
// its inliers, and its metric check and true geometry when it has them.
void PrintLoop(const DetectedLoop& l, const SequenceFeatures& sequence, bool has_truth) {
  std::string metric;
  if (l.metric.verified) {
    char text[96];
    std::snprintf(text, sizeof(text), "; metric: %zu 3D inliers, |t| %.3f m",
                  l.metric.inliers.size(), cv::norm(l.metric.t));
    metric = text;
  }
  std::string truth_text;
  if (l.geometry.has_value()) {
    char text[128];
    std::snprintf(text, sizeof(text),
                  "; cameras %.1f m and %.0f deg apart, %u on the true geometry",
                  l.geometry->distance_m, l.geometry->angle_deg, l.geometry->agreeing);
    truth_text = text;
  }
  std::printf("loop %s -> %s (%s%u inliers%s%s)\n", sequence.names[size_t(l.query)].c_str(),
              sequence.names[size_t(l.match)].c_str(),
              !has_truth    ? ""
              : l.ambiguous ? "ambiguous, "
              : l.correct   ? "correct, "
                            : "WRONG, ",
              l.inliers, metric.c_str(), truth_text.c_str());
}

// The results of one map as text: the scores, the stages' timings and the loops detected.
void PrintPlaceEvaluation(const EvalPlaceArgs& args, const PlaceEvaluation& e,
                          const PlaceSequence& sequence) {
  if (args.has_truth()) {
    std::printf("frames %d, query frames with a true match %d\n", e.frames,
                e.query_frames_with_truth);
    std::printf("detections %d, correct %d%s: precision %.1f %%, recall %.1f %%\n", e.detections,
                e.correct,
                e.ambiguous > 0 ? (", ambiguous " + std::to_string(e.ambiguous)).c_str() : "",
                100 * e.precision, 100 * e.recall);
    PrintMissSummary("", e);
  } else {
    std::printf("frames %d (layout %s), detections %d (no ground truth)\n", e.frames,
                LayoutName(sequence).c_str(), e.detections);
  }
  std::printf("%-26s %8s %8s %8s  (ms per frame)\n", "stage", "mean", "median", "max");
  for (const char* stage :
       {"features", "points", "conversion", "query", "islands", "insertion", "verification",
        "verification_per_candidate", "metric_verification", "total"}) {
    // points and metric_verification: with --camera; per candidate: frames that verified one
    if (!e.timing_ms.count(stage)) continue;
    const StageStats& s = e.timing_ms.at(stage);
    std::printf("%-26s %8.3f %8.3f %8.3f\n", stage, s.mean, s.median, s.max);
  }
  for (const DetectedLoop& l : e.loops) {
    if (l.status == LoopStatus::kLoopDetected) PrintLoop(l, sequence.features, args.has_truth());
  }
  PrintMisses("", e, [&](int frame) { return sequence.features.names[size_t(frame)]; });
  if (!args.sweep.empty()) std::printf("precision-recall plot: %s\n", args.plot.c_str());
}

// One robot's map over --images: the detections scored, then the sweep, the drawings and the
// trajectory plot asked for, and the report.
int ReportOneMap(const EvalPlaceArgs& args, const PlaceSequence& sequence,
                 std::shared_ptr<const Vocabulary> vocabulary,
                 const PlaceEvaluationOptions& options, nlohmann::json parameters) {
  std::vector<LoopResult> results;
  auto evaluation = EvaluatePlace(sequence.features, sequence.truth, vocabulary, options, &results,
                                  sequence.trajectory ? &*sequence.trajectory : nullptr);
  if (!evaluation.ok()) return Fail("eval place", evaluation.status());
  nlohmann::json out = EvaluationJson(args, *evaluation, sequence, std::move(parameters));
  if (!args.sweep.empty()) {
    if (Status s = SweepAlpha(args, sequence, vocabulary, options, &out); !s.ok())
      return Fail("eval place", s);
  }
  if (!args.draw_dir.empty()) {
    if (Status s = DrawDetections(args.draw_dir, sequence.features, results); !s.ok()) {
      return Fail("eval place", s);
    }
  }
  if (sequence.trajectory.has_value()) {
    if (Status s = PlotLoopsOverTrajectory(args, *sequence.trajectory, *evaluation, &out);
        !s.ok()) {
      return Fail("eval place", s);
    }
  }
  if (args.json) {
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    PrintPlaceEvaluation(args, *evaluation, sequence);
  }
  return 0;
}

// ---- recog eval place ----

// --preset, then --params over it; *features starts as --features, which --params may change.
// --mode is the old name of --preset: still read, with a line saying so.
Status ReadDetectorSettings(const EvalPlaceArgs& args, PlaceEvaluationOptions* options,
                            int* features) {
  if (!args.deprecated_mode.empty()) {
    std::fprintf(stderr, "recog eval place: --mode is deprecated, use --preset %s\n",
                 args.deprecated_mode.c_str());
  }
  const std::vector<NamedSetting> preset = {{"preset", PresetFlag(args)}};
  RECOG_RETURN_IF_ERROR(ApplyDetectorSettings(preset, &options->detector));
  *features = args.features;
  if (args.params_file.empty()) return Status::Ok();
  return ReadParams(args.params_file, options, features);
}

// --sweep, --split and --robot-b: what they take and need.
Status CheckReportFlags(const EvalPlaceArgs& args) {
  if (!args.sweep.empty() && args.sweep != "alpha") {
    return Status::InvalidArgument("--sweep only supports 'alpha'");
  }
  if (!args.sweep.empty() && !args.has_truth()) {
    return Status::InvalidArgument("--sweep needs --ground-truth");
  }
  if (args.two_robots() && (!args.has_truth() || !args.sweep.empty() || !args.draw_dir.empty())) {
    return Status::InvalidArgument(std::string(args.split > 0 ? "--split" : "--robot-b") +
                                   " needs --ground-truth, without --sweep or --draw");
  }
  return Status::Ok();
}

// --layout: none for auto (detected from the folder's files).
StatusOr<std::optional<DatasetLayout>> ParseLayoutFlag(const std::string& text) {
  if (text == "auto") return std::optional<DatasetLayout>();
  RECOG_ASSIGN_OR_RETURN(const DatasetLayout layout, ParseDatasetLayout(text));
  return std::optional<DatasetLayout>(layout);
}

// The sequence: --images, --bag or --rig, each without the flags of the others.
Status CheckSequenceFlags(const EvalPlaceArgs& args) {
  if (int(!args.rig.empty()) + int(!args.images.empty()) + int(args.bag.given()) != 1) {
    return Status::InvalidArgument("give the sequence with either --images or --rig (or --bag)");
  }
  if (args.bag.given() && args.layout != "auto") {
    return Status::InvalidArgument("--layout goes with --images, not --bag");
  }
  if (!args.camera.empty() && !args.bag.topics.camera_info.empty()) {
    return Status::InvalidArgument(
        "give the camera with --camera or --camera-info-topic, not both");
  }
  if (!args.rig.empty() && (args.two_robots() || !args.sweep.empty() || !args.draw_dir.empty() ||
                            !args.camera.empty() || args.baseline > 0)) {
    return Status::InvalidArgument(
        "--rig takes its cameras from the rig: without --camera, --baseline, --split, "
        "--robot-b, --sweep or --draw");
  }
  if (args.rig.empty() &&
      (!args.body_poses.empty() || !args.rig_cameras.empty() || args.no_depth)) {
    return Status::InvalidArgument("--body-poses, --cameras and --no-depth need --rig");
  }
  return Status::Ok();
}

int RunEvalPlace(const EvalPlaceArgs& args) {
  PlaceEvaluationOptions options;
  int features = 0;
  if (Status s = ReadDetectorSettings(args, &options, &features); !s.ok())
    return Fail("eval place", s);
  if (Status s = CheckReportFlags(args); !s.ok()) return Fail("eval place", s);
  auto layout = ParseLayoutFlag(args.layout);
  if (!layout.ok()) return Fail("eval place", layout.status());
  if (Status s = CheckSequenceFlags(args); !s.ok()) return Fail("eval place", s);
  const std::string vocabulary_path =
      args.vocabulary.empty() ? DefaultPlaceVocabularyPath() : args.vocabulary;
  auto vocabulary = LoadAnyVocabulary(vocabulary_path);
  if (!vocabulary.ok()) return Fail("eval place", vocabulary.status());
  auto shared = std::make_shared<const Vocabulary>(std::move(vocabulary).value());
  if (!args.rig.empty()) return RunEvalRig(args, options, features, shared, vocabulary_path);

  auto sequence = ReadPlaceSequence(args, *layout, features);
  if (!sequence.ok()) return Fail("eval place", sequence.status());
  nlohmann::json parameters = ParametersJson(options, features, vocabulary_path);
  if (sequence->split > 0) {
    return ReportAcrossMaps(args, sequence->split, sequence->features, sequence->truth, shared,
                            options, std::move(parameters));
  }
  return ReportOneMap(args, *sequence, shared, options, std::move(parameters));
}

}  // namespace

void AddEvalPlaceCommand(CLI::App& eval, int* exit_code) {
  auto args = std::make_shared<EvalPlaceArgs>();
  CLI::App* place = eval.add_subcommand(
      "place", "Run the loop detector over a sequence (scored when a ground truth is given)");
  CLI::Option* images =
      place->add_option("--images", args->images,
                        "Folder of frames (or a TUM RGB-D, EuRoC or KITTI dataset folder), a list "
                        "file, or a video");
  args->bag.AddTo(place, images);
  place->add_option("--rig", args->rig,
                    "A multi-camera rig sequence instead of --images: a rig file with one folder "
                    "per camera beside it (what recog seqgen rig writes), or a EuRoC (camN/"
                    "sensor.yaml) or KITTI (calib.txt, image_N/) folder; every camera's images "
                    "are searched against every camera's, loops verified across the rig");
  place
      ->add_option("--cameras", args->rig_cameras,
                   "With --rig: only these cameras, comma-separated (e.g. front: the "
                   "single-camera control)")
      ->delimiter(',');
  place->add_option("--body-poses", args->body_poses,
                    "With --rig: the body's poses (TUM trajectory, world from body, one line per "
                    "rig frame; recog seqgen rig writes body_poses.txt): each loop's pose error");
  place->add_flag("--no-depth", args->no_depth,
                  "With --rig: ignore the cameras' depth images (a monocular rig)");
  place
      ->add_option("--layout", args->layout,
                   "Folder layout: auto (detected), tum, euroc, kitti or folder; the datasets' "
                   "timestamps set tau_c in seconds")
      ->capture_default_str();
  place->add_option("--ground-truth", args->ground_truth,
                    "N x N 0/1 matrix (line i, column j = 1: frame i revisits frame j < i), or "
                    "the sparse format of recog seqgen; without it, only detections are reported");
  place
      ->add_option("--camera", args->camera,
                   std::string("The frames' camera: ") + kCameraFlagSyntax +
                       ". Loops are checked with the essential matrix (a lens's keypoints moved "
                       "into the pinhole image of its K); frames with a depth image (TUM) or a "
                       "right image (EuRoC, KITTI) of a camera without distortion get 3D points, "
                       "loops a 3D check and a metric pose")
      ->check(Accepts([](const std::string& text) { return ParseCameraFlag("--camera", text); }));
  place
      ->add_option("--poses", args->poses,
                   "With --camera: every frame's pose (a line per frame: r11..r33 camera to world, "
                   "then the centre cx cy cz, metres): each loop's distance and angle between "
                   "the cameras and its inliers on the true geometry (a loop whose inliers are "
                   "not is false), and a PNG of the loops over the trajectory")
      ->check(CLI::ExistingFile);
  place
      ->add_option("--trajectory-plot", args->trajectory_plot,
                   "With --poses: the PNG of the loops over the trajectory")
      ->capture_default_str();
  place
      ->add_option("--ambiguous", args->ambiguous,
                   "Pairs 'i j' (frame numbers from 1) neither right nor wrong: their loops are "
                   "left out of precision")
      ->check(CLI::ExistingFile);
  place->add_option("--depth-scale", args->depth_scale,
                    "With --camera: 16-bit depth units per metre (default: TUM's 5000, else "
                    "1000)");
  place->add_option("--baseline", args->baseline,
                    "With --camera: stereo baseline in metres (needed for right images; a bag's "
                    "--right-camera-info-topic gives it)");
  place->add_option("--vocab", args->vocabulary, "Vocabulary (default: the bundled place one)");
  place
      ->add_option("--preset", args->preset,
                   "Detector preset: 'default' (strong geometric evidence needs no temporal "
                   "consistency), 'thesis' (every loop needs k consistent queries) or "
                   "'keyframes' (frames metres apart: scores normalised by the best candidate, "
                   "tau_c 4 frames)")
      ->capture_default_str();
  place->add_option("--mode", args->deprecated_mode, "Deprecated: the old name of --preset")
      ->excludes("--preset");
  place->add_option("--params", args->params_file,
                    "YAML file of detector settings by name (over the --preset preset; "
                    "docs/places.md)");
  place->add_option("--features", args->features, "ORB features per frame")->capture_default_str();
  place
      ->add_option("--min-short-side", args->min_short_side,
                   "Frames whose shorter side is under this many pixels are enlarged to it before "
                   "ORB (0 = never)")
      ->capture_default_str();
  CLI::Option* split =
      place
          ->add_option("--split", args->split,
                       "Two robots: frames 1..N are robot A's map, the rest stream into robot B's "
                       "map with A's in its search set (inter-map loops and B's own, scored "
                       "apart)")
          ->check(CLI::PositiveNumber);
  place
      ->add_option("--robot-b", args->robot_b,
                   "Two robots, two sequences: --images is robot A's (its map), this robot B's "
                   "(streamed, A's map searched); --ground-truth covers A's frames, then B's")
      ->excludes(split);
  place->add_option("--sweep", args->sweep, "'alpha': precision-recall curve over alpha 0..1");
  place
      ->add_option(
          "--plot", args->plot,
          "PNG of the precision-recall curve (with --sweep); its points go to the same name .csv")
      ->capture_default_str();
  place->add_option("--draw", args->draw_dir, "Folder for images of every detection");
  place->add_flag("--json", args->json, "Print JSON");
  place->add_flag("-q,--quiet", args->quiet, "No progress output");
  place->callback([args, exit_code] { *exit_code = RunEvalPlace(*args); });
}

}  // namespace recog::cli
