// Repository replicas over loopback TCP: a primary recogd and a replica following it
// (repository.primary), both in this process. The replica copies every version as the primary
// stores it (numbers, tags, creation times, bytes) and recognises the models; it follows uploads
// and deletions, refuses writes naming its primary, keeps serving while the primary is away (or
// was never reached), catches up when either side comes back, and reconciles what changed while
// it was down; settings it cannot use stop it from starting.
#include <chrono>

#include <google/protobuf/util/message_differencer.h>

#include <gmock/gmock.h>

#include "client/cpp/recognition_client.h"
#include "tests/server/server_fixture.h"
#include "tests/testing/model_files.h"
#include "tests/testing/unix_socket.h"
#include "tests/testing/wait.h"

namespace recog::server::testing {
namespace {

using recog::testing::ModelFile;
using recog::testing::PosterModelFile;
using recog::testing::WaitUntil;

std::unique_ptr<client::RecognitionClient> ClientOf(const std::string& target) {
  client::ClientOptions options;
  options.target = target;
  options.retries = false;  // a test polls; it wants answers, not retries
  auto connected = client::RecognitionClient::Connect(options);
  EXPECT_TRUE(connected.ok()) << connected.status().error_message();
  return connected.ok() ? std::move(*connected) : nullptr;
}

// The primary is the fixture's server, on a fixed address (a unix socket) so that it can restart
// where the replica looks for it.
class ReplicationTest : public ServerFixture {
 protected:
  ReplicationTest() : sockets_("sockets"), replica_dir_("replica"), downloads_("downloads") {
    config().listen = recog::testing::UnixSocketAddress(sockets_.path(), "primary");
  }

  void SetUp() override {
    ServerFixture::SetUp();
    primary_ = ClientOf(config().listen);
  }

  void TearDown() override {
    replica_.reset();
    replica_server_.reset();
    ServerFixture::TearDown();
  }

  // The configuration of a replica of the fixture's server.
  ServerConfig ReplicaConfig() {
    ServerConfig replica_config = config();
    replica_config.listen = "127.0.0.1:0";
    replica_config.data_dir = replica_dir_.path().string();
    replica_config.repository.primary = config().listen;
    return replica_config;
  }

  void StartReplica(const ServerConfig& replica_config) {
    auto started = RecognitionServer::Start(replica_config);
    ASSERT_TRUE(started.ok()) << started.status().ToString();
    replica_server_ = std::move(*started);
    replica_ = ClientOf("127.0.0.1:" + std::to_string(replica_server_->port()));
  }
  void StartReplica() { StartReplica(ReplicaConfig()); }

  void StopReplica() {
    replica_.reset();
    replica_server_.reset();
  }

  pb::ModelInfo Upload(const std::string& file, const std::string& name,
                       const std::vector<std::string>& tags = {}) {
    auto uploaded = primary_->UploadModel(file, name, tags);
    EXPECT_TRUE(uploaded.ok()) << uploaded.status().error_message();
    return uploaded.ok() ? *uploaded : pb::ModelInfo();
  }

  // Version `version` of a model on `server`: its info and file; NOT_FOUND and the like as the
  // status.
  grpc::Status Fetch(client::RecognitionClient& server, const std::string& name, uint32_t version,
                     pb::ModelInfo* info, std::string* bytes) {
    const std::string path = (downloads_.path() / "model").string();
    auto downloaded = server.DownloadModel(name, version, path);
    if (!downloaded.ok()) return downloaded.status();
    *info = *downloaded;
    *bytes = ReadFileBytes(path);
    return grpc::Status::OK;
  }

  // True when the replica holds version `version` of `name` exactly as the primary does.
  bool ReplicaHolds(const std::string& name, uint32_t version) {
    pb::ModelInfo on_primary, on_replica;
    std::string primary_bytes, replica_bytes;
    if (!Fetch(*primary_, name, version, &on_primary, &primary_bytes).ok() ||
        !Fetch(*replica_, name, version, &on_replica, &replica_bytes).ok()) {
      return false;
    }
    return google::protobuf::util::MessageDifferencer::Equals(on_primary, on_replica) &&
           primary_bytes == replica_bytes;
  }

