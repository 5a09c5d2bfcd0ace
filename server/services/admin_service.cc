#include "server/services/admin_service.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>

#include <spdlog/spdlog.h>

#include "server/services/call.h"

namespace recog::server {
namespace {

namespace fs = std::filesystem;
namespace pb = ::recognition::v1;

constexpr char kMethod[] = "/recognition.v1.Admin/Checkpoint";
constexpr size_t kDefaultBackupChunkBytes = 1u << 20, kMaxBackupChunkBytes = 2u << 20;

// Checkpoint: on a worker, the store's copy and its manifest; then the files, a chunk per write.
class CheckpointDownload final : public grpc::ServerWriteReactor<pb::CheckpointResponse> {
 public:
  CheckpointDownload(ServerState& state, grpc::CallbackServerContext* context,
                     const pb::CheckpointRequest& request)
      : state_(state), context_(context) {
    chunk_bytes_ = request.chunk_bytes() == 0
                       ? kDefaultBackupChunkBytes
                       : std::min<size_t>(request.chunk_bytes(), kMaxBackupChunkBytes);
    grpc::Status status = BeginCall(state_, context_, kMethod, Right::kWrite, &call_);
    if (status.ok()) {
      status = ToCallStatus(
          context_, call_,
          TokenAuthenticator::CheckEveryMap(call_.caller, Right::kWrite, "Checkpoint"));
    }
    if (status.ok()) {
      if (state_.pool->TrySubmit([this](WorkerContext&) { Prepare(); })) return;
      status = Busy(state_, context_);
    }
    End(status);
  }

 private:
  void Prepare() {
    static std::atomic<uint64_t> sequence{0};
    const fs::path parent = fs::path(state_.config.data_dir) / "checkpoints";
    std::error_code ec;
    fs::create_directories(parent, ec);
    if (ec) {
      End(Status::FailedPrecondition("cannot create '" + parent.string() + "': " + ec.message()));
      return;
    }
    directory_ =
        parent / ("checkpoint-" + std::to_string(::getpid()) + "-" + std::to_string(sequence++));
    fs::remove_all(directory_, ec);
    const Status made = state_.store->Checkpoint(directory_.string());
    if (!made.ok()) {
      End(made);
      return;
    }
    pb::CheckpointManifest* manifest = response_.mutable_manifest();
    for (const fs::directory_entry& file : fs::directory_iterator(directory_, ec)) {
      if (file.is_regular_file()) files_.push_back(file.path());
    }
    std::sort(files_.begin(), files_.end());
    uint64_t total = 0;
    for (const fs::path& file : files_) {
      pb::CheckpointFile* entry = manifest->add_files();
      entry->set_name(file.filename().string());
      entry->set_size_bytes(fs::file_size(file, ec));
      total += entry->size_bytes();
    }
    if (ec) {
      End({grpc::StatusCode::INTERNAL, "cannot list the checkpoint: " + ec.message()});
      return;
    }
    manifest->set_total_bytes(total);
    manifest->set_maps(uint32_t(state_.maps->List().size()));
    manifest->set_models(uint32_t(state_.objects->size()));
    manifest->set_created_unix_ms(std::chrono::duration_cast<std::chrono::milliseconds>(
                                      std::chrono::system_clock::now().time_since_epoch())
                                      .count());
    spdlog::info("[{}] checkpoint: {} files, {} bytes, {} maps, {} models", call_.request_id,
                 files_.size(), total, manifest->maps(), manifest->models());
    StartWrite(&response_);
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      End({grpc::StatusCode::CANCELLED, "the client went away"});
      return;
    }
    std::string* chunk = response_.mutable_chunk();
    chunk->resize(chunk_bytes_);
    size_t filled = 0;
    while (filled < chunk_bytes_ && next_file_ < files_.size()) {
      if (!file_.is_open()) {
        file_.open(files_[next_file_], std::ios::binary);
        if (!file_) {
          End({grpc::StatusCode::INTERNAL,
               "cannot read checkpoint file " + files_[next_file_].filename().string()});
          return;
        }
      }
      file_.read(chunk->data() + filled, std::streamsize(chunk_bytes_ - filled));
      filled += size_t(file_.gcount());
      if (file_.eof()) {
        file_.close();
        ++next_file_;
      } else if (!file_) {
        End({grpc::StatusCode::INTERNAL,
             "cannot read checkpoint file " + files_[next_file_].filename().string()});
        return;
      }
    }
    if (filled == 0) {
      End(grpc::Status::OK);
      return;
    }
    chunk->resize(filled);
    StartWrite(&response_);
  }

