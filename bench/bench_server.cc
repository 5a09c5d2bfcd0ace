// Load benchmark of recogd: an in-process RecognitionServer (listening on 127.0.0.1, a fresh
// temporary data_dir but for the million scenario's, no metrics endpoint, the default number of
// workers) driven over real loopback TCP connections with the generated PlaceRecognition stubs,
// as robots would drive it.
// Not a Google Benchmark binary: the scenarios are multi-stream loads with their own figures.
//
// Scenarios (--scenarios, comma-separated; default all but million), each against its own fresh
// server:
//   corridor   one robot streams the corridor sequence once (84 JPEG files of 512x384, sent as
//              they are, in natural order) through StreamFrames, one frame in flight (write,
//              read, write, read). Latency = Write of a frame to Read of its answer.
//              Target: p50 <= 20 ms.
//   streams8   --streams robots (default 8), each over its own TCP connection into its own map,
//              each streaming --frames frames (default 150) of 640x480 JPEG (the corridor frames
//              resized, encoded once at quality 90, repeated in order), one frame in flight.
//              Aggregate frames/s = frames answered / wall time. Targets: >= 60 frames/s,
//              p99 <= 150 ms.
//   features8  the same streams sending features extracted on the client instead (Frame.features:
//              ORB, 1000 features at most, extracted from those 640x480 frames before the run).
//              Target: >= 400 queries/s.
//   flood      one stream whose writer sends --flood-frames 640x480 JPEG frames (default 400) as
//              fast as it can while another thread reads the answers: checks that every frame is
//              answered, in order, and samples VmRSS every 50 ms. The server reads a frame only
//              after answering the previous one, so memory should stay bounded by the HTTP/2 flow
//              control windows. Client and server share the process: the RSS figures cover both.
//   million  not run by default (it builds a map of --million-entries frames first: about 8
//            minutes and 5.2 GB of disk for 1,000,000): one robot streams the corridor's features
//            (as features8 sends them, one frame in flight) into a map that already holds that
//            many frames. The map is bench_database's real-statistics entries (bags of words of
//            the shared Caltech photos and random 60-100 % subsets of their features, seed 5),
//            each with 50 placeholder features (with --million-real-features, the real features
//            of that subset instead: keypoints, descriptors and direct index, as a map of real
//            frames stores them; about 11 minutes and 42 GB of disk for 1,000,000), written into
//            a RocksDB store with its index snapshot; the store's size per frame is reported; the
//            server is then started on that store (start-up time reported) and the stream's
//            latency and the server's recognition time per frame (the whole loop pipeline,
//            features given) are measured. Target: recognition median <= 20 ms.
//            --million-store DIR keeps the store there and reuses it on the next run (each run
//            adds the corridor's frames to it); without it, a temporary one is removed after.
// Every scenario also reports the medians of the server's own Timing (decode, features,
// recognition, queue). The client threads compete with the server's
// workers for the same cores, which the output notes.
//
// Output: a table on stdout, then one JSON line with every figure (also written to --json FILE).
// Needs the shared corridor images: $RECOG_SHARED_DATA/places/corridor/images (RECOG_SHARED_DATA
// defaults to ../shared/data next to the project root), or --images DIR.
//
// Run: build/bin/bench_server [--scenarios corridor,flood] [--streams 8] [--frames 150]
//        [--flood-frames 400] [--workers 0] [--json FILE] [--log-level warn]
//      build/bin/bench_server --scenarios million [--million-entries 1000000]
//        [--million-store DIR] [--million-real-features]
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <latch>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <spdlog/spdlog.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "bench/bench_support.h"
#include "client/cpp/frames.h"
#include "core/common/median.h"
#include "core/features/feature_extractor.h"
#include "core/place/map_registry.h"
#include "recognition/v1/place.grpc.pb.h"
#include "server/app/recognition_server.h"
#include "storage/rocksdb_index_store.h"
#include "tests/testing/data_paths.h"
#include "tools/common/cli_support.h"

