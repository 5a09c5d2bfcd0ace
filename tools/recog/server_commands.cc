// recog stream, query, maps and models: the subcommands that use recogd, over the C++ client
// library (client/cpp). Each takes the ServerFlags (--server, --token-file, --tls-*, --json); a
// failed call prints one line "recog <cmd>: CODE: message" and exits 1.
//
//   stream   a recorded sequence (folder, list or video) through one StreamFrames call, printing
//            every loop closure as it is answered
//   query    one QueryPlace: relocalisation, or the loop detector's step with --add
//   maps     list | create NAME [settings] | delete NAME | stats NAME
//   models   push | pull | list | delete | watch: the object model repository
#include <algorithm>
#include <cctype>
#include <chrono>
#include <condition_variable>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <deque>
#include <filesystem>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <mutex>
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
#include "core/features/feature_extractor.h"
#include "core/object/model_builder.h"
#include "core/object/model_file.h"
#include "storage/rocksdb_index_store.h"
#include "tools/recog/cli_support.h"
#include "tools/recog/commands.h"
#include "tools/recog/object_evaluation.h"
#include "tools/recog/place_evaluation.h"
#include "tools/recog/remote_support.h"
#include "tools/recog/server_flags.h"
#include "wire/grpc_code_names.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;
using client::RecognitionClient;
using json = nlohmann::ordered_json;

// Runs `body` with a client connected as `flags` say: its exit status, or 1 after the error line.
int WithClient(const char* command, const ServerFlags& flags,
               const std::function<int(RecognitionClient&)>& body) {
  auto client = flags.Connect();
  if (!client.ok()) return Fail(command, client.status());
  return body(**client);
}

