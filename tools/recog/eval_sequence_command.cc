// recog eval sequence: frame-by-frame recognition of one object over a sequence (a folder, or a
// ROS bag's image topic) (recall and false positives), optionally tracked from frame to frame,
// with pose errors against a ground truth (--truth from recog seqgen objects, or --poses).
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <limits>
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
#include "tools/evaluation/camera_calibration.h"
#include "tools/evaluation/frame_poses.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/recog/bag_flags.h"
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
  bool track = false;   // follow the object with an ObjectTracker, as a stream does
  BagFlags bag;         // --bag, --topic, --camera-info-topic: the frames instead of --images
  int first_frame = 0;  // --first-frame: the number of the bag's first frame
};

// The name of a bag's frame numbered `number` (SequenceFrames).
std::string BagFrameName(int number) {
  char name[32];
  std::snprintf(name, sizeof(name), "frame_%04d", number);
  return name;
}

// The frames of --images or --bag, with their camera. A folder's frames are its image files
// (ListImages: natural order) and their camera is --camera. A bag's frames are its --topic's
// messages in header-stamp order, the k-th (from 0) named frame_NNNN with NNNN = --first-frame + k
// (at least 4 digits, e.g. frame_0007): --exclude and --draw take that name, --poses and --truth
// its number (--truth: the truth's frame whose image name ends in it), so that a bag of the
// folder's images in order with --first-frame the number of its first image (0 for
// color_image_0000.png, 1 for seqgen's 000001.png) is scored against the same ground truth. Their
// camera is --camera or the bag's --camera-info-topic (K and D), one of the two.
class SequenceFrames {
 public:
  // INVALID_ARGUMENT without --images or --bag, for --images without --camera, and for --bag
  // with both or neither of --camera and --camera-info-topic; ParseCameraFlag's, ListImages' and
  // BagFlags::Open's errors (a bag is checked whole before the first frame).
  Status Open(const EvalSequenceArgs& args) {
    if (args.images.empty() != args.bag.given()) {
      return Status::InvalidArgument("give the frames with --images or --bag");
    }
    if (!args.bag.given()) {
      if (args.camera.empty()) return Status::InvalidArgument("--images needs --camera");
      RECOG_ASSIGN_OR_RETURN(camera_, ParseCameraFlag("--camera", args.camera));
      RECOG_ASSIGN_OR_RETURN(names_, ListImages(args.images));
      label_ = args.images;
      return Status::Ok();
    }
    if (args.camera.empty() == args.bag.topics.camera_info.empty()) {
      return Status::InvalidArgument(
          "--bag needs the frames' camera: give --camera or --camera-info-topic (one of them)");
    }
    if (!args.camera.empty()) {
      RECOG_ASSIGN_OR_RETURN(camera_, ParseCameraFlag("--camera", args.camera));
    }
    RECOG_ASSIGN_OR_RETURN(FrameSource source, args.bag.Open());
    bag_.emplace(std::move(source));
    if (args.camera.empty()) camera_ = *bag_->bag()->FrameCamera();
    if (bag_->size() > size_t(std::numeric_limits<int>::max() - args.first_frame)) {
      return Status::InvalidArgument("--first-frame " + std::to_string(args.first_frame) +
                                     ": the bag's frames would not all have a number");
    }
    for (size_t k = 0; k < bag_->size(); ++k) {
      names_.push_back(BagFrameName(args.first_frame + int(k)));
    }
    label_ = fs::path(args.bag.bag).filename().string();
    return Status::Ok();
  }

