// Benchmark of repository replication: how fast a replica (server/replication/) gets the primary's
// models. Two in-process RecognitionServers on 127.0.0.1 (loopback TCP, fresh temporary data
// directories, no metrics endpoints): a primary, and a replica with repository.primary set.
// Not a Google Benchmark binary: the figures are times between events on two servers.
//
// The model: a planar poster built from tests/data/corridor/1.jpg with the bundled object
// vocabulary (about 0.1 MB), uploaded under a new name each time (the primary re-encodes it with
// that name, so every stored file differs).
//
// Phases:
//   sync    --models models (default 50) are uploaded to the primary, then the replica starts;
//           time from the replica's start (its store open, the follower started) until it lists
//           every model. Reported as models/s and MB/s.
//   follow  with the replica synced, --uploads uploads (default 30) to the primary one after the
//           other; lag of each = from the primary's PutModel answer to the replica's own
//           WatchModels event for that version (stored and recognisable there). p50/p90/max.
//
// Output: the figures on stdout, and one JSON line (also written to --json FILE).
// Run: build/bin/bench_replication [--models 50] [--uploads 30] [--json FILE]
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <spdlog/spdlog.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "bench/bench_support.h"
#include "client/cpp/recognition_client.h"
#include "core/common/elapsed.h"
#include "core/object/builder/model_builder.h"
#include "core/object/formats/model_file.h"
#include "core/vocabulary/vocabulary_io.h"
#include "server/app/recognition_server.h"
#include "tests/testing/data_paths.h"

