#include "server/config/server_config.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <thread>
#include <vector>

namespace recog::server {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

class ServerConfigTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("recog_server_config_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Writes `text` to a file in the test's directory and returns its path.
  std::string WriteFile(const std::string& name, const std::string& text) {
    const fs::path path = dir_ / name;
    std::ofstream(path) << text;
    return path.string();
  }

  StatusOr<ServerConfig> Load(const std::string& yaml) {
    return ServerConfig::LoadYaml(WriteFile("recogd.yaml", yaml));
  }

  fs::path dir_;
};

StatusOr<CommandLine> Parse(std::vector<std::string> args) {
  args.insert(args.begin(), "recogd");
  std::vector<const char*> argv;
  for (const std::string& a : args) argv.push_back(a.c_str());
  return ParseCommandLine(static_cast<int>(argv.size()), argv.data());
}

TEST_F(ServerConfigTest, DefaultsAreValidAndAsDocumented) {
  const ServerConfig config;
  EXPECT_TRUE(config.Validate().ok()) << config.Validate().ToString();
  EXPECT_EQ(config.listen, "127.0.0.1:50051");
  EXPECT_EQ(config.data_dir, "./recog-data");
  EXPECT_EQ(config.place_vocabulary, "");
  EXPECT_EQ(config.object_vocabulary, "");
  EXPECT_EQ(config.workers, 0u);
  EXPECT_EQ(config.queue_capacity, 64u);
  EXPECT_EQ(config.retry_after_ms, 100u);
  EXPECT_EQ(config.request_log_entries, 10000u);
  EXPECT_EQ(config.max_message_bytes, 32u * 1024 * 1024);
  EXPECT_EQ(config.keepalive.time_ms, 20000u);
  EXPECT_EQ(config.keepalive.timeout_ms, 10000u);
  EXPECT_TRUE(config.keepalive.permit_without_calls);
  EXPECT_EQ(config.keepalive.min_ping_interval_ms, 10000u);
  EXPECT_EQ(config.grpc.max_concurrent_streams, 100u);
  EXPECT_EQ(config.grpc.memory_quota_mb, 128u);
  EXPECT_EQ(config.grpc.pending_requests_mb, 128u);
  EXPECT_EQ(config.grpc.decode_memory_mb, 256u);
  EXPECT_EQ(config.grpc.max_connection_idle_ms, 300000u);
  EXPECT_EQ(config.grpc.max_connection_age_ms, 0u);
  EXPECT_EQ(config.grpc.reserve_descriptors, 64u);
  EXPECT_EQ(config.tls.cert, "");
  EXPECT_EQ(config.tls.key, "");
  EXPECT_EQ(config.tls.client_ca, "");
  EXPECT_EQ(config.token_file, "");
  EXPECT_EQ(config.metrics_listen, "127.0.0.1:9464");
  EXPECT_EQ(config.store.sync, StoreSync::kGrouped);
  EXPECT_EQ(config.store.group_sync_interval_ms, 50u);
  EXPECT_EQ(config.store.block_cache_mb, 64u);
  EXPECT_EQ(config.store.recover, StoreRecover::kRefuse);
  EXPECT_EQ(config.store.verify_interval_s, 86400u);
  EXPECT_EQ(config.store.verify_mb_per_s, 32u);
  EXPECT_EQ(config.shard.name, "");
  EXPECT_EQ(config.shard.placement_file, "");
  EXPECT_EQ(config.repository.primary, "");
  EXPECT_EQ(config.repository.token_file, "");
  EXPECT_EQ(config.repository.tls_ca, "");
  EXPECT_EQ(config.shutdown_grace_ms, 10000u);
  EXPECT_EQ(config.log_level, "info");
  EXPECT_DOUBLE_EQ(config.place.alpha, 0.3);
  EXPECT_EQ(config.place.temporal_matches, 3u);
  EXPECT_EQ(config.place.epipolar.min_inliers, 12u);
  EXPECT_EQ(config.place.geometry, GeometryCheck::kDirectIndex);
  EXPECT_DOUBLE_EQ(config.place.recent_seconds, 20.0);
  EXPECT_EQ(config.place.recent_frames, 20u);
}

TEST_F(ServerConfigTest, ZeroWorkersMeansOnePerAvailableCpu) {
  ServerConfig config;
  EXPECT_EQ(config.WorkerCount(),
            AvailableCpus(CgroupPaths(), std::thread::hardware_concurrency()));
  EXPECT_GE(config.WorkerCount(), 1u);
  EXPECT_LE(config.WorkerCount(), std::max(1u, std::thread::hardware_concurrency()));
  config.workers = 3;
  EXPECT_EQ(config.WorkerCount(), 3u);
}

TEST_F(ServerConfigTest, AvailableCpusFollowsTheTightestCgroupQuota) {
  // cgroup v2 as systemd sets it: the service's own cpu.max and its slice's.
  CgroupPaths paths{(dir_ / "cgroup").string(),
                    WriteFile("self", "0::/system.slice/recogd.service\n")};
  const fs::path service = dir_ / "cgroup/system.slice/recogd.service";
  fs::create_directories(service);
  EXPECT_EQ(AvailableCpus(paths, 16), 16u) << "no cpu.max anywhere";
  EXPECT_EQ(AvailableCpus(paths, 0), 1u) << "an unknown hardware count is 1";
  std::ofstream(service / "cpu.max") << "max 100000\n";
  EXPECT_EQ(AvailableCpus(paths, 16), 16u) << "no quota";
  std::ofstream(service / "cpu.max") << "250000 100000\n";
  EXPECT_EQ(AvailableCpus(paths, 16), 3u) << "2.5 CPUs round up";
  EXPECT_EQ(AvailableCpus(paths, 2), 2u) << "never more than the hardware";
  std::ofstream(dir_ / "cgroup/system.slice/cpu.max") << "150000 100000\n";
  EXPECT_EQ(AvailableCpus(paths, 16), 2u) << "the slice's quota is tighter";
  std::ofstream(service / "cpu.max") << "1000 100000\n";
  EXPECT_EQ(AvailableCpus(paths, 16), 1u) << "at least one";

  // A container with its own cgroup namespace sees its cgroup as the root.
  CgroupPaths container{(dir_ / "container").string(), WriteFile("self_ns", "0::/\n")};
  fs::create_directories(container.root);
  std::ofstream(fs::path(container.root) / "cpu.max") << "400000 100000\n";
  EXPECT_EQ(AvailableCpus(container, 16), 4u);
}

TEST_F(ServerConfigTest, AvailableCpusReadsCgroupV1AndIgnoresMalformedFiles) {
  // A container's view: its cgroup (/docker/<id> on the host) is the root of the cpu hierarchy.
  CgroupPaths paths{(dir_ / "v1").string(),
                    WriteFile("self", "5:memory:/docker/abc\n4:cpu,cpuacct:/docker/abc\n")};
  const fs::path cpu = dir_ / "v1/cpu";
  fs::create_directories(cpu);
  std::ofstream(cpu / "cpu.cfs_period_us") << "100000\n";
  std::ofstream(cpu / "cpu.cfs_quota_us") << "-1\n";
  EXPECT_EQ(AvailableCpus(paths, 8), 8u) << "no quota";
  std::ofstream(cpu / "cpu.cfs_quota_us") << "300000\n";
  EXPECT_EQ(AvailableCpus(paths, 8), 3u);
  // A systemd service on a cgroup v1 host: its own directory of the cpu hierarchy.
  paths.self = WriteFile("self_service", "4:cpu,cpuacct:/system.slice/recogd.service\n");
  const fs::path service = cpu / "system.slice/recogd.service";
  fs::create_directories(service);
  std::ofstream(service / "cpu.cfs_period_us") << "50000\n";
  std::ofstream(service / "cpu.cfs_quota_us") << "100000\n";
  EXPECT_EQ(AvailableCpus(paths, 8), 2u);

  for (const char* malformed : {"", "lots", "100000 x", "0 100000", "100000 0", "-5 100000"}) {
    CgroupPaths v2{(dir_ / "bad").string(), WriteFile("self_bad", "0::/\n")};
    fs::create_directories(v2.root);
    std::ofstream(fs::path(v2.root) / "cpu.max") << malformed;
    EXPECT_EQ(AvailableCpus(v2, 8), 8u) << "'" << malformed << "'";
  }
  EXPECT_EQ(AvailableCpus(CgroupPaths{(dir_ / "absent").string(), (dir_ / "absent").string()}, 5),
            5u);
}

TEST_F(ServerConfigTest, StoreSyncNamesRoundTrip) {
  for (StoreSync sync : {StoreSync::kGrouped, StoreSync::kEveryWrite}) {
    StatusOr<StoreSync> parsed = ParseStoreSync(StoreSyncName(sync));
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(*parsed, sync);
  }
  EXPECT_EQ(ParseStoreSync("sometimes").status().code(), StatusCode::kInvalidArgument);
  for (StoreRecover recover : {StoreRecover::kRefuse, StoreRecover::kPointInTime}) {
    StatusOr<StoreRecover> parsed = ParseStoreRecover(StoreRecoverName(recover));
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(*parsed, recover);
  }
  EXPECT_EQ(ParseStoreRecover("skip").status().code(), StatusCode::kInvalidArgument);
}

TEST_F(ServerConfigTest, YamlSetsEveryFieldOfEverySection) {
  StatusOr<ServerConfig> config = Load(R"(
listen: "0.0.0.0:6000"
data_dir: /var/lib/recog
place_vocabulary: /voc/place.rvoc
object_vocabulary: /voc/object.rvoc
workers: 6
queue_capacity: 10
retry_after_ms: 250
request_log_entries: 0
max_message_bytes: 2097152
keepalive:
  time_ms: 30000
  timeout_ms: 5000
  permit_without_calls: false
  min_ping_interval_ms: 2000
grpc:
  max_concurrent_streams: 20
  memory_quota_mb: 64
  pending_requests_mb: 48
  decode_memory_mb: 100
  max_connection_idle_ms: 60000
  max_connection_age_ms: 3600000
  max_connection_age_grace_ms: 5000
  reserve_descriptors: 128
tls:
  cert: server.crt
  key: server.key
  client_ca: ca.crt
token_file: tokens.yaml
metrics_listen: "0.0.0.0:9000"
store:
  sync: every_write
  group_sync_interval_ms: 200
  block_cache_mb: 0
  recover: point-in-time
  verify_interval_s: 60
  verify_mb_per_s: 8
shard:
  name: shard_a
  placement_file: /etc/recogd/router/placement.map
repository:
  primary: "10.0.0.10:50051"
  token_file: primary.token
  tls_ca: primary-ca.crt
shutdown_grace_ms: 500
log_level: debug
place:
  alpha: 0.25
  temporal_matches: 2
  min_inliers: 20
  geometry: exhaustive
  recent_seconds: 5.5
  recent_frames: 7
)");
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  EXPECT_EQ(config->listen, "0.0.0.0:6000");
  EXPECT_EQ(config->data_dir, "/var/lib/recog");
  EXPECT_EQ(config->place_vocabulary, "/voc/place.rvoc");
  EXPECT_EQ(config->object_vocabulary, "/voc/object.rvoc");
  EXPECT_EQ(config->workers, 6u);
  EXPECT_EQ(config->queue_capacity, 10u);
  EXPECT_EQ(config->retry_after_ms, 250u);
  EXPECT_EQ(config->request_log_entries, 0u);
  EXPECT_EQ(config->max_message_bytes, 2097152u);
  EXPECT_EQ(config->keepalive.time_ms, 30000u);
  EXPECT_EQ(config->keepalive.timeout_ms, 5000u);
  EXPECT_FALSE(config->keepalive.permit_without_calls);
  EXPECT_EQ(config->keepalive.min_ping_interval_ms, 2000u);
  EXPECT_EQ(config->grpc.max_concurrent_streams, 20u);
  EXPECT_EQ(config->grpc.memory_quota_mb, 64u);
  EXPECT_EQ(config->grpc.pending_requests_mb, 48u);
  EXPECT_EQ(config->grpc.decode_memory_mb, 100u);
  EXPECT_EQ(config->grpc.max_connection_idle_ms, 60000u);
  EXPECT_EQ(config->grpc.max_connection_age_ms, 3600000u);
  EXPECT_EQ(config->grpc.max_connection_age_grace_ms, 5000u);
  EXPECT_EQ(config->grpc.reserve_descriptors, 128u);
  EXPECT_EQ(config->tls.cert, "server.crt");
  EXPECT_EQ(config->tls.key, "server.key");
  EXPECT_EQ(config->tls.client_ca, "ca.crt");
  EXPECT_EQ(config->token_file, "tokens.yaml");
  EXPECT_EQ(config->metrics_listen, "0.0.0.0:9000");
  EXPECT_EQ(config->store.sync, StoreSync::kEveryWrite);
  EXPECT_EQ(config->store.group_sync_interval_ms, 200u);
  EXPECT_EQ(config->store.block_cache_mb, 0u);
  EXPECT_EQ(config->store.recover, StoreRecover::kPointInTime);
  EXPECT_EQ(config->store.verify_interval_s, 60u);
  EXPECT_EQ(config->store.verify_mb_per_s, 8u);
  EXPECT_EQ(config->shard.name, "shard_a");
  EXPECT_EQ(config->shard.placement_file, "/etc/recogd/router/placement.map");
  EXPECT_EQ(config->repository.primary, "10.0.0.10:50051");
  EXPECT_EQ(config->repository.token_file, "primary.token");
  EXPECT_EQ(config->repository.tls_ca, "primary-ca.crt");
  EXPECT_EQ(config->shutdown_grace_ms, 500u);
  EXPECT_EQ(config->log_level, "debug");
  EXPECT_DOUBLE_EQ(config->place.alpha, 0.25);
  EXPECT_EQ(config->place.temporal_matches, 2u);
  EXPECT_EQ(config->place.epipolar.min_inliers, 20u);
  EXPECT_EQ(config->place.geometry, GeometryCheck::kExhaustive);
  EXPECT_DOUBLE_EQ(config->place.recent_seconds, 5.5);
  EXPECT_EQ(config->place.recent_frames, 7u);
  EXPECT_TRUE(config->Validate().ok()) << config->Validate().ToString();
}

TEST_F(ServerConfigTest, AbsentKeysKeepTheirDefaults) {
  StatusOr<ServerConfig> config = Load("workers: 2\nkeepalive:\n  time_ms: 1000\ntls:\n");
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  EXPECT_EQ(config->workers, 2u);
  EXPECT_EQ(config->keepalive.time_ms, 1000u);
  EXPECT_EQ(config->keepalive.timeout_ms, 10000u);
  EXPECT_EQ(config->listen, "127.0.0.1:50051");
  EXPECT_EQ(config->tls.cert, "");
  EXPECT_DOUBLE_EQ(config->place.alpha, 0.3);
}

TEST_F(ServerConfigTest, ThePlacePresetIsWhatTheOtherPlaceKeysOverride) {
  EXPECT_TRUE(ServerConfig().place.strong_acceptance) << "the default preset";
  StatusOr<ServerConfig> thesis = Load("place:\n  temporal_matches: 4\n  preset: thesis\n");
  ASSERT_TRUE(thesis.ok()) << thesis.status().ToString();
  EXPECT_FALSE(thesis->place.strong_acceptance);
  EXPECT_EQ(thesis->place.temporal_matches, 4u) << "keys override the preset wherever they stand";
  StatusOr<ServerConfig> keyframes =
      Load("place:\n  preset: keyframes\n  keyframe_confirmations: 2\n");
  ASSERT_TRUE(keyframes.ok()) << keyframes.status().ToString();
  EXPECT_EQ(keyframes->place.preset, DetectorPreset::kKeyframes);
  EXPECT_EQ(keyframes->place.keyframe_confirmations, 2u) << "every setting a map keeps";
  StatusOr<ServerConfig> bad = Load("place:\n  preset: dloop\n");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(bad.status().message(), HasSubstr("setting preset = 'dloop'"));
}

TEST_F(ServerConfigTest, TheOldNameModeStillSetsThePresetButNotBesideIt) {
  StatusOr<ServerConfig> old = Load("place:\n  mode: thesis\n  alpha: 0.2\n");
  ASSERT_TRUE(old.ok()) << old.status().ToString();
  EXPECT_EQ(old->place.preset, DetectorPreset::kThesis);
  EXPECT_DOUBLE_EQ(old->place.alpha, 0.2);
  StatusOr<ServerConfig> both = Load("place:\n  mode: thesis\n  preset: keyframes\n");
  ASSERT_FALSE(both.ok());
  EXPECT_THAT(both.status().message(), HasSubstr("'place.mode' and 'place.preset'"));
}

TEST_F(ServerConfigTest, EmptyFileGivesTheDefaults) {
  StatusOr<ServerConfig> config = Load("# nothing configured\n");
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  EXPECT_EQ(config->listen, ServerConfig().listen);
  EXPECT_EQ(config->queue_capacity, ServerConfig().queue_capacity);
}

TEST_F(ServerConfigTest, UnknownKeysAreRejectedByName) {
  StatusOr<ServerConfig> top = Load("listen: \"127.0.0.1:1\"\nworkerz: 4\n");
  ASSERT_FALSE(top.ok());
  EXPECT_EQ(top.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(top.status().message(), HasSubstr("unknown key 'workerz'"));

  StatusOr<ServerConfig> nested = Load("keepalive:\n  time_ms: 1\n  timeout: 5\n");
  ASSERT_FALSE(nested.ok());
  EXPECT_THAT(nested.status().message(), HasSubstr("unknown key 'keepalive.timeout'"));

  StatusOr<ServerConfig> place = Load("place:\n  min_features: 5\n");
  ASSERT_FALSE(place.ok());
  EXPECT_THAT(place.status().message(), HasSubstr("unknown key 'place.min_features'"));
}

TEST_F(ServerConfigTest, TheHttpPortsLimitsAreReadForTheConsoleAndTheMetrics) {
  const ServerConfig defaults;
  EXPECT_EQ(defaults.console.header_timeout_ms, 10000u);
  EXPECT_EQ(defaults.console.max_body_bytes, 16u << 20);
  EXPECT_EQ(defaults.metrics.max_connections, 8u);
  EXPECT_EQ(defaults.metrics.max_connections_per_client, 4u);
  EXPECT_TRUE(defaults.Validate().ok());
  StatusOr<ServerConfig> loaded = Load(
      "console:\n  header_timeout_ms: 2000\n  min_bytes_per_s: 0\n  max_header_lines: 50\n"
      "  max_header_bytes: 4096\n  max_body_bytes: 1048576\n  max_inflight_body_bytes: 2097152\n"
      "metrics:\n  hosts: [prometheus.lan]\n  max_connections: 3\n  max_connections_per_client: 1\n"
      "  request_timeout_ms: 5000\n");
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_EQ(loaded->console.header_timeout_ms, 2000u);
  EXPECT_EQ(loaded->console.min_bytes_per_s, 0u);
  EXPECT_EQ(loaded->console.max_header_lines, 50u);
  EXPECT_EQ(loaded->console.max_header_bytes, 4096u);
  EXPECT_EQ(loaded->console.max_body_bytes, 1048576u);
  EXPECT_EQ(loaded->console.max_inflight_body_bytes, 2097152u);
  EXPECT_EQ(loaded->metrics.hosts, std::vector<std::string>{"prometheus.lan"});
  EXPECT_EQ(loaded->metrics.max_connections, 3u);
  EXPECT_EQ(loaded->metrics.max_connections_per_client, 1u);
  EXPECT_EQ(loaded->metrics.request_timeout_ms, 5000u);
  EXPECT_EQ(loaded->metrics.header_timeout_ms, 10000u);  // the default
  EXPECT_TRUE(loaded->Validate().ok());
  StatusOr<ServerConfig> typo = Load("metrics:\n  listen: \"127.0.0.1:1\"\n");
  ASSERT_FALSE(typo.ok());
  EXPECT_THAT(typo.status().message(), HasSubstr("unknown key 'metrics.listen'"));
}

TEST_F(ServerConfigTest, TheConsoleSectionIsReadAndItsUnknownKeysRejected) {
  StatusOr<ServerConfig> console =
      Load("console:\n  listen: \"127.0.0.1:8080\"\n  loops_per_map: 7\n  charts_dir: /tmp/c\n");
  ASSERT_TRUE(console.ok()) << console.status().ToString();
  EXPECT_EQ(console->console.listen, "127.0.0.1:8080");
  EXPECT_EQ(console->console.loops_per_map, 7u);
  EXPECT_EQ(console->console.charts_dir, "/tmp/c");
  EXPECT_EQ(console->console.vendor_dir, "/usr/share/javascript");  // the default
  StatusOr<ServerConfig> guarded = Load(
      "console:\n  hosts: [recog.example.com, console.lan]\n  max_connections: 64\n"
      "  max_connections_per_client: 4\n  request_timeout_ms: 5000\n");
  ASSERT_TRUE(guarded.ok()) << guarded.status().ToString();
  EXPECT_EQ(guarded->console.hosts, (std::vector<std::string>{"recog.example.com", "console.lan"}));
  EXPECT_EQ(guarded->console.max_connections, 64u);
  EXPECT_EQ(guarded->console.max_connections_per_client, 4u);
  EXPECT_EQ(guarded->console.request_timeout_ms, 5000u);
  StatusOr<ServerConfig> not_a_list = Load("console:\n  hosts: recog.example.com\n");
  ASSERT_FALSE(not_a_list.ok());
  EXPECT_THAT(not_a_list.status().message(), HasSubstr("console.hosts' must be a list"));
  StatusOr<ServerConfig> typo = Load("console:\n  listn: \"127.0.0.1:8080\"\n");
  ASSERT_FALSE(typo.ok());
  EXPECT_THAT(typo.status().message(), HasSubstr("unknown key 'console.listn'"));
  StatusOr<ServerConfig> wrong_type = Load("console:\n  loops_per_map: many\n");
  ASSERT_FALSE(wrong_type.ok());
  EXPECT_THAT(wrong_type.status().message(), HasSubstr("console.loops_per_map"));
}

TEST_F(ServerConfigTest, ValuesOfTheWrongTypeAreRejectedByName) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"workers: many\n", "key 'workers' must be a non-negative integer, got 'many'"},
      {"queue_capacity: -1\n", "key 'queue_capacity' must be a non-negative integer"},
      {"workers: 99999999999\n", "key 'workers'"},
      {"listen: [a, b]\n", "key 'listen' must be a string, got a list"},
      {"data_dir:\n", "key 'data_dir' must be a string, got nothing"},
      {"keepalive:\n  permit_without_calls: sometimes\n",
       "key 'keepalive.permit_without_calls' must be true or false"},
      {"place:\n  alpha: high\n",
       "section 'place': setting alpha = 'high': must be a finite number >= 0"},
      {"place:\n  geometry: magic\n",
       "setting geometry = 'magic': must be one of direct_index, exhaustive, none"},
      {"store:\n  sync: sometimes\n", "key 'store.sync': unknown store sync policy 'sometimes'"},
      {"tls: yes\n", "key 'tls' must be a section"},
  };
  for (const auto& [yaml, expected] : cases) {
    StatusOr<ServerConfig> config = Load(yaml);
    ASSERT_FALSE(config.ok()) << yaml;
    EXPECT_EQ(config.status().code(), StatusCode::kInvalidArgument) << yaml;
    EXPECT_THAT(config.status().message(), HasSubstr(expected)) << yaml;
  }
}

