// recog load: simulated robots replaying image sequences (or a ROS 1 or ROS 2 bag) into recogd,
// each through its own frame stream into its own fresh map. Reports per RPC the count, throughput,
// latency percentiles and errors, the loops detected, and what the generator itself cost (its CPU
// time per frame, against the server's throughput); --verify checks every robot's loops against the
// offline detector,
// --plot draws the latency over the run. The work is in load_generator.h.
#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "tools/common/cli_support.h"
#include "tools/common/server_flags.h"
#include "tools/evaluation/camera_calibration.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/load/load_generator.h"
#include "tools/recog/bag_flags.h"
#include "tools/recog/commands.h"
#include "wire/grpc_code_names.h"

namespace recog::cli {
namespace {

struct LoadArgs {
  LoadOptions options;
  std::string camera;     // --camera, parsed into options.camera
  BagFlags bag;           // --bag and its topics, into options.bag
  bool json = false;      // --json given: JSON on stdout, or into json_file
  std::string json_file;  // --json FILE
  std::string plot;
  bool quiet = false;
  ServerFlags server;
};

// "-" for latencies of calls that were never answered.
std::string Ms(const RpcStats& stats, double percentile) {
  if (stats.samples.empty()) return "-";
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.1f", stats.LatencyPercentile(percentile));
  return buffer;
}

void PrintReport(const LoadArgs& args, const LoadReport& report) {
  const LoadOptions& o = args.options;
  char bound[64], pace[64];
  if (o.frames > 0) {
    std::snprintf(bound, sizeof(bound), "%llu frames each",
                  static_cast<unsigned long long>(o.frames));
  } else {
    std::snprintf(bound, sizeof(bound), "%g s", o.duration_s);
  }
  if (o.bag_speed > 0) {
    std::snprintf(pace, sizeof(pace), "the bag's pace x %g", o.bag_speed);
  } else if (o.rate_hz > 0) {
    std::snprintf(pace, sizeof(pace), "%g frames/s each", o.rate_hz);
  } else {
    std::snprintf(pace, sizeof(pace), "as fast as %u frames in flight allow", o.in_flight);
  }
  std::printf("run %s: %d robots, %s, %s, %s\n", report.run_id.c_str(), o.robots, bound, pace,
              o.features_on_client ? "ORB features extracted on the client"
              : o.bag.has_value()  ? "bag frames"
                                   : "image files");
  std::printf("%-17s %8s %9s %8s %8s %8s %8s  %s\n", "rpc", "ok", "per_s", "p50_ms", "p90_ms",
              "p99_ms", "max_ms", "errors");
  for (const char* name : {kCreateMapRpc, kStreamFramesRpc, kRecognizeObjectsRpc, kDeleteMapRpc}) {
    const auto found = report.rpcs.find(name);
    if (found == report.rpcs.end()) continue;
    const RpcStats& stats = found->second;
    std::string per_s = "-";
    if (const std::optional<double> rate = report.PerSecond(name)) {
      char buffer[32];
      std::snprintf(buffer, sizeof(buffer), "%.1f", *rate);
      per_s = buffer;
    }
    std::string errors;
    for (const auto& [code, count] : stats.errors) {
      errors += (errors.empty() ? "" : ", ") + code + " " + std::to_string(count);
    }
    std::printf("%-17s %8llu %9s %8s %8s %8s %8s  %s\n", name,
                static_cast<unsigned long long>(stats.ok), per_s.c_str(), Ms(stats, 50).c_str(),
                Ms(stats, 90).c_str(), Ms(stats, 99).c_str(), Ms(stats, 100).c_str(),
                errors.empty() ? "-" : errors.c_str());
  }
  std::printf("wall %.2f s: %llu of %llu frames answered, %.1f frames/s; %llu loops detected\n",
              report.wall_s, static_cast<unsigned long long>(report.frames_answered),
              static_cast<unsigned long long>(report.frames_sent), report.FramesPerSecond(),
              static_cast<unsigned long long>(report.loops));
  std::printf(
      "client CPU %.2f s = %.3f ms per frame: generator capacity %.0f frames/s per core = %.1fx "
      "the server's throughput\n",
      report.client_cpu_s, report.ClientCpuMsPerFrame(), report.GeneratorCapacity(),
      report.CapacityRatio());
  for (size_t i = 0; i < report.robots.size(); ++i) {
    const RobotReport& r = report.robots[i];
    std::printf("robot %zu %s: %llu frames, %llu answered, %llu loops", i, r.map.c_str(),
                static_cast<unsigned long long>(r.frames_sent),
                static_cast<unsigned long long>(r.frames_answered),
                static_cast<unsigned long long>(r.loops));
    if (!r.status.ok()) {
      std::printf(", stopped: %s %s", r.failed_rpc.c_str(), DescribeStatus(r.status).c_str());
    }
    if (r.verification.has_value()) {
      const Verification& v = *r.verification;
      if (v.ok) {
        std::printf("; verify OK (%d frames, %d loops)", v.frames_compared, v.server_loops);
      } else {
        std::printf("; verify MISMATCH: %s", v.detail.c_str());
      }
    }
    std::printf("\n");
  }
}

int RunLoadCommand(LoadArgs& args) {
  if (!args.camera.empty()) {
    StatusOr<CameraIntrinsics> camera = ParseCameraFlag("--camera", args.camera);
    if (!camera.ok()) return Fail("load", camera.status());
    args.options.camera = *camera;
  }
  if (args.bag.given()) {
    // Without --topic, the error lists the bag's image topics.
    if (args.bag.topics.image.empty()) return Fail("load", args.bag.Open().status());
    args.options.bag = LoadBag{args.bag.bag, args.bag.topics, args.bag.options};
  }
  const StatusOr<LoadGenerator> load = LoadGenerator::Prepare(args.options);
  if (!load.ok()) return Fail("load", load.status());
  auto client = args.server.Connect();  // after preparing (see LoadGenerator)
  if (!client.ok()) {
    std::fprintf(stderr, "recog load: %s\n", DescribeStatus(client.status()).c_str());
    return 1;
  }
  ProgressBar progress(!args.quiet);
  const StatusOr<LoadReport> report = load->Run(**client, [&](uint64_t done, uint64_t total) {
    progress.Update(args.options.frames > 0 ? "answers" : "run (ms)", done, total);
  });
  progress.Finish();
  if (!report.ok()) return Fail("load", report.status());

  nlohmann::json out = LoadReportJson(*report);
  const LoadOptions& o = args.options;
  out["options"] = {{"server", args.server.server},
                    {"sequences", o.sequences},
                    {"bag", o.bag.has_value() ? nlohmann::json(o.bag->path) : nlohmann::json()},
                    {"bag_speed", o.bag_speed},
                    {"robots", o.robots},
                    {"frames", o.frames},
                    {"duration_s", o.duration_s},
                    {"rate_hz", o.rate_hz},
                    {"in_flight", o.in_flight},
                    {"features_on_client", o.features_on_client},
                    {"objects_every", o.objects_every},
                    {"object_image", o.object_image},
                    {"verify", o.verify}};
  if (!args.plot.empty()) {
    if (Status s = WriteLatencyPlot(*report, args.plot); !s.ok()) return Fail("load", s);
    out["plot"] = args.plot;
  }
  if (args.json && args.json_file.empty()) {
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    PrintReport(args, *report);
    if (!args.plot.empty()) std::printf("latency plot: %s\n", args.plot.c_str());
  }
  if (!args.json_file.empty()) {
    std::ofstream file(args.json_file);
    file << out.dump(2) << "\n";
    if (!file) return Fail("load", Status::Internal("cannot write '" + args.json_file + "'"));
  }

  if (report->frames_answered == 0) {
    // Why: the first robot that stopped, else the frames' own errors.
    std::string code = "UNKNOWN", why = "every frame failed (errors above)";
    if (const auto frames = report->rpcs.find(kStreamFramesRpc);
        frames != report->rpcs.end() && !frames->second.errors.empty()) {
      code = frames->second.errors.begin()->first;
    }
    for (const RobotReport& r : report->robots) {
      if (!r.status.ok()) {
        code = GrpcCodeName(r.status.error_code());
        why = r.failed_rpc + " failed: " + r.status.error_message();
        break;
      }
    }
    std::fprintf(stderr, "recog load: %s: no frame was answered: %s\n", code.c_str(), why.c_str());
    return 1;
  }
  for (size_t i = 0; i < report->robots.size(); ++i) {
    const std::optional<Verification>& v = report->robots[i].verification;
    if (v.has_value() && !v->ok) {
      std::fprintf(stderr,
                   "recog load: FAILED_PRECONDITION: robot %zu's loops differ from the offline "
                   "detector's: %s\n",
                   i, v->detail.c_str());
      return 1;
    }
  }
  return 0;
}

}  // namespace

void AddLoadCommand(CLI::App& app, int* exit_code) {
  auto args = std::make_shared<LoadArgs>();
  LoadOptions& o = args->options;
  CLI::App* load = app.add_subcommand(
      "load", "Load-test recogd: simulated robots replay image sequences into maps of their own");
  CLI::Option* sequences =
      load->add_option("--sequences", o.sequences,
                       "Folders of images (natural order) or recog seqgen outputs; robot i replays "
                       "sequence i % count");
  args->bag.AddTo(load, sequences);
  load->add_option("--robots", o.robots, "Simulated robots, each with its own stream and map")
      ->required();
  CLI::Option* duration =
      load->add_option("--duration", o.duration_s, "Seconds each robot sends frames");
  load->add_option("--frames", o.frames, "Frames each robot sends (looping over its sequence)")
      ->excludes(duration);
  CLI::Option* rate =
      load->add_option("--rate", o.rate_hz, "Frames per second per robot; 0 = as fast as possible")
          ->capture_default_str();
  load->add_option("--bag-speed", o.bag_speed,
                   "With --bag: replay at this many times the bag's own pace, its frames' stamps "
                   "(1 = as recorded); without it, --rate applies")
      ->needs("--bag")
      ->excludes(rate);
  load->add_option("--in-flight", o.in_flight, "Frames a robot may have sent and not had answered")
      ->capture_default_str();
  load->add_flag("--features-on-client", o.features_on_client,
                 "Send ORB features extracted before the run instead of the image files");
  load->add_option("--objects-every", o.objects_every,
                   "Also call RecognizeObjects on frames 0, K, 2K, ... of each robot (0 = never)")
      ->capture_default_str();
  load->add_option("--camera", args->camera,
                   std::string("The camera of the RecognizeObjects frames (default with --bag: "
                               "its --camera-info-topic): ") +
                       kCameraFlagSyntax);
  load->add_option("--object-image", o.object_image,
                   "Recognise objects on this image instead of the robot's current frame");
  load->add_flag("--verify", o.verify,
                 "Check each robot's loops (first pass) against the offline detector; exit 1 on a "
                 "mismatch");
  load->add_option("--plot", args->plot,
                   "PNG of the latency over the run; its points go to the same name .csv");
  load->add_option("--map-prefix", o.map_prefix, "Maps are named PREFIX-<run id>-<robot>")
      ->capture_default_str();
  load->add_flag("--keep-maps", o.keep_maps, "Do not delete the maps at the end");
  load->add_flag("-q,--quiet", args->quiet, "No progress output");
  args->server.AddTo(load);
  // ServerFlags' --json is a plain flag; here it may also name a file.
  load->remove_option(load->get_option("--json"));
  CLI::Option* json = load->add_option("--json", args->json_file,
                                       "Print JSON instead of the table, or write it to FILE")
                          ->expected(0, 1)
                          ->type_name("[FILE]");
  load->callback([args, exit_code, json] {
    args->json = json->count() > 0;
    *exit_code = RunLoadCommand(*args);
  });
}

}  // namespace recog::cli
