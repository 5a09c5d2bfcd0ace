// The load generator against an in-process recogd (ClientFixture): every frame answered and
// counted, maps cleaned up, verification against the offline detector, pacing, object calls,
// an unreachable or vanishing server, and refused options.
#include "tools/load/load_generator.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include <gtest/gtest.h>

#include "client/cpp/client_test_fixture.h"
#include "tests/testing/test_data.h"
#include "tests/testing/wait.h"

namespace recog::cli {
namespace {

using Clock = std::chrono::steady_clock;

class LoadGeneratorTest : public client::testing::ClientFixture {
 protected:
  // Options for the four frames of tests/data/corridor.
  static LoadOptions CorridorLoad(int robots, uint64_t frames) {
    LoadOptions options;
    options.sequences = {recog::testing::ProjectTestData("corridor")};
    options.robots = robots;
    options.frames = frames;
    return options;
  }

  // Prepares the load, then runs it with a client of the fixture's server (or of `options`), as
  // recog load does.
  StatusOr<LoadReport> Run(const LoadOptions& load) { return Run(load, Options()); }
  static StatusOr<LoadReport> Run(const LoadOptions& load, const client::ClientOptions& options) {
    RECOG_ASSIGN_OR_RETURN(const LoadGenerator generator, LoadGenerator::Prepare(load));
    std::unique_ptr<client::RecognitionClient> client = Connect(options);
    if (client == nullptr) return Status::Internal("no client");
    return generator.Run(*client);
  }

