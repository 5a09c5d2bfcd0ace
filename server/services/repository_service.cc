#include "server/services/repository_service.h"

#include <algorithm>
#include <deque>

#include "server/api/object_converters.h"
#include "server/services/call.h"
#include "wire/sha256.h"

namespace recog::server {
namespace {

constexpr char kRepositoryService[] = "/recognition.v1.ObjectRepository/";
constexpr size_t kDefaultChunkBytes = 1u << 20, kMaxChunkBytes = 2u << 20;
std::string RepositoryMethod(const char* name) { return std::string(kRepositoryService) + name; }

// A replica's repository follows its primary (RepositoryFollower) and takes no writes of its own.
Status RefuseOnReplica(const ServerState& state) {
  const std::string& primary = state.config.repository.primary;
  if (primary.empty()) return Status::Ok();
  return Status::FailedPrecondition(
      "this server holds a read-only replica of the model repository; send uploads and "
      "deletions to its primary, " +
      primary);
}

bool IsSha256Hex(const std::string& s) {
  return s.size() == 64 && std::all_of(s.begin(), s.end(), [](char c) {
           return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f');
         });
}

// PutModel: a header, then the file's chunks; checked and stored once the client is done.
class ModelUpload final : public grpc::ServerReadReactor<pb::PutModelRequest> {
 public:
  ModelUpload(ServerState& state, PartialUploads& partial_uploads,
              grpc::CallbackServerContext* context, pb::PutModelResponse* response)
      : state_(state), partial_uploads_(partial_uploads), context_(context), response_(response) {
    grpc::Status status =
        BeginCall(state_, context_, RepositoryMethod("PutModel"), Right::kWrite, &call_);
    if (status.ok()) status = ToCallStatus(context_, call_, RefuseOnReplica(state_));
    if (!status.ok()) {
      End(status);
      return;
    }
    StartRead(&request_);
  }

 private:
  void OnReadDone(bool ok) override {
    if (!ok && context_->IsCancelled()) {  // the call broke off: keep what came for a resume
      const uint64_t received = bytes_.size();
      if (has_header_) partial_uploads_.KeepInterrupted(Key(), std::move(bytes_));
      End({grpc::StatusCode::CANCELLED, "the upload broke off after " + std::to_string(received) +
                                            " bytes (kept for a resumed upload)"});
      return;
    }
    if (!ok) {  // the client sent everything
      if (!has_header_) {
        End(Status::FailedPrecondition("PutModel needs a PutModelHeader first"));
      } else if (!state_.pool->TrySubmit([this](WorkerContext&) {
                   End(RunOnce(state_, context_, call_,
                               Replay{header_.request_id(), &header_, nullptr}, response_,
                               [this] { return Store(); }));
                 })) {
        End(Busy(state_, context_));
      }
      return;
    }
    const Status status = has_header_ ? TakeChunk() : TakeHeader();
    if (!status.ok()) {
      End(status);
      return;
    }
    StartRead(&request_);
  }

  Status TakeHeader() {
    if (!request_.has_header()) {
      return Status::FailedPrecondition("the first message of PutModel must be a PutModelHeader");
    }
    header_ = request_.header();
    call_.map = header_.name();
    if (header_.size_bytes() == 0) return Status::InvalidArgument("header.size_bytes is required");
    if (header_.size_bytes() > RepositoryService::kMaxModelBytes) {
      return Status::ResourceExhausted(
          "the model file has " + std::to_string(header_.size_bytes()) +
          " bytes; the server takes at most " + std::to_string(RepositoryService::kMaxModelBytes));
    }
    RECOG_RETURN_IF_ERROR(CheckRequestId(header_.request_id()));  // before the file is sent
    if (!IsSha256Hex(header_.sha256())) {
      return Status::InvalidArgument(
          "header.sha256 must be 64 lowercase hex digits (SHA-256 of the file)");
    }
    if (header_.offset() >= header_.size_bytes()) {
      return Status::InvalidArgument("header.offset must be below header.size_bytes (" +
                                     std::to_string(header_.size_bytes()) + ")");
    }
    if (header_.offset() > 0) {
      std::optional<std::string> kept = partial_uploads_.TakeInterrupted(Key());
      const uint64_t held = kept.has_value() ? kept->size() : 0;
      if (held < header_.offset()) {
        if (kept.has_value()) partial_uploads_.KeepInterrupted(Key(), std::move(*kept));
        return Status::FailedPrecondition(
            "cannot resume at byte " + std::to_string(header_.offset()) + ": the server holds " +
            std::to_string(held) + " bytes of this upload (GetUploadStatus)");
      }
      bytes_ = std::move(*kept);
      bytes_.resize(size_t(header_.offset()));
    }
    bytes_.reserve(size_t(header_.size_bytes()));
    has_header_ = true;
    return Status::Ok();
  }

