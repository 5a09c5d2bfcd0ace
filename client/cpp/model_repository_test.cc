// Loopback tests of RecognitionClient's model repository calls against an in-process recogd:
// upload and byte-exact download, an upload resumed after its connection broke, resumption of a
// download from a partial file, listings, deletion, watching,
// and recognition of an uploaded model by unary calls and an ObjectStream.
#include <filesystem>
#include <fstream>
#include <mutex>

#include <opencv2/imgcodecs.hpp>

#include "client/cpp/client_test_fixture.h"
#include "client/cpp/frame_stream.h"
#include "client/cpp/sha256.h"
#include "tests/testing/model_files.h"
#include "tests/testing/tcp_proxy.h"
#include "tests/testing/wait.h"
#include "wire/sha256.h"

namespace recog::client::testing {
namespace {

using recog::testing::ModelFile;
using recog::testing::PosterModelFile;
using recog::testing::WaitUntil;

// A model file of several 256 KiB chunks.
std::string BoxModelFile() { return ModelFile("crate", {1, 20, 41, 60}, "box"); }

void WriteFile(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

class ModelRepositoryTest : public ClientFixture {
 protected:
  void SetUp() override {
    ClientFixture::SetUp();
    client_ = Connect();
    ASSERT_NE(client_, nullptr);
  }

  // Where downloads go in this test.
  std::string Download(const std::string& name) const { return data_dir_.Sub(name + ".robj"); }

  std::unique_ptr<RecognitionClient> client_;
};

TEST_F(ModelRepositoryTest, AnUploadedModelDownloadsByteForByte) {
  // The server stores a file as uploaded when the name given is the one inside it (another name
  // is written into the stored file).
  const std::string file = BoxModelFile();
  ASSERT_GT(file.size(), 256u << 10);  // more than one chunk each way
  Result<pb::ModelInfo> uploaded = client_->UploadModel(file, "crate", {"hall", "paper"});
  ASSERT_TRUE(uploaded.ok()) << uploaded.status().error_message();
  EXPECT_EQ(uploaded->name(), "crate");
  EXPECT_EQ(uploaded->version(), 1u);
  EXPECT_EQ(uploaded->size_bytes(), file.size());
  EXPECT_EQ(uploaded->tags_size(), 2);

  const std::string path = Download("crate");
  Result<pb::ModelInfo> downloaded = client_->DownloadModel("crate", 0, path);
  ASSERT_TRUE(downloaded.ok()) << downloaded.status().error_message();
  EXPECT_EQ(downloaded->version(), 1u);
  EXPECT_EQ(downloaded->sha256(), uploaded->sha256());
  EXPECT_EQ(ReadFileBytes(path), file);
  EXPECT_FALSE(std::filesystem::exists(path + ".part"));

  // From a file, as version 2. The server writes the version number into the file it stores,
  // so this download is that file (the info's checksum), not quite the bytes uploaded.
  const std::string source = data_dir_.Sub("second.robj");
  WriteFile(source, ModelFile("crate", {41}, "box"));
  Result<pb::ModelInfo> again = client_->UploadModelFile(source);
  ASSERT_TRUE(again.ok()) << again.status().error_message();
  EXPECT_EQ(again->version(), 2u);
  Result<pb::ModelInfo> latest = client_->DownloadModel("crate", 0, path);
  ASSERT_TRUE(latest.ok());
  EXPECT_EQ(latest->version(), 2u);
  EXPECT_EQ(Sha256Hex(ReadFileBytes(path)), again->sha256());
  // Downloading version 1 again replaces the file.
  ASSERT_TRUE(client_->DownloadModel("crate", 1, path).ok());
  EXPECT_EQ(ReadFileBytes(path), file);

  EXPECT_EQ(client_->DownloadModel("crate", 3, path).status().error_code(),
            grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(client_->UploadModelFile(data_dir_.Sub("missing.robj")).status().error_code(),
            grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(client_->UploadModel("").status().error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(client_->UploadModel("not a model file").status().error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);  // refused by the server
}

TEST_F(ModelRepositoryTest, AnUploadCutOffMidFileIsResumedAndStoredOnce) {
  const std::string file = BoxModelFile();
  // The connection breaks once the first 256 KiB chunk and part of the second have left; the
  // resumption reconnects through the proxy. gRPC's retries are off: with them, gRPC would send
  // again the whole upload, which fits its retry buffer; larger ones are resumed like this.
  const uint64_t cut = (256u << 10) + 32768;
  ASSERT_GT(file.size(), cut + 65536);
  recog::testing::TcpProxy proxy(server_->port(), /*cut_first_after=*/cut);
  ClientOptions options = Options();
  options.target = "127.0.0.1:" + std::to_string(proxy.port());
  options.retries = false;
  std::unique_ptr<RecognitionClient> client = Connect(options);
  ASSERT_NE(client, nullptr);
  Result<pb::ModelInfo> uploaded = client->UploadModel(file, "crate");
  ASSERT_TRUE(uploaded.ok()) << uploaded.status().error_message();
  EXPECT_EQ(uploaded->version(), 1u);
  EXPECT_EQ(uploaded->sha256(), Sha256Hex(file));

  const std::vector<uint64_t> sent = proxy.upstream_bytes();
  ASSERT_GE(sent.size(), 2u);  // the connection that broke, and the retry's
  EXPECT_EQ(sent[0], cut);
  uint64_t after_the_cut = 0;
  for (size_t i = 1; i < sent.size(); ++i) after_the_cut += sent[i];
  EXPECT_LT(after_the_cut, file.size());  // the rest of the file, not all of it again
  Result<std::vector<pb::ModelInfo>> models = client_->ListModels();
  ASSERT_TRUE(models.ok());
  ASSERT_EQ(models->size(), 1u);
  EXPECT_EQ(models->front().version(), 1u);  // stored once
  const std::string path = Download("crate");
  ASSERT_TRUE(client_->DownloadModel("crate", 1, path).ok());
  EXPECT_EQ(ReadFileBytes(path), file);
}

TEST_F(ModelRepositoryTest, ADownloadContinuesFromThePartialFileOfABrokenOne) {
  const std::string file = BoxModelFile();
  ASSERT_TRUE(client_->UploadModel(file).ok());
  const std::string path = Download("crate");
  // What a download broken after its first chunk leaves behind.
  WriteFile(path + ".part", file.substr(0, 256u << 10));
  Result<pb::ModelInfo> resumed = client_->DownloadModel("crate", 1, path);
  ASSERT_TRUE(resumed.ok()) << resumed.status().error_message();
  EXPECT_EQ(ReadFileBytes(path), file);
  EXPECT_FALSE(std::filesystem::exists(path + ".part"));
}

TEST_F(ModelRepositoryTest, APartialFileOfOtherBytesIsReplacedByTheWholeModel) {
  const std::string file = PosterModelFile("poster", 1, "poster");
  ASSERT_TRUE(client_->UploadModel(file).ok());
  const std::string path = Download("poster");
  // Bytes of another file: the resumed download does not verify and is fetched again.
  WriteFile(path + ".part", std::string(1000, 'x'));
  ASSERT_TRUE(client_->DownloadModel("poster", 0, path).ok());
  EXPECT_EQ(ReadFileBytes(path), file);
  // Longer than the model: the server refuses the offset, and the whole file is fetched.
  WriteFile(path + ".part", file + "trailing bytes");
  ASSERT_TRUE(client_->DownloadModel("poster", 0, path).ok());
  EXPECT_EQ(ReadFileBytes(path), file);
  EXPECT_FALSE(std::filesystem::exists(path + ".part"));
}

TEST_F(ModelRepositoryTest, ListingFiltersByPrefixClassAndTagAndDeletingRemovesEveryVersion) {
  const std::string poster = PosterModelFile("x", 1, "poster");
  const std::string box = PosterModelFile("x", 20, "box");
  ASSERT_TRUE(client_->UploadModel(poster, "shelf-a", {"kitchen"}).ok());
  ASSERT_TRUE(client_->UploadModel(box, "shelf-b", {"kitchen"}).ok());
  ASSERT_TRUE(client_->UploadModel(poster, "wall-c", {"hall"}).ok());
  ASSERT_TRUE(client_->UploadModel(poster, "wall-c", {"hall"}).ok());

  Result<std::vector<pb::ModelInfo>> all = client_->ListModels();
  ASSERT_TRUE(all.ok()) << all.status().error_message();
  ASSERT_EQ(all->size(), 3u);
  EXPECT_EQ(all->at(2).name(), "wall-c");
  EXPECT_EQ(all->at(2).version(), 2u);  // the latest version of each
  EXPECT_EQ(client_->ListModels({.name_prefix = "shelf-"})->size(), 2u);
  EXPECT_EQ(client_->ListModels({.object_class = "box"})->size(), 1u);
  Result<std::vector<pb::ModelInfo>> kitchen = client_->ListModels({.tag = "kitchen"});
  ASSERT_TRUE(kitchen.ok());
  ASSERT_EQ(kitchen->size(), 2u);
  EXPECT_EQ(kitchen->at(1).name(), "shelf-b");

  Result<uint32_t> deleted = client_->DeleteModel("wall-c");
  ASSERT_TRUE(deleted.ok());
  EXPECT_EQ(*deleted, 2u);
  EXPECT_EQ(client_->DeleteModel("wall-c").status().error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(client_->ListModels()->size(), 2u);
}

TEST_F(ModelRepositoryTest, AWatcherReceivesTheUploadsOfItsModels) {
  std::mutex mutex;
  std::vector<pb::WatchModelsResponse> events;
  std::unique_ptr<ModelWatch> watch =
      client_->WatchModels("watched", [&](const pb::WatchModelsResponse& event) {
        std::lock_guard lock(mutex);
        events.push_back(event);
      });
  const auto seen = [&] {
    std::lock_guard lock(mutex);
    return events.size();
  };
  const auto deletion_seen = [&] {
    std::lock_guard lock(mutex);
    return !events.empty() && events.back().change() == pb::MODEL_CHANGE_DELETED;
  };
  // The server registers the watcher shortly after the call starts: upload until it reports.
  const std::string file = PosterModelFile("x", 1, "");
  ASSERT_TRUE(WaitUntil(
      [&] {
        EXPECT_TRUE(client_->UploadModel(file, "watched-1").ok());
        EXPECT_TRUE(client_->UploadModel(file, "other").ok());  // filtered out by the prefix
        return seen() > 0;
      },
      recog::testing::kEventTimeout, std::chrono::milliseconds(100)))
      << "no upload reached the watch";
  ASSERT_TRUE(client_->DeleteModel("watched-1").ok());
  EXPECT_TRUE(WaitUntil(deletion_seen)) << "the watch did not see the deletion";
  watch->Cancel();
  EXPECT_EQ(watch->Wait().error_code(), grpc::StatusCode::CANCELLED);
  ASSERT_GE(events.size(), 2u);
  EXPECT_EQ(events.front().change(), pb::MODEL_CHANGE_PUT);
  EXPECT_EQ(events.front().model().name(), "watched-1");
  EXPECT_EQ(events.back().change(), pb::MODEL_CHANGE_DELETED);
  for (size_t i = 1; i < events.size(); ++i) {
    EXPECT_EQ(events[i].model().name(), "watched-1");
    EXPECT_LT(events[i - 1].sequence(), events[i].sequence());
  }
}

TEST_F(ModelRepositoryTest, AnUploadedModelIsRecognisedByUnaryCallsAndAnObjectStream) {
  ASSERT_TRUE(client_->UploadModel(PosterModelFile("poster", 1, "poster")).ok());
  Result<pb::RecognizeObjectsResponse> seen = client_->RecognizeObjects(PosterView(1));
  ASSERT_TRUE(seen.ok()) << seen.status().error_message();
  ASSERT_EQ(seen->objects_size(), 1);
  EXPECT_EQ(seen->objects(0).name(), "poster");
  pb::ObjectFilter boxes;
  boxes.add_classes("box");
  EXPECT_EQ(client_->RecognizeObjects(PosterView(1), boxes)->objects_size(), 0);
  EXPECT_EQ(client_->RecognizeObjects(JpegFrame(CorridorJpeg(1))).status().error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);  // no intrinsics

  Result<std::unique_ptr<ObjectStream>> stream = ObjectStream::Open(*client_);
  ASSERT_TRUE(stream.ok());
  auto first = (*stream)->Send(PosterView(1));
  auto other = (*stream)->Send(PosterView(60));
  auto unusable = (*stream)->Send(JpegFrame(CorridorJpeg(1)));
  ObjectStream::Answer a = first.get(), b = other.get(), c = unusable.get();
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  EXPECT_EQ(a->objects_size(), 1);
  EXPECT_EQ(b->objects_size(), 0);
  EXPECT_EQ(b->sequence(), 1u);
  EXPECT_EQ(c->error().code(), int(grpc::StatusCode::INVALID_ARGUMENT));
  EXPECT_TRUE((*stream)->Close().ok());
}

}  // namespace
}  // namespace recog::client::testing
