// recog model build|info, recog recognize (offline, or on recogd with --server) and recog eval
// objects: object models and object recognition from the command line.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/index/memory_index_store.h"
#include "core/object/builder/model_builder.h"
#include "core/object/formats/model_file.h"
#include "core/object/recognition/object_recognizer.h"
#include "core/object/tracking/object_tracker.h"
#include "core/object/tracking/recording_learner.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tools/common/cli_support.h"
#include "tools/common/remote_support.h"
#include "tools/common/server_flags.h"
#include "tools/evaluation/frame_poses.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/evaluation/place_evaluation.h"
#include "tools/evaluation/rgbd_recording.h"
#include "tools/evaluation/visp_files.h"
#include "tools/recog/commands.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

json MetadataJson(const ObjectMetadata& m) {
  return {{"name", m.name},
          {"class", m.object_class},
          {"type", std::string(ObjectTypeName(m.type))},
          {"dimensions", {m.dimensions[0], m.dimensions[1], m.dimensions[2]}},
          {"units", m.units},
          {"source", m.source},
          {"version", m.version}};
}

json TimingJson(const RecognitionTiming& t) {
  return {{"orb", t.orb},
          {"clustering", t.clustering},
          {"conversion", t.conversion},
          {"query", t.query},
          {"correspondences", t.correspondences},
          {"ransac", t.ransac},
          {"second_pass", t.second_pass},
          {"total", t.total}};
}

// ---- recog model build / info ----

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

// --depth-camera fx,fy,cx,cy[,k1,k2,p1,p2[,k3]].
StatusOr<CameraIntrinsics> ParseDepthCamera(const std::string& text) {
  auto camera = ParseCamera(text);
  if (!camera.ok()) return Status::InvalidArgument("--depth-camera: " + camera.status().message());
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
  RECOG_ASSIGN_OR_RETURN(first.camera, ParseCamera(args.camera));
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
  RECOG_ASSIGN_OR_RETURN(options.camera, ParseCamera(args.camera));
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

// ---- recog recognize ----

// Offline (--models: core in this process) or on recogd (--server, whose models are those of its
// repository); both print and draw alike.
struct RecognizeArgs {
  std::vector<std::string> models;
  std::string image, camera, draw, vocabulary;
  DetectionOptions extras;  // --inliers, --covariance
  bool explain = false;     // --explain: where each model dropped out (offline)
  ServerFlags server;  // --server "" (this command's default): offline; --json belongs here too
};

// Model files (.robj) and RoboEarth folders named by `paths` (see FindModelSources).
Status LoadModels(const std::vector<std::string>& paths, ModelBuilder* builder,
                  ObjectDatabase* database) {
  for (const std::string& path : paths) {
    for (const ModelSource& source : FindModelSources(path)) {
      StatusOr<ObjectModel> model =
          source.roboearth ? builder->FromRoboEarth(source.path) : LoadObjectModel(source.path);
      RECOG_RETURN_IF_ERROR(model.status());
      RECOG_RETURN_IF_ERROR(database->Put(*model).status());
    }
  }
  if (database->size() == 0) return Status::InvalidArgument("--models named no object model");
  return Status::Ok();
}

// Recognises with the models of --models; `timing` gets the stages' milliseconds, and
// `explanation` (with --explain) what became of every model.
Status RecognizeOffline(const RecognizeArgs& args, const cv::Mat& image,
                        const CameraIntrinsics& camera, std::vector<Detection>* detections,
                        json* timing, std::vector<ObjectExplanation>* explanation) {
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<const Vocabulary> vocabulary,
                         LoadObjectVocabulary(args.vocabulary));
  MemoryIndexStore store;
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<ObjectDatabase> database,
                         ObjectDatabase::Open(&store, vocabulary));
  ModelBuildOptions build;
  build.keep_images = false;
  ModelBuilder builder(vocabulary, build);
  RECOG_RETURN_IF_ERROR(LoadModels(args.models, &builder, database.get()));
  ObjectRecognizer recognizer(std::shared_ptr<const ObjectDatabase>(std::move(database)));
  RecognitionTiming stages;
  RECOG_RETURN_IF_ERROR(recognizer.Recognize(image, camera, detections, &stages, {}, args.extras,
                                             args.explain ? explanation : nullptr));
  *timing = TimingJson(stages);
  return Status::Ok();
}