  PartialUploads::Key Key() const { return {header_.sha256(), header_.size_bytes()}; }

  Status TakeChunk() {
    if (!request_.has_chunk()) {
      return Status::InvalidArgument("only the first message of PutModel is a header");
    }
    if (bytes_.size() + request_.chunk().size() > header_.size_bytes()) {
      return Status::InvalidArgument("the upload is longer than header.size_bytes (" +
                                     std::to_string(header_.size_bytes()) + ")");
    }
    bytes_ += request_.chunk();
    return Status::Ok();
  }

  Status Store() {
    if (bytes_.size() != header_.size_bytes()) {
      return Status::InvalidArgument("the upload has " + std::to_string(bytes_.size()) +
                                     " bytes; the header said " +
                                     std::to_string(header_.size_bytes()));
    }
    if (Sha256Hex(bytes_) != header_.sha256()) {
      return Status::InvalidArgument(
          "the upload's SHA-256 differs from header.sha256 (damaged in transit?)");
    }
    std::vector<std::string> tags(header_.tags().begin(), header_.tags().end());
    RECOG_ASSIGN_OR_RETURN(const ModelVersionInfo stored,
                           state_.repository->Put(bytes_, header_.name(), std::move(tags)));
    call_.map = stored.metadata.name;
    partial_uploads_.RecordStored(Key(), {stored.metadata.name, stored.metadata.version});
    ToProto(stored, response_->mutable_model());
    state_.metrics.SetObjects(state_.objects->size());
    return Status::Ok();
  }

  void End(const Status& status) { End(ToCallStatus(context_, call_, status)); }
  // Made in gRPC's terms: the upload broken off, Busy, RunOnce's answer.
  void End(const grpc::Status& status) {
    EndCall(state_, call_, status);
    Finish(status);
  }
  void OnDone() override { delete this; }

  ServerState& state_;
  PartialUploads& partial_uploads_;
  grpc::CallbackServerContext* const context_;
  pb::PutModelResponse* const response_;
  CallInfo call_;
  pb::PutModelRequest request_;
  pb::PutModelHeader header_;
  bool has_header_ = false;
  std::string bytes_;
};

// GetModel: the ModelInfo, then the file in chunks from the requested offset, one write at a time.
class ModelDownload final : public grpc::ServerWriteReactor<pb::GetModelResponse> {
 public:
  ModelDownload(ServerState& state, grpc::CallbackServerContext* context,
                const pb::GetModelRequest& request)
      : state_(state), context_(context), offset_(request.offset()) {
    grpc::Status status =
        BeginCall(state_, context_, RepositoryMethod("GetModel"), Right::kRead, &call_);
    call_.map = request.name();
    chunk_bytes_ = request.chunk_bytes() == 0
                       ? kDefaultChunkBytes
                       : std::min<size_t>(request.chunk_bytes(), kMaxChunkBytes);
    if (status.ok()) {
      const std::string name = request.name();
      const uint32_t version = request.version();
      if (state_.pool->TrySubmit([this, name, version](WorkerContext&) { Fetch(name, version); }))
        return;
      status = Busy(state_, context_);
    }
    End(status);
  }

 private:
  void Fetch(const std::string& name, uint32_t version) {
    StatusOr<std::pair<ModelVersionInfo, std::string>> model =
        state_.repository->Get(name, version);
    if (!model.ok()) {
      End(ToCallStatus(context_, call_, model.status()));
      return;
    }
    bytes_ = std::move(model.value().second);
    if (offset_ > bytes_.size()) {
      End({grpc::StatusCode::OUT_OF_RANGE, "offset " + std::to_string(offset_) +
                                               " is beyond the end of the file (" +
                                               std::to_string(bytes_.size()) + " bytes)"});
      return;
    }
    ToProto(model.value().first, response_.mutable_info());
    StartWrite(&response_);
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      End({grpc::StatusCode::CANCELLED, "the client went away"});
      return;
    }
    if (offset_ >= bytes_.size()) {
      End(grpc::Status::OK);
      return;
    }
    const size_t n = std::min(chunk_bytes_, bytes_.size() - offset_);
    response_.set_chunk(bytes_.data() + offset_, n);
    offset_ += n;
    StartWrite(&response_);
  }

  void End(const grpc::Status& status) {
    EndCall(state_, call_, status);
    Finish(status);
  }
  void OnDone() override { delete this; }