namespace recog::bench {
namespace {

namespace pb = ::recognition::v1;
using Clock = std::chrono::steady_clock;
using nlohmann::json;

constexpr int kWidth = 640;
constexpr int kHeight = 480;
constexpr int kJpegQuality = 90;

struct Options {
  std::vector<std::string> scenarios = {"corridor", "streams8", "features8", "flood"};
  std::string images = testing::SharedData("places/corridor/images");
  int streams = 8;
  int frames = 150;
  int flood_frames = 400;
  uint32_t workers = 0;
  std::string json_file;
  std::string log_level = "warn";
  bool console = false;          // the servers run the web console (console.listen)
  bool keep_thumbnails = false;  // the scenarios' maps keep a thumbnail of each frame
  size_t million_entries = 1'000'000;
  std::string million_store;           // empty: a temporary one
  bool million_real_features = false;  // the million map's frames store their real features
};

double MsBetween(Clock::time_point from, Clock::time_point to) {
  return std::chrono::duration<double, std::milli>(to - from).count();
}

// VmRSS of this process in MiB (client and server together), 0 when unreadable.
double CurrentRssMiB() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) / 1024;
  }
  return 0;
}

// What one or more robot streams saw: per-frame latencies and the server's own timings.
struct StreamStats {
  std::vector<double> latency_ms;
  std::vector<double> decode_ms, features_ms, recognition_ms, queue_ms;
  uint64_t loops = 0;
  uint64_t errors = 0;  // frames answered with a FrameError

  void Record(const pb::StreamFramesResponse& response) {
    decode_ms.push_back(response.timing().decode_ms());
    features_ms.push_back(response.timing().features_ms());
    recognition_ms.push_back(response.timing().recognition_ms());
    queue_ms.push_back(response.timing().queue_ms());
    if (response.has_error()) ++errors;
    if (response.has_result() && response.result().status() == pb::LOOP_STATUS_LOOP_DETECTED) {
      ++loops;
    }
  }

  void Merge(const StreamStats& other) {
    auto append = [](std::vector<double>& to, const std::vector<double>& from) {
      to.insert(to.end(), from.begin(), from.end());
    };
    append(latency_ms, other.latency_ms);
    append(decode_ms, other.decode_ms);
    append(features_ms, other.features_ms);
    append(recognition_ms, other.recognition_ms);
    append(queue_ms, other.queue_ms);
    loops += other.loops;
    errors += other.errors;
  }
};

// One scenario's figures, as printed and as put in the JSON line.
struct LoadResult {
  std::string name;
  int streams = 0;
  double wall_s = 0;
  StreamStats stats;
  std::string target;  // e.g. "p50 <= 20 ms"
  bool target_met = false;

  double FramesPerSecond() const { return double(stats.latency_ms.size()) / wall_s; }
  double LatencyPercentile(double p) const {
    std::vector<double> sorted = stats.latency_ms;
    std::sort(sorted.begin(), sorted.end());
    return Percentile(sorted, p);
  }

  json ToJson() const {
    return {{"streams", streams},
            {"frames", stats.latency_ms.size()},
            {"wall_s", wall_s},
            {"frames_per_s", FramesPerSecond()},
            {"latency_ms",
             {{"p50", LatencyPercentile(50)},
              {"p90", LatencyPercentile(90)},
              {"p99", LatencyPercentile(99)},
              {"max", LatencyPercentile(100)}}},
            {"server_median_ms",
             {{"decode", Median(stats.decode_ms)},
              {"features", Median(stats.features_ms)},
              {"recognition", Median(stats.recognition_ms)},
              {"queue", Median(stats.queue_ms)}}},
            {"loops", stats.loops},
            {"frame_errors", stats.errors},
            {"target", target},
            {"target_met", target_met}};
  }
};

struct FloodResult {
  int frames_sent = 0;
  int frames_answered = 0;
  bool in_order = true;  // every answer had the next sequence number and no error
  int max_ahead = 0;     // most frames written and not yet answered at one time
  double wall_s = 0;
  double rss_start_mib = 0;
  double rss_peak_mib = 0;

  json ToJson() const {
    return {{"frames_sent", frames_sent},
            {"frames_answered", frames_answered},
            {"all_answered_in_order", in_order && frames_answered == frames_sent},
            {"max_frames_ahead", max_ahead},
            {"wall_s", wall_s},
            {"frames_per_s", frames_answered / wall_s},
            {"rss_start_mib", rss_start_mib},
            {"rss_peak_mib", rss_peak_mib},
            {"rss_growth_mib", rss_peak_mib - rss_start_mib}};
  }
};

