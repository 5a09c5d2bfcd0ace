// recog recognize: the objects in one image, recognised here with the models of --models, or on
// recogd (--server) with the models of its repository; both print and draw alike.
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/object/recognition/object_recognizer.h"
#include "tools/common/remote_support.h"
#include "tools/common/server_flags.h"
#include "tools/evaluation/camera_calibration.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/recog/commands.h"
#include "tools/recog/model_database.h"

namespace recog::cli {
namespace {

using nlohmann::json;

json RecognitionTimingJson(const RecognitionTiming& t) {
  return {{"orb", t.orb},
          {"clustering", t.clustering},
          {"conversion", t.conversion},
          {"query", t.query},
          {"correspondences", t.correspondences},
          {"ransac", t.ransac},
          {"second_pass", t.second_pass},
          {"total", t.total}};
}

// Offline (--models: core in this process) or on recogd (--server, whose models are those of its
// repository); both print and draw alike.
struct RecognizeArgs {
  std::vector<std::string> models;
  std::string image, camera, draw, vocabulary;
  DetectionOptions extras;  // --inliers, --covariance
  bool explain = false;     // --explain: where each model dropped out (offline)
  ServerFlags server;  // --server "" (this command's default): offline; --json belongs here too
};

// Recognises with the models of --models; `timing` gets the stages' milliseconds, and
// `explanation` (with --explain) what became of every model.
Status RecognizeOffline(const RecognizeArgs& args, const cv::Mat& image,
                        const CameraIntrinsics& camera, std::vector<Detection>* detections,
                        json* timing, std::vector<ObjectExplanation>* explanation) {
  MemoryIndexStore store;
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<const ObjectDatabase> database,
                         LoadModelDatabase(args.models, args.vocabulary, &store));
  RECOG_ASSIGN_OR_RETURN(ObjectRecognizer recognizer,
                         ObjectRecognizer::Create(std::move(database)));
  RecognitionTiming stages;
  RECOG_RETURN_IF_ERROR(recognizer.Recognize(image, camera, detections, &stages, {}, args.extras,
                                             args.explain ? explanation : nullptr));
  *timing = RecognitionTimingJson(stages);
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
  auto camera = ParseCameraFlag("--camera", args.camera);
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

}  // namespace

void AddRecognizeCommand(CLI::App& app, int* exit_code) {
  auto recognize_args = std::make_shared<RecognizeArgs>();
  CLI::App* recognize = app.add_subcommand(
      "recognize",
      "Recognise objects in one image: with the models of --models here, or on recogd (--server)");
  CLI::Option* models = recognize->add_option("--models", recognize_args->models,
                                              "Model files, folders of them, or RoboEarth folders");
  recognize->add_option("--image", recognize_args->image, "Image")->required();
  recognize
      ->add_option("--camera", recognize_args->camera,
                   std::string("The image's camera: ") + kCameraFlagSyntax)
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

}  // namespace recog::cli
