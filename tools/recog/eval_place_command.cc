// recog eval place: runs the loop detector over a sequence (a folder, a TUM RGB-D / EuRoC / KITTI
// dataset folder with timestamps, a list, a video or a ROS bag (1 or 2); or with --rig a
// multi-camera rig sequence) and reports the detections and per-stage timings, with a ground truth
// also precision, recall and why each missed revisit was missed (eval_place_misses.h); --sweep
// alpha draws the PR curve. This file holds the flags, their checks and the dispatch to the modes
// (eval_place.h lists the files of each).
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "core/place/detector_settings.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tools/common/cli_support.h"
#include "tools/evaluation/camera_calibration.h"
#include "tools/recog/commands.h"
#include "tools/recog/eval_place.h"

namespace recog::cli {
namespace {

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
  const StatusOr<EvalPlaceSettings> settings = ReadEvalPlaceSettings(args);
  if (!settings.ok()) return Fail("eval place", settings.status());
  const PlaceEvaluationOptions& options = settings->options;
  if (Status s = CheckReportFlags(args); !s.ok()) return Fail("eval place", s);
  auto layout = ParseLayoutFlag(args.layout);
  if (!layout.ok()) return Fail("eval place", layout.status());
  if (Status s = CheckSequenceFlags(args); !s.ok()) return Fail("eval place", s);
  const std::string vocabulary_path =
      args.vocabulary.empty() ? DefaultPlaceVocabularyPath() : args.vocabulary;
  auto vocabulary = LoadAnyVocabulary(vocabulary_path);
  if (!vocabulary.ok()) return Fail("eval place", vocabulary.status());
  auto shared = std::make_shared<const Vocabulary>(std::move(vocabulary).value());
  if (!args.rig.empty()) return RunEvalRig(args, *settings, shared, vocabulary_path);

  auto sequence = ReadPlaceSequence(args, *layout, settings->features);
  if (!sequence.ok()) return Fail("eval place", sequence.status());
  nlohmann::json parameters = ParametersJson(*settings, vocabulary_path, false);
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
  place->add_option("--preset", args->preset, "Detector preset:\n" + PresetHelp())
      ->capture_default_str();
  place->add_option("--mode", args->deprecated_mode, "Deprecated: the old name of --preset")
      ->excludes("--preset");
  place->add_option("--params", args->params_file,
                    "YAML file of detector settings by name (over the --preset preset; "
                    "docs/places.md), or a report of --json: its parameters, every setting "
                    "(not its vocabulary)");
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
