// recog eval sequence: frame-by-frame recognition of one object over a sequence (recall and false
// positives), optionally tracked from frame to frame, with pose errors against a ground truth
// (--truth from recog seqgen objects, or --poses).
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/median.h"
#include "core/object/recognition/object_recognizer.h"
#include "core/object/tracking/object_tracker.h"
#include "tools/common/cli_support.h"
#include "tools/common/remote_support.h"
#include "tools/evaluation/frame_poses.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/recog/commands.h"
#include "tools/recog/model_database.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct EvalSequenceArgs {
  std::vector<std::string> models;
  std::string images, camera, expect, draw, vocabulary;
  std::string truth, size_recall = "size_recall";  // --truth, --size-recall
  std::string poses, pose_errors = "pose_errors";  // --poses, --pose-errors
  SizeRecallOptions size_options;                  // its pose limits serve --poses too
  std::vector<std::string> exclude;                // frames (file stems) processed but not counted
  bool json = false, quiet = false;
  bool track = false;  // follow the object with an ObjectTracker, as a stream does
};

// --truth: per-frame pose errors and recall against object size (CSV + PNG + JSON + a table).
class SizeRecallReport {
 public:
  Status Open(const EvalSequenceArgs& args) {
    if (args.truth.empty()) return Status::Ok();
    RECOG_ASSIGN_OR_RETURN(truth_, ReadObjectSequenceTruth(args.truth));
    return Status::Ok();
  }
  bool enabled() const { return !truth_.frames.empty(); }

  Status Add(const EvalSequenceArgs& args, const std::string& image,
             const std::vector<Detection>& detections, json* frame) {
    if (!enabled()) return Status::Ok();
    RECOG_ASSIGN_OR_RETURN(const ObjectTruthFrame truth, FindTruthFrame(truth_, image));
    const TruthFrameScore& s =
        scores_.emplace_back(ScoreTruthFrame(truth, args.expect, detections, args.size_options));
    (*frame)["truth"] = {{"visible", s.visible},
                         {"area_fraction", s.area_fraction},
                         {"found", s.found},
                         {"correct_pose", s.correct_pose},
                         {"rotation_error_deg", s.rotation_error_deg},
                         {"translation_error_m", s.translation_error_m}};
    return Status::Ok();
  }

  Status Finish(const EvalSequenceArgs& args, json* out) {
    if (!enabled()) return Status::Ok();
    const SizeRecall r = SummariseSizeRecall(scores_, args.size_options);
    const std::string csv = args.size_recall + ".csv", png = args.size_recall + ".png";
    RECOG_RETURN_IF_ERROR(WriteSizeRecallCsv(r, csv));
    RECOG_RETURN_IF_ERROR(WriteSizeRecallPlot(
        r, "Recall of '" + args.expect + "' against its size on " + args.images, png));
    json bins = json::array();
    for (const SizeBin& b : r.bins) {
      bins.push_back({{"area_lo", b.lo},
                      {"area_hi", b.hi},
                      {"median_area", b.median_area},
                      {"frames", b.frames},
                      {"found", b.found},
                      {"correct", b.correct},
                      {"recall", b.recall},
                      {"found_rate", b.found_rate},
                      {"median_rotation_error_deg", b.median_rotation_error_deg},
                      {"median_translation_error_m", b.median_translation_error_m}});
    }
    (*out)["size_recall"] = {{"visible_frames", r.visible_frames},
                             {"found", r.found},
                             {"correct", r.correct},
                             {"recall", r.recall},
                             {"found_not_visible", r.found_not_visible},
                             {"other_objects", r.other_objects},
                             {"max_rotation_error_deg", args.size_options.max_rotation_error_deg},
                             {"max_translation_error", args.size_options.max_translation_error},
                             {"bins", bins},
                             {"csv", csv},
                             {"plot", png}};
    if (args.json) return Status::Ok();
    std::printf(
        "visible frames %zu: found %zu, right pose %zu (recall %.1f %%); reported while "
        "less than half in view: %zu\n",
        r.visible_frames, r.found, r.correct, 100 * r.recall, r.found_not_visible);
    std::printf("%-16s %6s %6s %6s %8s %8s %8s\n", "area (% frame)", "frames", "found", "right",
                "recall", "rot(deg)", "t (cm)");
    for (const SizeBin& b : r.bins) {
      char range[32];
      std::snprintf(range, sizeof(range), "%.1f-%.1f", 100 * b.lo, 100 * b.hi);
      std::printf("%-16s %6zu %6zu %6zu %7.1f%% %8.2f %8.2f\n", range, b.frames, b.found, b.correct,
                  100 * b.recall, b.median_rotation_error_deg, 100 * b.median_translation_error_m);
    }
    std::printf("size recall: %s, %s\n", csv.c_str(), png.c_str());
    return Status::Ok();
  }