// A proto enum value's name without its prefix, in lower case: "loop_detected" for
// LOOP_STATUS_LOOP_DETECTED (core's spelling, as `recog eval place` prints it).
std::string EnumLabel(std::string name, std::string_view prefix) {
  if (name.starts_with(prefix)) name.erase(0, prefix.size());
  std::transform(name.begin(), name.end(), name.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return name;
}

std::string StatusLabel(pb::LoopStatus status) {
  return EnumLabel(pb::LoopStatus_Name(status), "LOOP_STATUS_");
}

std::string TypeLabel(pb::ObjectType type) {
  return type == pb::OBJECT_TYPE_3D ? "3D" : EnumLabel(pb::ObjectType_Name(type), "OBJECT_TYPE_");
}

// "2024-05-01T12:00:00Z".
std::string UtcTime(int64_t unix_ms) {
  const std::time_t seconds = std::time_t(unix_ms / 1000);
  std::tm tm{};
  gmtime_r(&seconds, &tm);
  char text[32];
  std::strftime(text, sizeof(text), "%Y-%m-%dT%H:%M:%SZ", &tm);
  return text;
}

// Prints an object's fields one per line ("key  value"), nested objects flattened.
void PrintFields(const json& fields) {
  for (const auto& [key, value] : fields.items()) {
    if (value.is_object()) {
      PrintFields(value);
    } else {
      std::printf("%-20s %s\n", key.c_str(),
                  value.is_string() ? value.get<std::string>().c_str() : value.dump().c_str());
    }
  }
}

json MapJson(const pb::MapInfo& map) {
  const pb::MapSettings& s = map.settings();
  return {{"name", map.name()},
          {"id", map.id()},
          {"frames", map.frames()},
          {"next_frame_id", map.next_frame_id()},
          {"created", UtcTime(map.created_unix_ms())},
          {"vocabulary_checksum", map.vocabulary_checksum()},
          {"settings",
           {{"alpha", s.alpha()},
            {"temporal_matches", s.temporal_matches()},
            {"min_inliers", s.min_inliers()},
            {"geometry", EnumLabel(pb::GeometryCheck_Name(s.geometry()), "GEOMETRY_CHECK_")},
            {"recent_seconds", s.recent_seconds()},
            {"recent_frames", s.recent_frames()}}}};
}

json ModelJson(const pb::ModelInfo& model) {
  return {{"name", model.name()},
          {"version", model.version()},
          {"class", model.object_class()},
          {"type", TypeLabel(model.type())},
          {"dimensions", std::vector<double>(model.dimensions().begin(), model.dimensions().end())},
          {"units", model.units()},
          {"source", model.source()},
          {"tags", std::vector<std::string>(model.tags().begin(), model.tags().end())},
          {"sha256", model.sha256()},
          {"size_bytes", model.size_bytes()},
          {"created", UtcTime(model.created_unix_ms())},
          {"points", model.num_points()},
          {"descriptors", model.num_descriptors()}};
}

// "box v2: 3D, class 'box', 1234 points, 56789 bytes".
std::string ModelLine(const pb::ModelInfo& model) {
  return model.name() + " v" + std::to_string(model.version()) + ": " + TypeLabel(model.type()) +
         ", class '" + model.object_class() + "', " + std::to_string(model.num_points()) +
         " points, " + std::to_string(model.size_bytes()) + " bytes";
}

json LoopJson(const pb::LoopResult& r) {
  json out = {{"status", StatusLabel(r.status())},
              {"score", r.score()},
              {"normalized_score", r.normalized_score()},
              {"previous_score", r.previous_score()},
              {"island", {{"first", r.island_first()}, {"last", r.island_last()}}},
              {"island_score", r.island_score()},
              {"consistent_queries", r.consistent_queries()},
              {"correspondences", r.correspondences()},
              {"inliers", r.inliers()}};
  if (r.has_frame_id()) out["frame"] = r.frame_id();
  if (r.has_match_frame_id()) out["match"] = r.match_frame_id();
  if (r.has_relative_pose()) {
    const pb::Pose& pose = r.relative_pose();
    out["relative_pose"] = {
        {"rotation", std::vector<double>(pose.rotation().begin(), pose.rotation().end())},
        {"translation", std::vector<double>(pose.translation().begin(), pose.translation().end())}};
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
  std::string map, images, draw;
  double rate = 0;
  uint64_t frames = 0;  // 0: every frame of the sequence
  bool features_on_client = false, create = false, timestamps = false, quiet = false;
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

// What recog stream keeps of the frames it sent, to name (and draw) the loops.
struct SentFrames {
  std::vector<std::string> names;             // by sequence: file names
  std::vector<cv::Mat> images;                // by sequence, with --draw
  std::map<uint64_t, size_t> sequence_of_id;  // the map's frame id -> sequence

  // "45 (45.jpg)"; "3" for a frame that an earlier session added.
  std::string Describe(uint64_t id) const {
    const auto found = sequence_of_id.find(id);
    return std::to_string(id) +
           (found == sequence_of_id.end() ? "" : " (" + names[found->second] + ")");
  }
};

// Both frames of a loop side by side with a caption, as DIR/loop_<frame>_<match>.png.
Status DrawLoop(const std::string& dir, const SentFrames& sent, uint64_t frame, uint64_t match,
                uint32_t inliers) {
  const size_t a = sent.sequence_of_id.at(frame), b = sent.sequence_of_id.at(match);
  cv::Mat canvas;
  const std::vector<cv::KeyPoint> none;
  cv::drawMatches(sent.images[a], none, sent.images[b], none, std::vector<cv::DMatch>(), canvas);
  cv::copyMakeBorder(canvas, canvas, 36, 0, 0, 0, cv::BORDER_CONSTANT, cv::Scalar(255, 255, 255));
  const std::string caption = "frame " + sent.Describe(frame) + " closes a loop with frame " +
                              sent.Describe(match) + ": " + std::to_string(inliers) + " inliers";
  cv::putText(canvas, caption, {8, 25}, cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(0, 0, 0), 1,
              cv::LINE_AA);
  const std::string path =
      (fs::path(dir) / ("loop_" + std::to_string(frame) + "_" + std::to_string(match) + ".png"))
          .string();
  if (!cv::imwrite(path, canvas)) return Status::Internal("cannot write '" + path + "'");
  return Status::Ok();
}

int RunStream(const StreamArgs& args, RecognitionClient& client) {
  if (!(args.rate >= 0)) return Fail("stream", Status::InvalidArgument("--rate must be >= 0"));
  auto source = FrameSource::Open(args.images);
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
  auto stream = client::FrameStream::Open(client, config);
  if (!stream.ok()) return Fail("stream", stream.status());

  ProgressBar progress(!args.quiet);
  SentFrames sent;
  size_t answered = 0, loops = 0, errors = 0;
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
      std::printf("frame %s closes a loop with frame %s: %u inliers\n",
                  sent.Describe(r.frame_id()).c_str(), sent.Describe(r.match_frame_id()).c_str(),
                  r.inliers());
    }
    std::fflush(stdout);
    if (!args.draw.empty() && r.has_frame_id() &&
        sent.sequence_of_id.contains(r.match_frame_id())) {
      if (Status s = DrawLoop(args.draw, sent, r.frame_id(), r.match_frame_id(), r.inliers());
          !s.ok()) {
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
    cv::Mat gray;
    std::string name;
    StatusOr<bool> more = source->Next(&gray, &name);
    if (!more.ok()) {
      skip(more.status());
      continue;
    }
    if (!*more) break;
    client::Result<pb::Frame> frame = StreamFrame(args, !source->is_video(), name, gray);
    if (!frame.ok()) {
      skip(frame.status());
      continue;
    }
    if (args.rate > 0) {
      const auto due =
          start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                      std::chrono::duration<double>(double(sent.names.size()) / args.rate));
      answers_until(due);
      std::this_thread::sleep_until(due);
    }
    if (args.timestamps) {
      frame->set_timestamp(
          std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch())
              .count());
    }
    sent.names.push_back(fs::path(name).filename().string());
    if (!args.draw.empty()) sent.images.push_back(gray);
    pending.push_back((*stream)->Send(std::move(*frame)));
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
                              {"errors", errors},
                              {"seconds", seconds},
                              {"frames_per_second", rate}})
                            .dump()
                            .c_str());
  } else {
    std::printf("%zu frames, %zu loops, %zu errors in %.2f s (%.1f frames/s)\n", answered, loops,
                errors, seconds, rate);
  }
  return errors == 0 ? 0 : 1;
}

