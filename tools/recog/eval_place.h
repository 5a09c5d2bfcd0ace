// recog eval place: runs the loop detector over a sequence and reports its detections, timings
// and, with a ground truth, precision, recall and why each missed revisit was missed. The
// command's files, one concern each, share the declarations below:
//   eval_place_command.cc   the flags, their checks and the dispatch to a mode;
//   eval_place_settings.cc  --preset and --params (a YAML of settings, or an earlier report), and
//                           the report's "parameters" that reproduce the run;
//   eval_place_sequence.cc  the --images or --bag sequence with its truth, camera and geometry;
//   eval_place_images.cc    the modes over that sequence: one map (with --sweep alpha, --draw and
//                           the trajectory plot) or two robots' maps (--split, --robot-b);
//   eval_place_rig.cc       --rig: a multi-camera rig sequence;
//   eval_place_misses.cc    why each missed revisit was missed, in every mode.
#pragma once

#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/common/status.h"
#include "core/features/feature_extractor.h"
#include "core/place/rig_loop_detector.h"
#include "core/vocabulary/vocabulary.h"
#include "tools/evaluation/place_evaluation.h"
#include "tools/recog/bag_flags.h"

namespace recog::cli {

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

// ---- eval_place_settings.cc ----

// What the results depend on besides the sequence and the vocabulary: --preset with --params
// over it.
struct EvalPlaceSettings {
  PlaceEvaluationOptions options;  // the detector's settings, scoring, direct_index_levels_up
  int features = 0;                // ORB features per frame: --features, or --params'
  // With --rig: the rig detector's own settings; its `detector` is not read (options.detector is).
  RigLoopParams rig;
};

// --preset, or --mode (its old name) when that was given.
const std::string& PresetFlag(const EvalPlaceArgs& args);

// --preset, then --params over it (with --rig, the rig's own settings too). --mode is the old
// name of --preset: still read, with a line saying so.
StatusOr<EvalPlaceSettings> ReadEvalPlaceSettings(const EvalPlaceArgs& args);

// The report's "parameters": every setting of the detector's table (DetectorSettings(), typed:
// numbers, booleans, names), features, direct_index_levels_up, scoring, the vocabulary, and with
// `rig` the rig's own settings. Given back as --params, it sets all of them (but the vocabulary).
nlohmann::json ParametersJson(const EvalPlaceSettings& settings, const std::string& vocabulary_path,
                              bool rig);

// The text reports' line of settings: the preset and every setting whose value differs from it
// ("settings: preset thesis, ratio 0.7, recent_frames 0").
std::string ChangedSettingsLine(const LoopDetectorParams& params);

// ---- eval_place_sequence.cc ----

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
std::string LayoutName(const PlaceSequence& sequence);

// The ORB options of --features (or the features of --params) and --min-short-side.
FeatureOptions OrbFeatureOptions(const EvalPlaceArgs& args, int features);

// The ground truth of a sequence of `frames` frames without --ground-truth: no frame has a true
// match, so detections are counted and precision and recall are not reported.
GroundTruth NoTrueMatches(size_t frames);

// Reads --images (in `layout`, detected when none) or --bag and what goes with it, and extracts
// the frames' features.
StatusOr<PlaceSequence> ReadPlaceSequence(const EvalPlaceArgs& args,
                                          std::optional<DatasetLayout> layout, int features);

// ---- eval_place_images.cc ----
// Each prints its report (JSON with `parameters` under "parameters", or text) and returns the
// exit status.

// One robot's map over --images: the detections scored, then the sweep, the drawings and the
// trajectory plot asked for.
int ReportOneMap(const EvalPlaceArgs& args, const PlaceSequence& sequence,
                 std::shared_ptr<const Vocabulary> vocabulary,
                 const PlaceEvaluationOptions& options, nlohmann::json parameters);

// --split (or --robot-b, after A's frames): robot A's map from the first `split` frames, robot B
// streaming the rest with A in its search set; B's revisits of A's places are inter-map loops,
// the others B's own.
int ReportAcrossMaps(const EvalPlaceArgs& args, int split, const SequenceFeatures& sequence,
                     const GroundTruth& truth, std::shared_ptr<const Vocabulary> vocabulary,
                     const PlaceEvaluationOptions& options, nlohmann::json parameters);

// ---- eval_place_rig.cc ----

// --rig: the rig detector over a rig sequence (every camera image searched against every camera
// image of the map, loops verified across the rig), scored over rig frames.
int RunEvalRig(const EvalPlaceArgs& args, const EvalPlaceSettings& settings,
               std::shared_ptr<const Vocabulary> vocabulary, const std::string& vocabulary_path);

}  // namespace recog::cli