// A RecognitionServer on 127.0.0.1 with a fresh data_dir, removed again with the server.
class ScopedServer {
 public:
  // On `data_dir` as it is when given (and left there), else on a fresh temporary one.
  static StatusOr<std::unique_ptr<ScopedServer>> Start(const std::string& name,
                                                       const Options& options,
                                                       const std::string& data_dir = "") {
    server::ServerConfig config;
    config.listen = "127.0.0.1:0";
    config.data_dir = data_dir.empty() ? TempPath("server_" + name) : data_dir;
    config.metrics_listen = "";
    config.workers = options.workers;
    if (options.console) config.console.listen = "127.0.0.1:0";
    if (data_dir.empty()) std::filesystem::remove_all(config.data_dir);
    std::unique_ptr<ScopedServer> scoped(
        new ScopedServer(data_dir.empty() ? config.data_dir : std::string()));
    RECOG_ASSIGN_OR_RETURN(scoped->server_, server::RecognitionServer::Start(config));
    return scoped;
  }
  ~ScopedServer() {
    if (server_ != nullptr) server_->Shutdown(std::chrono::seconds(1));
    server_.reset();
    if (!data_dir_.empty()) std::filesystem::remove_all(data_dir_);
  }
  ScopedServer(const ScopedServer&) = delete;
  ScopedServer& operator=(const ScopedServer&) = delete;

  // A channel on a TCP connection of its own (a local subchannel pool keeps channels with the
  // same arguments from sharing one connection), connected before it is returned.
  StatusOr<std::shared_ptr<grpc::Channel>> Connect() const {
    grpc::ChannelArguments args;
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
    auto channel = grpc::CreateCustomChannel("127.0.0.1:" + std::to_string(server_->port()),
                                             grpc::InsecureChannelCredentials(), args);
    if (!channel->WaitForConnected(std::chrono::system_clock::now() + std::chrono::seconds(10))) {
      return Status::Unavailable("cannot connect to the server on port " +
                                 std::to_string(server_->port()));
    }
    return channel;
  }

 private:
  explicit ScopedServer(std::string data_dir) : data_dir_(std::move(data_dir)) {}

  std::string data_dir_;  // removed with the server; empty: nothing to remove
  std::unique_ptr<server::RecognitionServer> server_;
};

Status FromGrpc(const grpc::Status& status, const std::string& what) {
  return Status::Internal(what + ": gRPC code " + std::to_string(int(status.error_code())) + ", " +
                          status.error_message());
}

StatusOr<std::string> ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::NotFound("cannot read '" + path + "'");
  return std::string(std::istreambuf_iterator<char>(in), {});
}

pb::StreamFramesRequest EncodedFrameRequest(std::string bytes) {
  pb::StreamFramesRequest request;
  request.mutable_frame()->set_encoded_image(std::move(bytes));
  return request;
}

// The frame a robot extracting its own features sends.
StatusOr<pb::StreamFramesRequest> FeaturesFrameRequest(const FeatureSet& features) {
  client::Result<pb::Frame> frame =
      client::FrameFromFeatures(features.keypoints, features.descriptors, {kWidth, kHeight});
  if (!frame.ok()) return Status::InvalidArgument(frame.status().error_message());
  pb::StreamFramesRequest request;
  *request.mutable_frame() = std::move(frame).value();
  return request;
}

// The frames every scenario sends, prepared before any is run.
struct Frames {
  std::vector<pb::StreamFramesRequest> corridor;  // the files as they are
  std::vector<pb::StreamFramesRequest> jpeg640;   // resized to 640x480, JPEG quality 90
  std::vector<pb::StreamFramesRequest> features;  // ORB features of the 640x480 frames
  cv::Size original_size;
};