 private:
  ObjectSequenceTruth truth_;
  std::vector<TruthFrameScore> scores_;
};

// --poses: the pose error of every frame with a pose in the list (CSV + PNG + JSON + a line).
class PoseErrorReport {
 public:
  Status Open(const EvalSequenceArgs& args) {
    if (args.poses.empty()) return Status::Ok();
    RECOG_ASSIGN_OR_RETURN(poses_, ReadFramePoses(args.poses));
    return Status::Ok();
  }
  bool enabled() const { return !poses_.empty(); }

  // A frame that counts (not excluded by --exclude).
  void Add(const EvalSequenceArgs& args, const std::string& image,
           const std::vector<Detection>& detections, json* frame) {
    if (!enabled()) return;
    const std::optional<FramePoseScore> s =
        ScoreFramePose(poses_, image, args.expect, detections, args.size_options);
    if (!s) {
      ++frames_without_pose_;
      return;
    }
    scores_.push_back(*s);
    if (!s->score.found) return;
    (*frame)["rotation_error_deg"] = s->score.rotation_error_deg;
    (*frame)["translation_error_m"] = s->score.translation_error_m;
  }

  Status Finish(const EvalSequenceArgs& args, json* out) {
    if (!enabled()) return Status::Ok();
    const PoseErrorSummary r = SummarisePoseErrors(scores_);
    const std::string csv = args.pose_errors + ".csv", png = args.pose_errors + ".png";
    RECOG_RETURN_IF_ERROR(WritePoseErrorCsv(scores_, csv));
    RECOG_RETURN_IF_ERROR(
        WritePoseErrorPlot(scores_, "Pose errors of '" + args.expect + "' on " + args.images, png));
    (*out)["poses"] = {{"frames_with_pose", r.frames_with_pose},
                       {"frames_without_pose", frames_without_pose_},
                       {"found", r.found},
                       {"recall", r.recall},
                       {"wrong_objects", r.wrong_objects},
                       {"median_rotation_error_deg", r.median_rotation_error_deg},
                       {"median_translation_error_m", r.median_translation_error_m},
                       {"correct_pose", r.correct_pose},
                       {"max_rotation_error_deg", args.size_options.max_rotation_error_deg},
                       {"max_translation_error", args.size_options.max_translation_error},
                       {"csv", csv},
                       {"plot", png}};
    if (args.json) return Status::Ok();
    std::printf(
        "frames with a pose %zu (%zu without): found in %zu (recall %.1f %%), correct pose in %zu "
        "(<= %.1f deg, <= %.0f %% of the distance), median errors %.2f deg, %.2f cm; %zu wrong "
        "objects\n",
        r.frames_with_pose, frames_without_pose_, r.found, 100 * r.recall, r.correct_pose,
        args.size_options.max_rotation_error_deg, 100 * args.size_options.max_translation_error,
        r.median_rotation_error_deg, 100 * r.median_translation_error_m, r.wrong_objects);
    std::printf("pose errors: %s, %s\n", csv.c_str(), png.c_str());
    return Status::Ok();
  }

 private:
  std::map<int, RigidTransform> poses_;
  std::vector<FramePoseScore> scores_;
  size_t frames_without_pose_ = 0;
};