// A detection as recogd reports it (without inlier_pixels, which it does not send; with the
// inlier correspondences and the covariance when they were asked for).
Detection FromProto(const pb::DetectedObject& object) {
  Detection d;
  d.name = object.name();
  d.version = object.version();
  d.type = object.type() == pb::OBJECT_TYPE_PLANAR ? ObjectType::kPlanar : ObjectType::k3D;
  const pb::Pose& pose = object.pose();
  for (int i = 0; i < 9 && i < pose.rotation_size(); ++i) {
    d.camera_from_object.R.val[i] = pose.rotation(i);
  }
  for (int i = 0; i < 3 && i < pose.translation_size(); ++i) {
    d.camera_from_object.t[i] = pose.translation(i);
  }
  d.inliers = object.inliers();
  d.correspondences = object.correspondences();
  d.reprojection_error_px = object.reprojection_error_px();
  d.score = object.score();
  for (const pb::Point2& p : object.outline()) d.outline.emplace_back(p.x(), p.y());
  for (const pb::InlierCorrespondence& c : object.inliers_2d3d()) {
    d.inliers_2d3d.push_back({{c.pixel().x(), c.pixel().y()},
                              c.point_id(),
                              {float(c.point().x()), float(c.point().y()), float(c.point().z())}});
  }
  d.covariance.assign(object.covariance().begin(), object.covariance().end());
  return d;
}

// An explanation as recogd reports it.
ObjectExplanation FromProto(const pb::ObjectExplanation& explanation) {
  ObjectExplanation e;
  e.name = explanation.name();
  switch (explanation.outcome()) {
    case pb::OBJECT_OUTCOME_FEW_CORRESPONDENCES:
      e.outcome = ObjectOutcome::kFewCorrespondences;
      break;
    case pb::OBJECT_OUTCOME_FEW_INLIERS:
      e.outcome = ObjectOutcome::kFewInliers;
      break;
    case pb::OBJECT_OUTCOME_SUPPRESSED:
      e.outcome = ObjectOutcome::kSuppressed;
      break;
    case pb::OBJECT_OUTCOME_DETECTED:
      e.outcome = ObjectOutcome::kDetected;
      break;
    default:
      e.outcome = ObjectOutcome::kNotProposed;
  }
  e.regions = explanation.regions();
  e.best_score = explanation.best_score();
  e.correspondences = explanation.correspondences();
  e.inliers = explanation.inliers();
  e.min_inliers = explanation.min_inliers();
  return e;
}

// Sends the image with its intrinsics to recogd's RecognizeObjects; `timing` gets the server's
// milliseconds (decode, features, recognition, queue), `explanation` (with --explain) what became
// of every model.
grpc::Status RecognizeOnServer(const RecognizeArgs& args, const cv::Mat& image,
                               const CameraIntrinsics& camera, std::vector<Detection>* detections,
                               json* timing, std::vector<ObjectExplanation>* explanation) {
  auto client = args.server.Connect();
  if (!client.ok()) return client.status();
  auto frame = FrameFromImageFile(args.image, image);
  if (!frame.ok()) return frame.status();
  SetIntrinsics(camera, &*frame);
  pb::DetectionOptions extras;
  extras.set_include_inliers(args.extras.include_inliers);
  extras.set_include_covariance(args.extras.include_covariance);
  auto response = (*client)->RecognizeObjects(*frame, {}, extras, args.explain);
  if (!response.ok()) return response.status();
  for (const pb::DetectedObject& object : response->objects()) {
    detections->push_back(FromProto(object));
  }
  for (const pb::ObjectExplanation& e : response->explanations()) {
    explanation->push_back(FromProto(e));
  }
  const pb::Timing& t = response->timing();
  *timing = {{"decode", t.decode_ms()},
             {"features", t.features_ms()},
             {"recognition", t.recognition_ms()},
             {"queue", t.queue_ms()}};
  return grpc::Status::OK;
}

