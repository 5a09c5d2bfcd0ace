// ServerState: everything the RPC handlers of one recogd share.
//
// Built by RecognitionServer (server/app/recognition_server.h) before the gRPC server starts, so
// that health checks can answer while the store opens. Until `ready` is set, the domain members
// (store, maps, objects, repository) are null and every RPC answers UNAVAILABLE; once set they
// never change until the server is destroyed. `draining` is set on shutdown: streams stop after
// the frame they are answering, new calls get UNAVAILABLE.
#pragma once

#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <optional>

#include "core/features/feature_extractor.h"
#include "core/index/index_store.h"
#include "core/object/recognition/object_database.h"
#include "core/object/recognition/object_recognizer.h"
#include "core/object/repository/model_repository.h"
#include "core/place/map_registry.h"
#include "server/auth/token_auth.h"
#include "server/config/placement_table.h"
#include "server/config/server_config.h"
#include "server/metrics/metrics.h"
#include "server/runtime/byte_budget.h"
#include "server/runtime/frame_thumbnails.h"
#include "server/runtime/recent_loops.h"
#include "server/runtime/request_log.h"
#include "server/runtime/store_verifier.h"
#include "server/runtime/worker_pool.h"
#include "server/services/worker_context.h"
#include "storage/rocksdb_index_store.h"

namespace recog::server {

struct ServerState {
  ServerState(ServerConfig config, TokenAuthenticator authenticator)
      : config(std::move(config)),
        auth(std::move(authenticator)),
        requests(this->config.request_log_entries),
        pending_request_bytes(uint64_t(this->config.grpc.pending_requests_mb) << 20),
        recent_loops(this->config.console.listen.empty()
                         ? nullptr
                         : std::make_unique<RecentLoops>(this->config.console.loops_per_map)) {}

  const ServerConfig config;
  const TokenAuthenticator auth;
  // The answers of recent mutating calls by request_id (RunOnce in call.h).
  RequestLog requests;
  // The unary requests taken and not yet answered, by size (RunUnary in call.h).
  ByteBudget pending_request_bytes;
  // The last loops of each map, for the web console; null (nothing recorded) without a console.
  const std::unique_ptr<RecentLoops> recent_loops;
  ServerMetrics metrics;
  std::unique_ptr<WorkerPool<WorkerContext>> pool;  // its contexts read this state
  std::atomic<bool> ready{false};
  std::atomic<bool> draining{false};

  // Set once before `ready`.
  std::unique_ptr<IndexStore> store;
  std::unique_ptr<MapRegistry> maps;
  std::shared_ptr<ObjectDatabase> objects;
  std::unique_ptr<ModelRepository> repository;
  std::unique_ptr<FrameThumbnails> thumbnails;  // of the maps that keep them (keep_thumbnails)
  std::unique_ptr<StoreVerifier> verifier;      // checks the store's files (store_verifier.h)
  StoreRecovery recovery;  // what opening the store recovered (empty when it opened whole)
  // How frames sent as images are described for place maps.
  FeatureOptions place_features = PlaceFeatureOptions();
  RecognitionOptions recognition;  // object recognition settings

  // With config.shard set: the placement table, replaced whole by a reload (SIGHUP). Null when
  // this server owns every map.
  std::shared_ptr<const PlacementTable> placement() const {
    std::lock_guard lock(placement_mutex_);
    return placement_;
  }
  void set_placement(std::shared_ptr<const PlacementTable> table) {
    std::lock_guard lock(placement_mutex_);
    placement_ = std::move(table);
  }

  // The last check of the store's files (background or Admin.Verify), for Admin.StoreStatus.
  struct StoreCheck {
    std::chrono::system_clock::time_point finished;
    StoreVerifier::Result result;
    std::chrono::duration<double> took;
  };
  std::optional<StoreCheck> last_store_check() const {
    std::lock_guard lock(store_check_mutex_);
    return last_store_check_;
  }
  void set_last_store_check(StoreCheck check) {
    std::lock_guard lock(store_check_mutex_);
    last_store_check_ = std::move(check);
  }

 private:
  mutable std::mutex placement_mutex_;
  std::shared_ptr<const PlacementTable> placement_;
  mutable std::mutex store_check_mutex_;
  std::optional<StoreCheck> last_store_check_;
};

}  // namespace recog::server
