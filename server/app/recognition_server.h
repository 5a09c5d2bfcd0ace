// RecognitionServer: recogd assembled — the gRPC server, its services and the store behind them.
//
// Start() begins listening at once, with the health service reporting NOT_SERVING and every RPC
// answering UNAVAILABLE, then opens the RocksDB store under <data_dir>/store, the vocabularies,
// every place map and the object repository, and only then reports SERVING. It returns when the
// server is ready (or failed to become so).
//
// Shutdown(grace) drains: health NOT_SERVING, new calls get UNAVAILABLE, streams end after the
// frame they are answering, watch streams end; calls in flight get up to `grace` to finish, then
// are cancelled; the workers stop, the store is flushed (every acknowledged write made durable)
// and closed. The destructor shuts down with no grace if Shutdown was not called.
//
// With repository.primary set, the server is a read-only replica of that server's model
// repository: a RepositoryFollower (server/replication/) started once the store is open copies
// the primary's models, and uploads and deletions are refused (FAILED_PRECONDITION naming the
// primary). Shutdown stops the follower first.
//
// With a shard configuration, place-map calls for maps the placement table does not give to this
// shard are refused (FAILED_PRECONDITION naming the owner); the table is read at Start (a bad one
// fails it) and again by ReloadPlacement.
//
// Reload (recogd: SIGHUP) re-reads what may change while the server runs: the placement table,
// the token file (calls after it authenticate with the new tokens) and the TLS files (connections
// made after it use the new certificate, see server/app/server_tls.h). A file that does not load
// is logged and the one in use is kept. With TLS, checked copies of the files are kept under
// <data_dir>/tls.
//
// Also serving: grpc.health.v1.Health (server/services/health_service.h), server reflection
// (behind the token when tokens are on: server/app/grpc_guards.h), and Prometheus metrics over
// HTTP on `metrics_listen` (unless empty), including the standard gRPC server metrics of the
// recognition services (server/app/grpc_metrics.h). The gRPC port's connections are accepted by
// a GrpcListener (server/app/grpc_listener.h) and its limits are config.grpc's.
#pragma once

#include <chrono>
#include <memory>
#include <mutex>
#include <optional>

#include <grpcpp/grpcpp.h>

#include "core/common/status.h"
#include "server/auth/token_auth.h"
#include "server/config/server_config.h"
#include "server/runtime/store_verifier.h"

namespace recog::server {

struct ServerState;
class PlaceService;
class ObjectService;
class RepositoryService;
class AdminService;
class HealthService;
class RepositoryFollower;
class GrpcListener;
class ServerTls;
class WebConsole;

class RecognitionServer {
 public:
  // FAILED_PRECONDITION / NOT_FOUND / DATA_LOSS ... from the store, the vocabularies or the token
  // file; UNAVAILABLE when the address cannot be bound. `config` must be valid.
  static StatusOr<std::unique_ptr<RecognitionServer>> Start(const ServerConfig& config);
  // recogd --verify: opens the store of `config` (no server), checks every file of it as fast as
  // the disk goes and closes it. DATA_LOSS naming the first damaged file; the store's open errors.
  static StatusOr<IndexStore::VerifyReport> VerifyOffline(const ServerConfig& config);
  // The health service name that is NOT_SERVING while the last check of the store found damage.
  static constexpr char kStoreHealthService[] = "recog.store";
  ~RecognitionServer();
  RecognitionServer(const RecognitionServer&) = delete;
  RecognitionServer& operator=(const RecognitionServer&) = delete;

  // The port the gRPC server listens on (the one picked when `listen` ends in ":0"); 0 on a unix
  // socket.
  int port() const { return port_; }
  // The metrics port, 0 when metrics are off.
  int metrics_port() const;
  // The port of the web console (console.listen), 0 without one.
  int console_port() const;

  // Re-reads the placement table (ServerConfig::shard) and serves by it from the next call; OK
  // and nothing done without a shard configuration. On error the table in use is kept; a table
  // that places the group of one of this shard's maps on another shard is FAILED_PRECONDITION.
  Status ReloadPlacement();

  // Reloads the placement table, the tokens and the TLS files (see the header comment), each
  // independently; logs each failure and returns the first. Call from one thread at a time.
  Status Reload();

  // Graceful shutdown (see the header comment). Idempotent; thread-safe.
  void Shutdown(std::chrono::milliseconds grace);

 private:
  RecognitionServer();
  Status Open();            // the store and everything in it; sets ready
  Status StartFollowing();  // the repository follower of a replica; nothing on a primary
  // The outcome of a check of the store's files: logged, counted, and the store's health.
  void StoreChecked(const StoreVerifier::Result& result, std::chrono::duration<double> took);

  std::unique_ptr<ServerState> state_;
  std::optional<TokenAuthenticator> tokens_;  // a copy of state_->auth, to reload it
  std::unique_ptr<ServerTls> tls_;            // null without TLS; outlives server_
  std::unique_ptr<PlaceService> place_service_;
  std::unique_ptr<ObjectService> object_service_;
  std::unique_ptr<RepositoryService> repository_service_;
  std::unique_ptr<AdminService> admin_service_;
  std::unique_ptr<HealthService> health_service_;  // NOT_SERVING until the store is open
  // Hands the listener's connections to server_; outlives the listener's thread.
  std::unique_ptr<grpc::experimental::ExternalConnectionAcceptor> acceptor_;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<GrpcListener> listener_;        // the gRPC port's sockets; stopped first
  std::unique_ptr<RepositoryFollower> follower_;  // on a replica, once ready
  std::unique_ptr<WebConsole> console_;           // with console.listen, once ready
  int port_ = 0;
  std::once_flag shutdown_once_;
};

}  // namespace recog::server
