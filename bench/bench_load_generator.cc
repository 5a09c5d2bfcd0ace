// How fast `recog load` can generate load: the load generator (tools/load/load_generator.h)
// driving a trivial PlaceRecognition server, so that the generator, not the server, is the
// bottleneck. Not a Google Benchmark binary: one multi-robot run with its own figures.
//
// The trivial server runs in this process on 127.0.0.1 (gRPC callback API, its own threads): it
// creates and deletes maps without storing anything and answers every StreamFrames frame at once
// with an empty result, after gRPC has parsed it, as recogd's stream does before any recognition.
// The generator is the real one with the options of a `recog load` run: --robots robots (default
// 8), each sending --frames frames (default 3000) of ORB features extracted on the client from the
// corridor images (--features-on-client), --in-flight (default 4) frames ahead of their answers.
//
// Figures: frames/s (answers per second of the run's wall time: what the generator sustains on
// this machine, while the trivial server shares its cores), the CPU time of the whole process per
// frame (generator and trivial server), and, given --server-fps (the frames/s recogd answered in a
// real run, e.g. from `recog load` or bench_server's features8), the ratio of the two throughputs.
//
// Needs the corridor images: $RECOG_SHARED_DATA/places/corridor/images (default ../shared/data
// next to the project root), or --images DIR.
//
// Run: build/bin/bench_load_generator [--robots 8] [--frames 3000] [--in-flight 4]
//        [--server-fps F] [--json FILE]
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>

#include <grpcpp/grpcpp.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "recognition/v1/place.grpc.pb.h"
#include "tests/testing/data_paths.h"
#include "tools/load/load_generator.h"

