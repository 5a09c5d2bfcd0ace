// recog model build | info | export: object model files (.robj) built from their sources,
// described, and written back out as RoboEarth folders.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/object/builder/model_builder.h"
#include "core/object/formats/model_file.h"
#include "core/object/formats/roboearth.h"
#include "core/object/tracking/recording_learner.h"
#include "tools/common/cli_support.h"
#include "tools/common/remote_support.h"
#include "tools/evaluation/camera_calibration.h"
#include "tools/evaluation/frame_poses.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/evaluation/rgbd_recording.h"
#include "tools/evaluation/visp_files.h"
#include "tools/recog/commands.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// ---- recog model build ----

struct ModelBuildArgs {
  std::string roboearth, planar, rgbd, cad, rgbd_recording, output, name, vocabulary;
  std::string pose, image, camera, recording;  // with --cad (--pose, --camera: --rgbd-recording)
  double view_angle = RecordingLearningOptions().min_view_angle_deg;
  std::string box, depth_camera, depth_from_color;          // with --rgbd (--box: --rgbd-recording)
  double depth_scale = RgbdRecordingOptions().depth_scale;  // with --rgbd-recording
  std::string views;  // with --rgbd-recording: frame numbers posed by --pose, no learning
  std::vector<std::string> faces;  // side=IMAGE
  double width = 0, height = 0, depth = 0;
  bool no_images = false, quiet = false;
};

// --box W,H,D[,CX,CY,CZ]: the object's box, centred on the object frame unless a centre is given.
StatusOr<ObjectBox> ParseBox(const std::string& text) {
  RECOG_ASSIGN_OR_RETURN(std::vector<double> v, ParseNumbers("--box", text));
  if ((v.size() != 3 && v.size() != 6) || !(v[0] > 0 && v[1] > 0 && v[2] > 0)) {
    return Status::InvalidArgument("--box needs W,H,D[,CX,CY,CZ] with W, H, D > 0 (metres)");
  }
  ObjectBox box;
  box.size = {v[0], v[1], v[2]};
  if (v.size() == 6) box.centre = {v[3], v[4], v[5]};
  return box;
}

// --depth-camera: a camera whose lens depth registration models
// (core/geometry/depth_registration.h: radial-tangential, or none).
StatusOr<CameraIntrinsics> ParseDepthCamera(const std::string& text) {
  RECOG_ASSIGN_OR_RETURN(CameraIntrinsics camera, ParseCameraFlag("--depth-camera", text));
  if (camera.lens != LensModel::kRadialTangential && !camera.distortion.empty()) {
    const std::string lens(LensModelName(camera.lens));
    return Status::InvalidArgument("--depth-camera: radtan lenses only (depth registration), not " +
                                   lens);
  }
  return camera;
}

// --depth-from-color r11,...,r33,t1,t2,t3 (12 numbers, X_depth = R X_colour + t, metres), or a
// file holding those 12 numbers or the 4 x 4 matrix (whitespace-separated, '#' comments).
StatusOr<RigidTransform> ParseDepthFromColor(const std::string& text) {
  std::vector<double> v;
  if (fs::is_regular_file(text)) {
    std::ifstream in(text);
    std::string line, token;
    while (std::getline(in, line)) {
      std::istringstream tokens(line.substr(0, line.find('#')));
      while (tokens >> token) {
        RECOG_ASSIGN_OR_RETURN(std::vector<double> number,
                               ParseNumbers("--depth-from-color " + text, token));
        v.insert(v.end(), number.begin(), number.end());
      }
    }
    if (v.size() == 16) {  // [R t; 0 0 0 1] row by row
      v = {v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10], v[3], v[7], v[11]};
    }
  } else {
    RECOG_ASSIGN_OR_RETURN(v, ParseNumbers("--depth-from-color", text));
  }
  if (v.size() != 12) {
    return Status::InvalidArgument(
        "--depth-from-color needs r11,r12,r13,r21,r22,r23,r31,r32,r33,t1,t2,t3 or a file of "
        "those 12 numbers or a 4x4 matrix");
  }
  RigidTransform transform;
  for (int k = 0; k < 9; ++k) transform.R.val[k] = v[size_t(k)];
  transform.t = {v[9], v[10], v[11]};
  if (!IsRotationMatrix(transform.R)) {
    return Status::InvalidArgument("--depth-from-color: R is not a rotation matrix");
  }
  return transform;
}