  ServerState& state_;
  grpc::CallbackServerContext* const context_;
  CallInfo call_;
  size_t chunk_bytes_ = kDefaultChunkBytes;
  std::string bytes_;
  uint64_t offset_;  // the next byte to send
  pb::GetModelResponse response_;
};

}  // namespace

// WatchModels: the repository's events, filtered by name prefix, through a bounded queue; with
// include_existing, the versions stored when the watch began go first (not counted in the bound),
// then MODEL_CHANGE_SYNCED.
class ModelWatch final : public grpc::ServerWriteReactor<pb::WatchModelsResponse> {
 public:
  ModelWatch(RepositoryService& service, grpc::CallbackServerContext* context,
             const pb::WatchModelsRequest& request)
      : service_(service),
        state_(service.state_),
        prefix_(request.name_prefix()),
        synced_to_send_(request.include_existing()) {
    state_.metrics.StreamOpened("WatchModels");
    const grpc::Status status =
        BeginCall(state_, context, RepositoryMethod("WatchModels"), Right::kRead, &call_);
    std::lock_guard lock(mutex_);
    if (!status.ok()) {
      FinishLocked(status);
      return;
    }
    {
      std::lock_guard watches(service_.watches_mutex_);
      service_.watches_.insert(this);
    }
    watch_id_ = state_.repository->Watch([this](const ModelEvent& event) { OnEvent(event); },
                                         synced_to_send_ ? &existing_ : nullptr);
    watching_ = true;
    std::erase_if(existing_, [this](const ModelVersionInfo& info) { return !Watched(info); });
    if (synced_to_send_) WriteNextLocked();
  }

  void Close() {
    std::lock_guard lock(mutex_);
    FinishLocked({grpc::StatusCode::UNAVAILABLE, "the server is shutting down"});
  }

 private:
  bool Watched(const ModelVersionInfo& info) const {
    return info.metadata.name.starts_with(prefix_);
  }
  bool HasNextLocked() const { return synced_to_send_ || !pending_.empty(); }

  void OnEvent(const ModelEvent& event) {
    if (!Watched(event.info)) return;
    std::lock_guard lock(mutex_);
    if (finished_) return;
    if (pending_.size() >= RepositoryService::kMaxPendingEvents) {
      FinishLocked({grpc::StatusCode::RESOURCE_EXHAUSTED,
                    "the watcher fell behind by " +
                        std::to_string(RepositoryService::kMaxPendingEvents) +
                        " changes; list the models again, then watch anew"});
      return;
    }
    pb::WatchModelsResponse& response = pending_.emplace_back();
    response.set_change(event.kind == ModelEvent::Kind::kPut ? pb::MODEL_CHANGE_PUT
                                                             : pb::MODEL_CHANGE_DELETED);
    ToProto(event.info, response.mutable_model());
    response.set_sequence(event.sequence);
    if (!writing_) WriteNextLocked();
  }

  // Writes the next existing version, else SYNCED once, else the oldest pending change.
  void WriteNextLocked() {
    if (next_existing_ < existing_.size()) {
      response_.Clear();
      response_.set_change(pb::MODEL_CHANGE_PUT);
      ToProto(existing_[next_existing_++], response_.mutable_model());
    } else if (synced_to_send_) {
      response_.Clear();
      response_.set_change(pb::MODEL_CHANGE_SYNCED);
      synced_to_send_ = false;
      existing_ = {};
    } else {
      response_ = std::move(pending_.front());
      pending_.pop_front();
    }
    writing_ = true;
    StartWrite(&response_);
  }

  void OnWriteDone(bool ok) override {
    std::lock_guard lock(mutex_);
    writing_ = false;
    if (!ok) {
      FinishLocked({grpc::StatusCode::CANCELLED, "the client went away"});
    } else if (finish_pending_) {
      FinishLocked(final_status_);
    } else if (HasNextLocked() && !finished_) {
      WriteNextLocked();
    }
  }

  void OnCancel() override {
    std::lock_guard lock(mutex_);
    FinishLocked({grpc::StatusCode::CANCELLED, "the client cancelled"});
  }

  // Finishes once; after the outstanding write, if there is one.
  void FinishLocked(const grpc::Status& status) {
    if (finished_) return;
    if (writing_) {
      if (!finish_pending_) final_status_ = status;
      finish_pending_ = true;
      return;
    }
    finished_ = true;
    EndCall(state_, call_, status);
    Finish(status);
  }