  void End(const Status& status) { End(ToCallStatus(context_, call_, status)); }
  // Made in gRPC's terms: the client going away, and the failures to read the checkpoint's files,
  // which name the file (a core INTERNAL reaches the client sanitised, without it).
  void End(const grpc::Status& status) {
    EndCall(state_, call_, status);
    Finish(status);
  }
  void OnDone() override {
    if (!directory_.empty()) {
      std::error_code ec;
      fs::remove_all(directory_, ec);
    }
    delete this;
  }

  ServerState& state_;
  grpc::CallbackServerContext* const context_;
  CallInfo call_;
  size_t chunk_bytes_ = kDefaultBackupChunkBytes;
  fs::path directory_;  // the store's copy; deleted when the call ends
  std::vector<fs::path> files_;
  size_t next_file_ = 0;
  std::ifstream file_;  // files_[next_file_], while being read
  pb::CheckpointResponse response_;
};

void FillRecoveryReport(const StoreRecovery& recovery, pb::StoreRecoveryReport* report) {
  for (const std::string& damage : recovery.damage) report->add_damage(damage);
  report->set_damaged_copy(recovery.damaged_copy);
  for (const StoreRecovery::MapLoss& loss : recovery.maps) {
    pb::MapLoss* map = report->add_maps();
    map->set_name(loss.name);
    map->set_frames_before(loss.entries_before);
    map->set_frames_after(loss.entries_after);
    for (EntryId id : loss.missing) map->add_missing_frame_ids(id);
    map->set_map_lost(loss.map_lost);
  }
  for (const std::string& key : recovery.blobs_lost) report->add_blobs_lost(key);
}

void FillStoreCheck(const ServerState::StoreCheck& check, pb::StoreCheck* out) {
  out->set_finished_unix_ms(
      std::chrono::duration_cast<std::chrono::milliseconds>(check.finished.time_since_epoch())
          .count());
  if (check.result.ok()) {
    out->set_files(check.result->files);
    out->set_bytes(check.result->bytes);
  } else {
    out->set_error(check.result.status().ToString());
  }
  out->set_seconds(check.took.count());
}

}  // namespace

grpc::ServerWriteReactor<pb::CheckpointResponse>* AdminService::Checkpoint(
    grpc::CallbackServerContext* context, const pb::CheckpointRequest* request) {
  return new CheckpointDownload(state_, context, *request);
}

grpc::ServerUnaryReactor* AdminService::Verify(grpc::CallbackServerContext* context,
                                               const pb::VerifyRequest* request,
                                               pb::VerifyResponse* response) {
  return RunUnary(
      state_, context, "/recognition.v1.Admin/Verify", Right::kWrite, *request,
      [=, this](CallInfo& call, WorkerContext&) {
        RECOG_RETURN_IF_ERROR(
            TokenAuthenticator::CheckEveryMap(call.caller, Right::kWrite, "Verify"));
        const uint64_t mib = request->mib_per_second() != 0 ? request->mib_per_second()
                                                            : state_.config.store.verify_mb_per_s;
        const auto start = std::chrono::steady_clock::now();
        StoreVerifier::Result report = state_.verifier->RunNow(mib << 20);
        RECOG_RETURN_IF_ERROR(report.status());
        response->set_files(report->files);
        response->set_bytes(report->bytes);
        response->set_seconds(
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
        return Status::Ok();
      });
}

grpc::ServerUnaryReactor* AdminService::StoreStatus(grpc::CallbackServerContext* context,
                                                    const pb::StoreStatusRequest* request,
                                                    pb::StoreStatusResponse* response) {
  return RunUnary(state_, context, "/recognition.v1.Admin/StoreStatus", Right::kRead, *request,
                  [=, this](CallInfo& call, WorkerContext&) {
                    RECOG_RETURN_IF_ERROR(TokenAuthenticator::CheckEveryMap(
                        call.caller, Right::kRead, "StoreStatus"));
                    if (state_.recovery.recovered()) {
                      FillRecoveryReport(state_.recovery, response->mutable_recovery());
                    }
                    if (auto check = state_.last_store_check()) {
                      FillStoreCheck(*check, response->mutable_last_check());
                    }
                    return Status::Ok();
                  });
}

}  // namespace recog::server