  size_t MapsOnServer() {
    auto client = Connect();
    auto maps = client->ListMaps();
    EXPECT_TRUE(maps.ok()) << maps.status().error_message();
    return maps.ok() ? maps->size() : 0;
  }
};

TEST_F(LoadGeneratorTest, TwoRobotsGetEveryFrameAnsweredAndDeleteTheirMaps) {
  const StatusOr<LoadReport> report = Run(CorridorLoad(2, 6));
  ASSERT_TRUE(report.ok()) << report.status().ToString();

  ASSERT_EQ(report->rpcs.count(kStreamFramesRpc), 1u);
  const RpcStats& frames = report->rpcs.at(kStreamFramesRpc);
  EXPECT_EQ(frames.ok, 12u);
  EXPECT_EQ(frames.ErrorCount(), 0u);
  EXPECT_EQ(frames.samples.size(), 12u);
  for (const LatencySample& s : frames.samples) {
    EXPECT_GE(s.at_s, 0);
    EXPECT_LE(s.at_s, report->wall_s);
    EXPECT_GT(s.latency_ms, 0);
  }
  EXPECT_LE(frames.LatencyPercentile(50), frames.LatencyPercentile(99));
  EXPECT_EQ(frames.LatencyPercentile(100), frames.LatencyPercentile(99));  // 12 samples
  EXPECT_EQ(report->rpcs.at(kCreateMapRpc).ok, 2u);
  EXPECT_EQ(report->rpcs.at(kDeleteMapRpc).ok, 2u);
  EXPECT_EQ(report->rpcs.count(kRecognizeObjectsRpc), 0u);
  EXPECT_EQ(report->frames_sent, 12u);
  EXPECT_EQ(report->frames_answered, 12u);
  EXPECT_GT(report->wall_s, 0);
  EXPECT_GT(report->FramesPerSecond(), 0);
  EXPECT_GT(report->client_cpu_s, 0);
  EXPECT_GT(report->CapacityRatio(), 0);
  EXPECT_EQ(report->PerSecond(kStreamFramesRpc), 12 / report->wall_s);
  EXPECT_FALSE(report->PerSecond(kCreateMapRpc).has_value());
  ASSERT_EQ(report->robots.size(), 2u);
  for (const RobotReport& robot : report->robots) {
    EXPECT_EQ(robot.frames_sent, 6u);
    EXPECT_EQ(robot.frames_answered, 6u);
    EXPECT_TRUE(robot.status.ok()) << robot.status.error_message();
    EXPECT_FALSE(robot.verification.has_value());
    EXPECT_EQ(robot.map.rfind("load-" + report->run_id + "-", 0), 0u) << robot.map;
  }
  EXPECT_NE(report->robots[0].map, report->robots[1].map);
  EXPECT_EQ(MapsOnServer(), 0u);

  const nlohmann::json json = LoadReportJson(*report);
  EXPECT_EQ(json["rpcs"]["StreamFrames"]["ok"], 12);
  EXPECT_TRUE(json["rpcs"]["StreamFrames"].contains("per_s"));
  EXPECT_FALSE(json["rpcs"]["CreateMap"].contains("per_s"));
  EXPECT_EQ(json["robots"].size(), 2u);
  EXPECT_EQ(json["robots"][0]["status"], "OK");
  const std::string plot = data_dir_.Sub("latency.png");
  ASSERT_TRUE(WriteLatencyPlot(*report, plot).ok());
  EXPECT_GT(std::filesystem::file_size(plot), 0u);
  // Its numbers beside it: a header, then one row per plotted point (p50 and p99 per slice).
  std::ifstream csv(data_dir_.Sub("latency.csv"));
  std::string line;
  ASSERT_TRUE(std::getline(csv, line));
  EXPECT_EQ(line, "series,seconds since the start,latency (ms),point_label");
  int p50_rows = 0, p99_rows = 0;
  while (std::getline(csv, line)) {
    p50_rows += line.starts_with("StreamFrames p50,");
    p99_rows += line.starts_with("StreamFrames p99,");
  }
  EXPECT_GT(p50_rows, 0);
  EXPECT_EQ(p50_rows, p99_rows);
}

TEST_F(LoadGeneratorTest, VerificationPassesOnASequenceWithoutLoops) {
  LoadOptions options = CorridorLoad(2, 4);
  options.verify = true;
  const StatusOr<LoadReport> report = Run(options);
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_TRUE(report->Verified());
  for (const RobotReport& robot : report->robots) {
    ASSERT_TRUE(robot.verification.has_value());
    EXPECT_TRUE(robot.verification->ok) << robot.verification->detail;
    EXPECT_EQ(robot.verification->frames_compared, 4);
    EXPECT_EQ(robot.verification->server_loops, 0);
    EXPECT_EQ(robot.verification->offline_loops, 0);
  }
}

TEST(OfflineDetectorOptionsTest, AKeyframesMapIsCheckedAgainstTheKeyframesDetector) {
  // As MapInfo has a keyframes map's settings: every field set, the preset's values.
  pb::MapSettings settings;
  settings.set_preset("keyframes");
  settings.set_alpha(0.3);
  settings.set_temporal_matches(3);
  settings.set_min_inliers(12);
  settings.set_geometry(pb::GEOMETRY_CHECK_DIRECT_INDEX);
  settings.set_recent_seconds(20);
  settings.set_recent_frames(6);  // the map's own value over the preset's
  settings.set_keyframe_confirmations(1);
  const StatusOr<PlaceEvaluationOptions> options = OfflineDetectorOptions(settings);
  ASSERT_TRUE(options.ok()) << options.status().ToString();
  const LoopDetectorParams keyframes = LoopDetectorParams::Keyframes();
  EXPECT_EQ(options->detector.preset, DetectorPreset::kKeyframes);
  EXPECT_EQ(options->detector.normalisation, keyframes.normalisation);
  EXPECT_EQ(options->detector.consistency_max_island_gap, keyframes.consistency_max_island_gap);
  EXPECT_EQ(options->detector.min_spread, keyframes.min_spread);
  EXPECT_EQ(options->detector.recent_frames, 6u);
  EXPECT_EQ(options->detector.keyframe_confirmations, 1u);

  settings.set_preset("sideways");
  EXPECT_EQ(OfflineDetectorOptions(settings).status().code(), StatusCode::kInvalidArgument);
}

TEST_F(LoadGeneratorTest, ClientFeaturesVerifyTheFirstPassAndKeptMapsHoldEveryFrame) {
  LoadOptions options = CorridorLoad(1, 7);  // the sequence and three frames of a second pass
  options.features_on_client = true;
  options.verify = true;
  options.keep_maps = true;
  options.map_prefix = "kept";
  const StatusOr<LoadReport> report = Run(options);
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  ASSERT_EQ(report->robots.size(), 1u);
  const RobotReport& robot = report->robots[0];
  ASSERT_TRUE(robot.verification.has_value());
  EXPECT_TRUE(robot.verification->ok) << robot.verification->detail;
  EXPECT_EQ(robot.verification->frames_compared, 4);
  EXPECT_EQ(report->rpcs.count(kDeleteMapRpc), 0u);
  auto client = Connect();
  auto map = client->GetMap(robot.map);
  ASSERT_TRUE(map.ok()) << map.status().error_message();
  EXPECT_EQ(map->frames(), 7u);
}

TEST_F(LoadGeneratorTest, ARateBoundsTheFramesOfADuration) {
  LoadOptions options = CorridorLoad(2, 0);
  options.duration_s = 1.0;
  options.rate_hz = 5;
  const auto start = Clock::now();
  const StatusOr<LoadReport> report = Run(options);
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_LT(Clock::now() - start, std::chrono::seconds(10));
  for (const RobotReport& robot : report->robots) {
    // Frames at 0, 0.2, ... 0.8 s: five, give or take a busy machine's scheduling.
    EXPECT_GE(robot.frames_sent, 4u);
    EXPECT_LE(robot.frames_sent, 6u);
    EXPECT_EQ(robot.frames_answered, robot.frames_sent);
  }
  EXPECT_GE(report->wall_s, 0.8);
}

TEST_F(LoadGeneratorTest, EveryKthFrameIsAlsoSentToObjectRecognition) {
  LoadOptions options = CorridorLoad(2, 5);
  options.objects_every = 2;  // frames 0, 2 and 4
  options.camera = CameraIntrinsics{500, 500, 256, 192, {}};
  const StatusOr<LoadReport> report = Run(options);
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  ASSERT_EQ(report->rpcs.count(kRecognizeObjectsRpc), 1u);
  const RpcStats& objects = report->rpcs.at(kRecognizeObjectsRpc);
  EXPECT_EQ(objects.ok, 6u);
  EXPECT_EQ(objects.ErrorCount(), 0u);
  EXPECT_EQ(report->rpcs.at(kStreamFramesRpc).ok, 10u);
  EXPECT_EQ(report->frames_sent, 16u);
  EXPECT_EQ(report->frames_answered, 16u);

  options.object_image = recog::testing::ProjectTestData("corridor/20.jpg");
  const StatusOr<LoadReport> on_image = Run(options);
  ASSERT_TRUE(on_image.ok()) << on_image.status().ToString();
  EXPECT_EQ(on_image->rpcs.at(kRecognizeObjectsRpc).ok, 6u);
}

TEST_F(LoadGeneratorTest, AnUnreachableServerGivesCountedErrorsWithinTheDeadline) {
  client::ClientOptions options = Options();
  StopServer();  // nothing listens on its port any more
  // Long enough for gRPC's five attempts (proto/service_config.json: at most 1.5 s of backoff),
  // so that the calls end UNAVAILABLE rather than at their deadline.
  options.deadline = std::chrono::seconds(5);
  const auto start = Clock::now();
  const StatusOr<LoadReport> report = Run(CorridorLoad(2, 6), options);
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_LT(Clock::now() - start, std::chrono::seconds(10));
  ASSERT_EQ(report->rpcs.count(kCreateMapRpc), 1u);
  const RpcStats& create = report->rpcs.at(kCreateMapRpc);
  EXPECT_EQ(create.ok, 0u);
  EXPECT_EQ(create.errors.count("UNAVAILABLE"), 1u);
  EXPECT_EQ(create.ErrorCount(), 2u);
  EXPECT_EQ(report->rpcs.count(kStreamFramesRpc), 0u);
  EXPECT_EQ(report->frames_answered, 0u);
  for (const RobotReport& robot : report->robots) {
    EXPECT_EQ(robot.failed_rpc, kCreateMapRpc);
    EXPECT_EQ(robot.status.error_code(), grpc::StatusCode::UNAVAILABLE);
    EXPECT_EQ(robot.frames_sent, 0u);
  }
}

TEST_F(LoadGeneratorTest, AServerThatGoesAwayMidRunEndsTheRobotsWithCountedErrors) {
  client::ClientOptions options = Options();
  options.deadline = std::chrono::seconds(2);
  LoadOptions load = CorridorLoad(2, 0);
  load.duration_s = 30;
  load.rate_hz = 20;
  // The server goes away once the robots' frames are being answered (their maps hold some).
  std::thread stopper([this] {
    const std::unique_ptr<client::RecognitionClient> client = Connect();
    EXPECT_TRUE(recog::testing::WaitUntil([&] {
      const auto maps = client->ListMaps();
      return maps.ok() && std::any_of(maps->begin(), maps->end(),
                                      [](const auto& map) { return map.frames() > 0; });
    })) << "no frame was added to a robot's map";
    StopServer();
  });
  const auto start = Clock::now();
  const StatusOr<LoadReport> report = Run(load, options);
  stopper.join();
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_LT(Clock::now() - start, std::chrono::seconds(20));
  const RpcStats& frames = report->rpcs.at(kStreamFramesRpc);
  EXPECT_GT(frames.ok, 0u);
  EXPECT_GT(frames.ErrorCount(), 0u);
  for (const RobotReport& robot : report->robots) {
    EXPECT_EQ(robot.failed_rpc, kStreamFramesRpc);
    EXPECT_FALSE(robot.status.ok());
  }
  EXPECT_GT(report->rpcs.at(kDeleteMapRpc).ErrorCount(), 0u);
}

TEST_F(LoadGeneratorTest, BadOptionsAreRefusedBeforeAnyCall) {
  const auto refused = [&](const LoadOptions& options) {
    EXPECT_EQ(options.Validate().code(), StatusCode::kInvalidArgument);
    const StatusOr<LoadReport> report = Run(options);
    return !report.ok() && report.status().code() == StatusCode::kInvalidArgument;
  };
  LoadOptions options = CorridorLoad(2, 6);
  EXPECT_TRUE(options.Validate().ok());
  options.sequences.clear();
  EXPECT_TRUE(refused(options));
  options = CorridorLoad(0, 6);
  EXPECT_TRUE(refused(options));
  options = CorridorLoad(2, 0);  // neither frames nor duration
  EXPECT_TRUE(refused(options));
  options = CorridorLoad(2, 6);
  options.duration_s = 5;  // both
  EXPECT_TRUE(refused(options));
  options = CorridorLoad(2, 6);
  options.objects_every = 3;  // without a camera
  EXPECT_TRUE(refused(options));
  options = CorridorLoad(2, 6);
  options.map_prefix = "no spaces";
  EXPECT_TRUE(refused(options));
  options = CorridorLoad(2, 6);
  options.in_flight = 1000;  // beyond the client's max_frames_in_flight, which Run checks
  EXPECT_EQ(Run(options).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(MapsOnServer(), 0u);

  options = CorridorLoad(2, 6);
  options.sequences = {data_dir_.Sub("missing")};
  const StatusOr<LoadReport> missing = Run(options);
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
}

TEST_F(LoadGeneratorTest, TwoRobotsOnTheCorridorFindTheOfflineDetectorsThirtySixLoops) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("places/corridor/images");
  LoadOptions options;
  options.sequences = {recog::testing::SharedData("places/corridor/images")};
  options.robots = 2;
  options.frames = 84;
  options.verify = true;
  const StatusOr<LoadReport> report = Run(options);
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_TRUE(report->Verified());
  EXPECT_EQ(report->loops, 72u);  // the corridor's 36 loops with the default detector, twice
  for (const RobotReport& robot : report->robots) {
    ASSERT_TRUE(robot.verification.has_value());
    EXPECT_TRUE(robot.verification->ok) << robot.verification->detail;
    EXPECT_EQ(robot.verification->frames_compared, 84);
    EXPECT_EQ(robot.verification->server_loops, 36);
    EXPECT_EQ(robot.loops, 36u);
  }
}

}  // namespace
}  // namespace recog::cli
