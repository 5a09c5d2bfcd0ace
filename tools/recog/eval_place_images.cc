// recog eval place over --images or --bag (eval_place.h): one robot's map, scored and reported
// with the --sweep alpha curves, the --draw images and the loops over the --poses trajectory; or
// two robots' maps (--split, --robot-b), B's revisits of A's places scored apart from its own.
// Each as JSON or as text.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "tools/common/cli_support.h"
#include "tools/evaluation/plot.h"
#include "tools/recog/eval_place.h"
#include "tools/recog/eval_place_misses.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

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

}  // namespace

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
  std::printf("%s\n", ChangedSettingsLine(options.detector).c_str());
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
    std::printf("%s\n", ChangedSettingsLine(options.detector).c_str());
    PrintPlaceEvaluation(args, *evaluation, sequence);
  }
  return 0;
}

}  // namespace recog::cli
