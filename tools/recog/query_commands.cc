// recog query and recog relocalize: images looked up in maps of recogd, over the C++ client
// library. Both take the ServerFlags; a failed call prints one line "recog <cmd>: CODE: message"
// and exits 1.
//
//   query       one QueryPlace: relocalisation, or the loop detector's step with --add (one
//               image, or one per camera of a rig)
//   relocalize  one Relocalize: a few images looked up in maps or a group, nothing added
#include <chrono>
#include <csignal>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <future>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "client/cpp/frame_stream.h"
#include "client/cpp/frames.h"
#include "client/cpp/recognition_client.h"
#include "core/object/model/object_model.h"
#include "tools/common/cli_support.h"
#include "tools/common/remote_support.h"
#include "tools/common/server_flags.h"
#include "tools/evaluation/camera_calibration.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/evaluation/place_evaluation.h"
#include "tools/evaluation/rig_dataset.h"
#include "tools/evaluation/rig_file.h"
#include "tools/recog/commands.h"
#include "tools/recog/loop_json.h"
#include "wire/grpc_code_names.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;
using client::RecognitionClient;
using Json = nlohmann::ordered_json;

// ---- recog query ----

struct QueryArgs {
  ServerFlags server;
  std::vector<std::string> images;  // one, or one per camera of --rig in its order
  std::string map, rig, camera, client_frame_id, depth, right;
  double depth_scale = 1000, baseline = 0;
  bool add = false, correspondences = false;
  uint32_t top_k = 0;
};

// Attaches the depth image in `depth` or the right image in `right` (whichever is not empty) to
// the frame, for metric loops; the server checks the rest (intrinsics, sizes, the baseline).
// NOT_FOUND for a missing file, INVALID_ARGUMENT for one that does not decode.
Status AttachStructure(const std::string& depth, double depth_scale, const std::string& right,
                       double baseline, pb::Frame* frame) {
  if (depth.empty() && right.empty()) return Status::Ok();
  const std::string& file = depth.empty() ? right : depth;
  std::error_code error;
  if (!fs::exists(file, error)) return Status::NotFound("image file '" + file + "' does not exist");
  const cv::Mat image =
      cv::imread(file, depth.empty() ? cv::IMREAD_GRAYSCALE : cv::IMREAD_ANYDEPTH);
  if (image.empty()) return Status::InvalidArgument("cannot read '" + file + "'");
  const grpc::Status attached = depth.empty() ? client::AttachStereoRight(image, baseline, frame)
                                              : client::AttachDepth(image, depth_scale, frame);
  if (!attached.ok()) return Status::InvalidArgument(file + ": " + attached.error_message());
  return Status::Ok();
}

// The frame of `path` (FrameFromImageFile of its grey pixels).
StatusOr<pb::Frame> ReadFrame(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(const cv::Mat gray, ReadGrayImage(path));
  client::Result<pb::Frame> frame = FrameFromImageFile(path, gray);
  if (!frame.ok()) return Status::InvalidArgument(frame.status().error_message());
  return std::move(frame).value();
}

// recog query's frame: its one image, or with --rig a rig frame of one view per camera.
StatusOr<pb::Frame> QueryFrame(const QueryArgs& args) {
  if (args.rig.empty()) {
    if (args.images.size() != 1) {
      return Status::InvalidArgument("give one image (or --rig and one image per camera)");
    }
    return ReadFrame(args.images.front());
  }
  if (!args.camera.empty() || !args.depth.empty() || !args.right.empty()) {
    return Status::InvalidArgument(
        "--camera, --depth and --right are for single-camera maps (a rig map has its cameras)");
  }
  RECOG_ASSIGN_OR_RETURN(const std::vector<RigCamera> rig, ReadRigFile(args.rig));
  if (args.images.size() != rig.size()) {
    return Status::InvalidArgument("the rig has " + std::to_string(rig.size()) +
                                   " cameras: give one image per camera, in its order, not " +
                                   std::to_string(args.images.size()));
  }
  pb::Frame frame;
  for (size_t c = 0; c < rig.size(); ++c) {
    RECOG_ASSIGN_OR_RETURN(pb::Frame view, ReadFrame(args.images[c]));
    const grpc::Status added = client::AddRigView(rig[c].name, std::move(view), &frame);
    if (!added.ok()) return Status::InvalidArgument(added.error_message());
  }
  return frame;
}

