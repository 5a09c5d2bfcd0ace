// recog stream, recog query and recog relocalize: frames into (or looked up in) maps of recogd,
// over the C++ client library. All take the ServerFlags; a failed call prints one line
// "recog <cmd>: CODE: message" and exits 1.
//
//   stream      a recorded sequence (folder, list or video; or a multi-camera rig sequence)
//               through one StreamFrames call, printing every loop closure as it is answered
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
#include "tools/evaluation/object_evaluation.h"
#include "tools/evaluation/place_evaluation.h"
#include "tools/evaluation/rig_dataset.h"
#include "tools/evaluation/rig_file.h"
#include "tools/recog/commands.h"
#include "wire/grpc_code_names.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;
using client::RecognitionClient;
using json = nlohmann::ordered_json;

std::string StatusLabel(pb::LoopStatus status) {
  return EnumLabel(pb::LoopStatus_Name(status), "LOOP_STATUS_");
}

// The correspondences as [{query_index, query: [x, y], match_index, match: [x, y]}].
json CorrespondencesJson(const google::protobuf::RepeatedPtrField<pb::Correspondence>& in) {
  json pairs = json::array();
  for (const pb::Correspondence& c : in) {
    pairs.push_back({{"query_index", c.query_index()},
                     {"query", {c.query_x(), c.query_y()}},
                     {"match_index", c.match_index()},
                     {"match", {c.match_x(), c.match_y()}}});
  }
  return pairs;
}

json LoopJson(const pb::LoopResult& r) {
  json out = {{"status", StatusLabel(r.status())}, {"score", r.score()}};
  if (!r.has_rig()) {  // a rig map's scores are pooled over cameras, without islands
    out.update({{"normalized_score", r.normalized_score()},
                {"previous_score", r.previous_score()},
                {"island", {{"first", r.island_first()}, {"last", r.island_last()}}},
                {"island_score", r.island_score()},
                {"consistent_queries", r.consistent_queries()}});
  }
  out["correspondences"] = r.correspondences();
  out["inliers"] = r.inliers();
  if (r.has_evidence()) {
    const pb::LoopEvidence& e = r.evidence();
    out["evidence"] = {{"inliers", e.inliers()},
                       {"spread", e.spread()},
                       {"calibrated", e.calibrated()},
                       {"in_front", e.in_front()},
                       {"parallax_deg", e.parallax_deg()},
                       {"rotation_deg", e.rotation_deg()},
                       {"pure_rotation", e.pure_rotation()},
                       {"confirmations", e.confirmations()}};
  }
  if (r.has_frame_id()) out["frame"] = r.frame_id();
  if (r.has_match_frame_id()) {
    out["match"] = r.match_frame_id();
    out["match_client_frame_id"] = r.match_client_frame_id();
  }
  if (r.candidates_size() > 0) {
    json candidates = json::array();
    for (const pb::Candidate& c : r.candidates()) {
      json candidate = {{"frame", c.frame_id()},
                        {"client_frame_id", c.client_frame_id()},
                        {"score", c.score()},
                        {"normalized_score", c.normalized_score()}};
      if (c.has_inliers()) candidate["inliers"] = c.inliers();
      candidates.push_back(std::move(candidate));
    }
    out["candidates"] = std::move(candidates);
  }
  if (r.inlier_correspondences_size() > 0) {
    out["inlier_correspondences"] = CorrespondencesJson(r.inlier_correspondences());
  }
  if (r.has_relative_pose()) {
    const pb::Pose& pose = r.relative_pose();
    out["relative_pose"] = {
        {"rotation", std::vector<double>(pose.rotation().begin(), pose.rotation().end())},
        {"translation", std::vector<double>(pose.translation().begin(), pose.translation().end())}};
  }
  if (r.has_rig()) {
    const pb::RigLoop& rig = r.rig();
    json pairs = json::array();
    for (const pb::RigCameraMatch& pair : rig.pairs()) {
      pairs.push_back({{"query_camera", pair.query_camera()},
                       {"match_camera", pair.match_camera()},
                       {"correspondences", pair.correspondences()},
                       {"inliers", pair.inliers()},
                       {"posed", pair.posed()},
                       {"metric", pair.metric()},
                       {"consistent_ratio", pair.consistent_ratio()}});
      if (pair.inlier_correspondences_size() > 0) {
        pairs.back()["inlier_correspondences"] = CorrespondencesJson(pair.inlier_correspondences());
      }
    }
    json rig_json = {{"pairs", std::move(pairs)},
                     {"rotation_disagreement_deg", rig.rotation_disagreement_deg()},
                     {"posed", rig.posed()},
                     {"metric", rig.metric()}};
    if (rig.posed()) {
      // X_body_query = R X_body_match + t; t in metres when metric, else zero
      const pb::Pose& body = rig.body_pose();
      rig_json["body_pose"] = {
          {"rotation", std::vector<double>(body.rotation().begin(), body.rotation().end())},
          {"translation",
           std::vector<double>(body.translation().begin(), body.translation().end())}};
    }
    if (rig.metric()) {
      rig_json["covariance"] =
          std::vector<double>(rig.covariance().begin(), rig.covariance().end());
    }
    out["rig"] = std::move(rig_json);
  }
  if (r.has_metric()) {
    const pb::MetricLoop& m = r.metric();
    json metric = {{"checked", m.checked()},
                   {"verified", m.verified()},
                   {"correspondences", m.correspondences()},
                   {"inliers", m.inliers()},
                   {"rms_error_px", m.rms_error_px()}};
    if (m.verified()) {
      metric["pose"] = {
          // X_query = R X_match + t, metres
          {"rotation", std::vector<double>(m.pose().rotation().begin(), m.pose().rotation().end())},
          {"translation",
           std::vector<double>(m.pose().translation().begin(), m.pose().translation().end())}};
      metric["covariance"] = std::vector<double>(m.covariance().begin(), m.covariance().end());
    }
    out["metric"] = std::move(metric);
  }
  return out;
}

