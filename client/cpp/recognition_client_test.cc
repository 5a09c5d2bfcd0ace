// Loopback tests of RecognitionClient's unary calls against an in-process recogd: map
// management across pages, frames and queries in every frame form, retries of a flooded server,
// tokens from a file, and mutual TLS.
#include <atomic>
#include <fstream>
#include <latch>
#include <map>
#include <thread>

#include <opencv2/imgcodecs.hpp>

#include "client/cpp/client_test_fixture.h"
#include "client/cpp/frames.h"
#include "tests/testing/data_paths.h"

namespace recog::client::testing {
namespace {

class RecognitionClientTest : public ClientFixture {};

cv::Mat CorridorGrey(int n) {
  return cv::imread(recog::testing::ProjectTestData("corridor/" + std::to_string(n) + ".jpg"),
                    cv::IMREAD_GRAYSCALE);
}

TEST_F(RecognitionClientTest, MapsAreCreatedDescribedListedOverEveryPageAndDeleted) {
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  pb::MapSettings settings;
  settings.set_alpha(0.5);
  Result<pb::MapInfo> created = client->CreateMap("hall", settings);
  ASSERT_TRUE(created.ok()) << created.status().error_message();
  EXPECT_EQ(created->name(), "hall");
  EXPECT_DOUBLE_EQ(created->settings().alpha(), 0.5);
  EXPECT_EQ(created->settings().temporal_matches(), 3u);  // the server's default filled in
  EXPECT_EQ(client->CreateMap("hall").status().error_code(), grpc::StatusCode::ALREADY_EXISTS);

  Result<pb::MapInfo> got = client->GetMap("hall");
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got->id(), created->id());
  EXPECT_EQ(client->GetMap("nowhere").status().error_code(), grpc::StatusCode::NOT_FOUND);

  // The server sends 100 maps a page; the client fetches them all.
  for (int i = 0; i < 104; ++i) {
    ASSERT_TRUE(client->CreateMap("m" + std::to_string(1000 + i)).ok());
  }
  Result<std::vector<pb::MapInfo>> listed = client->ListMaps();
  ASSERT_TRUE(listed.ok()) << listed.status().error_message();
  ASSERT_EQ(listed->size(), 105u);
  EXPECT_EQ(listed->front().name(), "hall");
  EXPECT_EQ(listed->at(1).name(), "m1000");
  EXPECT_EQ(listed->back().name(), "m1103");