int RunQuery(const QueryArgs& args, RecognitionClient& client) {
  auto frame = QueryFrame(args);
  if (!frame.ok()) return Fail("query", frame.status());
  frame->set_client_frame_id(args.client_frame_id);
  pb::ResultOptions options;
  options.set_top_k(args.top_k);
  options.set_include_correspondences(args.correspondences);
  if (!args.camera.empty()) {
    auto camera = ParseCameraFlag("--camera", args.camera);
    if (!camera.ok()) return Fail("query", camera.status());
    SetIntrinsics(*camera, &*frame);
    options.set_include_relative_pose(true);
  }
  if (Status s = AttachStructure(args.depth, args.depth_scale, args.right, args.baseline, &*frame);
      !s.ok()) {
    return Fail("query", s);
  }
  auto answer = client.QueryPlace(
      args.map, *frame, args.add ? client::QueryMode::kAddFrame : client::QueryMode::kRelocalise,
      options);
  if (!answer.ok()) return Fail("query", answer.status());
  const pb::LoopResult& r = answer->result();
  if (args.server.json) {
    Json out = LoopJson(r);
    out["timing_ms"] = TimingJson(answer->timing());
    std::printf("%s\n", out.dump(2).c_str());
    return 0;
  }
  std::printf("status     %s\n", StatusLabel(r.status()).c_str());
  if (r.has_frame_id()) std::printf("added as   frame %llu\n", (unsigned long long)r.frame_id());
  if (r.has_match_frame_id()) {
    if (r.has_rig()) {  // a rig frame's score is pooled over its cameras: nothing to normalise
      std::printf("match      rig frame %llu (score %.3f over the cameras)\n",
                  (unsigned long long)r.match_frame_id(), r.score());
    } else {
      std::printf("match      frame %llu (score %.3f, normalised %.3f)\n",
                  (unsigned long long)r.match_frame_id(), r.score(), r.normalized_score());
    }
    if (!r.match_client_frame_id().empty()) {
      std::printf("match id   %s\n", r.match_client_frame_id().c_str());
    }
    std::printf("inliers    %u of %u correspondences\n", r.inliers(), r.correspondences());
  }
  for (const pb::RigCameraMatch& pair : r.rig().pairs()) {
    std::printf("cameras    %s saw what %s saw: %u inliers%s\n", pair.query_camera().c_str(),
                pair.match_camera().c_str(), pair.inliers(),
                pair.metric() ? ", metric" : (pair.posed() ? ", posed" : ""));
    for (const pb::Correspondence& c : pair.inlier_correspondences()) {
      std::printf("inlier     %s %u (%.1f, %.1f) <-> %s %u (%.1f, %.1f)\n",
                  pair.query_camera().c_str(), c.query_index(), c.query_x(), c.query_y(),
                  pair.match_camera().c_str(), c.match_index(), c.match_x(), c.match_y());
    }
  }
  if (r.rig().posed()) {
    const pb::Pose& p = r.rig().body_pose();
    std::printf(
        "body pose  R = [%.4f %.4f %.4f; %.4f %.4f %.4f; %.4f %.4f %.4f], t = [%.4f %.4f %.4f]%s "
        "(X_body_query = R X_body_match + t; rotations disagree by %.2f deg)\n",
        p.rotation(0), p.rotation(1), p.rotation(2), p.rotation(3), p.rotation(4), p.rotation(5),
        p.rotation(6), p.rotation(7), p.rotation(8), p.translation(0), p.translation(1),
        p.translation(2), r.rig().metric() ? " m" : " (no scale)",
        r.rig().rotation_disagreement_deg());
  }
  for (const pb::Candidate& c : r.candidates()) {
    std::printf("candidate  frame %llu%s%s (score %.3f, normalised %.3f)",
                (unsigned long long)c.frame_id(), c.client_frame_id().empty() ? "" : " ",
                c.client_frame_id().c_str(), c.score(), c.normalized_score());
    if (c.has_inliers()) std::printf(", %u inliers", c.inliers());
    std::printf("\n");
  }
  for (const pb::Correspondence& c : r.inlier_correspondences()) {
    std::printf("inlier     %u (%.1f, %.1f) <-> %u (%.1f, %.1f)\n", c.query_index(), c.query_x(),
                c.query_y(), c.match_index(), c.match_x(), c.match_y());
  }
  const pb::Pose& pose = r.relative_pose();
  if (pose.rotation_size() == 9 && pose.translation_size() == 3) {
    std::printf(
        "pose       R = [%.4f %.4f %.4f; %.4f %.4f %.4f; %.4f %.4f %.4f], "
        "t = [%.4f %.4f %.4f] (unit length)\n",
        pose.rotation(0), pose.rotation(1), pose.rotation(2), pose.rotation(3), pose.rotation(4),
        pose.rotation(5), pose.rotation(6), pose.rotation(7), pose.rotation(8), pose.translation(0),
        pose.translation(1), pose.translation(2));
  }
  if (r.has_metric()) {
    const pb::MetricLoop& m = r.metric();
    std::printf("metric     %s: %u of %u 3D correspondences, rms %.2f px\n",
                m.verified() ? "verified" : "failed", m.inliers(), m.correspondences(),
                m.rms_error_px());
    if (m.verified()) {
      const pb::Pose& p = m.pose();
      std::printf(
          "metric pose R = [%.4f %.4f %.4f; %.4f %.4f %.4f; %.4f %.4f %.4f], "
          "t = [%.4f %.4f %.4f] m (X_query = R X_match + t)\n",
          p.rotation(0), p.rotation(1), p.rotation(2), p.rotation(3), p.rotation(4), p.rotation(5),
          p.rotation(6), p.rotation(7), p.rotation(8), p.translation(0), p.translation(1),
          p.translation(2));
    }
  }
  return 0;
}