  bool ReplicaLacks(const std::string& name) {
    pb::ModelInfo info;
    std::string bytes;
    return Fetch(*replica_, name, 0, &info, &bytes).error_code() == grpc::StatusCode::NOT_FOUND;
  }

  // The names and versions of the latest models `server` lists.
  static std::vector<std::pair<std::string, uint32_t>> Latest(client::RecognitionClient& server) {
    std::vector<std::pair<std::string, uint32_t>> latest;
    auto models = server.ListModels();
    EXPECT_TRUE(models.ok()) << models.status().error_message();
    if (models.ok()) {
      for (const pb::ModelInfo& m : *models) latest.emplace_back(m.name(), m.version());
    }
    return latest;
  }

  // The names of the objects `server` recognises in corridor image 1 (a poster of it).
  static std::vector<std::string> Recognised(client::RecognitionClient& server) {
    std::vector<std::string> names;
    auto seen = server.RecognizeObjects(PosterView(1));
    EXPECT_TRUE(seen.ok()) << seen.status().error_message();
    if (seen.ok()) {
      for (const pb::DetectedObject& object : seen->objects()) names.push_back(object.name());
    }
    return names;
  }

  recog::testing::TempDir sockets_;
  recog::testing::TempDir replica_dir_;
  recog::testing::TempDir downloads_;
  std::unique_ptr<client::RecognitionClient> primary_;
  std::unique_ptr<RecognitionServer> replica_server_;
  std::unique_ptr<client::RecognitionClient> replica_;
};

TEST_F(ReplicationTest, AReplicaCopiesEveryVersionAsThePrimaryStoresItAndRecognisesIt) {
  Upload(PosterModelFile("poster", 20, "poster"), "poster", {"lab"});
  Upload(PosterModelFile("poster", 1, "poster"), "poster", {"lab", "v2"});
  Upload(ModelFile("box", {41, 60}, "box"), "box");
  StartReplica();
  ASSERT_TRUE(WaitUntil([&] { return ReplicaHolds("poster", 2) && ReplicaHolds("box", 1); }));
  EXPECT_TRUE(ReplicaHolds("poster", 1));
  EXPECT_EQ(Latest(*replica_), Latest(*primary_));
  EXPECT_EQ(Recognised(*replica_), std::vector<std::string>{"poster"});
}

TEST_F(ReplicationTest, AReplicaFollowsUploadsAndDeletionsAsTheyHappen) {
  StartReplica();
  Upload(ModelFile("box", {41, 60}, "box"), "box");
  ASSERT_TRUE(WaitUntil([&] { return ReplicaHolds("box", 1); }));
  Upload(PosterModelFile("poster", 20, "poster"), "poster");
  Upload(PosterModelFile("poster", 1, "poster"), "poster", {"newer"});
  ASSERT_TRUE(WaitUntil([&] { return ReplicaHolds("poster", 2); }));
  EXPECT_TRUE(ReplicaHolds("poster", 1));
  EXPECT_THAT(Recognised(*replica_), ::testing::Contains("poster"));
  ASSERT_TRUE(primary_->DeleteModel("poster").ok());
  ASSERT_TRUE(WaitUntil([&] { return ReplicaLacks("poster"); }));
  EXPECT_THAT(Recognised(*replica_), ::testing::Not(::testing::Contains("poster")));
  EXPECT_EQ(Latest(*replica_), (std::vector<std::pair<std::string, uint32_t>>{{"box", 1}}));
}

TEST_F(ReplicationTest, AReplicaRefusesWritesNamingItsPrimaryAndKeepsItsModels) {
  Upload(PosterModelFile("poster", 1, "poster"), "poster");
  StartReplica();
  ASSERT_TRUE(WaitUntil([&] { return ReplicaHolds("poster", 1); }));

  auto upload = replica_->UploadModel(PosterModelFile("poster", 20, "poster"), "poster");
  EXPECT_EQ(upload.status().error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(upload.status().error_message().find(config().listen), std::string::npos)
      << upload.status().error_message();
  auto deleted = replica_->DeleteModel("poster");
  EXPECT_EQ(deleted.status().error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(deleted.status().error_message().find("read-only replica"), std::string::npos)
      << deleted.status().error_message();
  EXPECT_TRUE(ReplicaHolds("poster", 1));
  EXPECT_EQ(Latest(*replica_), (std::vector<std::pair<std::string, uint32_t>>{{"poster", 1}}));
}

TEST_F(ReplicationTest, AReplicaServesWhileThePrimaryIsAwayAndFollowsItWhenItReturns) {
  Upload(PosterModelFile("poster", 1, "poster"), "poster");
  StartReplica();
  ASSERT_TRUE(WaitUntil([&] { return ReplicaHolds("poster", 1); }));
  primary_.reset();
  StopServer();
  EXPECT_EQ(Recognised(*replica_), std::vector<std::string>{"poster"});
  EXPECT_EQ(Latest(*replica_), (std::vector<std::pair<std::string, uint32_t>>{{"poster", 1}}));

  StartServer();  // same port, same data
  primary_ = ClientOf(config().listen);
  Upload(ModelFile("box", {41, 60}, "box"), "box");
  EXPECT_TRUE(WaitUntil([&] { return ReplicaHolds("box", 1); }));
}

TEST_F(ReplicationTest, AReplicaThatWasDownReconcilesWhatChangedMeanwhile) {
  Upload(PosterModelFile("poster", 1, "poster"), "poster");
  Upload(PosterModelFile("poster", 20, "poster"), "poster");
  Upload(ModelFile("box", {41, 60}, "box"), "box");
  StartReplica();
  ASSERT_TRUE(WaitUntil([&] { return ReplicaHolds("poster", 2) && ReplicaHolds("box", 1); }));
  StopReplica();

  // While the replica is down: the box goes, the poster is deleted and uploaded anew (another
  // version 1: the same number, another file), a cup arrives.
  ASSERT_TRUE(primary_->DeleteModel("box").ok());
  ASSERT_TRUE(primary_->DeleteModel("poster").ok());
  Upload(PosterModelFile("poster", 60, "poster"), "poster");
  Upload(PosterModelFile("cup", 41, "cup"), "cup");

  StartReplica();
  ASSERT_TRUE(WaitUntil([&] { return ReplicaHolds("cup", 1) && ReplicaHolds("poster", 1); }));
  EXPECT_TRUE(ReplicaLacks("box"));
  pb::ModelInfo info;
  std::string bytes;
  EXPECT_EQ(Fetch(*replica_, "poster", 2, &info, &bytes).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(Latest(*replica_), Latest(*primary_));
}

TEST_F(ReplicationTest, AReplicaWhosePrimaryTokenFileCannotBeReadDoesNotStartAndSaysWhy) {
  ServerConfig replica_config = ReplicaConfig();
  replica_config.repository.token_file = "/nonexistent/primary.token";
  auto started = RecognitionServer::Start(replica_config);
  ASSERT_FALSE(started.ok());
  EXPECT_EQ(started.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(started.status().message().find("/nonexistent/primary.token"), std::string::npos)
      << started.status().ToString();
}

TEST_F(ReplicationTest, AReplicaWhosePrimaryIsUnreachableStartsServesAndStillRefusesWrites) {
  ServerConfig replica_config = ReplicaConfig();
  replica_config.repository.primary = recog::testing::UnixSocketAddress(sockets_.path(), "nobody");
  StartReplica(replica_config);
  ASSERT_NE(replica_, nullptr);
  EXPECT_TRUE(Latest(*replica_).empty());
  EXPECT_TRUE(Recognised(*replica_).empty());
  auto upload = replica_->UploadModel(PosterModelFile("poster", 1, "poster"), "poster");
  EXPECT_EQ(upload.status().error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(upload.status().error_message().find(replica_config.repository.primary),
            std::string::npos)
      << upload.status().error_message();
}

}  // namespace
}  // namespace recog::server::testing