TEST_F(ServerConfigTest, MalformedYamlIsRejectedWithItsLine) {
  StatusOr<ServerConfig> syntax = Load("listen: \"127.0.0.1:1\"\nworkers: [1\n");
  ASSERT_FALSE(syntax.ok());
  EXPECT_EQ(syntax.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(syntax.status().message(), HasSubstr("not valid YAML"));
  EXPECT_THAT(syntax.status().message(), HasSubstr("line"));

  StatusOr<ServerConfig> list = Load("- listen\n- workers\n");
  ASSERT_FALSE(list.ok());
  EXPECT_THAT(list.status().message(), HasSubstr("must be a mapping"));
}

TEST_F(ServerConfigTest, MissingFileIsNotFound) {
  StatusOr<ServerConfig> config = ServerConfig::LoadYaml((dir_ / "absent.yaml").string());
  ASSERT_FALSE(config.ok());
  EXPECT_EQ(config.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(config.status().message(), HasSubstr("absent.yaml"));
}

TEST_F(ServerConfigTest, ValidateNamesTheBadField) {
  const std::vector<std::pair<std::function<void(ServerConfig&)>, std::string>> cases = {
      {[](ServerConfig& c) { c.listen = ""; }, "listen"},
      {[](ServerConfig& c) { c.data_dir = ""; }, "data_dir"},
      {[](ServerConfig& c) { c.workers = 100000; }, "workers"},
      {[](ServerConfig& c) { c.queue_capacity = 0; }, "queue_capacity"},
      {[](ServerConfig& c) { c.request_log_entries = 1000001; }, "request_log_entries"},
      {[](ServerConfig& c) { c.max_message_bytes = 1000; }, "max_message_bytes"},
      {[](ServerConfig& c) { c.max_message_bytes = 3u << 30; }, "max_message_bytes"},
      {[](ServerConfig& c) { c.keepalive.time_ms = 0; }, "keepalive.time_ms"},
      {[](ServerConfig& c) { c.keepalive.timeout_ms = 0; }, "keepalive.timeout_ms"},
      {[](ServerConfig& c) { c.tls.key = "k.pem"; }, "tls.key is set but tls.cert is not"},
      {[](ServerConfig& c) { c.tls.cert = "c.pem"; }, "tls.cert is set but tls.key is not"},
      {[](ServerConfig& c) { c.tls.client_ca = "ca.pem"; }, "tls.client_ca"},
      {[](ServerConfig& c) { c.metrics_listen = c.listen; }, "metrics_listen"},
      {[](ServerConfig& c) { c.store.group_sync_interval_ms = 0; }, "store.group_sync_interval_ms"},
      {[](ServerConfig& c) { c.store.group_sync_interval_ms = 60001; },
       "store.group_sync_interval_ms"},
      {[](ServerConfig& c) { c.store.block_cache_mb = uint64_t{1} << 30; }, "store.block_cache_mb"},
      {[](ServerConfig& c) { c.store.verify_mb_per_s = 0; }, "store.verify_mb_per_s"},
      {[](ServerConfig& c) { c.log_level = "verbose"; }, "log_level"},
      {[](ServerConfig& c) { c.shard.name = "a"; }, "shard.name and shard.placement_file"},
      {[](ServerConfig& c) {
         c.shard = {"a-b", "p.map"};
       },
       "shard.name 'a-b'"},
      {[](ServerConfig& c) { c.repository.token_file = "t"; }, "need repository.primary"},
      {[](ServerConfig& c) { c.repository.tls_ca = "ca.pem"; }, "need repository.primary"},
      {[](ServerConfig& c) { c.repository.primary = c.listen; }, "repository.primary is this"},
      {[](ServerConfig& c) { c.place.alpha = -1; }, "place.alpha = -1: must be"},
      {[](ServerConfig& c) { c.place.epipolar.min_inliers = 3; }, "place.min_inliers = 3"},
      {[](ServerConfig& c) { c.console.listen = c.listen; }, "console.listen"},
      {[](ServerConfig& c) { c.console.listen = c.metrics_listen; }, "console.listen"},
      {[](ServerConfig& c) { c.console.loops_per_map = 0; }, "console.loops_per_map"},
      {[](ServerConfig& c) { c.console.loops_per_map = 1001; }, "console.loops_per_map"},
      {[](ServerConfig& c) { c.console.max_connections = 0; }, "console.max_connections"},
      {[](ServerConfig& c) { c.console.max_connections = 1025; }, "console.max_connections"},
      {[](ServerConfig& c) { c.console.max_connections_per_client = 33; },
       "console.max_connections_per_client"},
      {[](ServerConfig& c) { c.console.max_connections_per_client = 0; },
       "console.max_connections_per_client"},
      {[](ServerConfig& c) { c.console.request_timeout_ms = 999; }, "console.request_timeout_ms"},
      {[](ServerConfig& c) { c.grpc.max_concurrent_streams = 0; }, "grpc.max_concurrent_streams"},
      {[](ServerConfig& c) { c.grpc.memory_quota_mb = 8; }, "grpc.memory_quota_mb"},
      // Fewer pending bytes than one message of max_message_bytes (32 MiB) could never take it.
      {[](ServerConfig& c) { c.grpc.pending_requests_mb = 31; }, "grpc.pending_requests_mb"},
      {[](ServerConfig& c) { c.grpc.decode_memory_mb = 15; }, "grpc.decode_memory_mb"},
      {[](ServerConfig& c) { c.grpc.max_connection_idle_ms = 999; }, "grpc.max_connection_idle_ms"},
      {[](ServerConfig& c) { c.grpc.max_connection_age_ms = 1; }, "grpc.max_connection_age_ms"},
      {[](ServerConfig& c) { c.grpc.reserve_descriptors = 8; }, "grpc.reserve_descriptors"},
      {[](ServerConfig& c) { c.console.hosts = {"a b"}; }, "console.hosts: 'a b'"},
      {[](ServerConfig& c) { c.console.header_timeout_ms = 999; }, "console.header_timeout_ms"},
      {[](ServerConfig& c) { c.console.min_bytes_per_s = (1u << 30) + 1; },
       "console.min_bytes_per_s"},
      {[](ServerConfig& c) { c.console.max_header_lines = 0; }, "console.max_header_lines"},
      {[](ServerConfig& c) { c.console.max_header_bytes = 1023; }, "console.max_header_bytes"},
      {[](ServerConfig& c) { c.console.max_body_bytes = 1000; }, "console.max_body_bytes"},
      {[](ServerConfig& c) { c.console.max_inflight_body_bytes = (16u << 20) - 1; },
       "console.max_inflight_body_bytes"},
      {[](ServerConfig& c) { c.metrics.max_connections = 0; }, "metrics.max_connections"},
      {[](ServerConfig& c) { c.metrics.max_connections_per_client = 9; },
       "metrics.max_connections_per_client"},
      {[](ServerConfig& c) { c.metrics.hosts = {"a/b"}; }, "metrics.hosts: 'a/b'"},
      {[](ServerConfig& c) { c.console.hosts = {""}; }, "console.hosts"},
  };
  for (const auto& [mutate, expected] : cases) {
    ServerConfig config;
    mutate(config);
    const Status status = config.Validate();
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << expected;
    EXPECT_THAT(status.message(), HasSubstr(expected));
  }
}

TEST_F(ServerConfigTest, ValidateAcceptsMutualTlsTwoFreePortsAndEverySpdlogLevel) {
  ServerConfig config;
  config.tls = {"c.pem", "k.pem", "ca.pem"};
  config.metrics_listen = "";
  EXPECT_TRUE(config.Validate().ok());
  config.listen = config.metrics_listen = "127.0.0.1:0";  // two free ports, no clash
  EXPECT_TRUE(config.Validate().ok());
  for (const char* level :
       {"trace", "debug", "info", "warn", "warning", "err", "error", "critical", "off"}) {
    config.log_level = level;
    EXPECT_TRUE(config.Validate().ok()) << level;
  }
}

TEST_F(ServerConfigTest, CommandLineFlagsOverrideTheFileWhereverTheyStand) {
  const std::string file = WriteFile("recogd.yaml", R"(
listen: "0.0.0.0:6000"
workers: 6
queue_capacity: 10
store:
  sync: every_write
)");
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"--config", file, "--workers", "2", "--sync", "grouped"},
        std::vector<std::string>{"--workers=2", "--sync", "grouped", "-c", file}}) {
    StatusOr<CommandLine> parsed = Parse(args);
    ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
    EXPECT_EQ(parsed->config_file, file);
    EXPECT_TRUE(parsed->help.empty());
    EXPECT_EQ(parsed->config.workers, 2u);                        // flag
    EXPECT_EQ(parsed->config.store.sync, StoreSync::kGrouped);    // flag
    EXPECT_EQ(parsed->config.listen, "0.0.0.0:6000");             // file
    EXPECT_EQ(parsed->config.queue_capacity, 10u);                // file
    EXPECT_EQ(parsed->config.data_dir, ServerConfig().data_dir);  // default
  }
}

