// RecognitionClient's model repository calls: chunked uploads, verified and resumable downloads,
// listings, deletions, and the WatchModels stream.
#include <algorithm>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <sstream>
#include <thread>

#include "client/cpp/file_errors.h"
#include "client/cpp/recognition_client.h"
#include "client/cpp/request_id.h"
#include "client/cpp/service_config.h"
#include "client/cpp/sha256.h"
#include "wire/sha256.h"

namespace recog::client {
namespace {

using internal::CannotWrite;

constexpr size_t kChunkBytes = 256u << 10;

// OK when the file at `path` has the size and SHA-256 of `info`; DATA_LOSS otherwise.
grpc::Status Verify(const std::string& path, const pb::ModelInfo& info) {
  std::error_code error;
  const uint64_t size = std::filesystem::file_size(path, error);
  if (error) return CannotWrite(path, error.message());
  if (size != info.size_bytes()) {
    return {grpc::StatusCode::DATA_LOSS, "the download has " + std::to_string(size) +
                                             " bytes; the server announced " +
                                             std::to_string(info.size_bytes())};
  }
  Result<std::string> sha256 = internal::Sha256HexOfFile(path);
  if (!sha256.ok()) return sha256.status();
  if (*sha256 != info.sha256()) {
    return {grpc::StatusCode::DATA_LOSS,
            "the download's SHA-256 differs from the one the server announced"};
  }
  return grpc::Status::OK;
}

}  // namespace

// --- WatchModels ---

namespace internal {

// One WatchModels call on the gRPC callback API: each event read goes to the callback, then the
// next read starts; OnDone records the status for Wait(). It holds a reference to the channel, so
// that the call may outlive the client.
class WatchReactor final : public grpc::ClientReadReactor<pb::WatchModelsResponse> {
 public:
  WatchReactor(std::shared_ptr<grpc::Channel> channel,
               std::function<void(const pb::WatchModelsResponse&)> on_change,
               std::function<void(const grpc::Status&)> on_end)
      : channel_(std::move(channel)),
        on_change_(std::move(on_change)),
        on_end_(std::move(on_end)) {}

  grpc::ClientContext& context() { return context_; }
  pb::WatchModelsRequest& request() { return request_; }

  void Start() {
    StartRead(&event_);
    StartCall();
  }
  void Cancel() { context_.TryCancel(); }
  grpc::Status Wait() {
    std::unique_lock lock(mutex_);
    done_changed_.wait(lock, [this] { return done_; });
    return status_;
  }

 private:
  void OnReadDone(bool ok) override {
    if (!ok) return;  // OnDone follows
    if (on_change_) on_change_(event_);
    StartRead(&event_);
  }
  void OnDone(const grpc::Status& status) override {
    if (on_end_) on_end_(status);  // before Wait() returns: the handle may go right after
    std::lock_guard lock(mutex_);
    status_ = status;
    done_ = true;
    done_changed_.notify_all();
  }

