// recog eval place's sequence (eval_place.h): the frames of --images (a folder, a TUM RGB-D,
// EuRoC or KITTI dataset folder, a list or a video; with --robot-b robot B's after them) or of
// --bag, their features, and what goes with them: --ground-truth with --ambiguous, the camera
// (--camera or the bag's camera info), --poses, and the depth or right images' 3D points.
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "tools/common/cli_support.h"
#include "tools/evaluation/camera_calibration.h"
#include "tools/recog/eval_place.h"

namespace recog::cli {
namespace {

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

}  // namespace

std::string LayoutName(const PlaceSequence& sequence) {
  return sequence.bag ? "bag" : std::string(DatasetLayoutName(sequence.layout));
}

FeatureOptions OrbFeatureOptions(const EvalPlaceArgs& args, int features) {
  FeatureOptions options = PlaceFeatureOptions();
  options.orb.max_features = features;
  options.orb.min_short_side = args.min_short_side;
  return options;
}

GroundTruth NoTrueMatches(size_t frames) {
  GroundTruth truth;
  truth.frames = int(frames);
  truth.matches.resize(frames);
  return truth;
}

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

}  // namespace recog::cli