StatusOr<Frames> PrepareFrames(const std::string& dir) {
  RECOG_ASSIGN_OR_RETURN(std::vector<std::string> files, cli::ListImages(dir));
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<FeatureExtractor> extractor,
                         CreateFeatureExtractor(PlaceFeatureOptions()));
  Frames frames;
  FeatureSet features;
  for (const std::string& file : files) {
    RECOG_ASSIGN_OR_RETURN(std::string bytes, ReadFileBytes(file));
    const cv::Mat image =
        cv::imdecode(cv::Mat(1, int(bytes.size()), CV_8UC1, bytes.data()), cv::IMREAD_COLOR);
    if (image.empty()) return Status::InvalidArgument("'" + file + "' is not a decodable image");
    frames.original_size = image.size();
    cv::Mat resized;
    cv::resize(image, resized, cv::Size(kWidth, kHeight), 0, 0, cv::INTER_LINEAR);
    std::vector<uint8_t> jpeg;
    cv::imencode(".jpg", resized, jpeg, {cv::IMWRITE_JPEG_QUALITY, kJpegQuality});
    // Features of what the server would see: the grey decoding of the JPEG that is sent.
    RECOG_RETURN_IF_ERROR(extractor->Extract(cv::imdecode(jpeg, cv::IMREAD_GRAYSCALE), &features));
    frames.corridor.push_back(EncodedFrameRequest(std::move(bytes)));
    frames.jpeg640.push_back(EncodedFrameRequest(std::string(jpeg.begin(), jpeg.end())));
    RECOG_ASSIGN_OR_RETURN(pb::StreamFramesRequest request, FeaturesFrameRequest(features));
    frames.features.push_back(std::move(request));
  }
  return frames;
}

StatusOr<
    std::unique_ptr<grpc::ClientReaderWriter<pb::StreamFramesRequest, pb::StreamFramesResponse>>>
OpenStream(pb::PlaceRecognition::Stub& stub, grpc::ClientContext* context, const std::string& map,
           const Options& options) {
  auto stream = stub.StreamFrames(context);
  pb::StreamFramesRequest config;
  config.mutable_config()->set_map(map);
  config.mutable_config()->set_create_if_missing(true);
  if (options.keep_thumbnails)
    config.mutable_config()->mutable_settings()->set_keep_thumbnails(true);
  if (!stream->Write(config)) return FromGrpc(stream->Finish(), "StreamFrames config of " + map);
  return stream;
}

// One robot: `count` frames (cycling through `frames`) into `map`, one in flight at a time.
StatusOr<StreamStats> RunRobot(const std::shared_ptr<grpc::Channel>& channel,
                               const std::string& map, const Options& options,
                               const std::vector<pb::StreamFramesRequest>& frames, int count) {
  auto stub = pb::PlaceRecognition::NewStub(channel);
  grpc::ClientContext context;
  RECOG_ASSIGN_OR_RETURN(auto stream, OpenStream(*stub, &context, map, options));
  StreamStats stats;
  pb::StreamFramesResponse response;
  for (int i = 0; i < count; ++i) {
    const auto start = Clock::now();
    if (!stream->Write(frames[size_t(i) % frames.size()]) || !stream->Read(&response)) {
      return FromGrpc(stream->Finish(), map + " ended at frame " + std::to_string(i));
    }
    stats.latency_ms.push_back(MsBetween(start, Clock::now()));
    stats.Record(response);
  }
  stream->WritesDone();
  const grpc::Status status = stream->Finish();
  if (!status.ok()) return FromGrpc(status, map + " did not finish");
  return stats;
}

// `streams` robots at once, each on its own connection into its own map.
StatusOr<LoadResult> RunRobots(const std::string& name, const Options& options, int streams,
                               int frames_each,
                               const std::vector<pb::StreamFramesRequest>& frames) {
  RECOG_ASSIGN_OR_RETURN(auto server, ScopedServer::Start(name, options));
  std::vector<std::shared_ptr<grpc::Channel>> channels;
  for (int s = 0; s < streams; ++s) {
    RECOG_ASSIGN_OR_RETURN(auto channel, server->Connect());
    channels.push_back(std::move(channel));
  }
  std::vector<StatusOr<StreamStats>> results(size_t(streams), Status::Internal("not run"));
  std::latch go(streams + 1);
  std::vector<std::jthread> robots;
  for (int s = 0; s < streams; ++s) {
    robots.emplace_back([&, s] {
      go.arrive_and_wait();
      results[size_t(s)] = RunRobot(channels[size_t(s)], name + "-" + std::to_string(s), options,
                                    frames, frames_each);
    });
  }
  go.arrive_and_wait();
  const auto start = Clock::now();
  robots.clear();  // joins
  LoadResult result;
  result.name = name;
  result.streams = streams;
  result.wall_s = MsBetween(start, Clock::now()) / 1000;
  for (StatusOr<StreamStats>& stats : results) {
    if (!stats.ok()) return stats.status();
    result.stats.Merge(stats.value());
  }
  return result;
}