json TimingJson(const pb::Timing& t) {
  return {{"decode", t.decode_ms()},
          {"features", t.features_ms()},
          {"recognition", t.recognition_ms()},
          {"queue", t.queue_ms()}};
}

// ---- recog stream ----

struct StreamArgs {
  ServerFlags server;
  std::string map, images, rig, draw;
  double depth_scale = 5000;  // --rig: units per metre of the cameras' 16-bit depth images
  std::string preset;  // with create: the new map's detector preset (the server's when empty)
  std::string group;   // with create: the new map's group
  std::vector<std::string> search_maps;  // other maps every frame is looked up in
  std::string search_group;
  double rate = 0;
  uint64_t frames = 0;  // 0: every frame of the sequence
  bool features_on_client = false, create = false, timestamps = false, quiet = false;
  bool keep_thumbnails = false;  // with create: the new map keeps a thumbnail of each frame
};

// Set by SIGINT/SIGTERM while `recog stream` runs: stop reading frames, take the answers of those
// sent, close the stream and print the summary.
volatile std::sig_atomic_t stop_streaming = 0;
void StopStreaming(int) { stop_streaming = 1; }

// Frames sent ahead of their answers: enough to keep the server busy while a frame travels.
constexpr size_t kFramesInFlight = 4;

// The frame of one image of the sequence (see the --help of recog stream).
client::Result<pb::Frame> StreamFrame(const StreamArgs& args, bool from_file,
                                      const std::string& name, const cv::Mat& gray) {
  if (args.features_on_client) {
    auto features = client::ExtractOrbFeatures(gray);
    if (!features.ok()) return features.status();
    return client::FrameFromFeatures(features->keypoints, features->descriptors, gray.size());
  }
  return from_file ? FrameFromImageFile(name, gray) : client::FrameFromImage(gray);
}

// What recog stream sends: the frames of an image sequence (--images), or the rig frames of a
// rig sequence (--rig: one view per camera, with the camera's depth image when it has one).
class StreamSequence {
 public:
  static StatusOr<StreamSequence> Open(const StreamArgs& args) {
    StreamSequence sequence;
    if (!args.rig.empty()) {
      RECOG_ASSIGN_OR_RETURN(sequence.rig_, ReadRigDataset(args.rig));
      for (const RigCamera& camera : sequence.rig_->cameras) {
        sequence.cameras_.push_back(camera.name);
      }
    } else {
      RECOG_ASSIGN_OR_RETURN(sequence.images_, FrameSource::Open(args.images));
      sequence.cameras_ = {""};
    }
    return sequence;
  }