// ---- recog relocalize ----

struct RelocalizeArgs {
  ServerFlags server;
  std::vector<std::string> images, maps, depths;
  std::string group, camera;
  double depth_scale = 1000;
  uint32_t max_results = 0;
};

int RunRelocalize(const RelocalizeArgs& args, RecognitionClient& client) {
  if (!args.depths.empty() && args.depths.size() != args.images.size()) {
    return Fail("relocalize",
                Status::InvalidArgument("--depth needs one depth image per image: " +
                                        std::to_string(args.depths.size()) + " for " +
                                        std::to_string(args.images.size()) + " images"));
  }
  std::optional<CameraIntrinsics> camera;
  pb::ResultOptions options;
  if (!args.camera.empty()) {
    auto parsed = ParseCameraFlag("--camera", args.camera);
    if (!parsed.ok()) return Fail("relocalize", parsed.status());
    camera = *parsed;
    options.set_include_relative_pose(true);
  }
  std::vector<pb::Frame> frames;
  for (size_t i = 0; i < args.images.size(); ++i) {
    const std::string& image = args.images[i];
    auto gray = ReadGrayImage(image);
    if (!gray.ok()) return Fail("relocalize", gray.status());
    auto frame = FrameFromImageFile(image, *gray);
    if (!frame.ok()) return Fail("relocalize", frame.status());
    frame->set_client_frame_id(fs::path(image).filename().string());
    if (camera.has_value()) SetIntrinsics(*camera, &*frame);
    const std::string no_depth;
    if (Status s = AttachStructure(args.depths.empty() ? no_depth : args.depths[i],
                                   args.depth_scale, {}, 0, &*frame);
        !s.ok()) {
      return Fail("relocalize", s);
    }
    frames.push_back(std::move(frame).value());
  }
  auto answer = client.Relocalize(frames, {.maps = args.maps, .group = args.group}, options,
                                  args.max_results);
  if (!answer.ok()) return Fail("relocalize", answer.status());
  if (args.server.json) {
    Json places = Json::array();
    for (const pb::Relocalization& place : answer->places()) {
      places.push_back({{"map", place.map()},
                        {"image", args.images[place.frame_index()]},
                        {"frame_index", place.frame_index()},
                        {"frames_recognised", place.frames_recognised()},
                        {"result", LoopJson(place.result())}});
    }
    std::printf("%s\n", Json({{"frames", frames.size()},
                              {"places", std::move(places)},
                              {"timing_ms", TimingJson(answer->timing())}})
                            .dump(2)
                            .c_str());
    return 0;
  }
  if (answer->places_size() == 0) {
    std::printf("no map recognised %s\n", frames.size() == 1 ? "the image" : "any of the images");
  }
  for (const pb::Relocalization& place : answer->places()) {
    const pb::LoopResult& r = place.result();
    std::printf(
        "map '%s': %s is frame %llu%s%s%s, %u inliers (score %.3f); %u of %zu images "
        "recognised\n",
        place.map().c_str(), place.client_frame_id().c_str(),
        (unsigned long long)r.match_frame_id(), r.match_client_frame_id().empty() ? "" : " (",
        r.match_client_frame_id().c_str(), r.match_client_frame_id().empty() ? "" : ")",
        r.inliers(), r.score(), place.frames_recognised(), frames.size());
  }
  return 0;
}

}  // namespace