StatusOr<FloodResult> RunFlood(const Options& options,
                               const std::vector<pb::StreamFramesRequest>& frames) {
  RECOG_ASSIGN_OR_RETURN(auto server, ScopedServer::Start("flood", options));
  RECOG_ASSIGN_OR_RETURN(auto channel, server->Connect());
  auto stub = pb::PlaceRecognition::NewStub(channel);
  grpc::ClientContext context;
  RECOG_ASSIGN_OR_RETURN(auto stream, OpenStream(*stub, &context, "flood", options));

  FloodResult result;
  result.rss_start_mib = CurrentRssMiB();
  std::atomic<double> rss_peak{result.rss_start_mib};
  std::atomic<bool> done{false};
  std::atomic<int> written{0};
  std::jthread sampler([&] {
    while (!done.load()) {
      const double rss = CurrentRssMiB();
      if (rss > rss_peak.load()) rss_peak = rss;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  });
  const auto start = Clock::now();
  std::jthread writer([&] {
    for (int i = 0; i < options.flood_frames; ++i) {
      if (!stream->Write(frames[size_t(i) % frames.size()])) return;
      written = i + 1;
    }
    stream->WritesDone();
  });
  pb::StreamFramesResponse response;
  while (stream->Read(&response)) {
    if (response.sequence() != uint64_t(result.frames_answered) || response.has_error()) {
      result.in_order = false;
    }
    ++result.frames_answered;
    result.max_ahead = std::max(result.max_ahead, written.load() - result.frames_answered);
  }
  writer.join();
  result.wall_s = MsBetween(start, Clock::now()) / 1000;
  done = true;
  sampler.join();
  result.frames_sent = written.load();
  result.rss_peak_mib = rss_peak.load();
  const grpc::Status status = stream->Finish();
  if (!status.ok()) return FromGrpc(status, "the flood stream did not finish");
  return result;
}

// The million scenario's figures beside its stream's.
struct MillionResult {
  size_t entries_before = 0;  // frames in the map when the stream started
  double build_s = 0;         // building the map (0: reused)
  double start_s = 0;         // RecognitionServer::Start on the store, to serving
  double store_gb = 0;        // the store's files (its snapshots included) before the stream
  double snapshot_gb = 0;     // of which the index snapshots
  double rss_after_start_mib = 0;
  LoadResult stream;

  json ToJson() const {
    json j = stream.ToJson();
    j["map_frames_before"] = entries_before;
    j["map_build_s"] = build_s;
    j["server_start_s"] = start_s;
    j["store_GB"] = store_gb;
    j["snapshot_GB"] = snapshot_gb;
    j["store_KB_per_frame"] = StoreKbPerFrame();
    j["rss_after_start_mib"] = rss_after_start_mib;
    return j;
  }
  double StoreKbPerFrame() const {
    return store_gb * 1e6 / double(std::max<size_t>(entries_before, 1));
  }
};

constexpr char kMillionMap[] = "fleet";

// Makes sure the store under `data_dir` (as recogd lays it out) has the place map kMillionMap with
// at least `entries` frames of real word statistics, and its index snapshot; returns how many it
// holds. Added frames store their real features with `real_features`, else 50 placeholders (a
// kept store keeps those it was built with). *build_s receives the seconds spent adding frames
// (0 when none were needed).
StatusOr<size_t> PrepareMillionMap(const std::string& data_dir, size_t entries, bool real_features,
                                   double* build_s) {
  std::filesystem::create_directories(data_dir);
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<IndexStore> store,
                         OpenRocksDbIndexStore(data_dir + "/store", RocksDbStoreOptions{}));
  auto vocabulary = std::make_shared<const Vocabulary>(LoadBundledPlaceVocabulary());
  {
    // The map as recogd creates it (its settings, then its database).
    RECOG_ASSIGN_OR_RETURN(std::unique_ptr<MapRegistry> registry,
                           MapRegistry::Open(store.get(), vocabulary));
    if (!registry->Get(kMillionMap).ok()) {
      RECOG_RETURN_IF_ERROR(registry->Create(kMillionMap, LoopDetectorParams{}, "", {}).status());
    }
  }
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<Database> db,
                         Database::Open(store.get(), kMillionMap, vocabulary));
  *build_s = 0;
  if (db->size() >= entries) return db->size();
  const auto start = Clock::now();
  std::printf("million: extracting the photos' features ...\n");
  std::fflush(stdout);
  const std::vector<FeatureSet> photos = RealImageFeatures(5);
  std::vector<cv::Mat> descriptors;
  if (!real_features) {
    for (const FeatureSet& photo : photos) descriptors.push_back(photo.descriptors);
  }
  std::mt19937_64 rng(5);
  for (size_t size = 100'000; db->size() < entries; size += 100'000) {
    if (real_features) {
      GrowRealDatabase(*db, photos, std::min(size, entries), rng);
    } else {
      GrowRealDatabase(*db, descriptors, std::min(size, entries), rng, nullptr, 50);
    }
    std::printf("million: %zu of %zu frames in the map (%.0f s)\n", db->size(), entries,
                MsBetween(start, Clock::now()) / 1000);
    std::fflush(stdout);
  }
  RECOG_RETURN_IF_ERROR(db->SaveSnapshot().status());
  *build_s = MsBetween(start, Clock::now()) / 1000;
  return db->size();
}

