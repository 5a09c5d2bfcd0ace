// Loopback tests of the ObjectRepository and ObjectRecognition services: versioned uploads and
// downloads, watching (also with the stored versions first), recognition of what was uploaded,
// bad uploads and bad frames.
#include <algorithm>
#include <chrono>
#include <iterator>
#include <mutex>
#include <string_view>
#include <thread>

#include <opencv2/imgcodecs.hpp>

#include "tests/server/server_fixture.h"
#include "tests/testing/model_files.h"
#include "tests/testing/wait.h"
#include "wire/sha256.h"

namespace recog::server::testing {
namespace {

using recog::testing::PosterModelFile;
using recog::testing::WaitUntil;

class RepositoryServiceTest : public ServerFixture {
 protected:
  // Uploads `bytes` in 64 KiB chunks with the header's size and SHA-256 (or the given ones).
  grpc::Status Put(const std::string& bytes, const std::string& name,
                   std::vector<std::string> tags = {}, pb::ModelInfo* info = nullptr,
                   std::string sha256 = {}, uint64_t size = 0) {
    pb::PutModelHeader header;
    header.set_name(name);
    for (const std::string& tag : tags) header.add_tags(tag);
    header.set_sha256(sha256.empty() ? Sha256Hex(bytes) : sha256);
    header.set_size_bytes(size == 0 ? bytes.size() : size);
    return Upload(header, bytes, info);
  }

  // Resumes the upload of `bytes` at `offset`: sends the rest.
  grpc::Status Resume(const std::string& bytes, uint64_t offset, pb::ModelInfo* info = nullptr) {
    return Upload(HeaderOf(bytes, offset), std::string_view(bytes).substr(offset), info);
  }