  size_t size() const { return rig_ ? rig_->images.size() : images_->size(); }
  // The camera of each of a frame's images ("" for the one camera of an image sequence).
  const std::vector<std::string>& cameras() const { return cameras_; }
  // With --rig: the rig of a map --create makes.
  void AddRig(pb::MapSettings* settings) const {
    if (!rig_) return;
    for (const RigCamera& c : rig_->cameras) {
      *settings->add_rig() = client::MakeRigCamera(c.name, c.size, c.K, c.distortion,
                                                   c.body_R_camera, c.body_t_camera);
    }
  }

  // The next frame, its name (its first image's path) and its grey images (one per camera);
  // false at the end. A frame that cannot be read or built is an error, and the next call goes
  // on with the following one.
  StatusOr<bool> Next(const StreamArgs& args, pb::Frame* frame, std::string* name,
                      std::vector<cv::Mat>* images) {
    images->clear();
    std::optional<double> recorded;
    if (rig_) {
      if (next_ == rig_->images.size()) return false;
      const size_t i = next_++;
      *frame = pb::Frame();
      *name = rig_->images[i].front();
      for (size_t c = 0; c < cameras_.size(); ++c) {
        RECOG_ASSIGN_OR_RETURN(cv::Mat gray, ReadGrayImage(rig_->images[i][c]));
        client::Result<pb::Frame> view =
            StreamFrame(args, /*from_file=*/true, rig_->images[i][c], gray);
        if (!view.ok()) return Status::InvalidArgument(view.status().error_message());
        RECOG_RETURN_IF_ERROR(AttachDepth(rig_->depths[i][c], args.depth_scale, &*view));
        const grpc::Status added = client::AddRigView(cameras_[c], std::move(*view), frame);
        if (!added.ok()) return Status::InvalidArgument(added.error_message());
        images->push_back(std::move(gray));
      }
      recorded = rig_->timestamps[i];
    } else {
      cv::Mat gray;
      RECOG_ASSIGN_OR_RETURN(const bool more, images_->Next(&gray, name));
      if (!more) return false;
      client::Result<pb::Frame> built = StreamFrame(args, !images_->is_video(), *name, gray);
      if (!built.ok()) return Status::InvalidArgument(built.status().error_message());
      *frame = std::move(*built);
      images->push_back(std::move(gray));
      recorded = images_->timestamp();
    }
    if (args.timestamps) {
      frame->set_timestamp(
          recorded.has_value()
              ? *recorded
              : std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch())
                    .count());
    }
    return true;
  }

 private:
  StreamSequence() = default;

  // A camera's depth image (none when `path` is empty), in units of 1/units_per_metre metres.
  static Status AttachDepth(const std::string& path, double units_per_metre, pb::Frame* view) {
    if (path.empty()) return Status::Ok();
    const cv::Mat depth = cv::imread(path, cv::IMREAD_ANYDEPTH);
    if (depth.empty()) return Status::InvalidArgument("cannot read depth image '" + path + "'");
    const grpc::Status attached = client::AttachDepth(depth, units_per_metre, view);
    if (!attached.ok()) return Status::InvalidArgument(path + ": " + attached.error_message());
    return Status::Ok();
  }

  std::optional<FrameSource> images_;
  std::optional<RigDataset> rig_;
  std::vector<std::string> cameras_;
  size_t next_ = 0;
};

// What recog stream keeps of the frames it sent, to name (and draw) the loops.
struct SentFrames {
  std::vector<std::string> names;             // by sequence: file names
  std::vector<std::vector<cv::Mat>> images;   // by sequence, per camera, with --draw
  std::map<uint64_t, size_t> sequence_of_id;  // the map's frame id -> sequence

