// Tests of the client's retries (gRPC's own, by proto/service_config.json; client_options.h), its
// request ids and its resumed downloads: RecognitionClient against small scripted gRPC servers
// that refuse, fail or break calls on purpose and record what reaches them.
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
#include "client/cpp/service_config.h"
#include "client/cpp/sha256.h"
#include "tests/testing/unix_socket.h"
#include "wire/sha256.h"

namespace recog::client {
namespace {

using std::chrono::milliseconds;
using Clock = std::chrono::steady_clock;

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

// Answers CreateMap, GetMap and AddFrame with the scripted failures, in order, then OK; records
// the request_id of every call that reaches it ("" for GetMap).
class ScriptedPlaces final : public pb::PlaceRecognition::Service {
 public:
  struct Failure {
    grpc::StatusCode code;
    std::optional<int> pushback_ms;  // sent as the `grpc-retry-pushback-ms` trailer
  };
  explicit ScriptedPlaces(std::vector<Failure> script = {}) : script_(std::move(script)) {}

  std::vector<std::string> request_ids() const {
    std::lock_guard lock(mutex_);
    return request_ids_;
  }
  int calls() const { return int(request_ids().size()); }

  grpc::Status CreateMap(grpc::ServerContext* context, const pb::CreateMapRequest* request,
                         pb::CreateMapResponse*) override {
    return Next(context, request->request_id());
  }
  grpc::Status GetMap(grpc::ServerContext* context, const pb::GetMapRequest*,
                      pb::GetMapResponse*) override {
    return Next(context, "");
  }
  grpc::Status AddFrame(grpc::ServerContext* context, const pb::AddFrameRequest* request,
                        pb::AddFrameResponse*) override {
    return Next(context, request->request_id());
  }

 private:
  grpc::Status Next(grpc::ServerContext* context, const std::string& request_id) {
    std::lock_guard lock(mutex_);
    const size_t index = request_ids_.size();
    request_ids_.push_back(request_id);
    if (index >= script_.size()) return grpc::Status::OK;
    const Failure& failure = script_[index];
    if (failure.pushback_ms.has_value()) {
      context->AddTrailingMetadata("grpc-retry-pushback-ms", std::to_string(*failure.pushback_ms));
    }
    return {failure.code, "scripted failure"};
  }