  ASSERT_TRUE(client->AddFrame("hall", JpegFrame(CorridorJpeg(1))).ok());
  Result<uint64_t> deleted = client->DeleteMap("hall");
  ASSERT_TRUE(deleted.ok());
  EXPECT_EQ(*deleted, 1u);
  EXPECT_EQ(client->DeleteMap("hall").status().error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(RecognitionClientTest, AClientBusyAfterConnectingCanStillChangeTheServer) {
  // A robot connects at start-up, then spends a while busy before it creates its map: the first
  // connection attempt must not time out for want of polling.
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(600);
  volatile uint64_t spins = 0;
  while (std::chrono::steady_clock::now() < until) spins = spins + 1;
  EXPECT_TRUE(client->CreateMap("after-a-busy-start").ok());
}

TEST_F(RecognitionClientTest, AnAddedPlaceIsFoundByARelocalisationQueryThatChangesNothing) {
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  ASSERT_TRUE(client->CreateMap("hall").ok());
  for (int n : {1, 20}) {
    pb::Frame frame = JpegFrame(CorridorJpeg(n));
    frame.set_client_frame_id("corridor-" + std::to_string(n));
    Result<pb::AddFrameResponse> added = client->AddFrame("hall", frame);
    ASSERT_TRUE(added.ok()) << added.status().error_message();
    EXPECT_EQ(added->client_frame_id(), frame.client_frame_id());
    EXPECT_GT(added->num_features(), 300u);
  }
  Result<pb::QueryPlaceResponse> found = client->QueryPlace("hall", JpegFrame(CorridorJpeg(20)));
  ASSERT_TRUE(found.ok()) << found.status().error_message();
  EXPECT_EQ(found->result().status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(found->result().match_frame_id(), 1u);
  EXPECT_FALSE(found->result().has_frame_id());
  EXPECT_EQ(client->GetMap("hall")->frames(), 2u);

  Result<pb::QueryPlaceResponse> kept =
      client->QueryPlace("hall", JpegFrame(CorridorJpeg(41)), QueryMode::kAddFrame);
  ASSERT_TRUE(kept.ok()) << kept.status().error_message();
  EXPECT_EQ(kept->result().frame_id(), 2u);
  EXPECT_EQ(client->GetMap("hall")->frames(), 3u);
  EXPECT_EQ(client->QueryPlace("nowhere", JpegFrame(CorridorJpeg(1))).status().error_code(),
            grpc::StatusCode::NOT_FOUND);
}

// A client of a server with robots A and B in group "fleet", A holding corridor frame 1; null
// when that failed.
std::unique_ptr<RecognitionClient> ConnectToFleet(std::unique_ptr<RecognitionClient> client) {
  if (client == nullptr) return nullptr;
  pb::MapSettings fleet;
  fleet.set_group("fleet");
  const bool created = client->CreateMap("robot-a", fleet).ok() &&
                       client->CreateMap("robot-b", fleet).ok() &&
                       client->AddFrame("robot-a", JpegFrame(CorridorJpeg(1))).ok();
  return created ? std::move(client) : nullptr;
}

TEST_F(RecognitionClientTest, AQueryAcrossAGroupFindsThePlaceInAnotherRobotsMap) {
  auto client = ConnectToFleet(Connect());
  ASSERT_NE(client, nullptr);
  Result<pb::QueryPlaceResponse> found = client->QueryPlace(
      "robot-b", JpegFrame(CorridorJpeg(41)), QueryMode::kAddFrame, {}, {}, {.group = "fleet"});
  ASSERT_TRUE(found.ok()) << found.status().error_message();
  ASSERT_EQ(found->inter_map_size(), 1);
  EXPECT_EQ(found->inter_map(0).map(), "robot-a");
  EXPECT_EQ(found->inter_map(0).result().match_frame_id(), 0u);
  const grpc::Status unknown = client
                                   ->QueryPlace("robot-b", JpegFrame(CorridorJpeg(41)),
                                                QueryMode::kAddFrame, {}, {}, {.maps = {"robot-z"}})
                                   .status();
  EXPECT_EQ(unknown.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(unknown.error_message().find("robot-z"), std::string::npos);
  EXPECT_EQ(client->GetMap("robot-b")->frames(), 1u) << "the refused query added nothing";
}

TEST_F(RecognitionClientTest, RelocalizeFindsTheFramesInTheGroupsMaps) {
  auto client = ConnectToFleet(Connect());
  ASSERT_NE(client, nullptr);
  ASSERT_TRUE(client->AddFrame("robot-b", JpegFrame(CorridorJpeg(60))).ok());
  const std::vector<pb::Frame> frames = {JpegFrame(CorridorJpeg(41)), JpegFrame(CorridorJpeg(60))};
  Result<pb::RelocalizeResponse> found = client->Relocalize(frames, {.group = "fleet"});
  ASSERT_TRUE(found.ok()) << found.status().error_message();
  std::map<std::string, pb::Relocalization> by_map;
  for (const pb::Relocalization& place : found->places()) by_map[place.map()] = place;
  ASSERT_EQ(by_map.size(), 2u) << found->DebugString();
  EXPECT_EQ(by_map["robot-a"].frame_index(), 0u);
  EXPECT_EQ(by_map["robot-a"].result().match_frame_id(), 0u);
  EXPECT_EQ(by_map["robot-b"].frame_index(), 1u);
  Result<pb::RelocalizeResponse> named = client->Relocalize(frames, {.maps = {"robot-b"}});
  ASSERT_TRUE(named.ok());
  ASSERT_EQ(named->places_size(), 1);
  EXPECT_EQ(named->places(0).map(), "robot-b");
  const grpc::Status unknown = client->Relocalize(frames, {.maps = {"robot-z"}}).status();
  EXPECT_EQ(unknown.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(unknown.error_message().find("robot-z"), std::string::npos);
  EXPECT_EQ(client->GetMap("robot-a")->frames(), 1u) << "relocalising added nothing";
}

TEST_F(RecognitionClientTest, MatchesNameTheClientsFrameIdsAndRemovedFramesAreGone) {
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  ASSERT_TRUE(client->CreateMap("keyframes").ok());
  for (int n : {1, 20, 41}) {
    pb::Frame frame = JpegFrame(CorridorJpeg(n));
    frame.set_client_frame_id("kf-" + std::to_string(n));
    ASSERT_TRUE(client->AddFrame("keyframes", frame).ok());
  }
  pb::ResultOptions options;
  options.set_top_k(2);
  options.set_include_correspondences(true);
  Result<pb::QueryPlaceResponse> found =
      client->QueryPlace("keyframes", JpegFrame(CorridorJpeg(20)), QueryMode::kRelocalise, options);
  ASSERT_TRUE(found.ok()) << found.status().error_message();
  const pb::LoopResult& r = found->result();
  ASSERT_EQ(r.status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(r.match_frame_id(), 1u);
  EXPECT_EQ(r.match_client_frame_id(), "kf-20");
  ASSERT_EQ(r.candidates_size(), 2);
  EXPECT_EQ(r.candidates(0).client_frame_id(), "kf-20");
  EXPECT_EQ(r.candidates(0).inliers(), r.inliers());
  EXPECT_EQ(r.inlier_correspondences_size(), int(r.inliers()));

  Result<std::vector<uint64_t>> removed = client->RemoveFramesByClientId("keyframes", "kf-20");
  ASSERT_TRUE(removed.ok()) << removed.status().error_message();
  EXPECT_EQ(*removed, std::vector<uint64_t>{1});
  removed = client->RemoveFrame("keyframes", 0);
  ASSERT_TRUE(removed.ok()) << removed.status().error_message();
  EXPECT_EQ(*removed, std::vector<uint64_t>{0});
  EXPECT_EQ(client->RemoveFrame("keyframes", 0).status().error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(client->RemoveFramesByClientId("keyframes", "kf-20").status().error_code(),
            grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(client->RemoveFrame("nowhere", 0).status().error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(client->GetMap("keyframes")->frames(), 1u);
  found =
      client->QueryPlace("keyframes", JpegFrame(CorridorJpeg(20)), QueryMode::kRelocalise, options);
  ASSERT_TRUE(found.ok());
  EXPECT_NE(found->result().match_frame_id(), 1u);
  for (const pb::Candidate& c : found->result().candidates()) EXPECT_EQ(c.frame_id(), 2u);
}

TEST_F(RecognitionClientTest, FeaturesRawPixelsAndJpegsOfAFrameGetTheSameAnswer) {
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  ASSERT_TRUE(client->CreateMap("jpeg").ok());
  ASSERT_TRUE(client->CreateMap("features").ok());
  for (int n : {1, 20, 41}) {
    Result<pb::AddFrameResponse> from_jpeg = client->AddFrame("jpeg", JpegFrame(CorridorJpeg(n)));
    Result<OrbFeatures> features = ExtractOrbFeatures(CorridorGrey(n));
    ASSERT_TRUE(features.ok());
    Result<pb::Frame> frame = FrameFromFeatures(features->keypoints, features->descriptors);
    ASSERT_TRUE(frame.ok());
    Result<pb::AddFrameResponse> from_features = client->AddFrame("features", *frame);
    ASSERT_TRUE(from_jpeg.ok() && from_features.ok());
    EXPECT_EQ(from_features->num_features(), from_jpeg->num_features());
    EXPECT_EQ(from_features->timing().features_ms(), 0.0);  // the server extracted nothing
  }
  Result<pb::Frame> raw = FrameFromImage(CorridorGrey(20));
  ASSERT_TRUE(raw.ok());
  Result<pb::QueryPlaceResponse> by_jpeg = client->QueryPlace("jpeg", JpegFrame(CorridorJpeg(20)));
  Result<pb::QueryPlaceResponse> by_features = client->QueryPlace("features", *raw);
  ASSERT_TRUE(by_jpeg.ok() && by_features.ok());
  EXPECT_EQ(by_jpeg->result().status(), pb::LOOP_STATUS_LOOP_DETECTED);
  EXPECT_EQ(by_features->result().status(), by_jpeg->result().status());
  EXPECT_EQ(by_features->result().match_frame_id(), by_jpeg->result().match_frame_id());
  EXPECT_DOUBLE_EQ(by_features->result().score(), by_jpeg->result().score());
  EXPECT_EQ(by_features->result().inliers(), by_jpeg->result().inliers());
}

// Sends `calls` AddFrames to `map` at once from as many threads; returns the statuses.
std::vector<grpc::Status> Flood(RecognitionClient& client, const std::string& map, int calls) {
  const pb::Frame frame = JpegFrame(CorridorJpeg(1));
  std::vector<grpc::Status> statuses(static_cast<size_t>(calls));
  std::latch start(calls);
  std::vector<std::thread> threads;
  for (int i = 0; i < calls; ++i) {
    threads.emplace_back([&, i] {
      start.arrive_and_wait();
      statuses[size_t(i)] = client.AddFrame(map, frame).status();
    });
  }
  for (std::thread& thread : threads) thread.join();
  return statuses;
}

TEST_F(RecognitionClientTest, AFloodedServerTakesEveryAddedFrameOnceThanksToRetries) {
  StopServer();
  config().workers = 1;
  config().queue_capacity = 3;
  // gRPC's retries come back after exactly the pushback, all together: each round of the flood
  // gets in as many frames as there is room (up to one running and three waiting), so ten calls
  // need three of the policy's five attempts when frames take under a quarter of a second, and
  // still fit in five on a slow machine.
  config().retry_after_ms = 1000;
  StartServer();
  constexpr int kCalls = 10;

  // Without retries, the calls beyond one running and three waiting are refused, and add nothing.
  ClientOptions once = Options();
  once.retries = false;
  auto impatient = Connect(once);
  ASSERT_NE(impatient, nullptr);
  ASSERT_TRUE(impatient->CreateMap("once").ok());
  int refused = 0, added = 0;
  for (const grpc::Status& status : Flood(*impatient, "once", kCalls)) {
    if (status.ok()) ++added;
    if (status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED) ++refused;
  }
  EXPECT_GT(refused, 0);
  EXPECT_EQ(added + refused, kCalls);
  EXPECT_EQ(impatient->GetMap("once")->frames(), uint64_t(added));

  // With them, every call gets through, once.
  auto patient = Connect();
  ASSERT_NE(patient, nullptr);
  ASSERT_TRUE(patient->CreateMap("patient").ok());
  for (const grpc::Status& status : Flood(*patient, "patient", kCalls)) {
    EXPECT_TRUE(status.ok()) << status.error_message();
  }
  EXPECT_EQ(patient->GetMap("patient")->frames(), uint64_t(kCalls));
}

TEST_F(RecognitionClientTest, ATokenFileAuthenticatesEveryCall) {
  constexpr char kWriter[] = "writer-token-0123456789";
  constexpr char kReader[] = "reader-token-0123456789";
  const std::string server_tokens = data_dir_.Sub("tokens.yaml");
  std::ofstream(server_tokens) << "tokens: [{name: t, token: \"" << kWriter
                               << "\", rights: [read, write]}, {name: r, token: \"" << kReader
                               << "\", rights: [read]}]\n";
  StopServer();
  config().token_file = server_tokens;
  StartServer();

  const std::string token_file = data_dir_.Sub("robot.token");
  std::ofstream(token_file) << "  " << kWriter << "\n\n";  // surrounding whitespace is trimmed
  ClientOptions with_file = Options();
  with_file.token_file = token_file;
  auto writer = Connect(with_file);
  ASSERT_NE(writer, nullptr);
  Result<pb::MapInfo> created = writer->CreateMap("guarded");
  ASSERT_TRUE(created.ok()) << created.status().error_message();
  EXPECT_TRUE(writer->AddFrame("guarded", JpegFrame(CorridorJpeg(1))).ok());

  ClientOptions reading = Options();
  reading.token = kReader;
  auto reader = Connect(reading);
  ASSERT_NE(reader, nullptr);
  EXPECT_TRUE(reader->ListMaps().ok());
  EXPECT_EQ(reader->DeleteMap("guarded").status().error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
  auto anonymous = Connect();
  ASSERT_NE(anonymous, nullptr);
  EXPECT_EQ(anonymous->GetMap("guarded").status().error_code(), grpc::StatusCode::UNAUTHENTICATED);
}

TEST_F(RecognitionClientTest, MutualTlsConnectsWithTheClientCertificateAndOnlyWithIt) {
  const auto tls = [](const std::string& name) {
    return recog::testing::ProjectTestData("tls/" + name);
  };
  StopServer();
  config().tls.cert = tls("server.crt");
  config().tls.key = tls("server.key");
  config().tls.client_ca = tls("ca.crt");
  StartServer();

  ClientOptions options = Options();
  options.target = "localhost:" + std::to_string(server_->port());
  options.tls.enabled = true;
  options.tls.ca_file = tls("ca.crt");
  options.tls.cert_file = tls("client.crt");
  options.tls.key_file = tls("client.key");
  auto client = Connect(options);
  ASSERT_NE(client, nullptr);
  ASSERT_TRUE(client->CreateMap("secure").ok());
  Result<std::vector<pb::MapInfo>> listed = client->ListMaps();
  ASSERT_TRUE(listed.ok()) << listed.status().error_message();
  EXPECT_EQ(listed->size(), 1u);

  // Without a certificate (or without TLS) the server does not let the client in.
  for (const bool use_tls : {true, false}) {
    ClientOptions refused = Options();
    refused.retries = false;
    refused.tls.enabled = use_tls;
    refused.tls.ca_file = use_tls ? tls("ca.crt") : "";
    auto outsider = Connect(refused);
    ASSERT_NE(outsider, nullptr);
    EXPECT_EQ(outsider->ListMaps().status().error_code(), grpc::StatusCode::UNAVAILABLE);
  }
}

}  // namespace
}  // namespace recog::client::testing
