// recog eval objects: leave-one-view-out recognition on RoboEarth models (each training view in
// turn a query, transformed by --transforms), with detection rates, pose errors and timings.
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tools/common/cli_support.h"
#include "tools/common/remote_support.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/recog/commands.h"

namespace recog::cli {
namespace {

using nlohmann::json;

struct EvalObjectsArgs {
  std::string roboearth, vocabulary, draw, method = "merged";
  std::vector<std::string> transforms = {"none", "scale0.5", "rot90", "rot180"};
  int min_views = 5;
  bool json = false, quiet = false;
};

json SummaryJson(const ObjectEvaluationSummary& s) {
  const RecognitionTiming& t = s.median_timing;
  const json timing = {{"orb", {{"median", t.orb}}},
                       {"clustering", {{"median", t.clustering}}},
                       {"conversion", {{"median", t.conversion}}},
                       {"query", {{"median", t.query}}},
                       {"correspondences", {{"median", t.correspondences}}},
                       {"ransac", {{"median", t.ransac}}},
                       {"second_pass", {{"median", t.second_pass}}},
                       {"total", {{"median", t.total}}}};
  return {{"queries", s.queries},
          {"detections", s.detections},
          {"detection_rate", s.detection_rate},
          {"wrong_detections", s.wrong_detections},
          {"median_rotation_error_deg", s.median_rotation_error_deg},
          {"median_translation_error_ratio", s.median_translation_error_ratio},
          {"timing_ms", timing}};
}

int RunEvalObjects(const EvalObjectsArgs& args) {
  ObjectEvaluationOptions options;
  options.roboearth_dir = args.roboearth;
  auto method = ParseObjectEvaluationMethod(args.method);
  if (!method.ok()) return Fail("eval objects", method.status());
  options.method = *method;
  options.vocabulary_path =
      args.vocabulary.empty() ? DefaultObjectVocabularyPath() : args.vocabulary;
  options.min_views = args.min_views;
  options.draw_dir = args.draw;
  options.transforms.clear();
  for (const std::string& name : args.transforms) {
    auto transform = ParseImageTransform(name);
    if (!transform.ok()) return Fail("eval objects", transform.status());
    options.transforms.push_back(*transform);
  }
  ProgressBar progress(!args.quiet);
  options.progress = [&progress](size_t done, size_t total) {
    progress.Update("queries", done, total);
  };
  auto evaluation = EvaluateObjects(options);
  progress.Finish();
  if (!evaluation.ok()) return Fail("eval objects", evaluation.status());
  json out = SummaryJson(evaluation->summaries.front());
  out["method"] = std::string(ObjectEvaluationMethodName(evaluation->method));
  out["transform"] = std::string(ImageTransformName(evaluation->summaries.front().transform));
  json by_transform;
  for (const ObjectEvaluationSummary& s : evaluation->summaries) {
    by_transform[std::string(ImageTransformName(s.transform))] = SummaryJson(s);
  }
  out["by_transform"] = by_transform;
  out["database"] = evaluation->database;
  json skipped = json::array();
  for (const auto& [entry, reason] : evaluation->skipped_views) {
    skipped.push_back({{"entry", entry}, {"reason", reason}});
  }
  out["skipped_views"] = skipped;
  json queries = json::array();
  for (const ObjectQuery& q : evaluation->queries) {
    queries.push_back({{"object", q.object},
                       {"view", q.view},
                       {"transform", std::string(ImageTransformName(q.transform))},
                       {"detected", q.detected},
                       {"matched", q.matched},
                       {"wrong", q.wrong},
                       {"inliers", q.inliers},
                       {"rotation_error_deg", q.rotation_error_deg},
                       {"translation_error_ratio", q.translation_error_ratio},
                       {"total_ms", q.timing.total}});
  }
  out["per_query"] = queries;
  if (args.json) {
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    std::printf("method %s: %zu database entries\n",
                std::string(ObjectEvaluationMethodName(evaluation->method)).c_str(),
                evaluation->database.size());
    for (const auto& [entry, reason] : evaluation->skipped_views) {
      std::printf("skipped view %s: %s\n", entry.c_str(), reason.c_str());
    }
    std::printf("%-9s %7s %9s %6s %9s %9s %9s\n", "transform", "queries", "detected", "wrong",
                "rot(deg)", "trans(%)", "total(ms)");
    for (const ObjectEvaluationSummary& s : evaluation->summaries) {
      std::printf("%-9s %7zu %8.1f%% %6zu %9.2f %9.2f %9.2f\n",
                  std::string(ImageTransformName(s.transform)).c_str(), s.queries,
                  100 * s.detection_rate, s.wrong_detections, s.median_rotation_error_deg,
                  100 * s.median_translation_error_ratio, s.median_timing.total);
    }
  }
  return 0;
}

}  // namespace

void AddEvalObjectsCommand(CLI::App& eval, int* exit_code) {
  auto args = std::make_shared<EvalObjectsArgs>();
  CLI::App* objects = eval.add_subcommand(
      "objects", "Leave-one-view-out recognition on RoboEarth models, with pose errors");
  objects->add_option("--roboearth", args->roboearth, "Folder of RoboEarth model folders")
      ->required();
  objects
      ->add_option("--method", args->method,
                   "merged (a model per object from all its views) or independent-views (an "
                   "entry per training view, thesis §5.3)")
      ->capture_default_str();
  objects->add_option("--vocab", args->vocabulary, "Vocabulary (default: the bundled object one)");
  objects->add_option("--transforms", args->transforms, "none, scale0.5, rot90, rot180")
      ->capture_default_str();
  objects->add_option("--min-views", args->min_views, "3D objects with at least this many views")
      ->capture_default_str();
  objects->add_option("--draw", args->draw, "Folder for a PNG per query");
  objects->add_flag("--json", args->json, "Print JSON");
  objects->add_flag("-q,--quiet", args->quiet, "No progress output");
  objects->callback([args, exit_code] { *exit_code = RunEvalObjects(*args); });
}

}  // namespace recog::cli
