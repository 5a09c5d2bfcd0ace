// ServerFixture: a recogd in this process, on a loopback port and a fresh data directory, with
// stubs of the three services connected to it over TCP. Tests restart it on the same directory to
// check persistence, and build frames from the corridor images under tests/data/.
#pragma once

#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include "recognition/v1/object.grpc.pb.h"
#include "recognition/v1/place.grpc.pb.h"
#include "recognition/v1/repository.grpc.pb.h"
#include "server/app/recognition_server.h"
#include "storage/store_test_util.h"
#include "tests/testing/data_paths.h"
#include "wire/sha256.h"

namespace recog::server::testing {

namespace pb = ::recognition::v1;

inline std::string ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

// The JPEG bytes of tests/data/corridor/<n>.jpg (n = 1, 20, 41, 60).
inline std::string CorridorJpeg(int n) {
  return ReadFileBytes(recog::testing::ProjectTestData("corridor/" + std::to_string(n) + ".jpg"));
}

// A frame of `jpeg`, with `timestamp` when given (none: unknown, tau_c counts frames).
inline pb::Frame JpegFrame(const std::string& jpeg,
                           std::optional<double> timestamp = std::nullopt) {
  pb::Frame frame;
  frame.set_encoded_image(jpeg);
  if (timestamp.has_value()) frame.set_timestamp(*timestamp);
  return frame;
}

// Corridor image `n` seen straight on, with intrinsics (for object recognition).
inline pb::Frame PosterView(int n) {
  pb::Frame frame = JpegFrame(CorridorJpeg(n));
  pb::CameraIntrinsics* k = frame.mutable_intrinsics();
  k->set_fx(500);
  k->set_fy(500);
  k->set_cx(256);
  k->set_cy(192);
  return frame;
}

class ServerFixture : public ::testing::Test {
 protected:
  ServerFixture() : data_dir_("server") {
    config_.listen = "127.0.0.1:0";
    config_.data_dir = data_dir_.path().string();
    config_.metrics_listen = "";  // tests that want metrics set an address
    config_.workers = 2;
  }

  void SetUp() override { StartServer(); }
  void TearDown() override { StopServer(); }

  // The configuration the fixture's servers use; tests adjust it before StartServer().
  ServerConfig& config() { return config_; }

  void StartServer() {
    spdlog::set_level(spdlog::level::warn);  // recogd's main applies config.log_level
    auto server = RecognitionServer::Start(config_);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(server).value();
    const bool on_unix_socket = config_.listen.starts_with("unix:");
    channel_ = grpc::CreateChannel(
        on_unix_socket ? config_.listen : "127.0.0.1:" + std::to_string(server_->port()),
        grpc::InsecureChannelCredentials());
    places_ = pb::PlaceRecognition::NewStub(channel_);
    objects_ = pb::ObjectRecognition::NewStub(channel_);
    models_ = pb::ObjectRepository::NewStub(channel_);
  }

  void StopServer() {
    places_.reset();
    objects_.reset();
    models_.reset();
    channel_.reset();
    if (server_ != nullptr) server_->Shutdown(std::chrono::milliseconds(2000));
    server_.reset();
  }

  void RestartServer() {
    StopServer();
    StartServer();
  }

  // A client context with a 30 s deadline (and a bearer token when given).
  static std::unique_ptr<grpc::ClientContext> Context(const std::string& token = {}) {
    auto context = std::make_unique<grpc::ClientContext>();
    context->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    if (!token.empty()) context->AddMetadata("authorization", "Bearer " + token);
    return context;
  }

  grpc::Status CreateMap(const std::string& name, pb::MapSettings settings = {}) {
    pb::CreateMapRequest request;
    request.set_name(name);
    *request.mutable_settings() = settings;
    pb::CreateMapResponse response;
    return places_->CreateMap(Context().get(), request, &response);
  }

  // Queries `map` with corridor image `n` (a real frame) as the caller of `token`.
  grpc::Status QueryCorridorFrame(const std::string& map, int n, const std::string& token = {}) {
    pb::QueryPlaceRequest query;
    query.set_map(map);
    *query.mutable_frame() = JpegFrame(CorridorJpeg(n));
    pb::QueryPlaceResponse answer;
    return places_->QueryPlace(Context(token).get(), query, &answer);
  }

  grpc::Status AddFrame(const std::string& map, const pb::Frame& frame,
                        pb::AddFrameResponse* response) {
    pb::AddFrameRequest request;
    request.set_map(map);
    *request.mutable_frame() = frame;
    return places_->AddFrame(Context().get(), request, response);
  }

  // Uploads the model file `bytes` as `name` in one chunk (with `token` when given).
  grpc::Status PutModel(const std::string& bytes, const std::string& name,
                        const std::string& token = {}) {
    auto context = Context(token);
    pb::PutModelResponse response;
    auto writer = models_->PutModel(context.get(), &response);
    pb::PutModelRequest request;
    request.mutable_header()->set_name(name);
    request.mutable_header()->set_sha256(Sha256Hex(bytes));
    request.mutable_header()->set_size_bytes(bytes.size());
    writer->Write(request);
    request.set_chunk(bytes);
    writer->Write(request);
    writer->WritesDone();
    return writer->Finish();
  }

  grpc::Status GetMap(const std::string& name, pb::MapInfo* info = nullptr) {
    pb::GetMapRequest request;
    request.set_name(name);
    pb::GetMapResponse response;
    grpc::Status status = places_->GetMap(Context().get(), request, &response);
    if (info != nullptr) *info = response.map();
    return status;
  }

  recog::testing::TempDir data_dir_;
  ServerConfig config_;
  std::unique_ptr<RecognitionServer> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<pb::PlaceRecognition::Stub> places_;
  std::unique_ptr<pb::ObjectRecognition::Stub> objects_;
  std::unique_ptr<pb::ObjectRepository::Stub> models_;
};

}  // namespace recog::server::testing
