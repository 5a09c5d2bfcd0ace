// RepositoryService: the ObjectRepository RPCs (proto/recognition/v1/repository.proto) over
// core's ModelRepository.
//
// Uploads are read one chunk at a time into memory (at most kMaxModelBytes), checked against the
// size and SHA-256 of their header, then stored on a worker. An upload that breaks off leaves its
// bytes in PartialUploads, from which a PutModel with the header's offset continues it, and a
// completed upload is remembered there too (GetUploadStatus). Downloads are written one chunk at a
// time, from the requested offset (a client resuming a broken download). Watchers get the
// repository's change events through a bounded queue each; a watcher that falls kMaxPendingEvents
// behind is ended with RESOURCE_EXHAUSTED. CloseWatchers() ends every watch stream (server
// shutdown: they would otherwise hold the drain until its deadline).
#pragma once

#include <chrono>
#include <mutex>
#include <set>

#include "recognition/v1/repository.grpc.pb.h"
#include "server/runtime/partial_uploads.h"
#include "server/services/server_state.h"

namespace recog::server {

class ModelWatch;

class RepositoryService final : public ::recognition::v1::ObjectRepository::CallbackService {
 public:
  static constexpr size_t kMaxModelBytes = 256u << 20;
  static constexpr size_t kMaxPendingEvents = 1024;
  // Interrupted uploads: the bytes kept for resumption (in all) and for how long.
  static constexpr size_t kMaxPartialUploadBytes = 256u << 20;
  static constexpr std::chrono::minutes kKeepPartialUploads{30};

  explicit RepositoryService(ServerState* state) : state_(*state) {}

  grpc::ServerReadReactor<::recognition::v1::PutModelRequest>* PutModel(
      grpc::CallbackServerContext* context, ::recognition::v1::PutModelResponse* response) override;
  grpc::ServerUnaryReactor* GetUploadStatus(
      grpc::CallbackServerContext* context,
      const ::recognition::v1::GetUploadStatusRequest* request,
      ::recognition::v1::GetUploadStatusResponse* response) override;
  grpc::ServerWriteReactor<::recognition::v1::GetModelResponse>* GetModel(
      grpc::CallbackServerContext* context,
      const ::recognition::v1::GetModelRequest* request) override;
  grpc::ServerUnaryReactor* ListModels(grpc::CallbackServerContext* context,
                                       const ::recognition::v1::ListModelsRequest* request,
                                       ::recognition::v1::ListModelsResponse* response) override;
  grpc::ServerUnaryReactor* DeleteModel(grpc::CallbackServerContext* context,
                                        const ::recognition::v1::DeleteModelRequest* request,
                                        ::recognition::v1::DeleteModelResponse* response) override;
  grpc::ServerWriteReactor<::recognition::v1::WatchModelsResponse>* WatchModels(
      grpc::CallbackServerContext* context,
      const ::recognition::v1::WatchModelsRequest* request) override;

  // Ends every open WatchModels stream with UNAVAILABLE.
  void CloseWatchers();

 private:
  friend class ModelWatch;
  ServerState& state_;
  PartialUploads partial_uploads_{kMaxPartialUploadBytes, kKeepPartialUploads};
  std::mutex watches_mutex_;
  std::set<ModelWatch*> watches_;
};

}  // namespace recog::server