TEST_F(ServerConfigTest, EveryFlagSetsItsField) {
  StatusOr<CommandLine> parsed = Parse({"--listen",
                                        "0.0.0.0:7000",
                                        "--data-dir",
                                        "/data",
                                        "--place-vocabulary",
                                        "p.rvoc",
                                        "--object-vocabulary",
                                        "o.rvoc",
                                        "--workers",
                                        "4",
                                        "--queue-capacity",
                                        "9",
                                        "--max-message-bytes",
                                        "4194304",
                                        "--token-file",
                                        "t.yaml",
                                        "--tls-cert",
                                        "c.pem",
                                        "--tls-key",
                                        "k.pem",
                                        "--tls-client-ca",
                                        "ca.pem",
                                        "--metrics-listen",
                                        "",
                                        "--sync",
                                        "every_write",
                                        "--recover",
                                        "point-in-time",
                                        "--shutdown-grace-ms",
                                        "0",
                                        "--log-level",
                                        "warn",
                                        "--shard-name",
                                        "shard_b",
                                        "--placement-file",
                                        "p.map",
                                        "--repository-primary",
                                        "primary:50051",
                                        "--repository-token-file",
                                        "primary.token",
                                        "--repository-tls-ca",
                                        "primary-ca.pem"});
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  const ServerConfig& c = parsed->config;
  EXPECT_EQ(parsed->config_file, "");
  EXPECT_EQ(c.listen, "0.0.0.0:7000");
  EXPECT_EQ(c.data_dir, "/data");
  EXPECT_EQ(c.place_vocabulary, "p.rvoc");
  EXPECT_EQ(c.object_vocabulary, "o.rvoc");
  EXPECT_EQ(c.workers, 4u);
  EXPECT_EQ(c.queue_capacity, 9u);
  EXPECT_EQ(c.max_message_bytes, 4194304u);
  EXPECT_EQ(c.token_file, "t.yaml");
  EXPECT_EQ(c.tls.cert, "c.pem");
  EXPECT_EQ(c.tls.key, "k.pem");
  EXPECT_EQ(c.tls.client_ca, "ca.pem");
  EXPECT_EQ(c.metrics_listen, "");
  EXPECT_EQ(c.store.sync, StoreSync::kEveryWrite);
  EXPECT_EQ(c.store.recover, StoreRecover::kPointInTime);
  EXPECT_EQ(c.shutdown_grace_ms, 0u);
  EXPECT_EQ(c.log_level, "warn");
  EXPECT_EQ(c.shard.name, "shard_b");
  EXPECT_EQ(c.shard.placement_file, "p.map");
  EXPECT_EQ(c.repository.primary, "primary:50051");
  EXPECT_EQ(c.repository.token_file, "primary.token");
  EXPECT_EQ(c.repository.tls_ca, "primary-ca.pem");
}

