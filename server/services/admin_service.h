// AdminService: the Admin RPCs (proto/recognition/v1/admin.proto): online checkpoints, checks
// of the store's files and the store's status.
//
// Checkpoint asks the store for a consistent copy (IndexStore::Checkpoint: RocksDB hard-links its
// files, so this is quick and costs little space) under <data_dir>/checkpoints/, then streams the
// copy's files to the caller one chunk at a time, each write waiting for the previous one (a slow
// caller holds only its own chunk in memory), and deletes the copy when the call ends, however
// it ends. Writes keep being served meanwhile; the copy holds every write acknowledged before the
// call.
#pragma once

#include "recognition/v1/admin.grpc.pb.h"
#include "server/services/server_state.h"

namespace recog::server {

class AdminService final : public ::recognition::v1::Admin::CallbackService {
 public:
  explicit AdminService(ServerState* state) : state_(*state) {}

  grpc::ServerWriteReactor<::recognition::v1::CheckpointResponse>* Checkpoint(
      grpc::CallbackServerContext* context,
      const ::recognition::v1::CheckpointRequest* request) override;

  // Verify runs the server's StoreVerifier now, on a worker (store_verifier.h).
  grpc::ServerUnaryReactor* Verify(grpc::CallbackServerContext* context,
                                   const ::recognition::v1::VerifyRequest* request,
                                   ::recognition::v1::VerifyResponse* response) override;

  // StoreStatus: the start-up's recovery report and the last check (ServerState).
  grpc::ServerUnaryReactor* StoreStatus(grpc::CallbackServerContext* context,
                                        const ::recognition::v1::StoreStatusRequest* request,
                                        ::recognition::v1::StoreStatusResponse* response) override;

 private:
  ServerState& state_;
};

}  // namespace recog::server