// ---- recog admin ----

int RunHealth(const ServerFlags& flags, RecognitionClient& client) {
  auto status = client.CheckHealth();
  if (!status.ok()) return Fail("admin health", status.status());
  const std::string name = grpc::health::v1::HealthCheckResponse::ServingStatus_Name(*status);
  if (flags.json) {
    std::printf("%s\n", json({{"status", name}}).dump().c_str());
  } else {
    std::printf("%s\n", name.c_str());
  }
  return *status == grpc::health::v1::HealthCheckResponse::SERVING ? 0 : 1;
}

struct CheckpointArgs {
  ServerFlags server;
  std::string to;
  bool quiet = false;
};

int RunCheckpoint(const CheckpointArgs& args, RecognitionClient& client) {
  ProgressBar progress(!args.quiet);
  auto manifest = client.DownloadCheckpoint(
      args.to, [&](uint64_t done, uint64_t total) { progress.Update("bytes", done, total); });
  progress.Finish();
  if (!manifest.ok()) return Fail("admin checkpoint", manifest.status());
  if (args.server.json) {
    std::printf("%s\n", json({{"directory", args.to},
                              {"files", manifest->files_size()},
                              {"bytes", manifest->total_bytes()},
                              {"maps", manifest->maps()},
                              {"models", manifest->models()},
                              {"created", UtcTime(manifest->created_unix_ms())}})
                            .dump()
                            .c_str());
  } else {
    std::printf("checkpoint of %u maps and %u models: %d files, %llu bytes in %s\n",
                manifest->maps(), manifest->models(), manifest->files_size(),
                static_cast<unsigned long long>(manifest->total_bytes()), args.to.c_str());
  }
  return 0;
}

