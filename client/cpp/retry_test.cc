// Tests of the retry rule (client_options.h) and of resumed downloads: the pure delay and
// decision functions, then RecognitionClient against small scripted gRPC servers that refuse,
// fail or break calls on purpose and count what reaches them.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <optional>
#include <random>
#include <sstream>
#include <thread>

#include <gtest/gtest.h>

#include "client/cpp/recognition_client.h"
#include "client/cpp/retry.h"
#include "client/cpp/sha256.h"
#include "tests/testing/free_port.h"
#include "wire/sha256.h"

namespace recog::client {
namespace {

using std::chrono::milliseconds;
using Clock = std::chrono::steady_clock;

TEST(RetryDelayTest, DelaysGrowByTheMultiplierUpToTheCapWithinTheJitter) {
  const RetryPolicy policy;  // 100 ms, x2, 5 s, jitter 0.2
  EXPECT_EQ(internal::RetryDelay(policy, 1, 0.5, std::nullopt), milliseconds(100));
  EXPECT_EQ(internal::RetryDelay(policy, 2, 0.5, std::nullopt), milliseconds(200));
  EXPECT_EQ(internal::RetryDelay(policy, 3, 0.5, std::nullopt), milliseconds(400));
  EXPECT_EQ(internal::RetryDelay(policy, 7, 0.5, std::nullopt), milliseconds(5000));
  EXPECT_EQ(internal::RetryDelay(policy, 99, 0.5, std::nullopt), milliseconds(5000));
  EXPECT_EQ(internal::RetryDelay(policy, 1, 0.0, std::nullopt), milliseconds(80));
  EXPECT_EQ(internal::RetryDelay(policy, 1, 0.999999, std::nullopt), milliseconds(120));
}

TEST(RetryDelayTest, TheServersHintIsTheShortestDelay) {
  const RetryPolicy policy;
  EXPECT_EQ(internal::RetryDelay(policy, 1, 0.5, milliseconds(300)), milliseconds(300));
  EXPECT_EQ(internal::RetryDelay(policy, 3, 0.5, milliseconds(50)), milliseconds(400));
  EXPECT_EQ(internal::RetryDelay(policy, 9, 0.5, milliseconds(60000)), milliseconds(60000));
}

TEST(ShouldRetryTest, OnlyRefusalsWithAHintAndFailuresThatCannotHaveBeenAppliedAreRetried) {
  using internal::CallKind;
  const grpc::Status busy(grpc::StatusCode::RESOURCE_EXHAUSTED, "busy");
  const grpc::Status down(grpc::StatusCode::UNAVAILABLE, "down");
  const std::optional<milliseconds> hint = milliseconds(100), none;
  for (const CallKind kind : {CallKind::kRepeatable, CallKind::kChanging}) {
    EXPECT_TRUE(internal::ShouldRetry(busy, kind, true, hint));
    EXPECT_FALSE(internal::ShouldRetry(busy, kind, true, none));  // e.g. a message too large
    EXPECT_TRUE(internal::ShouldRetry(down, kind, false, none));  // nothing was sent
    for (const grpc::StatusCode code :
         {grpc::StatusCode::INVALID_ARGUMENT, grpc::StatusCode::NOT_FOUND,
          grpc::StatusCode::DEADLINE_EXCEEDED, grpc::StatusCode::CANCELLED,
          grpc::StatusCode::UNAUTHENTICATED, grpc::StatusCode::INTERNAL}) {
      EXPECT_FALSE(internal::ShouldRetry({code, ""}, kind, true, hint)) << int(code);
    }
  }
  EXPECT_TRUE(internal::ShouldRetry(down, CallKind::kRepeatable, true, none));
  EXPECT_FALSE(internal::ShouldRetry(down, CallKind::kChanging, true, none));  // maybe applied
}

// A gRPC server in this process serving one service on a loopback port (0 = any).
class FakeServer {
 public:
  explicit FakeServer(grpc::Service* service, int port = 0) {
    grpc::ServerBuilder builder;
    builder.AddListeningPort("127.0.0.1:" + std::to_string(port), grpc::InsecureServerCredentials(),
                             &port_);
    builder.RegisterService(service);
    server_ = builder.BuildAndStart();
  }
  ~FakeServer() { server_->Shutdown(std::chrono::system_clock::now()); }
  std::string target() const { return "127.0.0.1:" + std::to_string(port_); }

 private:
  int port_ = 0;
  std::unique_ptr<grpc::Server> server_;
};

// Answers CreateMap, GetMap and AddFrame with the scripted failures, in order, then OK; counts
// the calls that reach it.
class ScriptedPlaces final : public pb::PlaceRecognition::Service {
 public:
  struct Failure {
    grpc::StatusCode code;
    std::optional<int> retry_after_ms;  // sent as the `retry-after-ms` trailer
  };
  explicit ScriptedPlaces(std::vector<Failure> script = {}) : script_(std::move(script)) {}

  int calls() const {
    std::lock_guard lock(mutex_);
    return calls_;
  }