// Recognises every frame of a sequence in which one known object (--expect) is visible: recall
// is the fraction of frames where it is found; any other object reported is a false positive.
// With --track the frames go through an ObjectTracker (object_tracker.h) as in a stream: each
// frame is either recognised (the full search ran) or only tracked, and the medians of both kinds
// of frame are reported, with the tracking time per tracked object. Frames named by --exclude
// (e.g. the model's own training views) are processed like the others, so that tracking sees
// the same stream, but left out of recall and false positives (and of the --poses report).
int RunEvalSequence(const EvalSequenceArgs& args) {
  auto camera = ParseCamera(args.camera);
  if (!camera.ok()) return Fail("eval sequence", camera.status());
  auto frames = ListImages(args.images);
  if (!frames.ok()) return Fail("eval sequence", frames.status());
  MemoryIndexStore store;
  auto loaded = LoadModelDatabase(args.models, args.vocabulary, &store);
  if (!loaded.ok()) return Fail("eval sequence", loaded.status());
  const std::shared_ptr<ObjectDatabase> database = std::move(loaded).value();
  const std::vector<ObjectMetadata> objects = database->List();
  if (std::none_of(objects.begin(), objects.end(),
                   [&](const ObjectMetadata& m) { return m.name == args.expect; })) {
    return Fail("eval sequence",
                Status::InvalidArgument("--expect '" + args.expect + "' is not among the models"));
  }
  SizeRecallReport size_recall;
  if (Status s = size_recall.Open(args); !s.ok()) return Fail("eval sequence", s);
  PoseErrorReport pose_errors;
  if (Status s = pose_errors.Open(args); !s.ok()) return Fail("eval sequence", s);
  if (!args.draw.empty()) fs::create_directories(args.draw);
  StatusOr<ObjectRecognizer> created = ObjectRecognizer::Create(database);
  if (!created.ok()) return Fail("eval sequence", created.status());
  ObjectRecognizer recognizer = std::move(created).value();
  ObjectTracker tracker(database);
  ProgressBar progress(!args.quiet);
  const std::set<std::string> excluded(args.exclude.begin(), args.exclude.end());
  for (const std::string& name : excluded) {
    if (std::none_of(frames->begin(), frames->end(),
                     [&](const std::string& path) { return fs::path(path).stem() == name; })) {
      return Fail("eval sequence",
                  Status::InvalidArgument("--exclude: no frame '" + name + "' in --images"));
    }
  }
  size_t counted = 0, found = 0, false_positives = 0, found_tracked = 0;
  std::vector<double> totals, inliers, recognised_totals, tracked_totals, per_object;
  json per_frame = json::array();
  std::vector<Detection> detections;
  for (size_t i = 0; i < frames->size(); ++i) {
    auto image = ReadGrayImage((*frames)[i]);
    if (!image.ok()) return Fail("eval sequence", image.status());
    RecognitionTiming timing;
    TrackingTiming tracking;
    const Status s = args.track ? tracker.Track(recognizer, *image, *camera, &detections, &tracking)
                                : recognizer.Recognize(*image, *camera, &detections, &timing);
    if (!s.ok()) return Fail("eval sequence", s);
    const double total = args.track ? tracking.total : timing.total;
    totals.push_back(total);
    json names = json::array();
    for (const Detection& d : detections) names.push_back(d.name);
    json frame = {{"frame", fs::path((*frames)[i]).filename().string()},
                  {"objects", names},
                  {"total_ms", total}};
    const bool count = !excluded.count(fs::path((*frames)[i]).stem().string());
    counted += count;
    if (!count) frame["excluded"] = true;
    bool hit = false;
    for (const Detection& d : detections) {
      if (!count) continue;
      if (d.name == args.expect) {
        hit = true;
        found_tracked += d.tracked;
        inliers.push_back(double(d.inliers));
      } else {
        ++false_positives;
      }
    }
    found += hit;
    if (args.track) {
      (tracking.recognized ? recognised_totals : tracked_totals).push_back(total);
      if (tracking.tracked + tracking.lost > 0) {
        per_object.push_back(tracking.tracking / double(tracking.tracked + tracking.lost));
      }
      json tracked = json::array();
      for (const Detection& d : detections) tracked.push_back(d.tracked);
      frame["tracked"] = tracked;
      frame["recognized"] = tracking.recognized;
    }
    if (Status s = size_recall.Add(args, (*frames)[i], detections, &frame); !s.ok()) {
      return Fail("eval sequence", s);
    }
    if (count) pose_errors.Add(args, (*frames)[i], detections, &frame);
    per_frame.push_back(std::move(frame));
    if (!args.draw.empty() && !detections.empty()) {
      cv::Mat canvas;
      cv::cvtColor(*image, canvas, cv::COLOR_GRAY2BGR);
      for (const Detection& d : detections) {
        DrawDetection(d, *camera,
                      d.name == args.expect ? cv::Scalar(0, 200, 0) : cv::Scalar(0, 0, 255),
                      &canvas);
      }
      cv::imwrite(
          (fs::path(args.draw) / (fs::path((*frames)[i]).stem().string() + ".png")).string(),
          canvas);
    }
    progress.Update("frames", i + 1, frames->size());
  }
  progress.Finish();
  const double recall = counted > 0 ? double(found) / double(counted) : 0.0;
  json out = {{"frames", counted},
              {"frames_excluded", frames->size() - counted},
              {"detections", found},
              {"recall", recall},
              {"false_positives", false_positives},
              {"median_inliers", Median(inliers)},
              {"timing_ms", {{"total", {{"median", Median(totals)}}}}},
              {"per_frame", per_frame}};
  if (args.track) {
    out["detections_tracked"] = found_tracked;
    out["frames_recognized"] = recognised_totals.size();
    out["frames_tracked"] = tracked_totals.size();
    out["timing_ms"]["recognized_frame"] = {{"median", Median(recognised_totals)}};
    out["timing_ms"]["tracked_frame"] = {{"median", Median(tracked_totals)}};
    out["timing_ms"]["tracking_per_object"] = {{"median", Median(per_object)}};
  }
  if (args.json) {
    if (Status s = size_recall.Finish(args, &out); !s.ok()) return Fail("eval sequence", s);
    if (Status s = pose_errors.Finish(args, &out); !s.ok()) return Fail("eval sequence", s);
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    const std::string left_out =
        excluded.empty() ? "" : " (" + std::to_string(excluded.size()) + " more excluded)";
    std::printf(
        "%zu frames%s: '%s' found in %zu (recall %.1f %%), %zu false positives, median %.2f ms\n",
        counted, left_out.c_str(), args.expect.c_str(), found, 100 * recall, false_positives,
        Median(totals));
    if (args.track) {
      std::printf(
          "tracking: found by tracking in %zu frames; %zu frames recognised (median %.2f ms), %zu "
          "only tracked (median %.2f ms); %.2f ms per tracked object (median)\n",
          found_tracked, recognised_totals.size(), Median(recognised_totals), tracked_totals.size(),
          Median(tracked_totals), Median(per_object));
    }
    if (Status s = size_recall.Finish(args, &out); !s.ok()) return Fail("eval sequence", s);
    if (Status s = pose_errors.Finish(args, &out); !s.ok()) return Fail("eval sequence", s);
  }
  return 0;
}

}  // namespace