struct RestoreArgs {
  std::string from, data_dir;
};

int RunRestore(const RestoreArgs& args) {
  std::error_code ec;
  fs::create_directories(args.data_dir, ec);
  if (ec) {
    return Fail("admin restore",
                Status::InvalidArgument("cannot create '" + args.data_dir + "': " + ec.message()));
  }
  const std::string store = (fs::path(args.data_dir) / "store").string();
  if (Status s = RestoreRocksDbCheckpoint(args.from, store); !s.ok()) {
    return Fail("admin restore", s);
  }
  return 0;  // the store logs what it restored
}

// ---- recog query ----

struct QueryArgs {
  ServerFlags server;
  std::string map, image, camera;
  bool add = false;
};

int RunQuery(const QueryArgs& args, RecognitionClient& client) {
  auto gray = ReadGrayImage(args.image);
  if (!gray.ok()) return Fail("query", gray.status());
  auto frame = FrameFromImageFile(args.image, *gray);
  if (!frame.ok()) return Fail("query", frame.status());
  pb::ResultOptions options;
  if (!args.camera.empty()) {
    auto camera = ParseCamera(args.camera);
    if (!camera.ok()) return Fail("query", camera.status());
    SetIntrinsics(*camera, &*frame);
    options.set_include_relative_pose(true);
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
    std::printf("match      frame %llu (score %.3f, normalised %.3f)\n",
                (unsigned long long)r.match_frame_id(), r.score(), r.normalized_score());
    std::printf("inliers    %u of %u correspondences\n", r.inliers(), r.correspondences());
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
  return 0;
}

// ---- recog maps ----

int RunMapsList(const ServerFlags& flags, RecognitionClient& client) {
  auto maps = client.ListMaps();
  if (!maps.ok()) return Fail("maps list", maps.status());
  if (flags.json) {
    json out = json::array();
    for (const pb::MapInfo& map : *maps) out.push_back(MapJson(map));
    std::printf("%s\n", out.dump(2).c_str());
    return 0;
  }
  std::printf("%-32s %10s  %s\n", "NAME", "FRAMES", "CREATED");
  for (const pb::MapInfo& map : *maps) {
    std::printf("%-32s %10llu  %s\n", map.name().c_str(), (unsigned long long)map.frames(),
                UtcTime(map.created_unix_ms()).c_str());
  }
  return 0;
}

// Prints a map's description (maps create, maps stats).
void PrintMap(const ServerFlags& flags, const pb::MapInfo& map) {
  if (flags.json) {
    std::printf("%s\n", MapJson(map).dump(2).c_str());
  } else {
    PrintFields(MapJson(map));
  }
}

// ---- recog models ----

struct PushArgs {
  ServerFlags server;
  std::string path, name, vocabulary;
  std::vector<std::string> tags;
};

int RunModelsPush(const PushArgs& args, RecognitionClient& client) {
  const std::vector<ModelSource> sources = FindModelSources(args.path);
  if (sources.empty()) {
    return Fail("models push",
                Status::InvalidArgument("'" + args.path +
                                        "' holds no model file (.robj) nor RoboEarth folder"));
  }
  if (!args.name.empty() && sources.size() > 1) {
    return Fail("models push",
                Status::InvalidArgument("--name needs a single model; '" + args.path + "' holds " +
                                        std::to_string(sources.size())));
  }
  std::unique_ptr<ModelBuilder> builder;  // made for the first RoboEarth folder
  json pushed = json::array();
  for (const ModelSource& source : sources) {
    client::Result<pb::ModelInfo> info = grpc::Status(grpc::StatusCode::INTERNAL, "unset");
    if (source.roboearth) {
      if (builder == nullptr) {
        auto vocabulary = LoadObjectVocabulary(args.vocabulary);
        if (!vocabulary.ok()) return Fail("models push", vocabulary.status());
        builder = std::make_unique<ModelBuilder>(*vocabulary);
      }
      StatusOr<ObjectModel> model = builder->FromRoboEarth(source.path);
      if (!model.ok()) return Fail("models push", model.status());
      StatusOr<std::string> bytes = EncodeObjectModel(*model);
      if (!bytes.ok()) return Fail("models push", bytes.status());
      info = client.UploadModel(*bytes, args.name, args.tags);
    } else {
      info = client.UploadModelFile(source.path, args.name, args.tags);
    }
    if (!info.ok()) return Fail("models push", info.status());
    if (args.server.json) {
      pushed.push_back(ModelJson(*info));
    } else {
      std::printf("pushed %s (from %s)\n", ModelLine(*info).c_str(), source.path.c_str());
    }
  }
  if (args.server.json) std::printf("%s\n", pushed.dump(2).c_str());
  return 0;
}

struct PullArgs {
  ServerFlags server;
  std::string name, output;
  uint32_t version = 0;
};

int RunModelsPull(const PullArgs& args, RecognitionClient& client) {
  auto info = client.DownloadModel(args.name, args.version, args.output);
  if (!info.ok()) return Fail("models pull", info.status());
  if (args.server.json) {
    json out = ModelJson(*info);
    out["file"] = args.output;
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    std::printf("pulled %s -> %s\n", ModelLine(*info).c_str(), args.output.c_str());
  }
  return 0;
}

struct ListModelsArgs {
  ServerFlags server;
  client::ModelFilter filter;
};

int RunModelsList(const ListModelsArgs& args, RecognitionClient& client) {
  auto models = client.ListModels(args.filter);
  if (!models.ok()) return Fail("models list", models.status());
  if (args.server.json) {
    json out = json::array();
    for (const pb::ModelInfo& model : *models) out.push_back(ModelJson(model));
    std::printf("%s\n", out.dump(2).c_str());
    return 0;
  }
  std::printf("%-32s %7s %-16s %-7s %8s %10s  %s\n", "NAME", "VERSION", "CLASS", "TYPE", "POINTS",
              "BYTES", "TAGS");
  for (const pb::ModelInfo& model : *models) {
    std::string tags;
    for (const std::string& tag : model.tags()) tags += (tags.empty() ? "" : ",") + tag;
    std::printf("%-32s %7u %-16s %-7s %8u %10llu  %s\n", model.name().c_str(), model.version(),
                model.object_class().c_str(), TypeLabel(model.type()).c_str(), model.num_points(),
                (unsigned long long)model.size_bytes(), tags.c_str());
  }
  return 0;
}

struct WatchArgs {
  ServerFlags server;
  std::string prefix;
  size_t count = 0;
};

// Prints every change until --count changes were seen (0: until the stream ends or the process
// is interrupted).
int RunModelsWatch(const WatchArgs& args, RecognitionClient& client) {
  std::mutex mutex;
  std::condition_variable changed;
  size_t seen = 0;
  bool ended = false;
  const auto on_change = [&](const pb::WatchModelsResponse& event) {
    std::lock_guard lock(mutex);
    if (args.count > 0 && seen >= args.count) return;
    const std::string change = EnumLabel(pb::ModelChange_Name(event.change()), "MODEL_CHANGE_");
    if (args.server.json) {
      std::printf("%s\n", json({{"change", change},
                                {"sequence", event.sequence()},
                                {"model", ModelJson(event.model())}})
                              .dump()
                              .c_str());
    } else {
      std::printf("%s %s\n", change.c_str(), ModelLine(event.model()).c_str());
    }
    std::fflush(stdout);
    ++seen;
    changed.notify_all();
  };
  std::unique_ptr<client::ModelWatch> watch = client.WatchModels(args.prefix, on_change);
  grpc::Status end;
  std::thread waiter([&] {
    end = watch->Wait();
    std::lock_guard lock(mutex);
    ended = true;
    changed.notify_all();
  });
  bool enough = false;
  {
    std::unique_lock lock(mutex);
    changed.wait(lock, [&] { return ended || (args.count > 0 && seen >= args.count); });
    enough = args.count > 0 && seen >= args.count;
  }
  if (enough) watch->Cancel();
  waiter.join();
  return enough ? 0 : Fail("models watch", end);
}

}  // namespace