  bool is_bag() const { return bag_.has_value(); }
  size_t size() const { return names_.size(); }
  // Frame i's path (a folder) or name (a bag).
  const std::string& name(size_t i) const { return names_[i]; }
  const CameraIntrinsics& camera() const { return camera_; }
  // --images, or the bag's file name: what the plots' titles name.
  const std::string& label() const { return label_; }
  // Frame i in 8-bit grey, the frames read in order (a bag's are read one after the other):
  // ReadGrayImage's errors, or the bag's (a compressed image that cannot be decoded).
  StatusOr<cv::Mat> Read(size_t i) {
    if (!bag_) return ReadGrayImage(names_[i]);
    cv::Mat gray;
    std::string name;
    RECOG_ASSIGN_OR_RETURN(const bool read, bag_->Next(&gray, &name));
    if (!read) return Status::Internal("bag '" + label_ + "' ended before " + names_[i]);
    return gray;
  }

 private:
  std::vector<std::string> names_;
  CameraIntrinsics camera_;
  std::string label_;
  std::optional<FrameSource> bag_;
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
    RECOG_ASSIGN_OR_RETURN(const ObjectTruthFrame truth, args.bag.given()
                                                             ? FindNumberedTruthFrame(image)
                                                             : FindTruthFrame(truth_, image));
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