TEST_F(ServerConfigTest, HelpIsReturnedNotPrintedAndSkipsTheFile) {
  StatusOr<CommandLine> parsed = Parse({"--config", (dir_ / "absent.yaml").string(), "--help"});
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  EXPECT_THAT(parsed->help, HasSubstr("--listen"));
  EXPECT_THAT(parsed->help, HasSubstr("--config"));
  EXPECT_THAT(parsed->help, HasSubstr("127.0.0.1:50051"));  // defaults are shown
  EXPECT_EQ(parsed->config.listen, ServerConfig().listen);
}

TEST_F(ServerConfigTest, VersionIsReturnedAndSkipsTheFile) {
  StatusOr<CommandLine> parsed = Parse({"--config", (dir_ / "absent.yaml").string(), "--version"});
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  EXPECT_TRUE(parsed->version);
  EXPECT_TRUE(parsed->help.empty());
  StatusOr<CommandLine> plain = Parse({"--workers", "2"});
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  EXPECT_FALSE(plain->version);
  EXPECT_FALSE(plain->verify);
}

TEST_F(ServerConfigTest, VerifyIsReturnedWithTheConfigurationOfTheStoreToCheck) {
  StatusOr<CommandLine> parsed = Parse({"--verify", "--data-dir", "/srv/recog"});
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  EXPECT_TRUE(parsed->verify);
  EXPECT_EQ(parsed->config.data_dir, "/srv/recog");
}