// Prints the views learned from a recording of `frames` frames after the first one.
void PrintLearnedViews(const LearnedModel& learned, size_t frames) {
  std::string names;
  for (const PosedImage& view : learned.views) names += (names.empty() ? "" : ",") + view.name;
  std::printf("%zu views (%s); the object was found in %zu of the %zu frames that follow %s\n",
              learned.views.size(), names.c_str(), learned.frames_found, frames,
              learned.views.front().name.c_str());
}

// Warns of every RGB-D view whose features with a depth mostly fall outside the object's box: its
// pose (or the depth's registration) is probably off, and its points are misplaced in the model.
void WarnOfMisposedViews(const std::vector<RgbdViewReport>& reports) {
  for (const RgbdViewReport& view : reports) {
    if (!view.LooksMisposed()) continue;
    std::fprintf(stderr,
                 "warning: view %s: %zu of its %zu features with a depth are in the box (%.0f %%, "
                 "fewer than %.0f %%): is its pose right?\n",
                 view.name.c_str(), view.in_box, view.with_depth,
                 100.0 * double(view.in_box) / double(view.with_depth),
                 100.0 * RgbdViewReport::kMinInBoxShare);
  }
}

// A model from a CAD file of planar faces and one registered image (--cad --pose --image
// --camera), e.g. the visp-cube; with --recording, the frames of the recording that follow the
// image are followed and more views learned from them (recording_learner.h).
StatusOr<ObjectModel> BuildFromCad(const ModelBuildArgs& args, ModelBuilder* builder) {
  if (args.pose.empty() || args.image.empty() || args.camera.empty()) {
    return Status::InvalidArgument("--cad needs --pose, --image and --camera");
  }
  RECOG_ASSIGN_OR_RETURN(std::vector<FacePolygon> faces, ReadCaoFaces(args.cad));
  PosedImage first;
  first.name = fs::path(args.image).stem().string();
  RECOG_ASSIGN_OR_RETURN(first.image, ReadGrayImage(args.image));
  RECOG_ASSIGN_OR_RETURN(first.camera, ParseCameraFlag("--camera", args.camera));
  RECOG_ASSIGN_OR_RETURN(first.camera_from_object, ReadVispPose(args.pose));
  const std::string name = args.name.empty() ? fs::path(args.cad).stem().string() : args.name;
  const ModelFromViews build = [&](const std::vector<PosedImage>& views) {
    return builder->FromPosedPolygons(name, faces, views);
  };
  if (args.recording.empty()) return build({first});
  // The recording's frames after --image (all of them when --image is not one of them).
  RECOG_ASSIGN_OR_RETURN(std::vector<std::string> paths, ListImages(args.recording));
  const auto position = std::find_if(paths.begin(), paths.end(), [&](const std::string& path) {
    std::error_code error;
    return fs::equivalent(path, args.image, error);
  });
  if (position != paths.end()) paths.erase(paths.begin(), position + 1);
  std::vector<RecordingFrame> frames;
  for (const std::string& path : paths) {
    RECOG_ASSIGN_OR_RETURN(cv::Mat image, ReadGrayImage(path));
    frames.push_back({fs::path(path).stem().string(), std::move(image)});
  }
  RecordingLearningOptions options;
  options.min_view_angle_deg = args.view_angle;
  ProgressBar progress(!args.quiet);
  RECOG_ASSIGN_OR_RETURN(LearnedModel learned,
                         LearnFromRecording(build, builder->vocabulary(), first, frames, options,
                                            [&](size_t done, size_t total, size_t /*views*/) {
                                              progress.Update("frames", done, total);
                                            }));
  progress.Finish();
  PrintLearnedViews(learned, frames.size());
  return std::move(learned.model);
}