  void OnDone() override {
    if (watching_) state_.repository->Unwatch(watch_id_);  // no event after this returns
    {
      std::lock_guard watches(service_.watches_mutex_);
      service_.watches_.erase(this);
    }
    state_.metrics.StreamClosed("WatchModels");
    delete this;
  }

  RepositoryService& service_;
  ServerState& state_;
  const std::string prefix_;
  CallInfo call_;
  uint64_t watch_id_ = 0;
  bool watching_ = false;
  std::mutex mutex_;                        // guards everything below
  std::vector<ModelVersionInfo> existing_;  // with include_existing: sent before anything else
  size_t next_existing_ = 0;
  bool synced_to_send_;                          // MODEL_CHANGE_SYNCED is still to be written
  std::deque<pb::WatchModelsResponse> pending_;  // changes, at most kMaxPendingEvents
  pb::WatchModelsResponse response_;             // being written
  bool writing_ = false, finished_ = false, finish_pending_ = false;
  grpc::Status final_status_;
};

grpc::ServerReadReactor<pb::PutModelRequest>* RepositoryService::PutModel(
    grpc::CallbackServerContext* context, pb::PutModelResponse* response) {
  return new ModelUpload(state_, partial_uploads_, context, response);
}

grpc::ServerUnaryReactor* RepositoryService::GetUploadStatus(
    grpc::CallbackServerContext* context, const pb::GetUploadStatusRequest* request,
    pb::GetUploadStatusResponse* response) {
  return RunUnary(
      state_, context, RepositoryMethod("GetUploadStatus"), Right::kWrite, *request,
      [=, this](CallInfo&, WorkerContext&) {
        RECOG_RETURN_IF_ERROR(RefuseOnReplica(state_));
        if (!IsSha256Hex(request->sha256())) {
          return Status::InvalidArgument(
              "sha256 must be 64 lowercase hex digits (SHA-256 of the file)");
        }
        const PartialUploads::Progress progress =
            partial_uploads_.ProgressOf({request->sha256(), request->size_bytes()});
        response->set_received_bytes(progress.received_bytes);
        if (progress.stored.has_value()) {
          for (const ModelVersionInfo& info : state_.repository->Versions(progress.stored->name)) {
            if (info.metadata.version == progress.stored->version) {
              ToProto(info, response->mutable_stored());
            }
          }
        }
        return Status::Ok();
      });
}

grpc::ServerWriteReactor<pb::GetModelResponse>* RepositoryService::GetModel(
    grpc::CallbackServerContext* context, const pb::GetModelRequest* request) {
  return new ModelDownload(state_, context, *request);
}

grpc::ServerUnaryReactor* RepositoryService::ListModels(grpc::CallbackServerContext* context,
                                                        const pb::ListModelsRequest* request,
                                                        pb::ListModelsResponse* response) {
  return RunUnary(
      state_, context, RepositoryMethod("ListModels"), Right::kRead, *request,
      [=, this](CallInfo&, WorkerContext&) {
        const ModelFilter filter{request->name_prefix(), request->object_class(), request->tag()};
        RECOG_ASSIGN_OR_RETURN(ModelPage page, state_.repository->List(filter, request->page_size(),
                                                                       request->page_token()));
        for (const ModelVersionInfo& info : page.models) ToProto(info, response->add_models());
        response->set_next_page_token(page.next_page_token);
        return Status::Ok();
      });
}

grpc::ServerUnaryReactor* RepositoryService::DeleteModel(grpc::CallbackServerContext* context,
                                                         const pb::DeleteModelRequest* request,
                                                         pb::DeleteModelResponse* response) {
  return RunUnary(state_, context, RepositoryMethod("DeleteModel"), Right::kWrite,
                  Replay{request->request_id(), request, nullptr}, response,
                  [=, this](CallInfo& call, WorkerContext&) {
                    call.map = request->name();
                    RECOG_RETURN_IF_ERROR(RefuseOnReplica(state_));
                    const size_t versions = state_.repository->Versions(request->name()).size();
                    RECOG_RETURN_IF_ERROR(state_.repository->Remove(request->name()));
                    response->set_versions_deleted(uint32_t(versions));
                    state_.metrics.SetObjects(state_.objects->size());
                    return Status::Ok();
                  });
}

grpc::ServerWriteReactor<pb::WatchModelsResponse>* RepositoryService::WatchModels(
    grpc::CallbackServerContext* context, const pb::WatchModelsRequest* request) {
  return new ModelWatch(*this, context, *request);
}

void RepositoryService::CloseWatchers() {
  std::lock_guard lock(watches_mutex_);
  for (ModelWatch* watch : watches_) watch->Close();
}

}  // namespace recog::server