void AddServerCommands(CLI::App& app, int* exit_code) {
  // Adds the server flags to `command` and runs `run` with a connected client when it is used.
  const auto connect = [exit_code](CLI::App* command, ServerFlags* flags, auto run) {
    flags->AddTo(command);
    const CLI::App* parent = command->get_parent();
    const std::string name = parent->get_parent() == nullptr
                                 ? command->get_name()
                                 : parent->get_name() + " " + command->get_name();
    command->callback(
        [exit_code, flags, name, run] { *exit_code = WithClient(name.c_str(), *flags, run); });
  };

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
  stream
      ->add_option("--images", stream_args->images,
                   "Folder of frames, a list file, a video, or camera:N for the live camera "
                   "/dev/videoN")
      ->required();
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
  stream->add_option("--draw", stream_args->draw,
                     "Folder for a PNG per loop (loop_<frame>_<match>.png): both frames side by "
                     "side with the inlier count");
  stream->add_flag("--timestamps", stream_args->timestamps,
                   "Stamp each frame with this machine's clock when it is sent (the map's "
                   "recent_seconds then applies instead of recent_frames)");
  stream->add_flag("-q,--quiet", stream_args->quiet, "No progress output");
  connect(stream, &stream_args->server,
          [stream_args](RecognitionClient& client) { return RunStream(*stream_args, client); });

  auto query_args = std::make_shared<QueryArgs>();
  CLI::App* query = app.add_subcommand(
      "query", "Look one image up in a map of recogd (relocalisation, unless --add)");
  query->add_option("--map", query_args->map, "Map name")->required();
  query->add_option("image", query_args->image, "Image file")->required();
  query->add_flag("--add", query_args->add,
                  "Run the map's loop detector and keep the frame, as a streamed frame");
  query->add_option("--camera", query_args->camera,
                    "fx,fy,cx,cy[,k1,k2,p1,p2[,k3]]: also report the relative pose of a loop");
  connect(query, &query_args->server,
          [query_args](RecognitionClient& client) { return RunQuery(*query_args, client); });

  CLI::App* maps = app.add_subcommand("maps", "Manage the place maps of recogd");
  maps->require_subcommand(1);
  auto list_flags = std::make_shared<ServerFlags>();
  connect(maps->add_subcommand("list", "List the maps"), list_flags.get(),
          [list_flags](RecognitionClient& client) { return RunMapsList(*list_flags, client); });

  struct CreateMapArgs {
    ServerFlags server;
    std::string name;
    pb::MapSettings settings;  // only the options given are set
  };
  auto create_args = std::make_shared<CreateMapArgs>();
  CLI::App* create =
      maps->add_subcommand("create", "Create an empty map; unset settings take the server's");
  create->add_option("name", create_args->name, "Map name (1-128 of A-Z a-z 0-9 . _ -)")
      ->required();
  pb::MapSettings* settings = &create_args->settings;
  create->add_option_function<double>(
      "--alpha", [settings](const double& v) { settings->set_alpha(v); },
      "Minimum normalised score (server default 0.3)");
  create->add_option_function<uint32_t>(
      "--temporal-matches", [settings](const uint32_t& v) { settings->set_temporal_matches(v); },
      "Consistent previous queries required (3)");
  create->add_option_function<uint32_t>(
      "--min-inliers", [settings](const uint32_t& v) { settings->set_min_inliers(v); },
      "RANSAC inliers of a loop, >= 8 (12)");
  create
      ->add_option_function<std::string>(
          "--geometry",
          [settings](const std::string& v) {
            pb::GeometryCheck geometry = pb::GEOMETRY_CHECK_UNSPECIFIED;
            std::string name = "GEOMETRY_CHECK_" + v;
            std::transform(name.begin(), name.end(), name.begin(),
                           [](unsigned char c) { return char(std::toupper(c)); });
            pb::GeometryCheck_Parse(name, &geometry);
            settings->set_geometry(geometry);
          },
          "How loops are verified (direct_index)")
      ->check(CLI::IsMember({"direct_index", "exhaustive", "none"}));
  create->add_option_function<double>(
      "--recent-seconds", [settings](const double& v) { settings->set_recent_seconds(v); },
      "Recent frames left out of queries, in seconds, for timestamped frames (20)");
  create->add_option_function<uint32_t>(
      "--recent-frames", [settings](const uint32_t& v) { settings->set_recent_frames(v); },
      "Recent frames left out of queries, for frames without timestamps (20)");
  connect(create, &create_args->server, [create_args](RecognitionClient& client) {
    auto map = client.CreateMap(create_args->name, create_args->settings);
    if (!map.ok()) return Fail("maps create", map.status());
    PrintMap(create_args->server, *map);
    return 0;
  });

  struct NamedArgs {
    ServerFlags server;
    std::string name;
  };
  auto delete_args = std::make_shared<NamedArgs>();
  CLI::App* delete_map = maps->add_subcommand("delete", "Delete a map and its frames");
  delete_map->add_option("name", delete_args->name, "Map name")->required();
  connect(delete_map, &delete_args->server, [delete_args](RecognitionClient& client) {
    auto frames = client.DeleteMap(delete_args->name);
    if (!frames.ok()) return Fail("maps delete", frames.status());
    if (delete_args->server.json) {
      std::printf("%s\n",
                  json({{"name", delete_args->name}, {"frames_deleted", *frames}}).dump(2).c_str());
    } else {
      std::printf("deleted map %s (%llu frame%s)\n", delete_args->name.c_str(),
                  (unsigned long long)*frames, *frames == 1 ? "" : "s");
    }
    return 0;
  });

  auto stats_args = std::make_shared<NamedArgs>();
  CLI::App* stats = maps->add_subcommand("stats", "Describe a map: frames, settings, vocabulary");
  stats->add_option("name", stats_args->name, "Map name")->required();
  connect(stats, &stats_args->server, [stats_args](RecognitionClient& client) {
    auto map = client.GetMap(stats_args->name);
    if (!map.ok()) return Fail("maps stats", map.status());
    PrintMap(stats_args->server, *map);
    return 0;
  });

  CLI::App* models = app.add_subcommand("models", "Manage the object model repository of recogd");
  models->require_subcommand(1);
  auto push_args = std::make_shared<PushArgs>();
  CLI::App* push = models->add_subcommand(
      "push",
      "Upload models as new versions: a .robj file, a RoboEarth model folder (converted "
      "here), or a folder of those");
  push->add_option("path", push_args->path, "Model file, RoboEarth folder, or folder of them")
      ->required();
  push->add_option("--name", push_args->name,
                   "Name to store the model under (default: the name inside the model)");
  push->add_option("--tag", push_args->tags, "Label of the uploaded versions (repeatable)");
  push->add_option("--vocab", push_args->vocabulary,
                   "Vocabulary for RoboEarth folders (default: the bundled object one)");
  connect(push, &push_args->server,
          [push_args](RecognitionClient& client) { return RunModelsPush(*push_args, client); });

  auto pull_args = std::make_shared<PullArgs>();
  CLI::App* pull = models->add_subcommand("pull", "Download a version of a model (verified)");
  pull->add_option("name", pull_args->name, "Model name")->required();
  pull->add_option("--version", pull_args->version, "Version (0: the latest)")
      ->capture_default_str();
  pull->add_option("-o,--output", pull_args->output, "File to write")->required();
  connect(pull, &pull_args->server,
          [pull_args](RecognitionClient& client) { return RunModelsPull(*pull_args, client); });

  auto list_args = std::make_shared<ListModelsArgs>();
  CLI::App* list = models->add_subcommand("list", "List the latest version of every model");
  list->add_option("--prefix", list_args->filter.name_prefix, "Only names starting with this");
  list->add_option("--class", list_args->filter.object_class, "Only this object class");
  list->add_option("--tag", list_args->filter.tag, "Only models with this tag");
  connect(list, &list_args->server,
          [list_args](RecognitionClient& client) { return RunModelsList(*list_args, client); });

  auto delete_model_args = std::make_shared<NamedArgs>();
  CLI::App* delete_model = models->add_subcommand("delete", "Delete every version of a model");
  delete_model->add_option("name", delete_model_args->name, "Model name")->required();
  connect(delete_model, &delete_model_args->server, [delete_model_args](RecognitionClient& client) {
    auto versions = client.DeleteModel(delete_model_args->name);
    if (!versions.ok()) return Fail("models delete", versions.status());
    if (delete_model_args->server.json) {
      std::printf("%s\n", json({{"name", delete_model_args->name}, {"versions_deleted", *versions}})
                              .dump(2)
                              .c_str());
    } else {
      std::printf("deleted model %s (%u version%s)\n", delete_model_args->name.c_str(), *versions,
                  *versions == 1 ? "" : "s");
    }
    return 0;
  });

  auto watch_args = std::make_shared<WatchArgs>();
  CLI::App* watch = models->add_subcommand(
      "watch", "Print every upload and deletion from now on (JSON: one object per line)");
  watch->add_option("--prefix", watch_args->prefix, "Only models whose names start with this");
  watch->add_option("--count", watch_args->count, "Stop after this many changes (0: never)")
      ->capture_default_str();
  connect(watch, &watch_args->server,
          [watch_args](RecognitionClient& client) { return RunModelsWatch(*watch_args, client); });

  CLI::App* admin = app.add_subcommand("admin", "Operate recogd: health, backups");
  admin->require_subcommand(1);
  auto health_flags = std::make_shared<ServerFlags>();
  CLI::App* health = admin->add_subcommand(
      "health", "Ask the server's gRPC health service; exit 0 when SERVING, 1 otherwise");
  health->add_option("--timeout-ms", health_flags->timeout_ms, "How long to wait for the answer")
      ->capture_default_str();
  connect(health, health_flags.get(),
          [health_flags](RecognitionClient& client) { return RunHealth(*health_flags, client); });

  auto checkpoint_args = std::make_shared<CheckpointArgs>();
  CLI::App* checkpoint = admin->add_subcommand(
      "checkpoint",
      "Copy the server's whole store (maps, frames, models) to a new folder here, "
      "online; `recog admin restore` puts it in place for a new server");
  checkpoint->add_option("--to", checkpoint_args->to, "The new folder")->required();
  checkpoint->add_flag("-q,--quiet", checkpoint_args->quiet, "No progress output");
  connect(checkpoint, &checkpoint_args->server, [checkpoint_args](RecognitionClient& client) {
    return RunCheckpoint(*checkpoint_args, client);
  });

  auto restore_args = std::make_shared<RestoreArgs>();
  CLI::App* restore =
      admin->add_subcommand("restore",
                            "Offline: make a checkpoint the store of a data directory for recogd "
                            "(<data-dir>/store must not exist; the server must not run on it)");
  restore->add_option("--from", restore_args->from, "A folder written by `recog admin checkpoint`")
      ->required();
  restore->add_option("--data-dir", restore_args->data_dir, "recogd's --data-dir")->required();
  restore->callback([exit_code, restore_args] { *exit_code = RunRestore(*restore_args); });
}

}  // namespace recog::cli