// A model learned from an RGB-D recording (--rgbd-recording DIR with images/ and depth/) given
// the first frame's pose (--pose: a ViSP .pos file or a pose list) and the object's box (--box);
// see rgbd_recording.h.
StatusOr<ObjectModel> BuildFromRgbdRecording(const ModelBuildArgs& args, ModelBuilder* builder) {
  if (args.camera.empty() || args.pose.empty() || args.box.empty()) {
    return Status::InvalidArgument("--rgbd-recording needs --camera, --pose and --box");
  }
  if (!args.image.empty() || !args.recording.empty()) {
    return Status::InvalidArgument(
        "--image and --recording go with --cad (--rgbd-recording starts at its first frame)");
  }
  RECOG_ASSIGN_OR_RETURN(const std::vector<RgbdRecordingFrame> frames,
                         ListRgbdRecording(args.rgbd_recording));
  RgbdRecordingOptions options;
  fs::path folder = fs::path(args.rgbd_recording).lexically_normal();
  if (!folder.has_filename()) folder = folder.parent_path();
  options.name = args.name.empty() ? folder.filename().string() : args.name;
  RECOG_ASSIGN_OR_RETURN(options.camera, ParseCameraFlag("--camera", args.camera));
  if (!args.views.empty()) {
    // Chosen frames whose poses are all known: a model of those views, nothing learned.
    RECOG_ASSIGN_OR_RETURN(std::vector<double> numbers, ParseNumbers("--views", args.views));
    std::vector<int> chosen;
    for (double number : numbers) {
      if (!(number >= 0 && number == std::floor(number))) {
        return Status::InvalidArgument("--views takes frame numbers N,N,... (got '" + args.views +
                                       "')");
      }
      chosen.push_back(int(number));
    }
    RECOG_ASSIGN_OR_RETURN(auto poses, ReadFramePoses(args.pose));
    RECOG_ASSIGN_OR_RETURN(std::vector<RgbdView> views,
                           PosedRgbdViews(frames, poses, options.camera, args.depth_scale, chosen));
    RECOG_ASSIGN_OR_RETURN(const ObjectBox box, ParseBox(args.box));
    std::vector<RgbdViewReport> reports;
    StatusOr<ObjectModel> model = builder->FromRgbd(options.name, views, box, &reports);
    WarnOfMisposedViews(reports);
    return model;
  }
  RECOG_ASSIGN_OR_RETURN(options.first_pose, ReadPoseOfFrame(args.pose, frames.front().image));
  RECOG_ASSIGN_OR_RETURN(options.box, ParseBox(args.box));
  options.depth_scale = args.depth_scale;
  options.learning.min_view_angle_deg = args.view_angle;
  ProgressBar progress(!args.quiet);
  std::vector<RgbdViewReport> reports;
  RECOG_ASSIGN_OR_RETURN(LearnedModel learned,
                         LearnFromRgbdRecording(
                             builder, frames, options,
                             [&](size_t done, size_t total, size_t /*views*/) {
                               progress.Update("frames", done, total);
                             },
                             &reports));
  progress.Finish();
  PrintLearnedViews(learned, frames.size() - 1);
  WarnOfMisposedViews(reports);
  return std::move(learned.model);
}

// A model from an RGB-D view list (--rgbd), with --box, --depth-camera and --depth-from-color.
StatusOr<ObjectModel> BuildFromRgbd(const ModelBuildArgs& args, ModelBuilder* builder) {
  if (args.depth_camera.empty() != args.depth_from_color.empty()) {
    return Status::InvalidArgument("--depth-camera and --depth-from-color go together");
  }
  RECOG_ASSIGN_OR_RETURN(std::vector<RgbdView> views, ReadRgbdViews(args.rgbd));
  if (!args.depth_camera.empty()) {
    RECOG_ASSIGN_OR_RETURN(CameraIntrinsics depth_camera, ParseDepthCamera(args.depth_camera));
    RECOG_ASSIGN_OR_RETURN(RigidTransform depth_from_color,
                           ParseDepthFromColor(args.depth_from_color));
    for (RgbdView& view : views) {
      view.depth_camera = depth_camera;
      view.depth_from_color = depth_from_color;
    }
  }
  std::optional<ObjectBox> box;
  if (!args.box.empty()) {
    RECOG_ASSIGN_OR_RETURN(box, ParseBox(args.box));
  }
  std::vector<RgbdViewReport> reports;
  StatusOr<ObjectModel> model = builder->FromRgbd(
      args.name.empty() ? fs::path(args.rgbd).parent_path().filename().string() : args.name, views,
      box, &reports);
  WarnOfMisposedViews(reports);
  return model;
}