StatusOr<MillionResult> RunMillion(const Options& options,
                                   const std::vector<pb::StreamFramesRequest>& frames) {
  const bool temporary = options.million_store.empty();
  const std::string data_dir = temporary ? TempPath("million") : options.million_store;
  MillionResult result;
  StatusOr<size_t> entries = PrepareMillionMap(data_dir, options.million_entries,
                                               options.million_real_features, &result.build_s);
  if (!entries.ok()) {
    if (temporary) std::filesystem::remove_all(data_dir);
    return entries.status();
  }
  result.entries_before = entries.value();
  result.store_gb = double(DirectoryBytes(data_dir)) / 1e9;
  result.snapshot_gb = double(DirectoryBytes(data_dir, data_dir + "/store/index-snapshots")) / 1e9;
  StatusOr<MillionResult> finished = [&]() -> StatusOr<MillionResult> {
    const auto start = Clock::now();
    RECOG_ASSIGN_OR_RETURN(auto server, ScopedServer::Start("million", options, data_dir));
    result.start_s = MsBetween(start, Clock::now()) / 1000;
    result.rss_after_start_mib = CurrentRssMiB();
    RECOG_ASSIGN_OR_RETURN(auto channel, server->Connect());
    const auto stream_start = Clock::now();
    RECOG_ASSIGN_OR_RETURN(result.stream.stats,
                           RunRobot(channel, kMillionMap, options, frames, int(frames.size())));
    result.stream.wall_s = MsBetween(stream_start, Clock::now()) / 1000;
    result.stream.name = "million";
    result.stream.streams = 1;
    result.stream.target = "recognition median <= 20 ms";
    result.stream.target_met = Median(result.stream.stats.recognition_ms) <= 20;
    return result;
  }();
  if (temporary) std::filesystem::remove_all(data_dir);
  return finished;
}