namespace recog::bench {
namespace {

namespace pb = ::recognition::v1;
using Clock = std::chrono::steady_clock;

struct Options {
  int models = 50;
  int uploads = 30;
  std::string json_path;
};

StatusOr<std::string> PosterModelFile() {
  RECOG_ASSIGN_OR_RETURN(Vocabulary vocabulary, LoadVocabulary(DefaultObjectVocabularyPath()));
  ModelBuilder builder(std::make_shared<const Vocabulary>(std::move(vocabulary)));
  const cv::Mat image =
      cv::imread(testing::ProjectTestData("corridor/1.jpg"), cv::IMREAD_GRAYSCALE);
  if (image.empty()) return Status::NotFound("tests/data/corridor/1.jpg cannot be read");
  RECOG_ASSIGN_OR_RETURN(
      ObjectModel model,
      builder.FromFaceImages("poster", {{BoxSide::kFront, image}}, 0.64, 0.48, 0.0));
  return EncodeObjectModel(model);
}

StatusOr<std::unique_ptr<server::RecognitionServer>> StartServer(const std::string& data_dir,
                                                                 const std::string& primary) {
  server::ServerConfig config;
  config.listen = "127.0.0.1:0";
  config.data_dir = data_dir;
  config.metrics_listen = "";
  config.repository.primary = primary;
  return server::RecognitionServer::Start(config);
}

StatusOr<std::unique_ptr<client::RecognitionClient>> ClientOf(int port) {
  client::ClientOptions options;
  options.target = "127.0.0.1:" + std::to_string(port);
  client::Result<std::unique_ptr<client::RecognitionClient>> connected =
      client::RecognitionClient::Connect(options);
  if (!connected.ok()) return Status::Internal(connected.status().error_message());
  return std::move(*connected);
}

Status Upload(client::RecognitionClient& primary, const std::string& file,
              const std::string& name) {
  client::Result<pb::ModelInfo> uploaded = primary.UploadModel(file, name);
  if (!uploaded.ok()) {
    return Status::Internal("upload of " + name + ": " + uploaded.status().error_message());
  }
  return Status::Ok();
}

int Run(const Options& options) {
  auto fail = [](const Status& status) {
    std::fprintf(stderr, "bench_replication: %s\n", status.ToString().c_str());
    return 1;
  };
  spdlog::set_level(spdlog::level::warn);
  const std::filesystem::path dir = TempPath("bench_replication");
  StatusOr<std::string> file = PosterModelFile();
  if (!file.ok()) return fail(file.status());
  const double file_mb = double(file->size()) / 1e6;

  auto primary_server = StartServer((dir / "primary").string(), "");
  if (!primary_server.ok()) return fail(primary_server.status());
  auto primary = ClientOf((*primary_server)->port());
  if (!primary.ok()) return fail(primary.status());
  for (int i = 0; i < options.models; ++i) {
    if (Status s = Upload(**primary, *file, "poster-" + std::to_string(i)); !s.ok()) return fail(s);
  }

  // sync: the replica starts and copies every model.
  const std::string primary_address = "127.0.0.1:" + std::to_string((*primary_server)->port());
  const Clock::time_point start = Clock::now();
  auto replica_server = StartServer((dir / "replica").string(), primary_address);
  if (!replica_server.ok()) return fail(replica_server.status());
  auto replica = ClientOf((*replica_server)->port());
  if (!replica.ok()) return fail(replica.status());
  while (true) {
    client::Result<std::vector<pb::ModelInfo>> listed = (*replica)->ListModels();
    if (listed.ok() && int(listed->size()) == options.models) break;
    if (MillisecondsSince(start) > 600000)
      return fail(Status::Unavailable("the replica did not sync"));
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  const double sync_ms = MillisecondsSince(start);

  // follow: the lag of each upload, seen by a watcher of the replica's repository.
  std::mutex mutex;
  std::condition_variable arrived;
  std::map<std::string, Clock::time_point> seen;  // name -> when the replica told of it
  auto watch = (*replica)->WatchModels("lag-", [&](const pb::WatchModelsResponse& event) {
    std::lock_guard lock(mutex);
    seen.emplace(event.model().name(), Clock::now());
    arrived.notify_all();
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the watch registers
  std::vector<double> lags_ms;
  for (int i = 0; i < options.uploads; ++i) {
    const std::string name = "lag-" + std::to_string(i);
    if (Status s = Upload(**primary, *file, name); !s.ok()) return fail(s);
    const Clock::time_point acknowledged = Clock::now();
    std::unique_lock lock(mutex);
    if (!arrived.wait_for(lock, std::chrono::seconds(60), [&] { return seen.contains(name); })) {
      return fail(Status::Unavailable("the replica did not follow " + name));
    }
    lags_ms.push_back(std::max(
        0.0, std::chrono::duration<double, std::milli>(seen[name] - acknowledged).count()));
  }
  watch.reset();
  std::sort(lags_ms.begin(), lags_ms.end());

  std::printf(
      "bench_replication: primary and replica in this process on 127.0.0.1, %u hardware threads\n"
      "model file %.2f MB\n"
      "sync:   %d models (%.1f MB) copied in %.0f ms from the replica's start: %.1f models/s, "
      "%.1f MB/s\n"
      "follow: %d uploads, lag from the primary's answer to the replica's event: p50 %.1f ms, "
      "p90 %.1f ms, max %.1f ms\n",
      std::thread::hardware_concurrency(), file_mb, options.models, options.models * file_mb,
      sync_ms, options.models / (sync_ms / 1000), options.models * file_mb / (sync_ms / 1000),
      options.uploads, Percentile(lags_ms, 50), Percentile(lags_ms, 90), Percentile(lags_ms, 100));
  const nlohmann::json report = {{"model_file_bytes", file->size()},
                                 {"sync", {{"models", options.models}, {"ms", sync_ms}}},
                                 {"follow",
                                  {{"uploads", options.uploads},
                                   {"lag_ms",
                                    {{"p50", Percentile(lags_ms, 50)},
                                     {"p90", Percentile(lags_ms, 90)},
                                     {"max", Percentile(lags_ms, 100)}}}}}};
  std::printf("%s\n", report.dump().c_str());
  if (!options.json_path.empty()) std::ofstream(options.json_path) << report.dump() << "\n";

  replica_server->reset();
  primary_server->reset();
  std::error_code error;
  std::filesystem::remove_all(dir, error);
  return 0;
}

}  // namespace
}  // namespace recog::bench

int main(int argc, char** argv) {
  recog::bench::Options options;
  CLI::App app("Repository replication: initial sync and follow lag of a replica");
  app.add_option("--models", options.models, "Models on the primary before the replica starts")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  app.add_option("--uploads", options.uploads, "Uploads whose follow lag is measured")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  app.add_option("--json", options.json_path, "Also write the JSON line to this file");
  CLI11_PARSE(app, argc, argv);
  return recog::bench::Run(options);
}