int RunModelBuild(const ModelBuildArgs& args) {
  if (args.rgbd.empty() && args.rgbd_recording.empty() && !args.box.empty()) {
    return Fail("model build", Status::InvalidArgument("--box needs --rgbd or --rgbd-recording"));
  }
  if (args.rgbd.empty() && !(args.depth_camera.empty() && args.depth_from_color.empty())) {
    return Fail("model build",
                Status::InvalidArgument("--depth-camera and --depth-from-color need --rgbd"));
  }
  const int sources = int(!args.roboearth.empty()) +
                      int(!args.planar.empty() || !args.faces.empty()) + int(!args.rgbd.empty()) +
                      int(!args.cad.empty()) + int(!args.rgbd_recording.empty());
  if (sources != 1) {
    return Fail("model build",
                Status::InvalidArgument("give exactly one of --roboearth, --planar/--face, "
                                        "--rgbd, --rgbd-recording or --cad"));
  }
  auto vocabulary = LoadObjectVocabulary(args.vocabulary);
  if (!vocabulary.ok()) return Fail("model build", vocabulary.status());
  ModelBuildOptions options;
  options.keep_images = !args.no_images;
  ModelBuilder builder(*vocabulary, options);
  StatusOr<ObjectModel> model = Status::Internal("no source");
  if (!args.roboearth.empty()) {
    model = builder.FromRoboEarth(args.roboearth);
  } else if (!args.cad.empty()) {
    model = BuildFromCad(args, &builder);
  } else if (!args.rgbd.empty()) {
    model = BuildFromRgbd(args, &builder);
  } else if (!args.rgbd_recording.empty()) {
    model = BuildFromRgbdRecording(args, &builder);
  } else {
    std::vector<FaceImage> faces;
    std::vector<std::string> specs = args.faces;
    if (!args.planar.empty()) specs.insert(specs.begin(), "front=" + args.planar);
    for (const std::string& spec : specs) {
      const size_t eq = spec.find('=');
      if (eq == std::string::npos) {
        return Fail("model build",
                    Status::InvalidArgument("--face needs SIDE=IMAGE, got '" + spec + "'"));
      }
      auto side = ParseBoxSide(spec.substr(0, eq));
      if (!side.ok()) return Fail("model build", side.status());
      auto image = ReadGrayImage(spec.substr(eq + 1));
      if (!image.ok()) return Fail("model build", image.status());
      faces.push_back({*side, *image});
    }
    const std::string name =
        args.name.empty()
            ? fs::path(specs.front().substr(specs.front().find('=') + 1)).stem().string()
            : args.name;
    model = builder.FromFaceImages(name, faces, args.width, args.height, args.depth);
  }
  if (!model.ok()) return Fail("model build", model.status());
  if (!args.name.empty()) model->metadata.name = args.name;
  if (Status s = SaveObjectModel(*model, args.output); !s.ok()) return Fail("model build", s);
  std::printf("%s: %s object, %zu points, %zu descriptors, %zu views -> %s\n",
              model->metadata.name.c_str(),
              std::string(ObjectTypeName(model->metadata.type)).c_str(), model->points.size(),
              model->num_features(), model->views.size(), args.output.c_str());
  return 0;
}

// ---- recog model info ----

json MetadataJson(const ObjectMetadata& m) {
  return {{"name", m.name},
          {"class", m.object_class},
          {"type", std::string(ObjectTypeName(m.type))},
          {"dimensions", {m.dimensions[0], m.dimensions[1], m.dimensions[2]}},
          {"units", m.units},
          {"source", m.source},
          {"version", m.version}};
}

int RunModelInfo(const std::string& path, bool as_json) {
  auto model = LoadObjectModel(path);
  if (!model.ok()) return Fail("model info", model.status());
  json out = MetadataJson(model->metadata);
  out["points"] = model->points.size();
  out["descriptors"] = model->num_features();
  out["faces"] = model->faces.size();
  out["views"] = model->views.size();
  if (as_json) {
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    for (const auto& [key, value] : out.items()) {
      std::printf("%-12s %s\n", key.c_str(), value.dump().c_str());
    }
  }
  return 0;
}

// ---- recog model export ----

int RunModelExport(const std::string& path, const std::string& dir) {
  auto model = LoadObjectModel(path);
  if (!model.ok()) return Fail("model export", model.status());
  if (Status s = ExportRoboEarthFolder(*model, dir); !s.ok()) return Fail("model export", s);
  std::printf("%s: %zu views, %zu points -> %s\n", model->metadata.name.c_str(),
              model->views.size(), model->points.size(), dir.c_str());
  return 0;
}

}  // namespace