int RunRecognize(const RecognizeArgs& args) {
  const bool remote = !args.server.server.empty();
  if (!remote && args.models.empty()) {
    return Fail("recognize",
                Status::InvalidArgument("give --models (recognise here) or --server (on recogd)"));
  }
  auto camera = ParseCamera(args.camera);
  if (!camera.ok()) return Fail("recognize", camera.status());
  auto image = ReadGrayImage(args.image);
  if (!image.ok()) return Fail("recognize", image.status());
  std::vector<Detection> detections;
  std::vector<ObjectExplanation> explanation;
  json timing;
  if (remote) {
    const grpc::Status s =
        RecognizeOnServer(args, *image, *camera, &detections, &timing, &explanation);
    if (!s.ok()) return Fail("recognize", s);
  } else if (Status s = RecognizeOffline(args, *image, *camera, &detections, &timing, &explanation);
             !s.ok()) {
    return Fail("recognize", s);
  }
  json out = json::array();
  for (const Detection& d : detections) {
    const RigidTransform& p = d.camera_from_object;
    json outline = json::array();
    for (const cv::Point2f& q : d.outline) outline.push_back({q.x, q.y});
    out.push_back({{"name", d.name},
                   {"version", d.version},
                   {"rotation",
                    {{p.R(0, 0), p.R(0, 1), p.R(0, 2)},
                     {p.R(1, 0), p.R(1, 1), p.R(1, 2)},
                     {p.R(2, 0), p.R(2, 1), p.R(2, 2)}}},
                   {"translation", {p.t[0], p.t[1], p.t[2]}},
                   {"inliers", d.inliers},
                   {"reprojection_error_px", d.reprojection_error_px},
                   {"outline", outline}});
    if (args.extras.include_inliers) {
      json inliers = json::array();
      for (const InlierCorrespondence& c : d.inliers_2d3d) {
        inliers.push_back({{"pixel", {c.pixel.x, c.pixel.y}},
                           {"point", {c.point.x, c.point.y, c.point.z}},
                           {"point_id", c.point_id}});
      }
      out.back()["inliers_2d3d"] = inliers;
    }
    if (args.extras.include_covariance) out.back()["covariance"] = d.covariance;
  }
  if (!args.draw.empty()) {
    cv::Mat canvas;
    cv::cvtColor(*image, canvas, cv::COLOR_GRAY2BGR);
    for (const Detection& d : detections) DrawDetection(d, *camera, {0, 200, 0}, &canvas);
    if (!cv::imwrite(args.draw, canvas)) {
      return Fail("recognize", Status::InvalidArgument("cannot write '" + args.draw + "'"));
    }
  }
  if (args.server.json) {
    json result = {{"detections", out}, {"timing_ms", timing}};
    if (args.explain) {
      json explained = json::array();
      for (const ObjectExplanation& e : explanation) {
        explained.push_back({{"name", e.name},
                             {"outcome", ObjectOutcomeName(e.outcome)},
                             {"regions", e.regions},
                             {"best_score", e.best_score},
                             {"correspondences", e.correspondences},
                             {"inliers", e.inliers},
                             {"min_inliers", e.min_inliers}});
      }
      result["explanation"] = explained;
    }
    std::printf("%s\n", result.dump(2).c_str());
  } else {
    for (const Detection& d : detections) {
      const cv::Vec3d& t = d.camera_from_object.t;
      std::printf("%s v%u: %zu inliers, t = (%.3f, %.3f, %.3f), %.2f px\n", d.name.c_str(),
                  d.version, d.inliers, t[0], t[1], t[2], d.reprojection_error_px);
    }
    if (detections.empty()) std::printf("no object recognised\n");
    for (const ObjectExplanation& e : explanation) {
      std::printf(
          "%s: %s (proposed by %zu regions, best score %.4f, %zu correspondences, %zu "
          "inliers of %zu needed)\n",
          e.name.c_str(), std::string(ObjectOutcomeName(e.outcome)).c_str(), e.regions,
          e.best_score, e.correspondences, e.inliers, e.min_inliers);
    }
  }
  return 0;
}