void PrintTable(const std::vector<LoadResult>& results) {
  std::printf("\n%-10s %7s %7s %7s %9s %7s %7s %7s %7s %6s %6s  %s\n", "scenario", "streams",
              "frames", "wall_s", "frames/s", "p50_ms", "p90_ms", "p99_ms", "max_ms", "loops",
              "errors", "target");
  for (const LoadResult& r : results) {
    std::printf("%-10s %7d %7zu %7.2f %9.1f %7.1f %7.1f %7.1f %7.1f %6llu %6llu  %s: %s\n",
                r.name.c_str(), r.streams, r.stats.latency_ms.size(), r.wall_s, r.FramesPerSecond(),
                r.LatencyPercentile(50), r.LatencyPercentile(90), r.LatencyPercentile(99),
                r.LatencyPercentile(100), static_cast<unsigned long long>(r.stats.loops),
                static_cast<unsigned long long>(r.stats.errors), r.target.c_str(),
                r.target_met ? "met" : "MISSED");
  }
  std::printf("\nserver-side medians per frame (ms, from the answers' Timing):\n");
  std::printf("%-10s %8s %9s %12s %8s\n", "scenario", "decode", "features", "recognition", "queue");
  for (const LoadResult& r : results) {
    std::printf("%-10s %8.2f %9.2f %12.2f %8.2f\n", r.name.c_str(), Median(r.stats.decode_ms),
                Median(r.stats.features_ms), Median(r.stats.recognition_ms),
                Median(r.stats.queue_ms));
  }
}

void PrintFlood(const FloodResult& f, int frames) {
  std::printf(
      "\nflood: %d of %d 640x480 JPEG frames answered in %.2f s (%.1f frames/s), %s; at most %d "
      "frames written ahead of their answer\n"
      "       VmRSS (client + server) %.1f MiB at the start, peak %.1f MiB, growth %.1f MiB\n",
      f.frames_answered, frames, f.wall_s, f.frames_answered / f.wall_s,
      f.in_order && f.frames_answered == f.frames_sent ? "all in order, no error"
                                                       : "NOT all answered in order",
      f.max_ahead, f.rss_start_mib, f.rss_peak_mib, f.rss_peak_mib - f.rss_start_mib);
}

int Run(const Options& options) {
  auto fail = [](const Status& status) {
    std::fprintf(stderr, "bench_server: %s\n", status.ToString().c_str());
    return 1;
  };
  auto selected = [&](const char* name) {
    return std::find(options.scenarios.begin(), options.scenarios.end(), name) !=
           options.scenarios.end();
  };
  server::ServerConfig defaults;
  defaults.workers = options.workers;
  const unsigned hardware_threads = std::thread::hardware_concurrency();
  std::printf(
      "bench_server: in-process recogd on 127.0.0.1 (TCP loopback), %u workers; %u hardware "
      "threads shared by the server and the client threads, so client work competes with the "
      "server for CPU\n",
      defaults.WorkerCount(), hardware_threads);
  std::printf("web console %s, maps %s thumbnails\n", options.console ? "on" : "off",
              options.keep_thumbnails ? "keep" : "keep no");

  std::printf("preparing frames from %s ...\n", options.images.c_str());
  StatusOr<Frames> frames = PrepareFrames(options.images);
  if (!frames.ok()) return fail(frames.status());
  double jpeg_bytes = 0, keypoints = 0;
  for (const pb::StreamFramesRequest& f : frames->jpeg640) {
    jpeg_bytes += double(f.frame().encoded_image().size());
  }
  for (const pb::StreamFramesRequest& f : frames->features) {
    keypoints += f.frame().features().keypoints().x_size();
  }
  const double n = double(frames->corridor.size());
  std::printf("%zu frames of %dx%d; as 640x480 JPEG %.1f KiB and %.0f ORB features on average\n",
              frames->corridor.size(), frames->original_size.width, frames->original_size.height,
              jpeg_bytes / n / 1024, keypoints / n);
  std::fflush(stdout);

  json report = {{"hardware_threads", hardware_threads}, {"workers", defaults.WorkerCount()}};
  std::vector<LoadResult> results;
  if (selected("corridor")) {
    StatusOr<LoadResult> r =
        RunRobots("corridor", options, 1, int(frames->corridor.size()), frames->corridor);
    if (!r.ok()) return fail(r.status());
    r->target = "p50 <= 20 ms";
    r->target_met = r->LatencyPercentile(50) <= 20;
    results.push_back(std::move(r).value());
  }
  if (selected("streams8")) {
    StatusOr<LoadResult> r =
        RunRobots("streams8", options, options.streams, options.frames, frames->jpeg640);
    if (!r.ok()) return fail(r.status());
    r->target = ">= 60 frames/s, p99 <= 150 ms";
    r->target_met = r->FramesPerSecond() >= 60 && r->LatencyPercentile(99) <= 150;
    results.push_back(std::move(r).value());
  }
  if (selected("features8")) {
    StatusOr<LoadResult> r =
        RunRobots("features8", options, options.streams, options.frames, frames->features);
    if (!r.ok()) return fail(r.status());
    r->target = ">= 400 queries/s";
    r->target_met = r->FramesPerSecond() >= 400;
    results.push_back(std::move(r).value());
  }
  if (selected("million")) {
    StatusOr<MillionResult> m = RunMillion(options, frames->features);
    if (!m.ok()) return fail(m.status());
    std::printf(
        "\nmillion: a map of %zu frames (%s), %.1f GB of store (%.1f KB per frame; %.1f GB of it "
        "the index snapshot); the server started in %.1f s, VmRSS then %.0f MiB (client + "
        "server)\n",
        m->entries_before,
        m->build_s > 0 ? ("built in " + std::to_string(int(m->build_s)) + " s").c_str() : "reused",
        m->store_gb, m->StoreKbPerFrame(), m->snapshot_gb, m->start_s, m->rss_after_start_mib);
    report["scenarios"]["million"] = m->ToJson();
    results.push_back(std::move(m->stream));
  }
  if (!results.empty()) PrintTable(results);
  for (const LoadResult& r : results) {
    if (r.name != "million") report["scenarios"][r.name] = r.ToJson();
  }
  if (selected("flood")) {
    StatusOr<FloodResult> flood = RunFlood(options, frames->jpeg640);
    if (!flood.ok()) return fail(flood.status());
    PrintFlood(flood.value(), options.flood_frames);
    report["scenarios"]["flood"] = flood->ToJson();
  }
  report["peak_rss_mib"] = cli::PeakRssMiB();
  std::printf("\npeak RSS of the process (getrusage): %.1f MiB\n", cli::PeakRssMiB());
  std::printf("%s\n", report.dump().c_str());
  if (!options.json_file.empty()) {
    std::ofstream out(options.json_file);
    out << report.dump(2) << "\n";
    if (!out) return fail(Status::Internal("cannot write '" + options.json_file + "'"));
  }
  return 0;
}

}  // namespace
}  // namespace recog::bench