  // `source`: the frames' folder or bag, for the plot's title.
  Status Finish(const EvalSequenceArgs& args, const std::string& source, json* out) {
    if (!enabled()) return Status::Ok();
    const SizeRecall r = SummariseSizeRecall(scores_, args.size_options);
    const std::string csv = args.size_recall + ".csv", png = args.size_recall + ".png";
    RECOG_RETURN_IF_ERROR(WriteSizeRecallCsv(r, csv));
    RECOG_RETURN_IF_ERROR(WriteSizeRecallPlot(
        r, "Recall of '" + args.expect + "' against its size on " + source, png));
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
  // A bag's frame (SequenceFrames) is the truth's frame whose image name ends in its number;
  // NOT_FOUND when none does.
  StatusOr<ObjectTruthFrame> FindNumberedTruthFrame(const std::string& name) const {
    const std::optional<int> number = FrameNumber(name);
    for (const ObjectTruthFrame& frame : truth_.frames) {
      if (number.has_value() && FrameNumber(frame.image) == number) return frame;
    }
    return Status::NotFound("the truth has no frame numbered " +
                            (number ? std::to_string(*number) : name) + " (the bag's " + name +
                            "; is --first-frame right?)");
  }

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

  // `source`: the frames' folder or bag, for the plot's title.
  Status Finish(const EvalSequenceArgs& args, const std::string& source, json* out) {
    if (!enabled()) return Status::Ok();
    const PoseErrorSummary r = SummarisePoseErrors(scores_);
    const std::string csv = args.pose_errors + ".csv", png = args.pose_errors + ".png";
    RECOG_RETURN_IF_ERROR(WritePoseErrorCsv(scores_, csv));
    RECOG_RETURN_IF_ERROR(
        WritePoseErrorPlot(scores_, "Pose errors of '" + args.expect + "' on " + source, png));
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
// the same stream, but left out of recall and false positives (and of the --poses report). The
// frames come from --images or --bag (SequenceFrames: how a bag's frames are named and matched
// to the ground truth).
int RunEvalSequence(const EvalSequenceArgs& args) {
  SequenceFrames frames;
  if (Status s = frames.Open(args); !s.ok()) return Fail("eval sequence", s);
  const CameraIntrinsics& camera = frames.camera();
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
    bool listed = false;
    for (size_t i = 0; i < frames.size() && !listed; ++i) {
      listed = fs::path(frames.name(i)).stem() == name;
    }
    if (!listed) {
      return Fail("eval sequence",
                  Status::InvalidArgument("--exclude: no frame '" + name + "' in " +
                                          (frames.is_bag() ? "--bag" : "--images")));
    }
  }
  size_t counted = 0, found = 0, false_positives = 0, found_tracked = 0;
  std::vector<double> totals, inliers, recognised_totals, tracked_totals, per_object;
  json per_frame = json::array();
  std::vector<Detection> detections;
  for (size_t i = 0; i < frames.size(); ++i) {
    const std::string& path = frames.name(i);
    auto image = frames.Read(i);
    if (!image.ok()) return Fail("eval sequence", image.status());
    RecognitionTiming timing;
    TrackingTiming tracking;
    const Status s = args.track ? tracker.Track(recognizer, *image, camera, &detections, &tracking)
                                : recognizer.Recognize(*image, camera, &detections, &timing);
    if (!s.ok()) return Fail("eval sequence", s);
    const double total = args.track ? tracking.total : timing.total;
    totals.push_back(total);
    json names = json::array();
    for (const Detection& d : detections) names.push_back(d.name);
    json frame = {
        {"frame", fs::path(path).filename().string()}, {"objects", names}, {"total_ms", total}};
    const bool count = !excluded.count(fs::path(path).stem().string());
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
    if (Status s = size_recall.Add(args, path, detections, &frame); !s.ok()) {
      return Fail("eval sequence", s);
    }
    if (count) pose_errors.Add(args, path, detections, &frame);
    per_frame.push_back(std::move(frame));
    if (!args.draw.empty() && !detections.empty()) {
      cv::Mat canvas;
      cv::cvtColor(*image, canvas, cv::COLOR_GRAY2BGR);
      for (const Detection& d : detections) {
        DrawDetection(d, camera,
                      d.name == args.expect ? cv::Scalar(0, 200, 0) : cv::Scalar(0, 0, 255),
                      &canvas);
      }
      cv::imwrite((fs::path(args.draw) / (fs::path(path).stem().string() + ".png")).string(),
                  canvas);
    }
    progress.Update("frames", i + 1, frames.size());
  }
  progress.Finish();
  const double recall = counted > 0 ? double(found) / double(counted) : 0.0;
  json out = {{"frames", counted},
              {"frames_excluded", frames.size() - counted},
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
    if (Status s = size_recall.Finish(args, frames.label(), &out); !s.ok()) {
      return Fail("eval sequence", s);
    }
    if (Status s = pose_errors.Finish(args, frames.label(), &out); !s.ok()) {
      return Fail("eval sequence", s);
    }
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
    if (Status s = size_recall.Finish(args, frames.label(), &out); !s.ok()) {
      return Fail("eval sequence", s);
    }
    if (Status s = pose_errors.Finish(args, frames.label(), &out); !s.ok()) {
      return Fail("eval sequence", s);
    }
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
  CLI::Option* images =
      sequence->add_option("--images", sequence_args->images, "Folder of frames (or --bag)");
  sequence->add_option("--camera", sequence_args->camera,
                       std::string("The frames' camera, required with --images (with --bag, this "
                                   "or --camera-info-topic): ") +
                           kCameraFlagSyntax);
  CLI::Option* bag =
      sequence_args->bag.AddImageTo(sequence, images,
                                    "A ROS 1 or ROS 2 bag instead of --images: the frames of "
                                    "--topic in header-stamp order, named "
                                    "frame_NNNN from --first-frame (docs/cli.md, \"ROS bags\")");
  sequence
      ->add_option("--first-frame", sequence_args->first_frame,
                   "With --bag: the number of its first frame, as --poses, --truth and --exclude "
                   "see it (the number of the first image of the bag's folder)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber)
      ->needs(bag);
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
                   "name, or its bag frame's name): recall over the frames with a pose and the "
                   "pose error of each")
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
                   "Frames (file names without extension, a bag's frame_NNNN; comma-separated) "
                   "processed but left out of recall, false positives and --poses, e.g. the "
                   "model's training views")
      ->delimiter(',');
  sequence->add_flag("--json", sequence_args->json, "Print JSON");
  sequence->add_flag("-q,--quiet", sequence_args->quiet, "No progress output");
  sequence->callback([sequence_args, exit_code] { *exit_code = RunEvalSequence(*sequence_args); });
}

}  // namespace recog::cli