TEST_F(ServerConfigTest, BadFlagsAreInvalidArgumentWithCli11sMessage) {
  StatusOr<CommandLine> unknown = Parse({"--wrokers", "2"});
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(unknown.status().message(), HasSubstr("--wrokers"));

  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"--workers", "many"}, std::vector<std::string>{"--workers", "-2"},
        std::vector<std::string>{"--sync", "sometimes"}, std::vector<std::string>{"--listen"}}) {
    StatusOr<CommandLine> parsed = Parse(args);
    ASSERT_FALSE(parsed.ok()) << args[0];
    EXPECT_EQ(parsed.status().code(), StatusCode::kInvalidArgument) << args[0];
    EXPECT_THAT(parsed.status().message(), HasSubstr(args[0]));
  }
}

TEST_F(ServerConfigTest, CommandLineReportsFileErrorsAndValidatesTheResult) {
  StatusOr<CommandLine> missing = Parse({"--config", (dir_ / "absent.yaml").string()});
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);

  StatusOr<CommandLine> typo = Parse({"--config", WriteFile("typo.yaml", "listne: x\n")});
  EXPECT_EQ(typo.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(typo.status().message(), HasSubstr("listne"));

  StatusOr<CommandLine> invalid = Parse({"--queue-capacity", "0"});
  EXPECT_EQ(invalid.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(invalid.status().message(), HasSubstr("queue_capacity"));

  const std::string key_only = WriteFile("key_only.yaml", "tls:\n  key: k.pem\n");
  EXPECT_EQ(Parse({"--config", key_only}).status().code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(Parse({"--config", key_only, "--tls-cert", "c.pem"}).ok());
}

}  // namespace
}  // namespace recog::server
