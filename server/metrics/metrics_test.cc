#include "server/metrics/metrics.h"

#include <arpa/inet.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <filesystem>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "recog_build_info.h"

namespace recog::server {
namespace {

using ::testing::DoubleNear;
using ::testing::HasSubstr;
using ::testing::Not;
using ::testing::Optional;

constexpr char kQueryPlace[] = "/recognition.v1.PlaceRecognition/QueryPlace";

// The value of the sample `series` (name and labels exactly as serialised) in `text`, if present.
std::optional<double> Sample(const std::string& text, const std::string& series) {
  std::istringstream lines(text);
  std::string line;
  while (std::getline(lines, line)) {
    if (line.rfind(series + " ", 0) == 0) return std::stod(line.substr(series.size() + 1));
  }
  return std::nullopt;
}

// A blocking HTTP/1.0 GET of `path` on 127.0.0.1:`port`; the whole response, empty on failure.
std::string HttpGet(int port, const std::string& path) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return "";
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  std::string response;
  if (::connect(fd, reinterpret_cast<const sockaddr*>(&address), sizeof(address)) == 0) {
    const std::string request = "GET " + path + " HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n";
    if (::send(fd, request.data(), request.size(), MSG_NOSIGNAL) ==
        static_cast<ssize_t>(request.size())) {
      char buffer[4096];
      ssize_t n;
      while ((n = ::recv(fd, buffer, sizeof(buffer), 0)) > 0) response.append(buffer, n);
    }
  }
  ::close(fd);
  return response;
}

TEST(ServerMetricsTest, RpcDurationsAreHistogramsByMethodAndCode) {
  ServerMetrics metrics;
  metrics.ObserveRpc(kQueryPlace, "OK", 0.003);
  metrics.ObserveRpc(kQueryPlace, "OK", 0.2);
  metrics.ObserveRpc(kQueryPlace, "NOT_FOUND", 0.0005);
  const std::string text = metrics.Serialize();
  const std::string ok = std::string("{code=\"OK\",method=\"") + kQueryPlace + "\"";
  const std::string not_found = std::string("{code=\"NOT_FOUND\",method=\"") + kQueryPlace + "\"";
  EXPECT_THAT(text, HasSubstr("# TYPE recog_rpc_duration_seconds histogram"));
  EXPECT_THAT(Sample(text, "recog_rpc_duration_seconds_count" + ok + "}"), Optional(2.0));
  EXPECT_THAT(Sample(text, "recog_rpc_duration_seconds_sum" + ok + "}"),
              Optional(DoubleNear(0.203, 1e-9)));
  EXPECT_THAT(Sample(text, "recog_rpc_duration_seconds_bucket" + ok + ",le=\"0.001\"}"),
              Optional(0.0));
  EXPECT_THAT(Sample(text, "recog_rpc_duration_seconds_bucket" + ok + ",le=\"0.005\"}"),
              Optional(1.0));
  EXPECT_THAT(Sample(text, "recog_rpc_duration_seconds_bucket" + ok + ",le=\"10\"}"),
              Optional(2.0));
  EXPECT_THAT(Sample(text, "recog_rpc_duration_seconds_bucket" + ok + ",le=\"+Inf\"}"),
              Optional(2.0));
  EXPECT_THAT(Sample(text, "recog_rpc_duration_seconds_bucket" + not_found + ",le=\"0.001\"}"),
              Optional(1.0));
  EXPECT_THAT(Sample(text, "recog_rpc_duration_seconds_count" + not_found + "}"), Optional(1.0));
}

TEST(ServerMetricsTest, RegisteredMethodsGetTheStandardGrpcSeries) {
  ServerMetrics metrics;
  constexpr char kStream[] = "/recognition.v1.PlaceRecognition/StreamFrames";
  metrics.RegisterRpc(kQueryPlace, RpcType::kUnary);
  metrics.RegisterRpc(kStream, RpcType::kBidiStream);
  metrics.RegisterRpc(kQueryPlace, RpcType::kUnary);  // again: nothing changes
  metrics.RpcStarted(kQueryPlace);
  metrics.MessageReceived(kQueryPlace);
  metrics.MessageSent(kQueryPlace);
  metrics.ObserveRpc(kQueryPlace, "OK", 0.02);
  metrics.RpcStarted(kQueryPlace);
  metrics.MessageReceived(kQueryPlace);
  metrics.ObserveRpc(kQueryPlace, "NOT_FOUND", 0.001);
  metrics.RpcStarted(kStream);
  metrics.MessageReceived(kStream);
  metrics.MessageReceived(kStream);
  metrics.ObserveRpc(std::string(kStream) + "#frame", "OK", 0.01);  // a frame, not a call
  // Not registered: only the project's own histogram.
  metrics.RpcStarted("/grpc.health.v1.Health/Check");
  metrics.ObserveRpc("/grpc.health.v1.Health/Check", "OK", 0.001);

  const std::string text = metrics.Serialize();
  const std::string query =
      "grpc_method=\"QueryPlace\",grpc_service=\"recognition.v1.PlaceRecognition\","
      "grpc_type=\"unary\"}";
  const std::string stream =
      "grpc_method=\"StreamFrames\",grpc_service=\"recognition.v1.PlaceRecognition\","
      "grpc_type=\"bidi_stream\"}";
  EXPECT_THAT(text, HasSubstr("# TYPE grpc_server_handling_seconds histogram"));
  EXPECT_THAT(Sample(text, "grpc_server_started_total{" + query), Optional(2.0));
  EXPECT_THAT(Sample(text, "grpc_server_handled_total{grpc_code=\"OK\"," + query), Optional(1.0));
  EXPECT_THAT(Sample(text, "grpc_server_handled_total{grpc_code=\"NOT_FOUND\"," + query),
              Optional(1.0));
  EXPECT_THAT(Sample(text, "grpc_server_msg_received_total{" + query), Optional(2.0));
  EXPECT_THAT(Sample(text, "grpc_server_msg_sent_total{" + query), Optional(1.0));
  EXPECT_THAT(Sample(text, "grpc_server_handling_seconds_count{" + query), Optional(2.0));
  EXPECT_THAT(Sample(text, "grpc_server_handling_seconds_sum{" + query),
              Optional(DoubleNear(0.021, 1e-9)));
  EXPECT_THAT(Sample(text, "grpc_server_started_total{" + stream), Optional(1.0));
  EXPECT_THAT(Sample(text, "grpc_server_msg_received_total{" + stream), Optional(2.0));
  EXPECT_THAT(Sample(text, "grpc_server_handling_seconds_count{" + stream), Optional(0.0));
  EXPECT_THAT(text, Not(HasSubstr("grpc_service=\"grpc.health.v1.Health\"")));
  EXPECT_THAT(text, Not(HasSubstr("grpc_method=\"StreamFrames#frame\"")));
  EXPECT_THAT(text,
              HasSubstr("recog_rpc_duration_seconds_count{code=\"OK\",method=\"/grpc.health"));
}

TEST(ServerMetricsTest, ConcurrentRpcObservationsAreAllCounted) {
  ServerMetrics metrics;
  constexpr int kThreads = 4, kCalls = 2000;
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&metrics, t] {
      for (int i = 0; i < kCalls; ++i) {
        metrics.ObserveRpc(i % 2 == 0 ? kQueryPlace : "/recognition.v1.Maps/ListMaps",
                           t % 2 == 0 ? "OK" : "UNAVAILABLE", 0.01);
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  const std::string text = metrics.Serialize();
  for (const char* code : {"OK", "UNAVAILABLE"}) {
    for (const char* method : {kQueryPlace, "/recognition.v1.Maps/ListMaps"}) {
      const std::string series = std::string("recog_rpc_duration_seconds_count{code=\"") + code +
                                 "\",method=\"" + method + "\"}";
      EXPECT_THAT(Sample(text, series), Optional(double{kThreads / 2 * kCalls / 2})) << series;
    }
  }
}

TEST(ServerMetricsTest, CountersAccumulate) {
  ServerMetrics metrics;
  metrics.AddFrames(FrameKind::kPlace);
  metrics.AddFrames(FrameKind::kPlace, 4);
  metrics.AddFrames(FrameKind::kObject, 2);
  metrics.AddLoopDetections();
  metrics.AddObjectDetections(3);
  metrics.AddReplicaChanges();
  metrics.AddReplicaChanges(2);
  const std::string text = metrics.Serialize();
  EXPECT_THAT(text, HasSubstr("# TYPE recog_frames_total counter"));
  EXPECT_THAT(Sample(text, "recog_frames_total{kind=\"place\"}"), Optional(5.0));
  EXPECT_THAT(Sample(text, "recog_frames_total{kind=\"object\"}"), Optional(2.0));
  EXPECT_THAT(Sample(text, "recog_loop_detections_total"), Optional(1.0));
  EXPECT_THAT(Sample(text, "recog_object_detections_total"), Optional(3.0));
  EXPECT_THAT(Sample(text, "recog_replica_changes_total"), Optional(3.0));
}

TEST(ServerMetricsTest, GaugesHoldTheLastValue) {
  ServerMetrics metrics;
  metrics.SetWorkerQueueDepth(7);
  metrics.SetWorkerQueueDepth(3);
  metrics.SetBusyWorkers(2);
  metrics.SetObjects(11);
  EXPECT_THAT(Sample(metrics.Serialize(), "recog_replica_synced"), Optional(0.0));
  EXPECT_THAT(Sample(metrics.Serialize(), "recog_store_recovery_lost{kind=\"entries\"}"),
              Optional(0.0));
  metrics.SetReplicaSynced(true);
  metrics.SetStoreRecoveryLoss(19, 1, 2);
  metrics.StoreVerified(false, 1000, 0.5);
  metrics.StoreVerified(true, 500, 0.25);
  const std::string text = metrics.Serialize();
  EXPECT_THAT(text, HasSubstr("# TYPE recog_worker_queue_depth gauge"));
  EXPECT_THAT(Sample(text, "recog_worker_queue_depth"), Optional(3.0));
  EXPECT_THAT(Sample(text, "recog_worker_busy"), Optional(2.0));
  EXPECT_THAT(Sample(text, "recog_objects"), Optional(11.0));
  EXPECT_THAT(Sample(text, "recog_replica_synced"), Optional(1.0));
  EXPECT_THAT(Sample(text, "recog_store_recovery_lost{kind=\"entries\"}"), Optional(19.0));
  EXPECT_THAT(Sample(text, "recog_store_recovery_lost{kind=\"maps\"}"), Optional(1.0));
  EXPECT_THAT(Sample(text, "recog_store_recovery_lost{kind=\"blobs\"}"), Optional(2.0));
  EXPECT_THAT(Sample(text, "recog_store_damaged"), Optional(1.0));
  EXPECT_THAT(Sample(text, "recog_store_verified_bytes_total"), Optional(1500.0));
  EXPECT_THAT(Sample(text, "recog_store_verify_seconds"), Optional(0.25));
}

TEST(ServerMetricsTest, BuildInfoIsOneSeriesLabelledWithTheVersionAndCommit) {
  ServerMetrics metrics;
  const std::string text = metrics.Serialize();
  EXPECT_THAT(text, HasSubstr("# TYPE recog_build_info gauge"));
  // Labels are serialised in name order.
  EXPECT_THAT(Sample(text, std::string("recog_build_info{commit=\"") + build_info::kCommit +
                               "\",version=\"" + build_info::kVersion + "\"}"),
              Optional(1.0));
  EXPECT_THAT(std::string(build_info::kVersion),
              ::testing::MatchesRegex("[0-9]+\\.[0-9]+\\.[0-9]+"));
}

TEST(ServerMetricsTest, MapEntriesHaveOneSeriesPerMapUntilTheMapIsRemoved) {
  ServerMetrics metrics;
  metrics.SetMapEntries("corridor", 10);
  metrics.SetMapEntries("corridor", 12);
  metrics.SetMapEntries("lab", 4);
  metrics.SetMapIndexOpening("corridor", true, 2);
  metrics.SetMapIndexOpening("lab", false, 4);
  std::string text = metrics.Serialize();
  EXPECT_THAT(Sample(text, "recog_map_index_from_snapshot{map=\"corridor\"}"), Optional(1.0));
  EXPECT_THAT(Sample(text, "recog_map_frames_read_at_start{map=\"corridor\"}"), Optional(2.0));
  EXPECT_THAT(Sample(text, "recog_map_index_from_snapshot{map=\"lab\"}"), Optional(0.0));
  EXPECT_THAT(Sample(text, "recog_map_frames_read_at_start{map=\"lab\"}"), Optional(4.0));
  EXPECT_THAT(Sample(text, "recog_map_entries{map=\"corridor\"}"), Optional(12.0));
  EXPECT_THAT(Sample(text, "recog_map_entries{map=\"lab\"}"), Optional(4.0));

  metrics.RemoveMap("corridor");
  metrics.RemoveMap("never-existed");
  text = metrics.Serialize();
  EXPECT_THAT(text, Not(HasSubstr("corridor")));
  EXPECT_THAT(Sample(text, "recog_map_entries{map=\"lab\"}"), Optional(4.0));
}

TEST(ServerMetricsTest, ActiveStreamsAreCountedPerRpc) {
  ServerMetrics metrics;
  metrics.StreamOpened("StreamFrames");
  metrics.StreamOpened("StreamFrames");
  metrics.StreamOpened("StreamObjects");
  metrics.StreamClosed("StreamFrames");
  const std::string text = metrics.Serialize();
  EXPECT_THAT(Sample(text, "recog_stream_active{rpc=\"StreamFrames\"}"), Optional(1.0));
  EXPECT_THAT(Sample(text, "recog_stream_active{rpc=\"StreamObjects\"}"), Optional(1.0));
}

TEST(ServerMetricsTest, HttpEndpointServesTheMetricsOnAnEphemeralPort) {
  ServerMetrics metrics;
  EXPECT_EQ(metrics.HttpPort(), 0);
  ASSERT_TRUE(metrics.StartHttp("127.0.0.1:0").ok());
  const int port = metrics.HttpPort();
  ASSERT_GT(port, 0);
  metrics.AddFrames(FrameKind::kObject, 6);
  const std::string response = HttpGet(port, "/metrics");
  EXPECT_THAT(response, HasSubstr("200 OK"));
  EXPECT_THAT(response, HasSubstr("recog_frames_total{kind=\"object\"} 6"));

  const Status again = metrics.StartHttp("127.0.0.1:0");
  EXPECT_EQ(again.code(), StatusCode::kFailedPrecondition);
}

TEST(ServerMetricsTest, TheDiskMetricsReportTheWatchedFileSystemAtEachScrape) {
  ServerMetrics metrics;
  ASSERT_TRUE(metrics.StartHttp("127.0.0.1:0").ok());
  EXPECT_THAT(metrics.Serialize(), Not(HasSubstr("recog_store_disk")));  // nothing watched
  const std::filesystem::path dir = std::filesystem::temp_directory_path();
  metrics.WatchDisk(dir.string());
  const std::filesystem::space_info space = std::filesystem::space(dir);
  const std::string text = HttpGet(metrics.HttpPort(), "/metrics");
  const std::optional<double> capacity = Sample(text, "recog_store_disk_capacity_bytes");
  const std::optional<double> available = Sample(text, "recog_store_disk_available_bytes");
  EXPECT_THAT(capacity, Optional(double(space.capacity)));
  ASSERT_TRUE(available.has_value()) << text;
  // Other processes write meanwhile: within 1 GiB of what this test read.
  EXPECT_NEAR(*available, double(space.available), double(1 << 30));
  EXPECT_LE(*available, *capacity);
  EXPECT_THAT(metrics.Serialize(), HasSubstr("# TYPE recog_store_disk_available_bytes gauge"));
  metrics.WatchDisk((dir / "no-such-directory-for-recog").string());
  EXPECT_THAT(metrics.Serialize(), Not(HasSubstr("recog_store_disk")));  // unreadable: absent
}

TEST(ServerMetricsTest, ABusyPortIsUnavailableNotAnException) {
  ServerMetrics first;
  ASSERT_TRUE(first.StartHttp("127.0.0.1:0").ok());
  const std::string address = "127.0.0.1:" + std::to_string(first.HttpPort());

  ServerMetrics second;
  const Status status = second.StartHttp(address);
  EXPECT_EQ(status.code(), StatusCode::kUnavailable);
  EXPECT_THAT(status.message(), HasSubstr(address));
  EXPECT_EQ(second.HttpPort(), 0);
  // The failure leaves the second instance free to serve elsewhere.
  EXPECT_TRUE(second.StartHttp("127.0.0.1:0").ok());
}

TEST(ServerMetricsTest, AnEmptyAddressIsInvalid) {
  ServerMetrics metrics;
  EXPECT_EQ(metrics.StartHttp("").code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace recog::server