  // "45 (45.jpg)"; "3" for a frame that an earlier session added.
  std::string Describe(uint64_t id) const {
    const auto found = sequence_of_id.find(id);
    return std::to_string(id) +
           (found == sequence_of_id.end() ? "" : " (" + names[found->second] + ")");
  }
};

// "rear>front, front>front": the camera pairs of a rig loop (empty for other loops).
std::string CameraPairs(const pb::LoopResult& r) {
  std::string pairs;
  for (const pb::RigCameraMatch& pair : r.rig().pairs()) {
    pairs += (pairs.empty() ? "" : ", ") + pair.query_camera() + ">" + pair.match_camera();
  }
  return pairs;
}

// The two images of a loop side by side with their inlier correspondences and a caption, as
// DIR/loop_<frame>_<match>.png. A rig loop shows its first camera pair.
Status DrawLoop(const std::string& dir, const SentFrames& sent,
                const std::vector<std::string>& cameras, const pb::LoopResult& r) {
  const uint64_t frame = r.frame_id(), match = r.match_frame_id();
  const size_t a = sent.sequence_of_id.at(frame), b = sent.sequence_of_id.at(match);
  size_t query_camera = 0, match_camera = 0;
  const google::protobuf::RepeatedPtrField<pb::Correspondence>* inliers =
      &r.inlier_correspondences();
  if (r.rig().pairs_size() > 0) {
    const pb::RigCameraMatch& pair = r.rig().pairs(0);
    const auto index = [&](const std::string& name) {
      return size_t(std::find(cameras.begin(), cameras.end(), name) - cameras.begin());
    };
    query_camera = index(pair.query_camera());
    match_camera = index(pair.match_camera());
    if (query_camera == cameras.size() || match_camera == cameras.size()) {
      return Status::InvalidArgument("the loop names a camera the sequence does not have");
    }
    inliers = &pair.inlier_correspondences();
  }
  std::vector<cv::KeyPoint> query_points, match_points;
  std::vector<cv::DMatch> lines;
  for (const pb::Correspondence& c : *inliers) {
    lines.emplace_back(int(query_points.size()), int(match_points.size()), 0.0f);
    query_points.emplace_back(c.query_x(), c.query_y(), 1.0f);
    match_points.emplace_back(c.match_x(), c.match_y(), 1.0f);
  }
  cv::Mat canvas;
  cv::drawMatches(sent.images[a][query_camera], query_points, sent.images[b][match_camera],
                  match_points, lines, canvas, cv::Scalar(0, 200, 0));
  cv::copyMakeBorder(canvas, canvas, 36, 0, 0, 0, cv::BORDER_CONSTANT, cv::Scalar(255, 255, 255));
  const std::string pairs = CameraPairs(r);
  const std::string caption = "frame " + sent.Describe(frame) + " closes a loop with frame " +
                              sent.Describe(match) + ": " + std::to_string(r.inliers()) +
                              " inliers" + (pairs.empty() ? "" : " (" + pairs + ")");
  // The caption shrinks to fit small images.
  int baseline = 0;
  const double width = cv::getTextSize(caption, cv::FONT_HERSHEY_SIMPLEX, 0.6, 1, &baseline).width;
  const double scale = std::min(0.6, 0.6 * (canvas.cols - 16) / width);
  cv::putText(canvas, caption, {8, 25}, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(0, 0, 0), 1,
              cv::LINE_AA);
  const std::string path =
      (fs::path(dir) / ("loop_" + std::to_string(frame) + "_" + std::to_string(match) + ".png"))
          .string();
  if (!cv::imwrite(path, canvas)) return Status::Internal("cannot write '" + path + "'");
  return Status::Ok();
}

