// Loopback tests of what surrounds the RPCs: health, authentication and TLS, metrics, draining on
// shutdown, a kill -9 in the middle of a stream, and network results equal to the offline tools'.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <fstream>
#include <future>
#include <thread>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/vocabulary/vocabulary_io.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "server/api/place_converters.h"
#include "tests/server/server_fixture.h"
#include "tests/testing/metrics_scrape.h"
#include "tests/testing/test_data.h"
#include "tests/testing/unix_socket.h"
#include "tests/testing/wait.h"
#include "tools/evaluation/ground_truth.h"
#include "tools/evaluation/place_evaluation.h"

extern char** environ;

namespace recog::server::testing {
namespace {

using recog::testing::FetchMetrics;
using recog::testing::WaitUntil;

constexpr char kRobotToken[] = "robot-token-0123456789";
constexpr char kOperatorToken[] = "operator-token-0123456789";

namespace health = ::grpc::health::v1;

// grpc.health.v1.Health/Check of `service`: SERVING = 1, NOT_SERVING = 2; -1 when the call fails.
int HealthStatus(const std::shared_ptr<grpc::Channel>& channel, const std::string& service = "") {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  health::HealthCheckRequest request;
  request.set_service(service);
  health::HealthCheckResponse response;
  if (!health::Health::NewStub(channel)->Check(&context, request, &response).ok()) return -1;
  return response.status();
}

// grpc.health.v1.Health/Watch of `service`: the status now, then each change.
class HealthWatch {
 public:
  explicit HealthWatch(const std::shared_ptr<grpc::Channel>& channel,
                       const std::string& service = "")
      : stub_(health::Health::NewStub(channel)) {
    health::HealthCheckRequest request;
    request.set_service(service);
    call_ = stub_->AsyncWatch(&context_, request, &queue_, Tag(1));
    started_ = Await(1);
  }
  ~HealthWatch() {
    context_.TryCancel();
    call_->Finish(&status_, Tag(9));
    queue_.Shutdown();
    void* tag;
    bool ok;
    while (queue_.Next(&tag, &ok)) {
    }
  }

  // The next status sent (SERVING = 1, NOT_SERVING = 2, SERVICE_UNKNOWN = 3); -1 when the stream
  // has ended or nothing comes within 10 s.
  int Next() {
    if (!started_) return -1;
    health::HealthCheckResponse response;
    call_->Read(&response, Tag(4));
    if (!Await(4)) return -1;
    return response.status();
  }

 private:
  static void* Tag(intptr_t n) { return reinterpret_cast<void*>(n); }
  bool Await(intptr_t expected) {
    void* tag = nullptr;
    bool ok = false;
    const auto deadline = std::chrono::system_clock::now() + std::chrono::seconds(10);
    return queue_.AsyncNext(&tag, &ok, deadline) == grpc::CompletionQueue::GOT_EVENT && ok &&
           tag == Tag(expected);
  }