  // Starts uploading `bytes`, sends the first `sent` of them, then cancels the call (as a lost
  // connection would end it) once the server has had time to read them. Nothing tells a client
  // that the server has read a chunk of a call still open (it answers at the end), so the pause
  // stays: the server keeps what it had read when it saw the cancellation, and the test accepts
  // any part of the `sent` bytes, only not none.
  void Interrupt(const std::string& bytes, size_t sent) {
    auto context = Context();
    pb::PutModelResponse response;
    auto writer = models_->PutModel(context.get(), &response);
    pb::PutModelRequest request;
    *request.mutable_header() = HeaderOf(bytes, 0);
    writer->Write(request);
    for (size_t offset = 0; offset < sent; offset += 4096) {
      request.set_chunk(bytes.substr(offset, std::min<size_t>(4096, sent - offset)));
      ASSERT_TRUE(writer->Write(request));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    context->TryCancel();
    EXPECT_EQ(writer->Finish().error_code(), grpc::StatusCode::CANCELLED);
  }

  // GetUploadStatus of the upload of `bytes`.
  pb::GetUploadStatusResponse UploadStatus(const std::string& bytes) {
    pb::GetUploadStatusRequest request;
    request.set_sha256(Sha256Hex(bytes));
    request.set_size_bytes(bytes.size());
    pb::GetUploadStatusResponse response;
    const grpc::Status status = models_->GetUploadStatus(Context().get(), request, &response);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return response;
  }

  static pb::PutModelHeader HeaderOf(const std::string& bytes, uint64_t offset) {
    pb::PutModelHeader header;
    header.set_sha256(Sha256Hex(bytes));
    header.set_size_bytes(bytes.size());
    header.set_offset(offset);
    return header;
  }

  // One PutModel call: `header`, then `bytes` in 64 KiB chunks.
  grpc::Status Upload(const pb::PutModelHeader& header, std::string_view bytes,
                      pb::ModelInfo* info) {
    auto context = Context();
    pb::PutModelResponse response;
    auto writer = models_->PutModel(context.get(), &response);
    pb::PutModelRequest request;
    *request.mutable_header() = header;
    writer->Write(request);
    for (size_t offset = 0; offset < bytes.size(); offset += 65536) {
      request.set_chunk(std::string(bytes.substr(offset, 65536)));
      if (!writer->Write(request)) break;
    }
    writer->WritesDone();
    grpc::Status status = writer->Finish();
    if (info != nullptr) *info = response.model();
    return status;
  }

  // Downloads a version from byte `offset` on; returns the bytes and fills the info.
  grpc::Status Get(const std::string& name, uint32_t version, pb::ModelInfo* info,
                   std::string* bytes, uint64_t offset = 0) {
    auto context = Context();
    pb::GetModelRequest request;
    request.set_name(name);
    request.set_version(version);
    request.set_chunk_bytes(50000);
    request.set_offset(offset);
    auto reader = models_->GetModel(context.get(), request);
    pb::GetModelResponse response;
    bytes->clear();
    while (reader->Read(&response)) {
      if (response.has_info()) *info = response.info();
      if (response.has_chunk()) *bytes += response.chunk();
    }
    return reader->Finish();
  }

  grpc::Status Recognize(const pb::Frame& frame, pb::RecognizeObjectsResponse* response,
                         const pb::ObjectFilter& filter = {},
                         const pb::DetectionOptions& detection_options = {}) {
    pb::RecognizeObjectsRequest request;
    *request.mutable_frame() = frame;
    *request.mutable_filter() = filter;
    *request.mutable_detection_options() = detection_options;
    return objects_->RecognizeObjects(Context().get(), request, response);
  }
};

TEST_F(RepositoryServiceTest, AnInterruptedUploadIsResumedFromTheBytesTheServerKept) {
  const std::string file = PosterModelFile("poster", 1, "poster");
  ASSERT_GT(file.size(), 20000u);
  EXPECT_EQ(UploadStatus(file).received_bytes(), 0u);
  Interrupt(file, 16384);
  // The server keeps the bytes once it has seen the cancellation.
  uint64_t kept = 0;
  ASSERT_TRUE(WaitUntil([&] { return (kept = UploadStatus(file).received_bytes()) > 0; }))
      << "the server kept none of the interrupted upload's bytes";
  EXPECT_LE(kept, 16384u);

  // Resuming beyond what the server holds is refused, and what it holds stays.
  const grpc::Status beyond = Resume(file, kept + 1);
  EXPECT_EQ(beyond.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(beyond.error_message().find("holds " + std::to_string(kept) + " bytes"),
            std::string::npos)
      << beyond.error_message();
  EXPECT_EQ(UploadStatus(file).received_bytes(), kept);
  EXPECT_EQ(Resume(file, file.size()).error_code(), grpc::StatusCode::INVALID_ARGUMENT);

  pb::ModelInfo info;
  const grpc::Status resumed = Resume(file, kept, &info);
  ASSERT_TRUE(resumed.ok()) << resumed.error_message();
  EXPECT_EQ(info.version(), 1u);
  std::string stored;
  pb::ModelInfo got;
  ASSERT_TRUE(Get("poster", 1, &got, &stored).ok());
  EXPECT_EQ(stored, file);  // the kept bytes and the rest, in order

  // The server now remembers the upload as stored, not its bytes.
  const pb::GetUploadStatusResponse done = UploadStatus(file);
  EXPECT_EQ(done.received_bytes(), 0u);
  EXPECT_EQ(done.stored().name(), "poster");
  EXPECT_EQ(done.stored().version(), 1u);
  EXPECT_EQ(Resume(file, kept).error_code(), grpc::StatusCode::FAILED_PRECONDITION);

  pb::GetUploadStatusRequest bad;
  bad.set_sha256("not hex");
  pb::GetUploadStatusResponse ignored;
  EXPECT_EQ(models_->GetUploadStatus(Context().get(), bad, &ignored).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(RepositoryServiceTest, EveryUploadIsANewVersionAndTheLatestIsRecognisedAtOnce) {
  const std::string v1 = PosterModelFile("poster", 1, "poster");
  pb::ModelInfo info;
  ASSERT_TRUE(Put(v1, "", {"hall", "paper"}, &info).ok());
  EXPECT_EQ(info.name(), "poster");
  EXPECT_EQ(info.version(), 1u);
  EXPECT_EQ(info.object_class(), "poster");
  EXPECT_EQ(info.type(), pb::OBJECT_TYPE_PLANAR);
  EXPECT_GT(info.num_descriptors(), 300u);
  EXPECT_EQ(info.tags_size(), 2);

  pb::RecognizeObjectsResponse seen;
  ASSERT_TRUE(Recognize(PosterView(1), &seen).ok());
  ASSERT_EQ(seen.objects_size(), 1);
  EXPECT_EQ(seen.objects(0).name(), "poster");
  EXPECT_EQ(seen.objects(0).version(), 1u);
  EXPECT_EQ(seen.objects(0).pose().rotation_size(), 9);
  EXPECT_GT(seen.objects(0).pose().translation(2), 0.0);  // in front of the camera
  EXPECT_GE(seen.objects(0).inliers(), 12u);
  EXPECT_GE(seen.objects(0).outline_size(), 3);

  // A second upload of the name (another picture) is version 2; version 1 stays downloadable.
  pb::ModelInfo info2;
  ASSERT_TRUE(Put(PosterModelFile("whatever", 41, "poster"), "poster", {}, &info2).ok());
  EXPECT_EQ(info2.version(), 2u);
  pb::ModelInfo got;
  std::string bytes;
  ASSERT_TRUE(Get("poster", 1, &got, &bytes).ok());
  EXPECT_EQ(got.version(), 1u);
  EXPECT_EQ(Sha256Hex(bytes), got.sha256());
  EXPECT_EQ(bytes.size(), got.size_bytes());
  auto decoded = DecodeObjectModel(bytes, "download");
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  EXPECT_EQ(decoded.value().metadata.version, 1u);
  ASSERT_TRUE(Get("poster", 0, &got, &bytes).ok());
  EXPECT_EQ(got.version(), 2u);
  EXPECT_EQ(Get("poster", 3, &got, &bytes).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(Get("nothing", 0, &got, &bytes).error_code(), grpc::StatusCode::NOT_FOUND);

  ASSERT_TRUE(Recognize(PosterView(41), &seen).ok());
  ASSERT_EQ(seen.objects_size(), 1);
  EXPECT_EQ(seen.objects(0).version(), 2u);
}

TEST_F(RepositoryServiceTest, ARepeatedRequestIdStoresNoSecondVersionAndDeletesOnce) {
  const std::string file = PosterModelFile("poster", 1, "poster");
  pb::PutModelHeader header = HeaderOf(file, 0);
  header.set_request_id("upload-1");
  pb::ModelInfo first, repeat;
  ASSERT_TRUE(Upload(header, file, &first).ok());
  ASSERT_TRUE(Upload(header, file, &repeat).ok());
  EXPECT_EQ(repeat.version(), first.version());
  header.set_request_id("upload-2");  // a new id: a new version
  pb::ModelInfo second;
  ASSERT_TRUE(Upload(header, file, &second).ok());
  EXPECT_EQ(second.version(), first.version() + 1);

  header.set_request_id(std::string(129, 'x'));
  EXPECT_EQ(Upload(header, file, nullptr).error_code(), grpc::StatusCode::INVALID_ARGUMENT);

  pb::DeleteModelRequest remove;
  remove.set_name("poster");
  remove.set_request_id("delete-1");
  pb::DeleteModelResponse removed, removed_again;
  ASSERT_TRUE(models_->DeleteModel(Context().get(), remove, &removed).ok());
  ASSERT_TRUE(models_->DeleteModel(Context().get(), remove, &removed_again).ok());
  EXPECT_EQ(removed_again.versions_deleted(), 2u);  // the first answer, not NOT_FOUND
  remove.set_request_id("delete-2");
  EXPECT_EQ(models_->DeleteModel(Context().get(), remove, &removed).error_code(),
            grpc::StatusCode::NOT_FOUND);
}

TEST_F(RepositoryServiceTest, ADownloadFromAnOffsetSendsTheTailAndOneBeyondTheEndIsOutOfRange) {
  const std::string file = PosterModelFile("poster", 1, "poster");
  ASSERT_GT(file.size(), 60000u);  // more than one 50000-byte chunk
  ASSERT_TRUE(Put(file, "").ok());
  pb::ModelInfo info;
  std::string bytes;
  for (const uint64_t offset : {uint64_t{1}, uint64_t{50000}, uint64_t{file.size() - 7}}) {
    ASSERT_TRUE(Get("poster", 1, &info, &bytes, offset).ok());
    EXPECT_EQ(info.size_bytes(), file.size());  // the info describes the whole file
    EXPECT_EQ(info.sha256(), Sha256Hex(file));
    EXPECT_EQ(bytes, file.substr(offset)) << "offset " << offset;
  }
  ASSERT_TRUE(Get("poster", 1, &info, &bytes, file.size()).ok());
  EXPECT_EQ(info.version(), 1u);
  EXPECT_TRUE(bytes.empty());  // at the end: the info and nothing else
  const grpc::Status beyond = Get("poster", 1, &info, &bytes, file.size() + 1);
  EXPECT_EQ(beyond.error_code(), grpc::StatusCode::OUT_OF_RANGE) << beyond.error_message();
}

TEST_F(RepositoryServiceTest, ListingFiltersByPrefixClassAndTagAPageAtATime) {
  ASSERT_TRUE(Put(PosterModelFile("a", 1, "poster"), "shelf-a", {"kitchen"}).ok());
  ASSERT_TRUE(Put(PosterModelFile("b", 20, "box"), "shelf-b", {"kitchen"}).ok());
  ASSERT_TRUE(Put(PosterModelFile("c", 41, "poster"), "wall-c", {"hall"}).ok());
  pb::ListModelsRequest request;
  pb::ListModelsResponse response;
  request.set_name_prefix("shelf-");
  ASSERT_TRUE(models_->ListModels(Context().get(), request, &response).ok());
  ASSERT_EQ(response.models_size(), 2);
  EXPECT_EQ(response.models(0).name(), "shelf-a");
  request.Clear();
  request.set_object_class("poster");
  ASSERT_TRUE(models_->ListModels(Context().get(), request, &response).ok());
  ASSERT_EQ(response.models_size(), 2);
  EXPECT_EQ(response.models(1).name(), "wall-c");
  request.Clear();
  request.set_tag("kitchen");
  request.set_page_size(1);
  ASSERT_TRUE(models_->ListModels(Context().get(), request, &response).ok());
  ASSERT_EQ(response.models_size(), 1);
  ASSERT_FALSE(response.next_page_token().empty());
  request.set_page_token(response.next_page_token());
  ASSERT_TRUE(models_->ListModels(Context().get(), request, &response).ok());
  ASSERT_EQ(response.models_size(), 1);
  EXPECT_EQ(response.models(0).name(), "shelf-b");
  request.set_page_token("garbage token");
  EXPECT_EQ(models_->ListModels(Context().get(), request, &response).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(RepositoryServiceTest, BadUploadsAreRefusedAndStoreNothing) {
  const std::string file = PosterModelFile("poster", 1, "");
  std::string damaged = file;
  damaged[damaged.size() / 2] ^= 0x55;
  EXPECT_EQ(Put(damaged, "", {}, nullptr, Sha256Hex(file)).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);  // damaged in transit: checksum mismatch
  EXPECT_EQ(Put(file, "", {}, nullptr, "", file.size() + 1).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);  // shorter than announced
  EXPECT_EQ(Put(file, "", {}, nullptr, "", file.size() - 1).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);  // longer than announced
  EXPECT_EQ(Put(file, "", {}, nullptr, "not-hex").error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(Put("garbage bytes, checksum right", "x").error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);  // not a model file
  EXPECT_EQ(Put(file, "bad/name").error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(Put(file, "", {}, nullptr, "", uint64_t(1) << 40).error_code(),
            grpc::StatusCode::RESOURCE_EXHAUSTED);  // larger than the server takes
  {
    auto context = Context();
    pb::PutModelResponse response;
    auto writer = models_->PutModel(context.get(), &response);
    pb::PutModelRequest chunk;
    chunk.set_chunk(file.substr(0, 100));
    writer->Write(chunk);
    writer->WritesDone();
    EXPECT_EQ(writer->Finish().error_code(), grpc::StatusCode::FAILED_PRECONDITION);  // no header
  }
  pb::ListModelsResponse listed;
  ASSERT_TRUE(models_->ListModels(Context().get(), {}, &listed).ok());
  EXPECT_EQ(listed.models_size(), 0);
  ASSERT_TRUE(Put(file, "").ok());  // the server still takes good uploads
}

TEST_F(RepositoryServiceTest, WatchersSeeEveryChangeInOrder) {
  grpc::ClientContext context;
  pb::WatchModelsRequest request;
  request.set_name_prefix("watched");
  auto reader = models_->WatchModels(&context, request);
  std::mutex mutex;
  std::vector<pb::WatchModelsResponse> events;  // guarded by mutex
  std::thread watcher([&] {
    pb::WatchModelsResponse event;
    while (reader->Read(&event)) {
      std::lock_guard lock(mutex);
      events.push_back(event);
    }
  });
  const auto seen = [&](const std::string& name, pb::ModelChange change) {
    std::lock_guard lock(mutex);
    return std::any_of(events.begin(), events.end(), [&](const pb::WatchModelsResponse& event) {
      return event.model().name() == name && event.change() == change;
    });
  };
  // The watch is registered once the server has handled the call, which the client does not see:
  // uploads of a probe the watch matches go until one of them arrives. Every change after that
  // reaches the watch.
  const std::string file = PosterModelFile("x", 1, "");
  const bool registered = WaitUntil([&] {
    EXPECT_TRUE(Put(file, "watched-probe").ok());
    return WaitUntil([&] { return seen("watched-probe", pb::MODEL_CHANGE_PUT); },
                     std::chrono::seconds(1));
  });
  bool deletion_seen = false;
  if (registered) {
    EXPECT_TRUE(Put(file, "watched-1").ok());
    EXPECT_TRUE(Put(file, "other").ok());  // filtered out by the prefix
    EXPECT_TRUE(Put(file, "watched-1").ok());
    pb::DeleteModelRequest remove;
    remove.set_name("watched-1");
    pb::DeleteModelResponse removed;
    EXPECT_TRUE(models_->DeleteModel(Context().get(), remove, &removed).ok());
    EXPECT_EQ(removed.versions_deleted(), 2u);
    EXPECT_EQ(models_->DeleteModel(Context().get(), remove, &removed).error_code(),
              grpc::StatusCode::NOT_FOUND);
    deletion_seen = WaitUntil([&] { return seen("watched-1", pb::MODEL_CHANGE_DELETED); });
  }
  context.TryCancel();
  watcher.join();
  reader->Finish();
  ASSERT_TRUE(registered) << "no upload of the probe reached the watch";
  ASSERT_TRUE(deletion_seen) << "the watch did not see the deletion of watched-1";

  std::vector<pb::WatchModelsResponse> watched;  // the changes of watched-1, in their order
  std::copy_if(events.begin(), events.end(), std::back_inserter(watched),
               [](const pb::WatchModelsResponse& event) {
                 EXPECT_NE(event.model().name(), "other");
                 return event.model().name() == "watched-1";
               });
  ASSERT_EQ(watched.size(), 3u);
  EXPECT_EQ(watched[0].change(), pb::MODEL_CHANGE_PUT);
  EXPECT_EQ(watched[0].model().version(), 1u);
  EXPECT_EQ(watched[1].change(), pb::MODEL_CHANGE_PUT);
  EXPECT_EQ(watched[1].model().version(), 2u);
  EXPECT_EQ(watched[2].change(), pb::MODEL_CHANGE_DELETED);
  EXPECT_LT(watched[0].sequence(), watched[1].sequence());
  EXPECT_LT(watched[1].sequence(), watched[2].sequence());
}

TEST_F(RepositoryServiceTest, WatchingWithTheExistingVersionsSendsThemThenSyncedThenChanges) {
  const std::string file = PosterModelFile("x", 1, "");
  ASSERT_TRUE(Put(file, "watched-1").ok());
  ASSERT_TRUE(Put(file, "other").ok());  // filtered out by the prefix
  ASSERT_TRUE(Put(file, "watched-1").ok());
  ASSERT_TRUE(Put(file, "watched-0").ok());
  grpc::ClientContext context;
  pb::WatchModelsRequest request;
  request.set_name_prefix("watched");
  request.set_include_existing(true);
  auto reader = models_->WatchModels(&context, request);
  std::vector<pb::WatchModelsResponse> events;
  pb::WatchModelsResponse event;
  while (events.size() < 4 && reader->Read(&event)) events.push_back(event);
  // The state needs no waiting for the watch to register: a change now comes after SYNCED.
  pb::ModelInfo put;
  ASSERT_TRUE(Put(file, "watched-0", {}, &put).ok());
  if (reader->Read(&event)) events.push_back(event);
  context.TryCancel();
  reader->Finish();

  ASSERT_EQ(events.size(), 5u);
  const std::vector<std::pair<std::string, uint32_t>> existing = {
      {"watched-0", 1}, {"watched-1", 1}, {"watched-1", 2}};
  for (size_t i = 0; i < existing.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(events[i].change(), pb::MODEL_CHANGE_PUT);
    EXPECT_EQ(events[i].model().name(), existing[i].first);
    EXPECT_EQ(events[i].model().version(), existing[i].second);
    EXPECT_EQ(events[i].model().sha256().size(), 64u);
    EXPECT_EQ(events[i].sequence(), 0u);
  }
  EXPECT_EQ(events[3].change(), pb::MODEL_CHANGE_SYNCED);
  EXPECT_FALSE(events[3].has_model());
  EXPECT_EQ(events[4].change(), pb::MODEL_CHANGE_PUT);
  EXPECT_EQ(events[4].model().name(), "watched-0");
  EXPECT_EQ(events[4].model().version(), 2u);
  EXPECT_EQ(events[4].model().sha256(), put.sha256());
  EXPECT_GT(events[4].sequence(), 0u);
}

TEST_F(RepositoryServiceTest, RecognitionFiltersAndRefusesFramesItCannotUse) {
  ASSERT_TRUE(Put(PosterModelFile("poster", 1, "poster"), "").ok());
  pb::RecognizeObjectsResponse seen;
  pb::ObjectFilter only_boxes;
  only_boxes.add_classes("box");
  ASSERT_TRUE(Recognize(PosterView(1), &seen, only_boxes).ok());
  EXPECT_EQ(seen.objects_size(), 0);
  pb::ObjectFilter by_name;
  by_name.add_names("poster");
  ASSERT_TRUE(Recognize(PosterView(1), &seen, by_name).ok());
  EXPECT_EQ(seen.objects_size(), 1);
  ASSERT_TRUE(Recognize(PosterView(60), &seen).ok());
  EXPECT_EQ(seen.objects_size(), 0);  // another picture: nothing, and not an error

  EXPECT_EQ(Recognize(JpegFrame(CorridorJpeg(1)), &seen).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);  // no intrinsics
  pb::Frame garbage = PosterView(1);
  garbage.set_encoded_image("\x89PNG garbage");
  EXPECT_EQ(Recognize(garbage, &seen).error_code(), grpc::StatusCode::INVALID_ARGUMENT);

  // The stream answers each frame, errors included, and goes on.
  grpc::ClientContext context;
  auto stream = objects_->StreamRecognizeObjects(&context);
  pb::StreamRecognizeObjectsRequest request;
  request.mutable_config();
  ASSERT_TRUE(stream->Write(request));
  std::vector<pb::StreamRecognizeObjectsResponse> answers;
  for (const pb::Frame& frame :
       {PosterView(1), garbage, JpegFrame(CorridorJpeg(1)), PosterView(1)}) {
    *request.mutable_frame() = frame;
    ASSERT_TRUE(stream->Write(request));
    pb::StreamRecognizeObjectsResponse answer;
    ASSERT_TRUE(stream->Read(&answer));
    answers.push_back(answer);
  }
  stream->WritesDone();
  EXPECT_TRUE(stream->Finish().ok());
  ASSERT_EQ(answers.size(), 4u);
  EXPECT_EQ(answers[0].objects_size(), 1);
  EXPECT_EQ(answers[1].error().code(), int(grpc::StatusCode::INVALID_ARGUMENT));
  EXPECT_EQ(answers[2].error().code(), int(grpc::StatusCode::INVALID_ARGUMENT));
  EXPECT_EQ(answers[3].objects_size(), 1);
  EXPECT_EQ(answers[3].sequence(), 3u);
}

// Streams `frames` after `config`; the answers, in order (fewer when the stream broke).
std::vector<pb::StreamRecognizeObjectsResponse> StreamPosterViews(
    pb::ObjectRecognition::Stub* objects, const pb::RecognitionConfig& config,
    const std::vector<pb::Frame>& frames) {
  grpc::ClientContext context;
  auto stream = objects->StreamRecognizeObjects(&context);
  pb::StreamRecognizeObjectsRequest request;
  *request.mutable_config() = config;
  std::vector<pb::StreamRecognizeObjectsResponse> answers;
  if (!stream->Write(request)) return answers;
  for (const pb::Frame& frame : frames) {
    *request.mutable_frame() = frame;
    pb::StreamRecognizeObjectsResponse answer;
    if (!stream->Write(request) || !stream->Read(&answer)) break;
    answers.push_back(answer);
  }
  stream->WritesDone();
  EXPECT_TRUE(stream->Finish().ok());
  return answers;
}

TEST_F(RepositoryServiceTest, AStreamTracksItsObjectsUnlessTrackingIsOff) {
  ASSERT_TRUE(Put(PosterModelFile("poster", 1, "poster"), "").ok());
  // Corridor image 60 (with the same intrinsics) does not show the poster.
  pb::Frame other = PosterView(60);
  const std::vector<pb::Frame> frames = {PosterView(1), PosterView(1), PosterView(1), other,
                                         PosterView(1)};

  // Tracking (the default): recognised in the first frame, tracked in the next ones; a frame
  // without the poster loses it, and the one after recognises it again.
  auto answers = StreamPosterViews(objects_.get(), {}, frames);
  ASSERT_EQ(answers.size(), 5u);
  for (size_t i : {0u, 1u, 2u, 4u}) {
    ASSERT_EQ(answers[i].objects_size(), 1) << "frame " << i;
    EXPECT_EQ(answers[i].objects(0).name(), "poster");
    EXPECT_EQ(answers[i].objects(0).tracked(), i == 1 || i == 2) << "frame " << i;
    EXPECT_GE(answers[i].objects(0).inliers(), 12u);
  }
  EXPECT_EQ(answers[3].objects_size(), 0);

  pb::RecognitionConfig off;
  off.set_disable_tracking(true);
  answers = StreamPosterViews(objects_.get(), off, frames);
  ASSERT_EQ(answers.size(), 5u);
  for (size_t i : {0u, 1u, 2u, 4u}) {
    ASSERT_EQ(answers[i].objects_size(), 1) << "frame " << i;
    EXPECT_FALSE(answers[i].objects(0).tracked()) << "frame " << i;
  }

  // A unary call is never tracked.
  pb::RecognizeObjectsResponse seen;
  ASSERT_TRUE(Recognize(PosterView(1), &seen).ok());
  ASSERT_EQ(seen.objects_size(), 1);
  EXPECT_FALSE(seen.objects(0).tracked());
}

TEST_F(RepositoryServiceTest, DetectionsCarryInliersAndCovarianceOnlyWhenAsked) {
  ASSERT_TRUE(Put(PosterModelFile("poster", 1, "poster"), "").ok());
  pb::RecognizeObjectsResponse plain, full;
  ASSERT_TRUE(Recognize(PosterView(1), &plain).ok());
  ASSERT_EQ(plain.objects_size(), 1);
  EXPECT_EQ(plain.objects(0).inliers_2d3d_size(), 0);
  EXPECT_EQ(plain.objects(0).covariance_size(), 0);

  pb::DetectionOptions slam;
  slam.set_include_inliers(true);
  slam.set_include_covariance(true);
  ASSERT_TRUE(Recognize(PosterView(1), &full, {}, slam).ok());
  ASSERT_EQ(full.objects_size(), 1);
  const pb::DetectedObject& object = full.objects(0);
  EXPECT_EQ(uint32_t(object.inliers_2d3d_size()), object.inliers());
  for (const pb::InlierCorrespondence& c : object.inliers_2d3d()) {
    EXPECT_TRUE(c.has_pixel());
    EXPECT_NEAR(c.point().z(), 0.0, 1e-6);  // a flat poster
  }
  ASSERT_EQ(object.covariance_size(), 36);
  for (int i = 0; i < 6; ++i) {
    EXPECT_GT(object.covariance(i * 7), 0.0);
    for (int j = 0; j < 6; ++j)
      EXPECT_EQ(object.covariance(i * 6 + j), object.covariance(j * 6 + i));
  }

  // A stream asks once, in its config, for every frame.
  grpc::ClientContext context;
  auto stream = objects_->StreamRecognizeObjects(&context);
  pb::StreamRecognizeObjectsRequest request;
  request.mutable_config()->mutable_detection_options()->set_include_covariance(true);
  ASSERT_TRUE(stream->Write(request));
  *request.mutable_frame() = PosterView(1);
  ASSERT_TRUE(stream->Write(request));
  pb::StreamRecognizeObjectsResponse answer;
  ASSERT_TRUE(stream->Read(&answer));
  stream->WritesDone();
  EXPECT_TRUE(stream->Finish().ok());
  ASSERT_EQ(answer.objects_size(), 1);
  EXPECT_EQ(answer.objects(0).covariance_size(), 36);
  EXPECT_EQ(answer.objects(0).inliers_2d3d_size(), 0);
}

TEST_F(RepositoryServiceTest, ModelsSurviveARestartAndDeletedOnesStayDeleted) {
  const std::string file = PosterModelFile("poster", 1, "poster");
  ASSERT_TRUE(Put(file, "kept").ok());
  ASSERT_TRUE(Put(file, "kept").ok());
  ASSERT_TRUE(Put(file, "dropped").ok());
  pb::DeleteModelRequest remove;
  remove.set_name("dropped");
  pb::DeleteModelResponse removed;
  ASSERT_TRUE(models_->DeleteModel(Context().get(), remove, &removed).ok());
  RestartServer();
  pb::ListModelsResponse listed;
  ASSERT_TRUE(models_->ListModels(Context().get(), {}, &listed).ok());
  ASSERT_EQ(listed.models_size(), 1);
  EXPECT_EQ(listed.models(0).name(), "kept");
  EXPECT_EQ(listed.models(0).version(), 2u);
  pb::ModelInfo info;
  std::string bytes;
  ASSERT_TRUE(Get("kept", 1, &info, &bytes).ok());
  pb::RecognizeObjectsResponse seen;
  ASSERT_TRUE(Recognize(PosterView(1), &seen).ok());
  ASSERT_EQ(seen.objects_size(), 1);
  EXPECT_EQ(seen.objects(0).name(), "kept");
}

}  // namespace
}  // namespace recog::server::testing