// ---- recog eval sequence ----

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
  auto vocabulary = LoadObjectVocabulary(args.vocabulary);
  if (!vocabulary.ok()) return Fail("eval sequence", vocabulary.status());
  MemoryIndexStore store;
  auto opened = ObjectDatabase::Open(&store, *vocabulary);
  if (!opened.ok()) return Fail("eval sequence", opened.status());
  std::shared_ptr<ObjectDatabase> database = std::move(*opened);
  ModelBuildOptions build;
  build.keep_images = false;
  ModelBuilder builder(*vocabulary, build);
  if (Status s = LoadModels(args.models, &builder, database.get()); !s.ok()) {
    return Fail("eval sequence", s);
  }
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
  ObjectRecognizer recognizer(database);
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

// ---- recog eval objects ----

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

void AddObjectCommands(CLI::App& app, int* exit_code) {
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
                   "With --rgbd: the depth images come from their own camera "
                   "fx,fy,cx,cy[,k1,k2,p1,p2[,k3]] (else they are registered to colour)")
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
                    "fx,fy,cx,cy of --image (--cad) or of the recording (--rgbd-recording)");
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

  auto recognize_args = std::make_shared<RecognizeArgs>();
  CLI::App* recognize = app.add_subcommand(
      "recognize",
      "Recognise objects in one image: with the models of --models here, or on recogd (--server)");
  CLI::Option* models = recognize->add_option("--models", recognize_args->models,
                                              "Model files, folders of them, or RoboEarth folders");
  recognize->add_option("--image", recognize_args->image, "Image")->required();
  recognize->add_option("--camera", recognize_args->camera, "fx,fy,cx,cy[,k1,k2,p1,p2[,k3]]")
      ->required();
  recognize->add_option("--draw", recognize_args->draw, "PNG with outlines and axes");
  recognize->add_flag("--inliers", recognize_args->extras.include_inliers,
                      "With --json: each detection's inlier 2D-3D correspondences (inliers_2d3d)");
  recognize->add_flag("--explain", recognize_args->explain,
                      "Say for every model where it dropped out: not_proposed (no region's bag "
                      "of words proposed it), few_correspondences, few_inliers, suppressed (by a "
                      "stronger object's outline) or detected");
  recognize->add_flag("--covariance", recognize_args->extras.include_covariance,
                      "With --json: each detection's 6x6 pose covariance (row-major, rotation "
                      "first)");
  CLI::Option* vocabulary =
      recognize->add_option("--vocab", recognize_args->vocabulary, "Vocabulary (with --models)");
  recognize_args->server.server.clear();  // no --server: offline
  recognize_args->server.AddTo(recognize);
  CLI::Option* server = recognize->get_option("--server");
  server->description(
      "recogd address host:port: recognise there, with its repository's models, instead of "
      "--models (default: offline)");
  models->excludes(server);
  vocabulary->excludes(server);
  // Offline unless --server is given: the connection's environment variables are not read here.
  server->envname("");
  for (const char* name : {"--token-file", "--tls-ca", "--tls-cert", "--tls-key"}) {
    recognize->get_option(name)->needs(server)->envname("");
  }
  recognize->callback([recognize_args, exit_code] { *exit_code = RunRecognize(*recognize_args); });
}

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