  std::unique_ptr<health::Health::Stub> stub_;
  grpc::ClientContext context_;
  grpc::CompletionQueue queue_;
  std::unique_ptr<grpc::ClientAsyncReader<health::HealthCheckResponse>> call_;
  grpc::Status status_;
  bool started_ = false;
};

class ServerLifecycleTest : public ServerFixture {};

TEST_F(ServerLifecycleTest, HealthReportsServingAndTheMetricsEndpointCountsCalls) {
  EXPECT_EQ(HealthStatus(channel_), 1);
  StopServer();
  config().metrics_listen = "127.0.0.1:0";
  StartServer();
  ASSERT_TRUE(CreateMap("m").ok());
  EXPECT_EQ(CreateMap("m").error_code(), grpc::StatusCode::ALREADY_EXISTS);
  pb::AddFrameResponse added;
  ASSERT_TRUE(AddFrame("m", JpegFrame(CorridorJpeg(1)), &added).ok());
  const std::string metrics = FetchMetrics(server_->metrics_port());
  EXPECT_NE(metrics.find("recog_rpc_duration_seconds_count{code=\"OK\",method=\"/recognition.v1."
                         "PlaceRecognition/CreateMap\"} 1"),
            std::string::npos)
      << metrics;
  EXPECT_NE(metrics.find("code=\"ALREADY_EXISTS\""), std::string::npos);
  EXPECT_NE(metrics.find("recog_frames_total{kind=\"place\"} 1"), std::string::npos);
  EXPECT_NE(metrics.find("recog_map_entries{map=\"m\"} 1"), std::string::npos);
}

// A second recogd given a port of a running one must not share it (the kernel would hand each new
// connection to either server, whatever their data): it refuses to start and says why. Its gRPC
// port, its metrics port and its console's are each checked.
TEST_F(ServerLifecycleTest, ASecondServerOnAPortInUseRefusesToStart) {
  StopServer();
  config().metrics_listen = "127.0.0.1:0";
  config().console.listen = "127.0.0.1:0";
  StartServer();
  const auto on_port = [](int port) { return "127.0.0.1:" + std::to_string(port); };
  const auto refused = [&](const std::string& what, ServerConfig second) {
    recog::testing::TempDir second_dir("second");
    second.data_dir = second_dir.path().string();
    auto started = RecognitionServer::Start(second);
    ASSERT_FALSE(started.ok()) << what;
    EXPECT_EQ(started.status().code(), StatusCode::kUnavailable) << what;
    EXPECT_NE(started.status().message().find("in use"), std::string::npos)
        << what << ": " << started.status().ToString();
  };
  ServerConfig second = config();
  second.listen = on_port(server_->port());
  refused("gRPC", second);
  second = config();
  second.metrics_listen = on_port(server_->metrics_port());
  refused("metrics", second);
  second = config();
  second.console.listen = on_port(server_->console_port());
  refused("console", second);
  EXPECT_EQ(HealthStatus(channel_), 1);  // the first one still serves
}

// The store's CURRENT file (the name of its manifest, read by every RocksDB open) is replaced by a
// FIFO: opening the store blocks on it until the test writes the saved content, so the server is
// seen listening before its store is open.
TEST_F(ServerLifecycleTest, HealthIsNotServingUntilTheStoreIsOpen) {
  ASSERT_TRUE(CreateMap("kept").ok());
  StopServer();
  const std::string current = data_dir_.Sub("store/CURRENT");
  const std::string manifest = ReadFileBytes(current);
  ASSERT_FALSE(manifest.empty());
  ASSERT_EQ(std::remove(current.c_str()), 0);
  ASSERT_EQ(mkfifo(current.c_str(), 0600), 0);
  const recog::testing::TempDir socket_dir("socket");
  const std::string listen = recog::testing::UnixSocketAddress(socket_dir.path());
  config().listen = listen;
  std::atomic<bool> started = false;
  auto start = std::async(std::launch::async, [&] {
    auto server = RecognitionServer::Start(config());
    started = true;
    return server;
  });
  auto channel = grpc::CreateChannel(listen, grpc::InsecureChannelCredentials());
  ASSERT_TRUE(
      channel->WaitForConnected(std::chrono::system_clock::now() + std::chrono::seconds(10)));
  EXPECT_EQ(HealthStatus(channel), 2);
  EXPECT_EQ(HealthStatus(channel, RecognitionServer::kStoreHealthService), 2);
  HealthWatch watch(channel);
  EXPECT_EQ(watch.Next(), 2);
  auto stub = pb::PlaceRecognition::NewStub(channel);
  pb::ListMapsResponse listed;
  EXPECT_EQ(stub->ListMaps(Context().get(), {}, &listed).error_code(),
            grpc::StatusCode::UNAVAILABLE);
  EXPECT_FALSE(started);

  // Feed the manifest's name to every reader of the FIFO until RocksDB replaces it with a file.
  std::thread feeder([&] {
    while (!started) {
      const int fd = open(current.c_str(), O_WRONLY | O_NONBLOCK);  // ENXIO while nobody reads
      if (fd < 0) {
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
        continue;
      }
      struct stat info {};
      if (fstat(fd, &info) == 0 && S_ISFIFO(info.st_mode)) {
        const int flags = fcntl(fd, F_GETFL);
        fcntl(fd, F_SETFL, flags & ~O_NONBLOCK);
        EXPECT_EQ(write(fd, manifest.data(), manifest.size()), ssize_t(manifest.size()));
      }
      close(fd);
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  });
  EXPECT_EQ(watch.Next(), 1);  // SERVING once the store is open
  auto server = start.get();
  feeder.join();
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  server_ = std::move(server).value();
  EXPECT_EQ(HealthStatus(channel), 1);
  ASSERT_TRUE(stub->ListMaps(Context().get(), {}, &listed).ok());
  ASSERT_EQ(listed.maps_size(), 1);
  EXPECT_EQ(listed.maps(0).name(), "kept");
}

TEST_F(ServerLifecycleTest, HealthAnswersForTheServerAndTheStoreAndRefusesOtherNames) {
  EXPECT_EQ(HealthStatus(channel_), 1);
  EXPECT_EQ(HealthStatus(channel_, RecognitionServer::kStoreHealthService), 1);
  grpc::ClientContext context;
  health::HealthCheckRequest request;
  request.set_service("recog.nothing");
  health::HealthCheckResponse response;
  EXPECT_EQ(health::Health::NewStub(channel_)->Check(&context, request, &response).error_code(),
            grpc::StatusCode::NOT_FOUND);
  HealthWatch unknown(channel_, "recog.nothing");
  EXPECT_EQ(unknown.Next(), health::HealthCheckResponse::SERVICE_UNKNOWN);
  HealthWatch store(channel_, RecognitionServer::kStoreHealthService);
  EXPECT_EQ(store.Next(), 1);
}

TEST_F(ServerLifecycleTest, DrainingAnswersNotServingAndRefusesNewCalls) {
  ASSERT_TRUE(CreateMap("busy").ok());
  HealthWatch watch(channel_);
  ASSERT_EQ(watch.Next(), 1);
  grpc::ClientContext context;
  auto stream = places_->StreamFrames(&context);
  pb::StreamFramesRequest request;
  request.mutable_config()->set_map("busy");
  ASSERT_TRUE(stream->Write(request));
  *request.mutable_frame() = JpegFrame(CorridorJpeg(1));
  ASSERT_TRUE(stream->Write(request));
  pb::StreamFramesResponse response;
  ASSERT_TRUE(stream->Read(&response));
  // The open stream, waiting for its next frame, holds the drain for its whole grace period. The
  // pause lets the server finish the answer's write first: a stream whose write completes after
  // the drain began ends there (every frame sent was answered), and nothing would hold the drain.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  auto shutdown =
      std::async(std::launch::async, [&] { server_->Shutdown(std::chrono::milliseconds(3000)); });
  EXPECT_EQ(watch.Next(), 2);
  EXPECT_EQ(watch.Next(), -1) << "the health watch did not end with the drain's NOT_SERVING";
  // Once the drain is under way a new client is refused (the listener is closed), and so is a new
  // call on a connection opened before it. A call that arrives in the very instant gRPC begins its
  // shutdown may be CANCELLED instead: that one is sent again.
  pb::ListMapsResponse listed;
  auto fresh = pb::PlaceRecognition::NewStub(grpc::CreateChannel(
      "127.0.0.1:" + std::to_string(server_->port()), grpc::InsecureChannelCredentials()));
  const auto refusal = [&](pb::PlaceRecognition::Stub& stub) {
    grpc::StatusCode code = grpc::StatusCode::CANCELLED;
    EXPECT_TRUE(WaitUntil([&] {
      code = stub.ListMaps(Context().get(), {}, &listed).error_code();
      return code != grpc::StatusCode::CANCELLED;
    })) << "every ListMaps was cancelled";
    return code;
  };
  EXPECT_EQ(refusal(*fresh), grpc::StatusCode::UNAVAILABLE);
  EXPECT_EQ(refusal(*places_), grpc::StatusCode::UNAVAILABLE);
  EXPECT_EQ(shutdown.wait_for(std::chrono::milliseconds(0)), std::future_status::timeout)
      << "the drain ended before the checks: they did not run during it";
  shutdown.get();
  EXPECT_FALSE(stream->Finish().ok());
}

// One worker kept busy by large frames (seconds of decoding and ORB); a call whose deadline passes
// while it waits behind them ends with DEADLINE_EXCEEDED and its frame is never added.
TEST_F(ServerLifecycleTest, ACallWhoseDeadlinePassesInTheQueueDoesNotRun) {
  StopServer();
  config().workers = 1;
  config().metrics_listen = "127.0.0.1:0";
  StartServer();
  ASSERT_TRUE(CreateMap("queued").ok());
  const std::string jpeg = CorridorJpeg(1);
  const cv::Mat small =
      cv::imdecode(std::vector<uchar>(jpeg.begin(), jpeg.end()), cv::IMREAD_COLOR);
  ASSERT_FALSE(small.empty());
  std::vector<uchar> big;
  // 4096x3072, the largest robots' cameras give (an image may have 16 Mpixel).
  ASSERT_TRUE(cv::imencode(".jpg", cv::repeat(small, 8, 8), big));
  const pb::Frame large = JpegFrame(std::string(big.begin(), big.end()));
  // Six of them: seconds of work on one worker (decoding and ORB on 12.6 Mpixel take several
  // hundred ms each). The queued call is sent once the first has ended with at least two still
  // waiting (the queue-depth gauge is sampled as each call ends), so it waits far beyond its 300 ms
  // deadline however loaded the machine is.
  std::vector<std::future<grpc::Status>> busy;
  for (int i = 0; i < 6; ++i) {
    busy.push_back(std::async(std::launch::async, [&] {
      pb::AddFrameResponse added;
      return AddFrame("queued", large, &added);
    }));
  }
  const auto waiting = [&] {
    const std::string metrics = FetchMetrics(server_->metrics_port());
    const size_t at = metrics.find("\nrecog_worker_queue_depth ");
    return at == std::string::npos ? 0.0 : std::atof(metrics.c_str() + at + 26);
  };
  ASSERT_TRUE(WaitUntil([&] { return waiting() >= 2; })) << "the large frames never queued";
  pb::AddFrameRequest request;
  request.set_map("queued");
  *request.mutable_frame() = JpegFrame(CorridorJpeg(20));
  pb::AddFrameResponse added;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(300));
  EXPECT_EQ(places_->AddFrame(&context, request, &added).error_code(),
            grpc::StatusCode::DEADLINE_EXCEEDED);
  for (auto& call : busy) EXPECT_TRUE(call.get().ok());
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("queued", &info).ok());
  EXPECT_EQ(info.frames(), 6u);  // the large frames only
  // The server ended the queued call itself, with DEADLINE_EXCEEDED, once a worker took it.
  const std::string metrics = FetchMetrics(server_->metrics_port());
  EXPECT_NE(metrics.find("recog_rpc_duration_seconds_count{code=\"DEADLINE_EXCEEDED\",method=\"/"
                         "recognition.v1.PlaceRecognition/AddFrame\"} 1"),
            std::string::npos)
      << metrics;
}

TEST_F(ServerLifecycleTest, TokensDecideWhoMayReadAndWhoMayWrite) {
  const std::string token_file = data_dir_.Sub("tokens.yaml");
  std::ofstream(token_file) << "tokens:\n"
                            << "  - {name: robot-7, token: \"" << kRobotToken
                            << "\", rights: [read]}\n"
                            << "  - {name: operator, token: \"" << kOperatorToken
                            << "\", rights: [read, write]}\n";
  StopServer();
  config().token_file = token_file;
  StartServer();
  pb::CreateMapRequest create;
  create.set_name("shared");
  pb::CreateMapResponse created;
  EXPECT_EQ(places_->CreateMap(Context().get(), create, &created).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(
      places_->CreateMap(Context("wrong-token-0123456789").get(), create, &created).error_code(),
      grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(places_->CreateMap(Context(kRobotToken).get(), create, &created).error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
  ASSERT_TRUE(places_->CreateMap(Context(kOperatorToken).get(), create, &created).ok());
  pb::ListMapsResponse listed;
  ASSERT_TRUE(places_->ListMaps(Context(kRobotToken).get(), {}, &listed).ok());
  EXPECT_EQ(listed.maps_size(), 1);

  // A robot with the read right may look places up but not add them.
  pb::QueryPlaceRequest query;
  query.set_map("shared");
  *query.mutable_frame() = JpegFrame(CorridorJpeg(1));
  pb::QueryPlaceResponse answer;
  EXPECT_TRUE(places_->QueryPlace(Context(kRobotToken).get(), query, &answer).ok());
  query.set_add_frame(true);
  EXPECT_EQ(places_->QueryPlace(Context(kRobotToken).get(), query, &answer).error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
  for (const bool query_only : {false, true}) {
    auto context = Context(kRobotToken);
    auto stream = places_->StreamFrames(context.get());
    pb::StreamFramesRequest request;
    request.mutable_config()->set_map("shared");
    request.mutable_config()->set_query_only(query_only);
    stream->Write(request);
    *request.mutable_frame() = JpegFrame(CorridorJpeg(1));
    stream->Write(request);
    pb::StreamFramesResponse response;
    const bool answered = stream->Read(&response);
    stream->WritesDone();
    const grpc::Status status = stream->Finish();
    EXPECT_EQ(answered, query_only);
    EXPECT_EQ(status.error_code(),
              query_only ? grpc::StatusCode::OK : grpc::StatusCode::PERMISSION_DENIED);
  }
  pb::DeleteModelRequest remove;
  remove.set_name("anything");
  pb::DeleteModelResponse removed;
  EXPECT_EQ(models_->DeleteModel(Context(kRobotToken).get(), remove, &removed).error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(models_->DeleteModel(Context(kOperatorToken).get(), remove, &removed).error_code(),
            grpc::StatusCode::NOT_FOUND);
  pb::GetUploadStatusRequest upload;  // part of an upload: the write right
  upload.set_sha256(std::string(64, 'a'));
  upload.set_size_bytes(10);
  pb::GetUploadStatusResponse progress;
  EXPECT_EQ(models_->GetUploadStatus(Context(kRobotToken).get(), upload, &progress).error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_TRUE(models_->GetUploadStatus(Context(kOperatorToken).get(), upload, &progress).ok());
}

TEST_F(ServerLifecycleTest, MutualTlsAdmitsOnlyClientsWithACertificateFromTheCa) {
  const auto tls = [](const std::string& name) {
    return ReadFileBytes(recog::testing::ProjectTestData("tls/" + name));
  };
  StopServer();
  config().tls.cert = recog::testing::ProjectTestData("tls/server.crt");
  config().tls.key = recog::testing::ProjectTestData("tls/server.key");
  config().tls.client_ca = recog::testing::ProjectTestData("tls/ca.crt");
  StartServer();
  const std::string target = "localhost:" + std::to_string(server_->port());
  grpc::SslCredentialsOptions with_cert{tls("ca.crt"), tls("client.key"), tls("client.crt")};
  grpc::SslCredentialsOptions without_cert{tls("ca.crt"), "", ""};
  for (const bool present : {true, false}) {
    auto channel =
        grpc::CreateChannel(target, grpc::SslCredentials(present ? with_cert : without_cert));
    auto stub = pb::PlaceRecognition::NewStub(channel);
    pb::ListMapsResponse listed;
    const grpc::Status status = stub->ListMaps(Context().get(), {}, &listed);
    EXPECT_EQ(status.ok(), present) << status.error_message();
  }
  // A plaintext client cannot talk to a TLS server.
  auto plain = pb::PlaceRecognition::NewStub(
      grpc::CreateChannel(target, grpc::InsecureChannelCredentials()));
  pb::ListMapsResponse listed;
  EXPECT_FALSE(plain->ListMaps(Context().get(), {}, &listed).ok());
}

TEST_F(ServerLifecycleTest, ShutdownDrainsAStreamWithoutLosingAnsweredFrames) {
  ASSERT_TRUE(CreateMap("drained").ok());
  grpc::ClientContext context;
  auto stream = places_->StreamFrames(&context);
  pb::StreamFramesRequest request;
  request.mutable_config()->set_map("drained");
  ASSERT_TRUE(stream->Write(request));
  for (int n : {1, 20}) {
    *request.mutable_frame() = JpegFrame(CorridorJpeg(n));
    ASSERT_TRUE(stream->Write(request));
    pb::StreamFramesResponse response;
    ASSERT_TRUE(stream->Read(&response));
  }
  const auto start = std::chrono::steady_clock::now();
  server_->Shutdown(std::chrono::milliseconds(500));  // the idle stream is cut at the deadline
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(10));
  EXPECT_FALSE(stream->Finish().ok());
  RestartServer();
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("drained", &info).ok());
  EXPECT_EQ(info.frames(), 2u);
}

// A clean stop writes each changed map's index snapshot; the next start loads it instead of
// reading every frame (the metrics say which), and the map answers as before.
TEST_F(ServerLifecycleTest, ARestartLoadsEachMapsIndexFromTheSnapshotWrittenAtStop) {
  StopServer();
  config().metrics_listen = "127.0.0.1:0";
  StartServer();
  ASSERT_TRUE(CreateMap("m").ok());
  for (int n : {1, 20, 41}) {
    pb::AddFrameResponse added;
    const grpc::Status status = AddFrame("m", JpegFrame(CorridorJpeg(n)), &added);
    ASSERT_TRUE(status.ok()) << status.error_message();
  }
  const auto query = [&](pb::QueryPlaceResponse* response) {
    pb::QueryPlaceRequest request;
    request.set_map("m");
    *request.mutable_frame() = JpegFrame(CorridorJpeg(60));
    return places_->QueryPlace(Context().get(), request, response);
  };
  pb::QueryPlaceResponse before;
  ASSERT_TRUE(query(&before).ok());
  RestartServer();
  std::string metrics = FetchMetrics(server_->metrics_port());
  EXPECT_NE(metrics.find("recog_map_index_from_snapshot{map=\"m\"} 1"), std::string::npos)
      << metrics;
  EXPECT_NE(metrics.find("recog_map_frames_read_at_start{map=\"m\"} 0"), std::string::npos);
  pb::QueryPlaceResponse after;
  ASSERT_TRUE(query(&after).ok());
  EXPECT_EQ(after.result().DebugString(), before.result().DebugString());

  // A frame added after the snapshot: the stop writes a new one, so the next start reads no frame
  // either (a crash would leave the old one, and the start would read that frame alone).
  pb::AddFrameResponse added;
  ASSERT_TRUE(AddFrame("m", JpegFrame(CorridorJpeg(60)), &added).ok());
  RestartServer();
  metrics = FetchMetrics(server_->metrics_port());
  EXPECT_NE(metrics.find("recog_map_index_from_snapshot{map=\"m\"} 1"), std::string::npos);
  EXPECT_NE(metrics.find("recog_map_frames_read_at_start{map=\"m\"} 0"), std::string::npos);
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("m", &info).ok());
  EXPECT_EQ(info.frames(), 4u);
}

TEST_F(ServerLifecycleTest, KillNineDuringAStreamLosesNoAcknowledgedFrame) {
  StopServer();  // the store is the child's now
  const recog::testing::TempDir socket_dir("socket");
  const std::string listen = recog::testing::UnixSocketAddress(socket_dir.path());
  const std::string dir = data_dir_.path().string();
  std::vector<std::string> args = {RECOGD_PATH,        "--listen", listen,        "--data-dir", dir,
                                   "--metrics-listen", "",         "--log-level", "warn"};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t child = 0;
  ASSERT_EQ(posix_spawn(&child, RECOGD_PATH, nullptr, nullptr, argv.data(), environ), 0);
  auto channel = grpc::CreateChannel(listen, grpc::InsecureChannelCredentials());
  auto stub = pb::PlaceRecognition::NewStub(channel);
  grpc::Status ready;
  ASSERT_TRUE(WaitUntil([&] {
    pb::ListMapsResponse listed;
    ready = stub->ListMaps(Context().get(), {}, &listed);
    return ready.ok();
  })) << "recogd did not serve: "
      << ready.error_message();
  const std::string jpegs[] = {CorridorJpeg(1), CorridorJpeg(20), CorridorJpeg(41),
                               CorridorJpeg(60)};

  // A map filled before the stream: its loop answers must be the same after the restart.
  const auto query_loops = [&](pb::PlaceRecognition::Stub* places) {
    std::vector<pb::LoopResult> answers;
    for (const std::string& jpeg : jpegs) {
      pb::QueryPlaceRequest query;
      query.set_map("before");
      *query.mutable_frame() = JpegFrame(jpeg);
      pb::QueryPlaceResponse answer;
      const grpc::Status status = places->QueryPlace(Context().get(), query, &answer);
      EXPECT_TRUE(status.ok()) << status.error_message();
      answers.push_back(answer.result());
    }
    return answers;
  };
  {
    pb::CreateMapRequest create;
    create.set_name("before");
    pb::CreateMapResponse created;
    ASSERT_TRUE(stub->CreateMap(Context().get(), create, &created).ok());
    for (int i = 0; i < 8; ++i) {
      pb::AddFrameRequest add;
      add.set_map("before");
      *add.mutable_frame() = JpegFrame(jpegs[i % 4]);
      pb::AddFrameResponse added;
      ASSERT_TRUE(stub->AddFrame(Context().get(), add, &added).ok());
    }
  }
  const std::vector<pb::LoopResult> answers_before = query_loops(stub.get());
  ASSERT_EQ(answers_before.size(), 4u);
  EXPECT_TRUE(std::any_of(answers_before.begin(), answers_before.end(),
                          [](const pb::LoopResult& r) { return r.has_match_frame_id(); }));

  grpc::ClientContext context;
  auto stream = stub->StreamFrames(&context);
  pb::StreamFramesRequest request;
  request.mutable_config()->set_map("crash");
  request.mutable_config()->set_create_if_missing(true);
  ASSERT_TRUE(stream->Write(request));
  // The writer keeps several frames in flight so that the kill lands mid-frame.
  std::thread writer([&] {
    for (int i = 0; i < 200; ++i) {
      *request.mutable_frame() = JpegFrame(jpegs[i % 4]);
      if (!stream->Write(request)) return;
    }
  });
  uint64_t acknowledged = 0;
  pb::StreamFramesResponse response;
  while (stream->Read(&response)) {
    ASSERT_TRUE(response.has_result());
    EXPECT_EQ(response.result().frame_id(), acknowledged);
    if (++acknowledged == 12) kill(child, SIGKILL);
  }
  writer.join();
  stream->Finish();
  int status = 0;
  waitpid(child, &status, 0);
  EXPECT_TRUE(WIFSIGNALED(status));
  EXPECT_GE(acknowledged, 12u);

  StartServer();  // same data directory, in this process
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("crash", &info).ok());
  EXPECT_GE(info.frames(), acknowledged);  // frames ids 0 .. acknowledged - 1 all present
  EXPECT_EQ(info.frames(), info.next_frame_id());
  pb::AddFrameResponse added;
  ASSERT_TRUE(AddFrame("crash", JpegFrame(jpegs[0]), &added).ok());
  EXPECT_EQ(added.frame_id(), info.frames());

  const std::vector<pb::LoopResult> answers_after = query_loops(places_.get());
  ASSERT_EQ(answers_after.size(), answers_before.size());
  for (size_t i = 0; i < answers_before.size(); ++i) {
    EXPECT_EQ(answers_after[i].status(), answers_before[i].status()) << "query " << i;
    EXPECT_EQ(answers_after[i].match_frame_id(), answers_before[i].match_frame_id())
        << "query " << i;
    EXPECT_EQ(answers_after[i].inliers(), answers_before[i].inliers()) << "query " << i;
    EXPECT_EQ(answers_after[i].has_match_frame_id(), answers_before[i].has_match_frame_id());
    EXPECT_DOUBLE_EQ(answers_after[i].score(), answers_before[i].score()) << "query " << i;
  }
}

// A disk that fills up while frames stream in (the data directory on a small filesystem of its
// own, nearly full): the frame that finds no room is RESOURCE_EXHAUSTED with a retry pushback of
// -1 (retrying at once cannot help), every frame acknowledged before it is in the map, also after
// a restart, and frames are taken again once there is room, without a restart.
TEST_F(ServerLifecycleTest, AFullDiskRefusesFramesWithoutRetryLosesNoneAcknowledgedAndResumes) {
  recog::testing::SmallFilesystem disk("server_disk_full", size_t(256) << 20);
  if (!disk.error().empty()) GTEST_SKIP() << disk.error();
  StopServer();
  config().data_dir = disk.Sub("data");
  disk.Fill(2 << 20);  // before the store opens, so that its log finds only what is left
  StartServer();
  ASSERT_TRUE(CreateMap("m").ok());
  const std::string jpegs[] = {CorridorJpeg(1), CorridorJpeg(20), CorridorJpeg(41),
                               CorridorJpeg(60)};
  // AddFrame of the next corridor image; *pushback gets the refusal's retry pushback.
  int sent = 0;
  auto add_next_frame = [&](std::string* pushback) {
    pb::AddFrameRequest request;
    request.set_map("m");
    *request.mutable_frame() = JpegFrame(jpegs[sent % 4], sent);
    auto context = Context();
    pb::AddFrameResponse response;
    const grpc::Status status = places_->AddFrame(context.get(), request, &response);
    sent += status.ok();
    const auto& trailers = context->GetServerTrailingMetadata();
    const auto found = trailers.find("grpc-retry-pushback-ms");
    if (found != trailers.end()) pushback->assign(found->second.data(), found->second.size());
    return status;
  };

  grpc::Status refused;
  std::string pushback;
  for (int frame = 0; frame < 1000 && refused.ok(); ++frame) refused = add_next_frame(&pushback);
  ASSERT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << refused.error_message();
  EXPECT_EQ(pushback, "-1");
  EXPECT_NE(refused.error_message().find("No space left"), std::string::npos)
      << refused.error_message();
  ASSERT_GT(sent, 0);
  pb::MapInfo info;
  ASSERT_TRUE(GetMap("m", &info).ok());
  EXPECT_EQ(info.frames(), uint64_t(sent));

  disk.FreeSpace();
  // The store looks for room every 5 s and then takes writes again.
  grpc::Status resumed = refused;
  ASSERT_TRUE(WaitUntil(
      [&] {
        resumed = add_next_frame(&pushback);
        return resumed.error_code() != grpc::StatusCode::RESOURCE_EXHAUSTED;
      },
      recog::testing::kEventTimeout, std::chrono::milliseconds(100)))
      << "the store took no write again after the disk was freed";
  ASSERT_TRUE(resumed.ok()) << resumed.error_message();

  RestartServer();
  ASSERT_TRUE(GetMap("m", &info).ok());
  EXPECT_EQ(info.frames(), uint64_t(sent));
  StopServer();  // before the small filesystem goes
}

TEST_F(ServerLifecycleTest, StreamingTheCorridorGivesTheOfflineEvaluationsResults) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("places/corridor/ground_truth.txt");
  const std::string images = recog::testing::SharedData("places/corridor/images");
  // Offline: what `recog eval place` computes.
  auto source = cli::FrameSource::Open(images);
  ASSERT_TRUE(source.ok());
  auto sequence = cli::ExtractSequence(*source, FeatureOptions{}, false);
  ASSERT_TRUE(sequence.ok());
  auto truth = cli::ReadGroundTruth(recog::testing::SharedData("places/corridor/ground_truth.txt"));
  ASSERT_TRUE(truth.ok());
  auto vocabulary = LoadVocabulary(DefaultPlaceVocabularyPath());
  ASSERT_TRUE(vocabulary.ok());
  std::vector<LoopResult> offline;
  auto evaluation = cli::EvaluatePlace(
      *sequence, *truth, std::make_shared<const Vocabulary>(std::move(vocabulary).value()),
      cli::PlaceEvaluationOptions{}, &offline);
  ASSERT_TRUE(evaluation.ok());

  // Over the network: the same files, as JPEG bytes, through one stream.
  grpc::ClientContext context;
  auto stream = places_->StreamFrames(&context);
  pb::StreamFramesRequest request;
  request.mutable_config()->set_map("corridor");
  request.mutable_config()->set_create_if_missing(true);
  ASSERT_TRUE(stream->Write(request));
  std::vector<pb::LoopResult> online;
  for (const std::string& name : sequence->names) {
    *request.mutable_frame() = JpegFrame(ReadFileBytes(name));
    ASSERT_TRUE(stream->Write(request));
    pb::StreamFramesResponse response;
    ASSERT_TRUE(stream->Read(&response));
    ASSERT_TRUE(response.has_result()) << response.error().message();
    online.push_back(response.result());
  }
  stream->WritesDone();
  ASSERT_TRUE(stream->Finish().ok());
  ASSERT_EQ(online.size(), offline.size());
  int loops = 0;
  for (size_t i = 0; i < online.size(); ++i) {
    EXPECT_EQ(online[i].status(), ToProto(offline[i].status)) << "frame " << i;
    if (offline[i].match != kInvalidEntryId) {
      EXPECT_EQ(online[i].match_frame_id(), offline[i].match) << "frame " << i;
    }
    EXPECT_EQ(online[i].inliers(), offline[i].inliers.size()) << "frame " << i;
    loops += online[i].status() == pb::LOOP_STATUS_LOOP_DETECTED;
  }
  EXPECT_EQ(loops, evaluation->detections);
}

TEST_F(ServerLifecycleTest, RelocalisationGivesTheRelativePoseOfTheNeighbouringFrame) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("places/corridor/images/10.jpg");
  const auto corridor = [](int n) {
    return JpegFrame(ReadFileBytes(
        recog::testing::SharedData("places/corridor/images/" + std::to_string(n) + ".jpg")));
  };
  ASSERT_TRUE(CreateMap("walk").ok());
  for (int n = 2; n <= 20; n += 2) {
    pb::AddFrameResponse added;
    ASSERT_TRUE(AddFrame("walk", corridor(n), &added).ok());
  }
  pb::QueryPlaceRequest query;
  query.set_map("walk");
  *query.mutable_frame() = corridor(11);
  pb::CameraIntrinsics* k = query.mutable_frame()->mutable_intrinsics();
  k->set_fx(400);
  k->set_fy(400);
  k->set_cx(256);
  k->set_cy(192);
  query.mutable_options()->set_include_relative_pose(true);
  query.mutable_options()->set_include_fundamental(true);
  pb::QueryPlaceResponse response;
  ASSERT_TRUE(places_->QueryPlace(Context().get(), query, &response).ok());
  const pb::LoopResult& result = response.result();
  ASSERT_EQ(result.status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_TRUE(result.match_frame_id() == 4u || result.match_frame_id() == 5u)  // frame 10 or 12
      << result.match_frame_id();
  ASSERT_EQ(result.fundamental_size(), 9);
  ASSERT_EQ(result.relative_pose().rotation_size(), 9);
  ASSERT_EQ(result.relative_pose().translation_size(), 3);
  cv::Matx33d R;
  for (int i = 0; i < 9; ++i) R.val[i] = result.relative_pose().rotation(i);
  EXPECT_LT(cv::norm(R * R.t() - cv::Matx33d::eye()), 1e-6);  // a rotation
  EXPECT_GT(cv::determinant(R), 0.0);
  const cv::Vec3d t(result.relative_pose().translation(0), result.relative_pose().translation(1),
                    result.relative_pose().translation(2));
  EXPECT_NEAR(cv::norm(t), 1.0, 1e-6);  // direction only
}

}  // namespace
}  // namespace recog::server::testing
