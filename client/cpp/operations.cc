// RecognitionClient's calls for operators: the health check, online checkpoints, checks of the
// store's files and the store's status.
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "client/cpp/file_errors.h"
#include "client/cpp/recognition_client.h"
#include "client/cpp/service_config.h"

namespace recog::client {
namespace {

namespace fs = std::filesystem;
namespace health = ::grpc::health::v1;
using internal::CannotWrite;

// fsyncs a file or a folder; false when it cannot.
bool Sync(const fs::path& path) {
  FILE* file = std::fopen(path.c_str(), "r");
  if (file == nullptr) return false;
  const bool synced = ::fsync(::fileno(file)) == 0;
  std::fclose(file);
  return synced;
}

// A file name the server may give: no folders, nothing hidden behind "." or "..".
bool PlainFileName(const std::string& name) {
  return !name.empty() && name != "." && name != ".." && name.find('/') == std::string::npos;
}

}  // namespace

Result<health::HealthCheckResponse::ServingStatus> RecognitionClient::CheckHealth() {
  // Not in the service config's names: gRPC does not retry the probe.
  health::HealthCheckResponse response;
  const grpc::Status status =
      health_->Check(UnaryContext().get(), health::HealthCheckRequest(), &response);
  if (!status.ok()) return status;
  return response.status();
}

Result<pb::VerifyResponse> RecognitionClient::VerifyStore(uint32_t mib_per_second) {
  grpc::ClientContext context;
  const Deadline deadline = std::chrono::system_clock::now() + options_.transfer_deadline;
  PrepareContext(context, &deadline);
  pb::VerifyRequest request;
  request.set_mib_per_second(mib_per_second);
  pb::VerifyResponse response;
  const grpc::Status status = admin_->Verify(&context, request, &response);
  if (!status.ok()) return status;
  return response;
}

Result<pb::StoreStatusResponse> RecognitionClient::GetStoreStatus() {
  pb::StoreStatusResponse response;
  const grpc::Status status =
      admin_->StoreStatus(UnaryContext().get(), pb::StoreStatusRequest(), &response);
  if (!status.ok()) return status;
  return response;
}

Result<pb::CheckpointManifest> RecognitionClient::DownloadCheckpoint(
    const std::string& directory, const std::function<void(uint64_t, uint64_t)>& progress) {
  std::error_code error;
  if (fs::exists(directory, error)) {
    return grpc::Status(grpc::StatusCode::ALREADY_EXISTS,
                        "'" + directory + "' already exists; a checkpoint goes to a new folder");
  }
  const fs::path part = directory + ".part";
  pb::CheckpointManifest manifest;
  const Deadline deadline = std::chrono::system_clock::now() + options_.transfer_deadline;
  uint64_t received = 0;  // bytes of the current attempt
  const auto attempt = [&](grpc::ClientContext& context) {
    std::error_code e;
    fs::remove_all(part, e);
    if (!fs::create_directories(part, e)) return CannotWrite(part.string(), e.message());
    std::unique_ptr<grpc::ClientReader<pb::CheckpointResponse>> reader =
        admin_->Checkpoint(&context, pb::CheckpointRequest());
    pb::CheckpointResponse response;
    size_t file = 0;    // index in the manifest of the file being written
    uint64_t left = 0;  // its bytes still to come
    received = 0;
    std::ofstream out;
    // Opens the next file of the manifest that has bytes (creating the empty ones on the way).
    const auto next_file = [&]() -> grpc::Status {
      while (file < size_t(manifest.files_size()) && left == 0) {
        const pb::CheckpointFile& f = manifest.files(int(file));
        if (out.is_open()) out.close();
        if (!out) return CannotWrite((part / f.name()).string());
        out.open(part / f.name(), std::ios::binary | std::ios::trunc);
        if (!out) return CannotWrite((part / f.name()).string());
        left = f.size_bytes();
        if (left == 0) ++file;
      }
      return grpc::Status::OK;
    };
    bool have_manifest = false;
    while (reader->Read(&response)) {
      if (response.has_manifest()) {
        manifest = response.manifest();
        have_manifest = true;
        for (const pb::CheckpointFile& f : manifest.files()) {
          if (!PlainFileName(f.name())) {
            context.TryCancel();
            return grpc::Status(grpc::StatusCode::DATA_LOSS,
                                "the checkpoint names a file '" + f.name() + "'");
          }
        }
        if (grpc::Status opened = next_file(); !opened.ok()) return opened;
        continue;
      }
      std::string_view bytes = response.chunk();
      while (!bytes.empty()) {
        if (!have_manifest || file >= size_t(manifest.files_size())) {
          context.TryCancel();
          return grpc::Status(grpc::StatusCode::DATA_LOSS,
                              "the checkpoint has more bytes than its manifest announced");
        }
        const size_t n = size_t(std::min<uint64_t>(left, bytes.size()));
        out.write(bytes.data(), std::streamsize(n));
        bytes.remove_prefix(n);
        left -= n;
        received += n;
        if (left == 0) {
          ++file;
          if (grpc::Status opened = next_file(); !opened.ok()) return opened;
        }
      }
      if (progress) progress(received, manifest.total_bytes());
    }
    grpc::Status finished = reader->Finish();
    if (!finished.ok()) return finished;
    if (out.is_open()) out.close();
    if (!out) return CannotWrite(part.string());
    if (!have_manifest || file < size_t(manifest.files_size())) {
      return grpc::Status(grpc::StatusCode::DATA_LOSS,
                          "the checkpoint ended after " + std::to_string(received) + " of " +
                              std::to_string(manifest.total_bytes()) + " bytes");
    }
    return grpc::Status::OK;
  };
  // gRPC retries the call until its first answer; a checkpoint that broke after bytes arrived
  // starts again from the beginning (the store's files change between two checkpoints), at most
  // as many times as the retry policy's attempts.
  grpc::Status status;
  int attempts = 0;
  do {
    grpc::ClientContext context;
    PrepareContext(context, &deadline);
    status = attempt(context);
  } while (!status.ok() && received > 0 && Resumable(status) &&
           ++attempts < internal::kMaxAttempts);
  if (!status.ok()) {
    fs::remove_all(part, error);
    return status;
  }
  for (const pb::CheckpointFile& f : manifest.files()) {
    if (!Sync(part / f.name())) return CannotWrite((part / f.name()).string(), "cannot sync");
  }
  fs::rename(part, directory, error);
  if (error) return CannotWrite(directory, error.message());
  if (!Sync(fs::absolute(directory).parent_path())) {
    return CannotWrite(directory, "cannot sync its parent folder");
  }
  return manifest;
}

}  // namespace recog::client