void AddModelCommands(CLI::App& app, int* exit_code) {
  CLI::App* model = app.add_subcommand("model", "Build and inspect object models");
  model->require_subcommand(1);
  auto build_args = std::make_shared<ModelBuildArgs>();
  CLI::App* build = model->add_subcommand("build", "Build an object model file (.robj)");
  build->add_option("--roboearth", build_args->roboearth, "A RoboEarth re_vision model folder");
  build->add_option("--planar", build_args->planar,
                    "Image of a planar object (with --width, --height)");
  build->add_option(
      "--face", build_args->faces,
      "SIDE=IMAGE face of a box (front, back, left, right, top, bottom), with --width "
      "--height --depth");
  build->add_option("--width", build_args->width, "Physical width, metres");
  build->add_option("--height", build_args->height, "Physical height, metres");
  build->add_option("--depth", build_args->depth, "Physical depth of a box, metres");
  build->add_option("--rgbd", build_args->rgbd,
                    "RGB-D view list: lines 'rgb depth fx fy cx cy depth_scale r11..r33 t1 t2 t3 "
                    "[mask]' (pose T_camera<-object, paths relative to the list)");
  CLI::Option* rgbd_recording = build->add_option(
      "--rgbd-recording", build_args->rgbd_recording,
      "Folder of an RGB-D recording: images/ (colour) and depth/ (16-bit, registered to colour), "
      "paired by the number ending each file name; the object is followed from the first frame "
      "(its pose: --pose) and views from new directions are learned (with --camera, --box)");
  build
      ->add_option("--box", build_args->box,
                   "With --rgbd or --rgbd-recording: the object's box W,H,D[,CX,CY,CZ] (metres, "
                   "object frame, centred on CX,CY,CZ, default 0,0,0), projected into views "
                   "without a mask; points outside it are dropped")
      ->check(Accepts(ParseBox));
  build
      ->add_option("--views", build_args->views,
                   "With --rgbd-recording: build from these frames N,N,... instead of learning, "
                   "each posed by its line of --pose (a pose list)")
      ->needs(rgbd_recording);
  build
      ->add_option("--depth-scale", build_args->depth_scale,
                   "With --rgbd-recording: raw depth units per metre (1000: millimetres)")
      ->capture_default_str()
      ->check(CLI::PositiveNumber)
      ->needs(rgbd_recording);
  build
      ->add_option("--depth-camera", build_args->depth_camera,
                   std::string("With --rgbd: the depth images come from their own camera (else "
                               "they are registered to colour), radtan or pinhole: ") +
                       kCameraFlagSyntax)
      ->check(Accepts(ParseDepthCamera));
  build
      ->add_option("--depth-from-color", build_args->depth_from_color,
                   "With --depth-camera: X_depth = R X_colour + t as r11,...,r33,t1,t2,t3 "
                   "(metres), or a file of those 12 numbers or the 4x4 matrix")
      ->check(Accepts(ParseDepthFromColor));
  build->add_option("--cad", build_args->cad,
                    "ViSP .cao model of planar faces (with --pose, --image, --camera)");
  build->add_option("--pose", build_args->pose,
                    "The object's pose: with --cad in --image, a ViSP .pos file; with "
                    "--rgbd-recording in its first frame, a .pos file or a pose list (lines "
                    "'NNNN r11..r33 tx ty tz', T_camera<-object, metres; the line of the first "
                    "frame's number is used)");
  build->add_option("--image", build_args->image, "Registered image for --cad");
  build->add_option("--camera", build_args->camera,
                    std::string("The camera of --image (--cad) or of the recording "
                                "(--rgbd-recording): ") +
                        kCameraFlagSyntax);
  build->add_option("--recording", build_args->recording,
                    "With --cad: folder of the recording --image belongs to; the object is "
                    "followed through the frames after --image and views from new directions "
                    "are added to the model");
  build
      ->add_option("--view-angle", build_args->view_angle,
                   "With --recording or --rgbd-recording: a frame becomes a view when it sees "
                   "the object from a direction this far (degrees) from every view's")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 179.0));
  build->add_option("--name", build_args->name, "Object name (default: from the source)");
  build->add_option("--vocab", build_args->vocabulary,
                    "Vocabulary (default: the bundled object one)");
  build->add_flag("--no-images", build_args->no_images, "Do not keep the training images");
  build->add_flag("-q,--quiet", build_args->quiet, "No progress output");
  build->add_option("-o,--output", build_args->output, "Model file to write")->required();
  build->callback([build_args, exit_code] { *exit_code = RunModelBuild(*build_args); });

  auto info_path = std::make_shared<std::string>();
  auto info_json = std::make_shared<bool>(false);
  CLI::App* info = model->add_subcommand("info", "Describe an object model file");
  info->add_option("file", *info_path, "Model file")->required();
  info->add_flag("--json", *info_json, "Print JSON");
  info->callback(
      [info_path, info_json, exit_code] { *exit_code = RunModelInfo(*info_path, *info_json); });

  auto export_path = std::make_shared<std::string>();
  auto export_dir = std::make_shared<std::string>();
  CLI::App* export_command =
      model->add_subcommand("export", "Write an object model file as a RoboEarth folder");
  export_command->add_option("file", *export_path, "Model file (.robj)")->required();
  export_command
      ->add_option("--roboearth", *export_dir, "Folder to create (missing or empty) for the model")
      ->required();
  export_command->callback([export_path, export_dir, exit_code] {
    *exit_code = RunModelExport(*export_path, *export_dir);
  });
}

}  // namespace recog::cli