  const std::shared_ptr<grpc::Channel> channel_;
  const std::function<void(const pb::WatchModelsResponse&)> on_change_;
  const std::function<void(const grpc::Status&)> on_end_;
  grpc::ClientContext context_;
  pb::WatchModelsRequest request_;
  pb::WatchModelsResponse event_;
  std::mutex mutex_;  // guards the three below
  std::condition_variable done_changed_;
  bool done_ = false;
  grpc::Status status_;
};

}  // namespace internal

ModelWatch::ModelWatch(std::unique_ptr<internal::WatchReactor> reactor)
    : reactor_(std::move(reactor)) {}

ModelWatch::~ModelWatch() {
  reactor_->Cancel();
  reactor_->Wait();
}

void ModelWatch::Cancel() { reactor_->Cancel(); }

grpc::Status ModelWatch::Wait() { return reactor_->Wait(); }

std::unique_ptr<ModelWatch> RecognitionClient::WatchModels(
    const std::string& name_prefix, std::function<void(const pb::WatchModelsResponse&)> on_change,
    bool include_existing, std::function<void(const grpc::Status&)> on_end) {
  auto reactor =
      std::make_unique<internal::WatchReactor>(channel_, std::move(on_change), std::move(on_end));
  PrepareContext(reactor->context(), nullptr);
  reactor->request().set_name_prefix(name_prefix);
  reactor->request().set_include_existing(include_existing);
  models_->async()->WatchModels(&reactor->context(), &reactor->request(), reactor.get());
  reactor->Start();
  return std::unique_ptr<ModelWatch>(new ModelWatch(std::move(reactor)));
}

// --- Uploads ---

namespace {

// Sends `header` (with `offset`) and the file from that byte in chunks on one PutModel call.
grpc::Status SendUpload(pb::ObjectRepository::Stub& models, grpc::ClientContext& context,
                        std::string_view file_bytes, pb::PutModelRequest header, uint64_t offset,
                        pb::PutModelResponse* response) {
  response->Clear();
  header.mutable_header()->set_offset(offset);
  std::unique_ptr<grpc::ClientWriter<pb::PutModelRequest>> writer =
      models.PutModel(&context, response);
  bool open = writer->Write(header);
  pb::PutModelRequest chunk;
  for (size_t at = size_t(offset); open && at < file_bytes.size(); at += kChunkBytes) {
    chunk.set_chunk(file_bytes.data() + at, std::min(kChunkBytes, file_bytes.size() - at));
    open = writer->Write(chunk);
  }
  if (open) writer->WritesDone();
  return writer->Finish();
}

}  // namespace

Result<pb::ModelInfo> RecognitionClient::UploadModel(std::string_view file_bytes,
                                                     const std::string& name,
                                                     const std::vector<std::string>& tags,
                                                     const std::string& request_id) {
  if (file_bytes.empty()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "the model file is empty");
  }
  pb::PutModelRequest header;
  header.mutable_header()->set_name(name);
  for (const std::string& tag : tags) header.mutable_header()->add_tags(tag);
  header.mutable_header()->set_sha256(Sha256Hex(file_bytes));
  header.mutable_header()->set_size_bytes(file_bytes.size());
  header.mutable_header()->set_request_id(internal::RequestIdOr(request_id));
  const Deadline deadline = std::chrono::system_clock::now() + options_.transfer_deadline;
  pb::PutModelResponse response;
  // gRPC retries a PutModel whole while it has sent at most the retry buffer (max_message_bytes);
  // a larger upload that broke off is resumed here. Each attempt first asks the server what it
  // holds of this file: the bytes of an interrupted upload (an earlier attempt's, or another
  // process's) are not sent again, and an earlier attempt of this call that completed but lost its
  // answer is not stored twice. A first attempt does not take a completed upload for its own
  // (uploading a file again creates a new version). At most as many attempts as the retry policy's.
  for (int attempt = 0;; ++attempt) {
    if (attempt > 0) {
      // The server keeps the bytes of a broken upload once it notices the break, which may be a
      // moment after this side did: the policy's first backoff gives it that moment.
      std::this_thread::sleep_for(std::chrono::milliseconds(internal::kInitialBackoffMs));
    }
    pb::GetUploadStatusRequest request;
    request.set_sha256(header.header().sha256());
    request.set_size_bytes(header.header().size_bytes());
    pb::GetUploadStatusResponse progress;
    grpc::ClientContext status_context;
    PrepareContext(status_context, &deadline);
    const grpc::Status asked = models_->GetUploadStatus(&status_context, request, &progress);
    if (!asked.ok()) return asked;
    if (attempt > 0 && progress.has_stored() &&
        (name.empty() || progress.stored().name() == name)) {
      return progress.stored();
    }
    const uint64_t offset = progress.received_bytes();
    grpc::ClientContext context;
    PrepareContext(context, &deadline);
    grpc::Status sent = SendUpload(*models_, context, file_bytes, header, offset, &response);
    if (sent.error_code() == grpc::StatusCode::FAILED_PRECONDITION && offset > 0) {
      // The kept bytes went in the meantime (expired, or resumed by another client).
      grpc::ClientContext again;
      PrepareContext(again, &deadline);
      sent = SendUpload(*models_, again, file_bytes, header, 0, &response);
    }
    if (sent.ok()) return std::move(*response.mutable_model());
    if (!Resumable(sent) || attempt + 1 >= internal::kMaxAttempts) return sent;
  }
}

Result<pb::ModelInfo> RecognitionClient::UploadModelFile(const std::string& path,
                                                         const std::string& name,
                                                         const std::vector<std::string>& tags,
                                                         const std::string& request_id) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return grpc::Status(grpc::StatusCode::NOT_FOUND, "cannot open '" + path + "'");
  std::ostringstream bytes;
  bytes << in.rdbuf();
  if (in.bad()) {
    return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, "cannot read '" + path + "'");
  }
  return UploadModel(bytes.view(), name, tags, request_id);
}