void AddEvalSequenceCommand(CLI::App& eval, int* exit_code) {
  auto sequence_args = std::make_shared<EvalSequenceArgs>();
  CLI::App* sequence = eval.add_subcommand(
      "sequence", "Frame-by-frame recognition of one object: recall and false positives");
  sequence
      ->add_option("--models", sequence_args->models,
                   "Model files, folders of them, or RoboEarth folders")
      ->required();
  sequence->add_option("--images", sequence_args->images, "Folder of frames")->required();
  sequence->add_option("--camera", sequence_args->camera, "fx,fy,cx,cy[,k1,k2,p1,p2[,k3]]")
      ->required();
  sequence->add_option("--expect", sequence_args->expect, "Name of the object in every frame")
      ->required();
  sequence->add_option("--draw", sequence_args->draw, "Folder for a PNG per frame with detections");
  sequence->add_option("--vocab", sequence_args->vocabulary, "Vocabulary");
  sequence->add_flag("--track", sequence_args->track,
                     "Track the objects from frame to frame (as StreamRecognizeObjects does)");
  CLI::Option* truth =
      sequence->add_option("--truth", sequence_args->truth,
                           "Ground truth of recog seqgen objects (truth.txt): pose errors per "
                           "frame and recall against object size");
  sequence
      ->add_option("--size-recall", sequence_args->size_recall,
                   "With --truth: write PREFIX.csv and PREFIX.png")
      ->capture_default_str();
  sequence
      ->add_option("--poses", sequence_args->poses,
                   "The object's pose per frame (lines 'NNNN r11..r33 tx ty tz', T_camera<-object, "
                   "metres, '#' comments; a frame is the line of the number ending its file "
                   "name): recall over the frames with a pose and the pose error of each")
      ->excludes(truth);
  sequence
      ->add_option("--pose-errors", sequence_args->pose_errors,
                   "With --poses: write PREFIX.csv (a line per frame with a pose) and PREFIX.png "
                   "(the errors over the frames)")
      ->capture_default_str();
  sequence
      ->add_option("--max-rotation-error", sequence_args->size_options.max_rotation_error_deg,
                   "With --truth or --poses: largest rotation error of a right pose, degrees")
      ->capture_default_str();
  sequence
      ->add_option("--max-translation-error", sequence_args->size_options.max_translation_error,
                   "With --truth or --poses: largest translation error of a right pose, "
                   "fraction of the distance")
      ->capture_default_str();
  sequence
      ->add_option("--exclude", sequence_args->exclude,
                   "Frames (file names without extension, comma-separated) processed but "
                   "left out of recall, false positives and --poses, e.g. the model's training "
                   "views")
      ->delimiter(',');
  sequence->add_flag("--json", sequence_args->json, "Print JSON");
  sequence->add_flag("-q,--quiet", sequence_args->quiet, "No progress output");
  sequence->callback([sequence_args, exit_code] { *exit_code = RunEvalSequence(*sequence_args); });
}

}  // namespace recog::cli