  grpc::Status CreateMap(grpc::ServerContext* context, const pb::CreateMapRequest*,
                         pb::CreateMapResponse*) override {
    return Next(context);
  }
  grpc::Status GetMap(grpc::ServerContext* context, const pb::GetMapRequest*,
                      pb::GetMapResponse*) override {
    return Next(context);
  }
  grpc::Status AddFrame(grpc::ServerContext* context, const pb::AddFrameRequest*,
                        pb::AddFrameResponse*) override {
    return Next(context);
  }

 private:
  grpc::Status Next(grpc::ServerContext* context) {
    std::lock_guard lock(mutex_);
    const size_t index = size_t(calls_++);
    if (index >= script_.size()) return grpc::Status::OK;
    const Failure& failure = script_[index];
    if (failure.retry_after_ms.has_value()) {
      context->AddTrailingMetadata("retry-after-ms", std::to_string(*failure.retry_after_ms));
    }
    return {failure.code, "scripted failure"};
  }

  const std::vector<Failure> script_;
  mutable std::mutex mutex_;
  int calls_ = 0;
};

class ScriptedClientTest : public ::testing::Test {
 protected:
  // Options for `target` with short backoffs, so that the tests take milliseconds.
  static ClientOptions FastRetries(const std::string& target) {
    ClientOptions options;
    options.target = target;
    options.retry.initial_backoff = milliseconds(5);
    options.retry.max_backoff = milliseconds(20);
    return options;
  }
  static std::unique_ptr<RecognitionClient> Connect(const ClientOptions& options) {
    auto client = RecognitionClient::Connect(options);
    EXPECT_TRUE(client.ok()) << client.status().error_message();
    return client.ok() ? std::move(client).value() : nullptr;
  }
};

TEST_F(ScriptedClientTest, ABusyRefusalIsRetriedAfterTheServersHintEvenForAChangingCall) {
  ScriptedPlaces places(
      {{grpc::StatusCode::RESOURCE_EXHAUSTED, 150}, {grpc::StatusCode::RESOURCE_EXHAUSTED, 150}});
  FakeServer server(&places);
  auto client = Connect(FastRetries(server.target()));
  ASSERT_NE(client, nullptr);
  const auto start = Clock::now();
  EXPECT_TRUE(client->AddFrame("m", pb::Frame()).ok());
  EXPECT_GE(Clock::now() - start, milliseconds(300));  // the hint, not the 5 ms backoff
  EXPECT_EQ(places.calls(), 3);
}

TEST_F(ScriptedClientTest, ARefusalWithoutAHintIsFinal) {
  ScriptedPlaces places({{grpc::StatusCode::RESOURCE_EXHAUSTED, std::nullopt}});
  FakeServer server(&places);
  auto client = Connect(FastRetries(server.target()));
  ASSERT_NE(client, nullptr);
  EXPECT_EQ(client->GetMap("m").status().error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(places.calls(), 1);
}

TEST_F(ScriptedClientTest, UnavailableAfterSendingIsRetriedOnlyForCallsThatChangeNothing) {
  const std::vector<ScriptedPlaces::Failure> twice_down = {
      {grpc::StatusCode::UNAVAILABLE, std::nullopt}, {grpc::StatusCode::UNAVAILABLE, std::nullopt}};
  {
    ScriptedPlaces places(twice_down);
    FakeServer server(&places);
    auto client = Connect(FastRetries(server.target()));
    ASSERT_NE(client, nullptr);
    EXPECT_TRUE(client->GetMap("m").ok());
    EXPECT_EQ(places.calls(), 3);
  }
  for (const bool create : {false, true}) {
    ScriptedPlaces places(twice_down);
    FakeServer server(&places);
    auto client = Connect(FastRetries(server.target()));
    ASSERT_NE(client, nullptr);
    const grpc::Status status =
        create ? client->CreateMap("m").status() : client->AddFrame("m", pb::Frame()).status();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE);
    EXPECT_EQ(places.calls(), 1);  // the server may have applied it: not sent again
  }
}

TEST_F(ScriptedClientTest, AttemptsStopAtTheLimitAndOtherErrorsAreNeverRetried) {
  std::vector<ScriptedPlaces::Failure> always_down(10, {grpc::StatusCode::UNAVAILABLE, {}});
  ScriptedPlaces down(always_down);
  FakeServer down_server(&down);
  auto client = Connect(FastRetries(down_server.target()));
  ASSERT_NE(client, nullptr);
  EXPECT_EQ(client->GetMap("m").status().error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_EQ(down.calls(), 5);  // max_attempts

  ScriptedPlaces invalid({{grpc::StatusCode::INVALID_ARGUMENT, 100}});
  FakeServer invalid_server(&invalid);
  auto other = Connect(FastRetries(invalid_server.target()));
  ASSERT_NE(other, nullptr);
  EXPECT_EQ(other->GetMap("m").status().error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(invalid.calls(), 1);
}

TEST_F(ScriptedClientTest, NoRetryStartsAfterTheDeadline) {
  ScriptedPlaces places({{grpc::StatusCode::RESOURCE_EXHAUSTED, 5000}});
  FakeServer server(&places);
  ClientOptions options = FastRetries(server.target());
  options.deadline = milliseconds(500);
  auto client = Connect(options);
  ASSERT_NE(client, nullptr);
  const auto start = Clock::now();
  EXPECT_EQ(client->AddFrame("m", pb::Frame()).status().error_code(),
            grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_LT(Clock::now() - start, milliseconds(2000));
  EXPECT_EQ(places.calls(), 1);
}

TEST_F(ScriptedClientTest, AChangingCallIsSentOnceTheServerComesUp) {
  const int port = recog::testing::FreePort();
  ScriptedPlaces places;
  std::unique_ptr<FakeServer> server;
  std::thread late([&] {
    std::this_thread::sleep_for(milliseconds(300));
    server = std::make_unique<FakeServer>(&places, port);
  });
  ClientOptions options = FastRetries("127.0.0.1:" + std::to_string(port));
  options.retry.max_attempts = 100;
  auto client = Connect(options);
  ASSERT_NE(client, nullptr);
  const grpc::Status status = client->AddFrame("m", pb::Frame()).status();
  late.join();
  EXPECT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(places.calls(), 1);  // the failed connection attempts sent nothing
}

TEST_F(ScriptedClientTest, AServerThatNeverComesUpIsReportedUnavailable) {
  ClientOptions options = FastRetries("127.0.0.1:" + std::to_string(recog::testing::FreePort()));
  auto client = Connect(options);
  ASSERT_NE(client, nullptr);
  EXPECT_EQ(client->AddFrame("m", pb::Frame()).status().error_code(),
            grpc::StatusCode::UNAVAILABLE);
  EXPECT_EQ(client->GetMap("m").status().error_code(), grpc::StatusCode::UNAVAILABLE);
}

// Serves `file` as version 7 of model "m"; the first download breaks with UNAVAILABLE after its
// first chunk, as a lost connection would. Records every request.
class BreakingRepository final : public pb::ObjectRepository::Service {
 public:
  explicit BreakingRepository(std::string file) : file_(std::move(file)) {}

  std::vector<pb::GetModelRequest> requests() const {
    std::lock_guard lock(mutex_);
    return requests_;
  }

  grpc::Status GetModel(grpc::ServerContext*, const pb::GetModelRequest* request,
                        grpc::ServerWriter<pb::GetModelResponse>* writer) override {
    bool first = false;
    {
      std::lock_guard lock(mutex_);
      requests_.push_back(*request);
      first = requests_.size() == 1;
    }
    if (request->name() != "m" || (request->version() != 0 && request->version() != 7)) {
      return {grpc::StatusCode::NOT_FOUND, "no such model"};
    }
    if (request->offset() > file_.size()) return {grpc::StatusCode::OUT_OF_RANGE, "offset"};
    pb::GetModelResponse response;
    pb::ModelInfo* info = response.mutable_info();
    info->set_name("m");
    info->set_version(7);
    info->set_size_bytes(file_.size());
    info->set_sha256(Sha256Hex(file_));
    writer->Write(response);
    for (size_t offset = request->offset(); offset < file_.size();
         offset += request->chunk_bytes()) {
      response.set_chunk(file_.substr(offset, request->chunk_bytes()));
      writer->Write(response);
      if (first) return {grpc::StatusCode::UNAVAILABLE, "connection lost"};
    }
    return grpc::Status::OK;
  }

 private:
  const std::string file_;
  mutable std::mutex mutex_;
  std::vector<pb::GetModelRequest> requests_;
};

TEST_F(ScriptedClientTest, ABrokenDownloadResumesFromTheBytesItHasOfTheSameVersion) {
  std::mt19937 random(7);
  std::string file(700000, '\0');
  for (char& c : file) c = char(random());
  BreakingRepository repository(file);
  FakeServer server(&repository);
  auto client = Connect(FastRetries(server.target()));
  ASSERT_NE(client, nullptr);
  const std::string path = std::filesystem::temp_directory_path() /
                           ("recog_client_resume_" + std::to_string(getpid()) + ".robj");
  Result<pb::ModelInfo> info = client->DownloadModel("m", 0, path);
  ASSERT_TRUE(info.ok()) << info.status().error_message();
  EXPECT_EQ(info->version(), 7u);
  std::ifstream in(path, std::ios::binary);
  std::ostringstream downloaded;
  downloaded << in.rdbuf();
  EXPECT_EQ(downloaded.str(), file);
  std::filesystem::remove(path);

  const std::vector<pb::GetModelRequest> requests = repository.requests();
  ASSERT_EQ(requests.size(), 2u);
  EXPECT_EQ(requests[0].offset(), 0u);
  EXPECT_EQ(requests[0].version(), 0u);
  EXPECT_EQ(requests[1].offset(), requests[0].chunk_bytes());  // one chunk arrived
  EXPECT_EQ(requests[1].version(), 7u);  // the version being fetched, not whatever is latest
}

}  // namespace
}  // namespace recog::client