// --- Downloads ---

Result<pb::ModelInfo> RecognitionClient::DownloadModel(const std::string& name, uint32_t version,
                                                       const std::string& path) {
  const std::string part = path + ".part";
  const Deadline deadline = std::chrono::system_clock::now() + options_.transfer_deadline;
  std::error_code error;
  uint64_t have = std::filesystem::is_regular_file(part, error)
                      ? std::filesystem::file_size(part, error)
                      : 0;  // bytes of an earlier broken download
  if (error) have = 0;
  // Whether every byte in `part` came from this call's version, fetched from byte 0: a file that
  // then does not verify is not fetched again.
  bool from_start = have == 0;
  pb::ModelInfo info;  // of the version being fetched, once the server has named it
  // gRPC retries each GetModel until its first answer; a download that broke after bytes arrived
  // is continued here from the byte it has, and one that broke before ends the call.
  for (;;) {
    grpc::ClientContext context;
    PrepareContext(context, &deadline);
    pb::GetModelRequest request;
    request.set_name(name);
    request.set_version(info.version() != 0 ? info.version() : version);  // resume that version
    request.set_chunk_bytes(kChunkBytes);
    request.set_offset(have);
    std::ofstream out(part, std::ios::binary | (have == 0 ? std::ios::trunc : std::ios::app));
    if (!out) return CannotWrite(part);

    std::unique_ptr<grpc::ClientReader<pb::GetModelResponse>> reader =
        models_->GetModel(&context, request);
    pb::GetModelResponse response;
    bool progressed = false, too_long = false;
    while (reader->Read(&response)) {
      if (response.has_info()) {
        info = response.info();
        continue;
      }
      const std::string& chunk = response.chunk();
      too_long = have + chunk.size() > info.size_bytes();
      if (too_long || !out.write(chunk.data(), std::streamsize(chunk.size()))) break;
      have += chunk.size();
      progressed = true;
    }
    if (too_long || !out) context.TryCancel();  // ends the server's side; Finish collects it
    grpc::Status status = reader->Finish();
    out.close();
    if (!out) return CannotWrite(part);
    if (too_long) {
      status = {grpc::StatusCode::DATA_LOSS, "the server sent more bytes than it announced"};
    } else if (status.ok()) {
      status = Verify(part, info);
      if (status.ok()) {
        std::filesystem::rename(part, path, error);
        if (error) return CannotWrite(path, error.message());
        return info;
      }
    }
    const bool bad_file = status.error_code() == grpc::StatusCode::DATA_LOSS ||
                          status.error_code() == grpc::StatusCode::OUT_OF_RANGE;
    if (bad_file) {
      std::filesystem::remove(part, error);
      have = 0;
      if (!from_start) {  // the partial file was not (all) this version's: fetch it whole
        from_start = true;
        continue;
      }
      return status;
    }
    if (!progressed || !Resumable(status)) return status;  // `part` stays, for a later call
  }
}

// --- Listings and deletions ---

Result<std::vector<pb::ModelInfo>> RecognitionClient::ListModels(const ModelFilter& filter) {
  std::vector<pb::ModelInfo> models;
  pb::ListModelsRequest request;
  request.set_name_prefix(filter.name_prefix);
  request.set_object_class(filter.object_class);
  request.set_tag(filter.tag);
  pb::ListModelsResponse response;
  do {
    response.Clear();
    const grpc::Status status = models_->ListModels(UnaryContext().get(), request, &response);
    if (!status.ok()) return status;
    for (pb::ModelInfo& model : *response.mutable_models()) models.push_back(std::move(model));
    request.set_page_token(response.next_page_token());
  } while (!request.page_token().empty());
  return models;
}

Result<uint32_t> RecognitionClient::DeleteModel(const std::string& name,
                                                const std::string& request_id) {
  pb::DeleteModelRequest request;
  request.set_name(name);
  request.set_request_id(internal::RequestIdOr(request_id));
  pb::DeleteModelResponse response;
  const grpc::Status status = models_->DeleteModel(UnaryContext().get(), request, &response);
  if (!status.ok()) return status;
  return response.versions_deleted();
}

}  // namespace recog::client
