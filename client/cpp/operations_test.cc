// Loopback tests of RecognitionClient's operator calls against an in-process recogd: the health
// check, and an online checkpoint restored into a fresh server that then holds every map, frame
// and model version.
#include <filesystem>

#include "client/cpp/client_test_fixture.h"
#include "storage/rocksdb_index_store.h"
#include "tests/testing/model_files.h"

namespace recog::client::testing {
namespace {

namespace fs = std::filesystem;
using grpc::health::v1::HealthCheckResponse;
using recog::testing::PosterModelFile;

class OperationsTest : public ClientFixture {};

TEST_F(OperationsTest, TheHealthCheckSaysServingUntilTheServerStops) {
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  Result<HealthCheckResponse::ServingStatus> health = client->CheckHealth();
  ASSERT_TRUE(health.ok()) << health.status().error_message();
  EXPECT_EQ(*health, HealthCheckResponse::SERVING);
  StopServer();
  EXPECT_EQ(client->CheckHealth().status().error_code(), grpc::StatusCode::UNAVAILABLE);
}

TEST_F(OperationsTest, ACheckpointRestoredIntoAFreshServerHoldsEveryMapFrameAndModel) {
  auto client = Connect();
  ASSERT_NE(client, nullptr);
  ASSERT_TRUE(client->CreateMap("hall").ok());
  ASSERT_TRUE(client->CreateMap("yard").ok());
  for (int n : {1, 20, 41}) ASSERT_TRUE(client->AddFrame("hall", JpegFrame(CorridorJpeg(n))).ok());
  ASSERT_TRUE(client->AddFrame("yard", JpegFrame(CorridorJpeg(60))).ok());
  ASSERT_TRUE(client->UploadModel(PosterModelFile("poster", 1, "poster")).ok());
  ASSERT_TRUE(client->UploadModel(PosterModelFile("poster", 1, "poster"), "", {"again"}).ok());

  const std::string checkpoint = data_dir_.Sub("backup");
  uint64_t last_progress = 0;
  Result<pb::CheckpointManifest> manifest = client->DownloadCheckpoint(
      checkpoint, [&](uint64_t done, uint64_t) { last_progress = done; });
  ASSERT_TRUE(manifest.ok()) << manifest.status().error_message();
  EXPECT_EQ(manifest->maps(), 2u);
  EXPECT_EQ(manifest->models(), 1u);
  EXPECT_EQ(last_progress, manifest->total_bytes());
  uint64_t on_disk = 0;
  for (const pb::CheckpointFile& file : manifest->files()) {
    on_disk += fs::file_size(fs::path(checkpoint) / file.name());
  }
  EXPECT_EQ(on_disk, manifest->total_bytes());
  EXPECT_FALSE(fs::exists(checkpoint + ".part"));
  EXPECT_TRUE(fs::is_empty(data_dir_.path() / "checkpoints"));  // the server's copy is gone
  EXPECT_EQ(client->DownloadCheckpoint(checkpoint).status().error_code(),
            grpc::StatusCode::ALREADY_EXISTS);

  // Offline restore into a new data directory, and a fresh server on it.
  const std::string restored = data_dir_.Sub("restored");
  fs::create_directories(restored);
  ASSERT_TRUE(RestoreRocksDbCheckpoint(checkpoint, restored + "/store").ok());
  server::ServerConfig config = config_;
  config.data_dir = restored;
  auto fresh = server::RecognitionServer::Start(config);
  ASSERT_TRUE(fresh.ok()) << fresh.status().ToString();
  ClientOptions options = Options();
  options.target = "127.0.0.1:" + std::to_string((*fresh)->port());
  auto restored_client = Connect(options);
  ASSERT_NE(restored_client, nullptr);
  Result<std::vector<pb::MapInfo>> maps = restored_client->ListMaps();
  ASSERT_TRUE(maps.ok());
  ASSERT_EQ(maps->size(), 2u);
  EXPECT_EQ((*maps)[0].name(), "hall");
  EXPECT_EQ((*maps)[0].frames(), 3u);
  EXPECT_EQ((*maps)[1].name(), "yard");
  EXPECT_EQ((*maps)[1].frames(), 1u);
  Result<pb::QueryPlaceResponse> found =
      restored_client->QueryPlace("hall", JpegFrame(CorridorJpeg(20)));
  ASSERT_TRUE(found.ok());
  EXPECT_EQ(found->result().match_frame_id(), 1u);  // the frames themselves came back
  Result<std::vector<pb::ModelInfo>> models = restored_client->ListModels();
  ASSERT_TRUE(models.ok());
  ASSERT_EQ(models->size(), 1u);
  EXPECT_EQ(models->front().version(), 2u);
  EXPECT_TRUE(restored_client->DownloadModel("poster", 1, data_dir_.Sub("v1.robj")).ok());
  Result<pb::RecognizeObjectsResponse> seen = restored_client->RecognizeObjects(PosterView(1));
  ASSERT_TRUE(seen.ok());
  ASSERT_EQ(seen->objects_size(), 1);
  EXPECT_EQ(seen->objects(0).name(), "poster");
  (*fresh)->Shutdown(std::chrono::milliseconds(1000));
}

}  // namespace
}  // namespace recog::client::testing