int RunStream(const StreamArgs& args, RecognitionClient& client) {
  if (!(args.rate >= 0)) return Fail("stream", Status::InvalidArgument("--rate must be >= 0"));
  if (args.images.empty() == args.rig.empty()) {
    return Fail("stream", Status::InvalidArgument("give --images or --rig"));
  }
  auto source = StreamSequence::Open(args);
  if (!source.ok()) return Fail("stream", source.status());
  if (!args.draw.empty()) {
    std::error_code ec;
    fs::create_directories(args.draw, ec);
    if (ec) {
      return Fail("stream",
                  Status::InvalidArgument("cannot create '" + args.draw + "': " + ec.message()));
    }
  }
  pb::StreamConfig config;
  config.set_map(args.map);
  config.set_create_if_missing(args.create);
  if (!args.preset.empty()) config.mutable_settings()->set_preset(args.preset);
  if (!args.group.empty()) config.mutable_settings()->set_group(args.group);
  if (args.keep_thumbnails) config.mutable_settings()->set_keep_thumbnails(true);
  for (const std::string& name : args.search_maps) config.add_search_maps(name);
  config.set_search_group(args.search_group);
  if (args.create) source->AddRig(config.mutable_settings());
  // Drawn loops show their inliers.
  config.mutable_options()->set_include_correspondences(!args.draw.empty());
  auto stream = client::FrameStream::Open(client, config);
  if (!stream.ok()) return Fail("stream", stream.status());

  ProgressBar progress(!args.quiet);
  SentFrames sent;
  size_t answered = 0, loops = 0, inter_map_loops = 0, errors = 0;
  grpc::Status failure;  // the stream's, once it failed
  // Reports one answer, in order; false once the stream has failed.
  const auto handle = [&](client::FrameStream::Answer answer) {
    if (!answer.ok()) {
      failure = answer.status();
      return false;
    }
    const size_t sequence = answered++;
    progress.Update("frames", answered, source->size());
    if (answer->has_error()) {
      ++errors;
      progress.Finish();
      const pb::FrameError& e = answer->error();
      std::fprintf(stderr, "recog stream: frame %s: %s: %s\n", sent.names[sequence].c_str(),
                   std::string(GrpcCodeName(grpc::StatusCode(e.code()))).c_str(),
                   e.message().c_str());
      return true;
    }
    const pb::LoopResult& r = answer->result();
    if (r.has_frame_id()) sent.sequence_of_id[r.frame_id()] = sequence;
    for (const pb::InterMapMatch& found : answer->inter_map()) {
      ++inter_map_loops;
      const pb::LoopResult& m = found.result();
      if (args.server.json) {
        json loop = {{"event", "inter_map_loop"}, {"map", found.map()}};
        loop.update(LoopJson(m));
        loop["frame_file"] = sent.names[sequence];
        std::printf("%s\n", loop.dump().c_str());
      } else {
        progress.Finish();
        std::printf("frame %s was seen in map '%s' as frame %llu%s: %u inliers\n",
                    sent.names[sequence].c_str(), found.map().c_str(),
                    static_cast<unsigned long long>(m.match_frame_id()),
                    m.match_client_frame_id().empty()
                        ? ""
                        : (" (" + m.match_client_frame_id() + ")").c_str(),
                    m.inliers());
      }
    }
    if (r.status() == pb::LOOP_STATUS_CANDIDATE && r.has_match_frame_id()) {
      // Awaiting the next keyframes' confirmation (MapSettings.keyframe_confirmations): shown,
      // not counted as a loop.
      if (args.server.json) {
        json candidate = {{"event", "candidate"}};
        candidate.update(LoopJson(r));
        std::printf("%s\n", candidate.dump().c_str());
      } else {
        progress.Finish();
        std::printf("frame %s: candidate loop with frame %s, %u inliers, awaiting confirmation\n",
                    sent.Describe(r.frame_id()).c_str(), sent.Describe(r.match_frame_id()).c_str(),
                    r.inliers());
      }
      std::fflush(stdout);
      return true;
    }
    if (r.status() != pb::LOOP_STATUS_LOOP_DETECTED || !r.has_match_frame_id()) return true;
    ++loops;
    if (args.server.json) {
      json loop = {{"event", "loop"}};
      loop.update(LoopJson(r));
      loop["frame_file"] = sent.names[sequence];
      const auto match = sent.sequence_of_id.find(r.match_frame_id());
      if (match != sent.sequence_of_id.end()) loop["match_file"] = sent.names[match->second];
      std::printf("%s\n", loop.dump().c_str());
    } else {
      progress.Finish();
      const std::string pairs = CameraPairs(r);
      std::printf("frame %s closes a loop with frame %s: %u inliers%s\n",
                  sent.Describe(r.frame_id()).c_str(), sent.Describe(r.match_frame_id()).c_str(),
                  r.inliers(), pairs.empty() ? "" : (" (" + pairs + ")").c_str());
    }
    std::fflush(stdout);
    if (!args.draw.empty() && r.has_frame_id() &&
        sent.sequence_of_id.contains(r.match_frame_id())) {
      if (Status s = DrawLoop(args.draw, sent, source->cameras(), r); !s.ok()) {
        ++errors;
        Fail("stream", s);
      }
    }
    return true;
  };

  const auto start = std::chrono::steady_clock::now();
  std::deque<std::future<client::FrameStream::Answer>> pending;
  bool streaming = true;
  // Waits for the oldest answer and reports it.
  const auto take_oldest = [&] {
    streaming = handle(pending.front().get());
    pending.pop_front();
  };
  // Reports the answers that come before `until`, in order.
  const auto answers_until = [&](std::chrono::steady_clock::time_point until) {
    while (streaming && !pending.empty() &&
           pending.front().wait_until(until) == std::future_status::ready) {
      take_oldest();
    }
  };
  // A frame that cannot be read or sent is reported, and the stream goes on.
  const auto skip = [&](const auto& status) {
    ++errors;
    progress.Finish();
    Fail("stream", status);
  };
  stop_streaming = 0;
  const auto previous_int = std::signal(SIGINT, StopStreaming);
  const auto previous_term = std::signal(SIGTERM, StopStreaming);
  while (streaming && !stop_streaming && (args.frames == 0 || sent.names.size() < args.frames)) {
    pb::Frame frame;
    std::string name;
    std::vector<cv::Mat> images;
    StatusOr<bool> more = source->Next(args, &frame, &name, &images);
    if (!more.ok()) {
      skip(more.status());
      continue;
    }
    if (!*more) break;
    if (args.rate > 0) {
      const auto due =
          start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                      std::chrono::duration<double>(double(sent.names.size()) / args.rate));
      answers_until(due);
      std::this_thread::sleep_until(due);
    }
    sent.names.push_back(fs::path(name).filename().string());
    if (!args.draw.empty()) sent.images.push_back(std::move(images));
    pending.push_back((*stream)->Send(std::move(frame)));
    answers_until(std::chrono::steady_clock::now());  // those that have come
    while (streaming && pending.size() > kFramesInFlight) take_oldest();
  }
  std::signal(SIGINT, previous_int);
  std::signal(SIGTERM, previous_term);
  while (streaming && !pending.empty()) take_oldest();
  const grpc::Status end = (*stream)->Close();
  progress.Finish();
  if (!failure.ok()) return Fail("stream", failure);
  if (!end.ok()) return Fail("stream", end);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double rate = seconds > 0 ? double(answered) / seconds : 0.0;
  if (args.server.json) {
    std::printf("%s\n", json({{"event", "summary"},
                              {"map", args.map},
                              {"frames", answered},
                              {"loops", loops},
                              {"inter_map_loops", inter_map_loops},
                              {"errors", errors},
                              {"seconds", seconds},
                              {"frames_per_second", rate}})
                            .dump()
                            .c_str());
  } else {
    const bool searching = !args.search_maps.empty() || !args.search_group.empty();
    std::printf("%zu frames, %zu loops, %s%zu errors in %.2f s (%.1f frames/s)\n", answered, loops,
                searching ? (std::to_string(inter_map_loops) + " inter-map loops, ").c_str() : "",
                errors, seconds, rate);
  }
  return errors == 0 ? 0 : 1;
}

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
    auto camera = ParseCamera(args.camera);
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
    json out = LoopJson(r);
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
    auto parsed = ParseCamera(args.camera);
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
    json places = json::array();
    for (const pb::Relocalization& place : answer->places()) {
      places.push_back({{"map", place.map()},
                        {"image", args.images[place.frame_index()]},
                        {"frame_index", place.frame_index()},
                        {"frames_recognised", place.frames_recognised()},
                        {"result", LoopJson(place.result())}});
    }
    std::printf("%s\n", json({{"frames", frames.size()},
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

void AddStreamCommands(CLI::App& app, int* exit_code) {
  auto stream_args = std::make_shared<StreamArgs>();
  CLI::App* stream = app.add_subcommand(
      "stream", "Stream a recorded sequence into a map of recogd and print every loop closure");
  stream->footer(
      "JPEG and PNG files are sent as they are: the server decodes them to the grey pixels that "
      "`recog eval place` reads, so the loops are the same. Other images and video frames are sent "
      "as raw grey pixels. Frames are numbered as the map numbers them, from 0. --json prints one "
      "object per line: {\"event\": \"loop\", ...} per loop, then {\"event\": \"summary\", ...}. "
      "A frame that fails on its own is reported and the stream goes on; the exit status is then "
      "1. Ctrl-C (SIGINT) or SIGTERM stops reading frames: the answers of those sent are taken, "
      "the stream is closed and the summary printed (how a camera stream ends).");
  stream->add_option("--map", stream_args->map, "Map name")->required();
  CLI::Option* images =
      stream->add_option("--images", stream_args->images,
                         "Folder of frames, a list file, a video, or camera:N for the live camera "
                         "/dev/videoN");
  stream
      ->add_option("--rig", stream_args->rig,
                   "Instead of --images, a multi-camera rig sequence (a folder with rig.yaml and "
                   "one folder per camera, a EuRoC folder of cam0, cam1, ... or a KITTI sequence "
                   "folder) into a rig map: every frame carries one view per camera, and a "
                   "camera's depth image when it has one")
      ->excludes(images);
  stream
      ->add_option("--depth-scale", stream_args->depth_scale,
                   "With --rig: units per metre of the cameras' 16-bit depth images")
      ->capture_default_str()
      ->needs("--rig");
  stream->add_option("--frames", stream_args->frames, "Stop after this many frames (0: all)")
      ->capture_default_str();
  stream
      ->add_option("--rate", stream_args->rate,
                   "Frames per second to send (0: as fast as the "
                   "server answers, a few frames in flight)")
      ->capture_default_str();
  stream->add_flag("--features-on-client", stream_args->features_on_client,
                   "Extract the ORB features here and send them instead of the images");
  stream->add_flag("--create", stream_args->create,
                   "Create the map (with the server's default settings) if it does not exist");
  stream
      ->add_option("--preset", stream_args->preset,
                   "With --create: the new map's detector preset (default, thesis, or keyframes "
                   "for a SLAM's keyframes)")
      ->check(CLI::IsMember({"default", "thesis", "keyframes"}))
      ->needs("--create");
  stream
      ->add_option("--group", stream_args->group,
                   "With --create: the new map's group (searched together by --search-group)")
      ->needs("--create");
  stream
      ->add_flag("--keep-thumbnails", stream_args->keep_thumbnails,
                 "With --create: the new map keeps a small JPEG of each frame, which the web "
                 "console shows beside its loops")
      ->needs("--create");
  stream->add_option("--search-maps", stream_args->search_maps,
                     "Other maps every frame is also looked up in (relocalisation; their matches "
                     "are reported as inter-map loops)");
  stream->add_option("--search-group", stream_args->search_group,
                     "Every map of this group is searched too, as --search-maps");
  stream->add_option("--draw", stream_args->draw,
                     "Folder for a PNG per loop (loop_<frame>_<match>.png): both frames side by "
                     "side with their inlier correspondences (a rig loop: its first camera pair)");
  stream->add_flag("--timestamps", stream_args->timestamps,
                   "Stamp each frame with its time in the dataset (TUM, EuRoC, KITTI; 0.0 is a "
                   "time), or else this machine's clock when it is sent (the map's "
                   "recent_seconds then applies instead of recent_frames)");
  stream->add_flag("-q,--quiet", stream_args->quiet, "No progress output");
  ConnectCommand(stream, &stream_args->server, exit_code, [stream_args](RecognitionClient& client) {
    return RunStream(*stream_args, client);
  });

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
                    "fx,fy,cx,cy[,k1,k2,p1,p2[,k3]]: also report the relative pose of a loop");
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
                             "fx,fy,cx,cy[,k1,k2,p1,p2[,k3]]: also report the relative pose");
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