int main(int argc, char** argv) {
  recog::bench::Options options;
  CLI::App app{"bench_server: load benchmark of recogd over loopback gRPC"};
  app.add_option("--scenarios", options.scenarios, "Scenarios to run")
      ->delimiter(',')
      ->check(CLI::IsMember({"corridor", "streams8", "features8", "flood", "million"}))
      ->capture_default_str();
  app.add_option("--images", options.images, "Folder of the corridor sequence")
      ->capture_default_str();
  app.add_option("--streams", options.streams, "Concurrent robots of streams8 and features8")
      ->check(CLI::Range(1, 256))
      ->capture_default_str();
  app.add_option("--frames", options.frames, "Frames per robot in streams8 and features8")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--flood-frames", options.flood_frames, "Frames sent by the flood scenario")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--workers", options.workers, "Server workers (0: one per hardware thread)")
      ->capture_default_str();
  app.add_option("--million-entries", options.million_entries,
                 "Frames of the million scenario's map before its stream")
      ->check(CLI::Range(size_t(1), size_t(1) << 31))
      ->capture_default_str();
  app.add_option("--million-store", options.million_store,
                 "Data directory of the million scenario, kept and reused (default: temporary)");
  app.add_flag("--million-real-features", options.million_real_features,
               "The million map's frames store the real features of their photo subsets (about "
               "42 GB of disk for a million) instead of 50 placeholder features each");
  app.add_option("--json", options.json_file, "Also write the JSON report to this file");
  app.add_option("--log-level", options.log_level, "Server log level (spdlog)")
      ->capture_default_str();
  app.add_flag("--console", options.console,
               "Run the servers with the web console on (loops recorded for it, live samples)");
  app.add_flag("--keep-thumbnails", options.keep_thumbnails,
               "The scenarios' maps keep a thumbnail of each frame (MapSettings.keep_thumbnails)");
  CLI11_PARSE(app, argc, argv);
  spdlog::set_level(spdlog::level::from_str(options.log_level));
  return recog::bench::Run(options);
}