  const std::vector<Failure> script_;
  mutable std::mutex mutex_;
  std::vector<std::string> request_ids_;
};

class ScriptedClientTest : public ::testing::Test {
 protected:
  static std::unique_ptr<RecognitionClient> Connect(const std::string& target,
                                                    bool retries = true) {
    ClientOptions options;
    options.target = target;
    options.retries = retries;
    auto client = RecognitionClient::Connect(options);
    EXPECT_TRUE(client.ok()) << client.status().error_message();
    return client.ok() ? std::move(client).value() : nullptr;
  }
};

TEST_F(ScriptedClientTest, ABusyRefusalIsRetriedAfterTheServersPushbackWithTheSameRequestId) {
  ScriptedPlaces places(
      {{grpc::StatusCode::RESOURCE_EXHAUSTED, 150}, {grpc::StatusCode::RESOURCE_EXHAUSTED, 150}});
  FakeServer server(&places);
  auto client = Connect(server.target());
  ASSERT_NE(client, nullptr);
  const auto start = Clock::now();
  const grpc::Status status = client->AddFrame("m", pb::Frame()).status();
  EXPECT_TRUE(status.ok()) << status.error_message();
  EXPECT_GE(Clock::now() - start, milliseconds(300));  // the pushback, not the policy's backoff
  const std::vector<std::string> ids = places.request_ids();
  ASSERT_EQ(ids.size(), 3u);
  EXPECT_EQ(ids[0].size(), 36u);  // a UUID
  EXPECT_EQ(ids[1], ids[0]);      // gRPC resends the same message: the server can deduplicate
  EXPECT_EQ(ids[2], ids[0]);
}

TEST_F(ScriptedClientTest, ANegativePushbackMakesARefusalFinal) {
  ScriptedPlaces places({{grpc::StatusCode::RESOURCE_EXHAUSTED, -1}});
  FakeServer server(&places);
  auto client = Connect(server.target());
  ASSERT_NE(client, nullptr);
  EXPECT_EQ(client->AddFrame("m", pb::Frame()).status().error_code(),
            grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(places.calls(), 1);
}

TEST_F(ScriptedClientTest, UnavailableIsRetriedForChangingCallsTooEachCallWithItsOwnId) {
  ScriptedPlaces places({{grpc::StatusCode::UNAVAILABLE, std::nullopt},
                         {grpc::StatusCode::UNAVAILABLE, std::nullopt}});
  FakeServer server(&places);
  auto client = Connect(server.target());
  ASSERT_NE(client, nullptr);
  EXPECT_TRUE(client->AddFrame("m", pb::Frame()).ok());
  EXPECT_TRUE(client->AddFrame("m", pb::Frame()).ok());
  EXPECT_TRUE(client->CreateMap("m", {}, "my-own-id").ok());
  const std::vector<std::string> ids = places.request_ids();
  ASSERT_EQ(ids.size(), 5u);
  EXPECT_EQ(ids[1], ids[0]);
  EXPECT_EQ(ids[2], ids[0]);
  EXPECT_NE(ids[3], ids[0]);  // the next call has a fresh id
  EXPECT_EQ(ids[4], "my-own-id");
}

TEST_F(ScriptedClientTest, AttemptsStopAtThePolicysLimitAndOtherErrorsAreNeverRetried) {
  std::vector<ScriptedPlaces::Failure> always_down(10, {grpc::StatusCode::UNAVAILABLE, {}});
  ScriptedPlaces down(always_down);
  FakeServer down_server(&down);
  auto client = Connect(down_server.target());
  ASSERT_NE(client, nullptr);
  EXPECT_EQ(client->GetMap("m").status().error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_EQ(down.calls(), internal::kMaxAttempts);

  ScriptedPlaces invalid({{grpc::StatusCode::INVALID_ARGUMENT, 100}});
  FakeServer invalid_server(&invalid);
  auto other = Connect(invalid_server.target());
  ASSERT_NE(other, nullptr);
  EXPECT_EQ(other->GetMap("m").status().error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(invalid.calls(), 1);
}

TEST_F(ScriptedClientTest, WithRetriesOffEveryCallIsOneAttempt) {
  ScriptedPlaces places({{grpc::StatusCode::RESOURCE_EXHAUSTED, 10}});
  FakeServer server(&places);
  auto client = Connect(server.target(), /*retries=*/false);
  ASSERT_NE(client, nullptr);
  EXPECT_EQ(client->AddFrame("m", pb::Frame()).status().error_code(),
            grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(places.calls(), 1);
}

TEST_F(ScriptedClientTest, NoRetryStartsAfterTheDeadline) {
  ScriptedPlaces places({{grpc::StatusCode::RESOURCE_EXHAUSTED, 5000}});
  FakeServer server(&places);
  ClientOptions options;
  options.target = server.target();
  options.deadline = milliseconds(500);
  auto connected = RecognitionClient::Connect(options);
  ASSERT_TRUE(connected.ok());
  const auto start = Clock::now();
  // gRPC waits for the pushback; the deadline ends the call while it waits.
  EXPECT_EQ((*connected)->AddFrame("m", pb::Frame()).status().error_code(),
            grpc::StatusCode::DEADLINE_EXCEEDED);
  EXPECT_LT(Clock::now() - start, milliseconds(2000));
  EXPECT_EQ(places.calls(), 1);
}

TEST_F(ScriptedClientTest, AServerThatNeverComesUpIsReportedUnavailable) {
  auto client = Connect(recog::testing::UnixSocketAddress(
      std::filesystem::temp_directory_path(), "recog_nobody_" + std::to_string(getpid())));
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
  auto client = Connect(server.target());
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