namespace recog::bench {
namespace {

namespace pb = ::recognition::v1;

// StreamFrames: reads a frame, answers it, reads the next; the config message is not answered.
class AnsweringStream final
    : public grpc::ServerBidiReactor<pb::StreamFramesRequest, pb::StreamFramesResponse> {
 public:
  AnsweringStream() { StartRead(&request_); }

 private:
  void OnReadDone(bool ok) override {
    if (!ok) {
      Finish(grpc::Status::OK);
      return;
    }
    if (request_.has_config()) {
      StartRead(&request_);
      return;
    }
    response_.set_sequence(sequence_++);
    response_.mutable_result()->set_frame_id(response_.sequence());
    StartWrite(&response_);
  }
  void OnWriteDone(bool ok) override {
    if (!ok) {
      Finish(grpc::Status(grpc::StatusCode::CANCELLED, "the client went away"));
      return;
    }
    StartRead(&request_);
  }
  void OnDone() override { delete this; }

  pb::StreamFramesRequest request_;
  pb::StreamFramesResponse response_;
  uint64_t sequence_ = 0;
};

class TrivialPlaceService final : public pb::PlaceRecognition::CallbackService {
  grpc::ServerUnaryReactor* CreateMap(grpc::CallbackServerContext* context,
                                      const pb::CreateMapRequest* request,
                                      pb::CreateMapResponse* response) override {
    response->mutable_map()->set_name(request->name());
    grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
    reactor->Finish(grpc::Status::OK);
    return reactor;
  }
  grpc::ServerUnaryReactor* DeleteMap(grpc::CallbackServerContext* context,
                                      const pb::DeleteMapRequest*,
                                      pb::DeleteMapResponse*) override {
    grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
    reactor->Finish(grpc::Status::OK);
    return reactor;
  }
  grpc::ServerBidiReactor<pb::StreamFramesRequest, pb::StreamFramesResponse>* StreamFrames(
      grpc::CallbackServerContext*) override {
    return new AnsweringStream();
  }
};

int Run(int argc, char** argv) {
  cli::LoadOptions load;
  load.robots = 8;
  load.frames = 3000;
  load.features_on_client = true;
  std::string images = testing::SharedData("places/corridor/images");
  double server_fps = 0;
  std::string json_path;
  CLI::App app{"the load generator against a trivial server (see the header of the source)"};
  app.add_option("--images", images, "folder of the sequence each robot replays")
      ->capture_default_str();
  app.add_option("--robots", load.robots, "simulated robots")->capture_default_str();
  app.add_option("--frames", load.frames, "frames per robot")->capture_default_str();
  app.add_option("--in-flight", load.in_flight, "frames a robot sends ahead of their answers")
      ->capture_default_str();
  app.add_option("--server-fps", server_fps,
                 "frames/s recogd answered in a real run, to compare with");
  app.add_option("--json", json_path, "also write the figures to this file");
  CLI11_PARSE(app, argc, argv);
  load.sequences = {images};

  std::fprintf(stderr, "extracting the features of %s ...\n", images.c_str());
  StatusOr<cli::LoadGenerator> generator = cli::LoadGenerator::Prepare(load);
  if (!generator.ok()) {
    std::fprintf(stderr, "bench_load_generator: %s\n", generator.status().ToString().c_str());
    return 1;
  }
  TrivialPlaceService service;
  grpc::ServerBuilder builder;
  int port = 0;
  builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port);
  builder.RegisterService(&service);
  std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
  if (server == nullptr || port == 0) {
    std::fprintf(stderr, "bench_load_generator: cannot start the trivial server\n");
    return 1;
  }
  client::ClientOptions options;
  options.target = "127.0.0.1:" + std::to_string(port);
  client::Result<std::unique_ptr<client::RecognitionClient>> connected =
      client::RecognitionClient::Connect(options);
  if (!connected.ok()) {
    std::fprintf(stderr, "bench_load_generator: %s\n", connected.status().error_message().c_str());
    return 1;
  }
  StatusOr<cli::LoadReport> report = generator->Run(**connected);
  server->Shutdown();
  if (!report.ok()) {
    std::fprintf(stderr, "bench_load_generator: %s\n", report.status().ToString().c_str());
    return 1;
  }
  const double fps = report->FramesPerSecond();
  const cli::RpcStats& frames = report->rpcs.at(cli::kStreamFramesRpc);
  nlohmann::json figures = {
      {"robots", load.robots},
      {"frames_per_robot", load.frames},
      {"in_flight", load.in_flight},
      {"frames_answered", report->frames_answered},
      {"frames_sent", report->frames_sent},
      {"wall_s", report->wall_s},
      {"frames_per_s", fps},
      {"latency_p50_ms", frames.LatencyPercentile(50)},
      {"latency_p99_ms", frames.LatencyPercentile(99)},
      {"process_cpu_ms_per_frame", report->ClientCpuMsPerFrame()},
  };
  std::printf(
      "load generator against a trivial server: %d robots x %llu frames of client-side "
      "features, %u in flight\n",
      load.robots, static_cast<unsigned long long>(load.frames), load.in_flight);
  std::printf("answered %llu of %llu frames in %.2f s: %.0f frames/s, p50 %.2f ms, p99 %.2f ms\n",
              static_cast<unsigned long long>(report->frames_answered),
              static_cast<unsigned long long>(report->frames_sent), report->wall_s, fps,
              frames.LatencyPercentile(50), frames.LatencyPercentile(99));
  std::printf("process CPU (generator + trivial server) %.3f ms per frame\n",
              report->ClientCpuMsPerFrame());
  if (server_fps > 0) {
    figures["server_fps"] = server_fps;
    figures["ratio"] = fps / server_fps;
    std::printf("%.0f / %.0f frames/s of recogd = %.1fx\n", fps, server_fps, fps / server_fps);
  }
  std::printf("%s\n", figures.dump().c_str());
  if (!json_path.empty()) std::ofstream(json_path) << figures.dump(2) << "\n";
  return report->frames_answered == report->frames_sent ? 0 : 1;
}

}  // namespace
}  // namespace recog::bench

int main(int argc, char** argv) { return recog::bench::Run(argc, argv); }