void AddQueryCommands(CLI::App& app, int* exit_code) {
  auto query_args = std::make_shared<QueryArgs>();
  CLI::App* query = app.add_subcommand(
      "query", "Look one image up in a map of recogd (relocalisation, unless --add)");
  query->add_option("--map", query_args->map, "Map name")->required();
  query
      ->add_option("images", query_args->images,
                   "Image file; with --rig, one per camera in the rig file's order")
      ->required();
  query->add_option("--rig", query_args->rig,
                    "Rig file (YAML) of the map's cameras: the images form one rig frame");
  query->add_flag("--add", query_args->add,
                  "Run the map's loop detector and keep the frame, as a streamed frame");
  query->add_option("--camera", query_args->camera,
                    std::string("The image's camera, to also report the relative pose of a "
                                "loop: ") +
                        kCameraFlagSyntax);
  query->add_option("--client-frame-id", query_args->client_frame_id,
                    "Your own id of the frame (at most 128 bytes); with --add the map keeps it "
                    "and returns it whenever the frame is a match");
  query
      ->add_option("--top-k", query_args->top_k,
                   "Also list the best N candidates of the query with their scores (0 to 50)")
      ->check(CLI::Range(0, 50));
  CLI::Option* depth =
      query->add_option("--depth", query_args->depth,
                        "Aligned depth image of the frame (16-bit PNG; needs --camera): the loop's "
                        "pose is then metric (\"metric\" in --json)");
  query->add_option("--depth-scale", query_args->depth_scale, "Depth units per metre")
      ->capture_default_str();
  query
      ->add_option("--right", query_args->right,
                   "Right image of a rectified stereo pair whose left image is the frame "
                   "(needs --camera and --baseline)")
      ->excludes(depth);
  query->add_option("--baseline", query_args->baseline, "Stereo baseline in metres");
  query->add_flag("--correspondences", query_args->correspondences,
                  "Also list the inliers of a verified loop: keypoint index and pixel in both "
                  "frames");
  ConnectCommand(query, &query_args->server, exit_code,
                 [query_args](RecognitionClient& client) { return RunQuery(*query_args, client); });

  auto relocalize_args = std::make_shared<RelocalizeArgs>();
  CLI::App* relocalize = app.add_subcommand(
      "relocalize",
      "Find where one image, or a few consecutive ones, was seen: in maps or a map group of "
      "recogd (nothing is added)");
  relocalize->footer(
      "Each image is looked up in every map with no temporal consistency to wait for (as "
      "`recog query` without --add). One line per map that recognised any image, best first: a "
      "map that recognised more of the images first, each with its best image's match. Finding "
      "nothing is not an error (exit status 0). --json prints {\"places\": [...]} with each "
      "map's loop result.");
  relocalize->add_option("images", relocalize_args->images, "1 to 10 image files")->required();
  relocalize
      ->add_option("--maps", relocalize_args->maps, "Maps to search, by name (A,B or repeated)")
      ->delimiter(',')
      ->allow_extra_args(false);
  relocalize->add_option("--group", relocalize_args->group, "Search every map of this group");
  relocalize
      ->add_option("--max-results", relocalize_args->max_results,
                   "Report the best N maps only (0: every map that recognised an image)")
      ->capture_default_str();
  CLI::Option* relocalize_camera =
      relocalize->add_option("--camera", relocalize_args->camera,
                             std::string("The images' camera, to also report the relative "
                                         "pose: ") +
                                 kCameraFlagSyntax);
  relocalize
      ->add_option("--depth", relocalize_args->depths,
                   "Depth images aligned with the images, one per image (A,B or repeated; "
                   "needs --camera without distortion): metric poses in maps built with or "
                   "without depth")
      ->delimiter(',')
      ->needs(relocalize_camera);
  relocalize->add_option("--depth-scale", relocalize_args->depth_scale, "Depth units per metre")
      ->capture_default_str();
  ConnectCommand(relocalize, &relocalize_args->server, exit_code,
                 [relocalize_args](RecognitionClient& client) {
                   return RunRelocalize(*relocalize_args, client);
                 });
}

}  // namespace recog::cli
