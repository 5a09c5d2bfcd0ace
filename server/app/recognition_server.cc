#include "server/app/recognition_server.h"

#include <algorithm>
#include <filesystem>

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <spdlog/spdlog.h>

#include "core/vocabulary/vocabulary_io.h"
#include "server/app/grpc_guards.h"
#include "server/app/grpc_listener.h"
#include "server/app/grpc_metrics.h"
#include "server/app/server_tls.h"
#include "server/console/web_console.h"
#include "server/replication/repository_follower.h"
#include "server/services/admin_service.h"
#include "server/services/health_service.h"
#include "server/services/object_service.h"
#include "server/services/place_service.h"
#include "server/services/repository_service.h"
#include "server/services/server_state.h"
#include "storage/rocksdb_index_store.h"
#include "wire/sha256.h"

namespace recog::server {
namespace {

namespace pb = ::recognition::v1;

// The directory under data_dir of the checked copies of the TLS files (see ServerTls).
constexpr char kLiveTlsDir[] = "tls";

RocksDbStoreOptions StoreOptionsOf(const ServerConfig& config) {
  RocksDbStoreOptions options;
  options.sync =
      config.store.sync == StoreSync::kEveryWrite ? SyncPolicy::kEveryWrite : SyncPolicy::kGrouped;
  options.group_sync_interval_ms = config.store.group_sync_interval_ms;
  options.block_cache_mb = size_t(config.store.block_cache_mb);
  options.damaged_log = config.store.recover == StoreRecover::kPointInTime
                            ? DamagedLogPolicy::kPointInTime
                            : DamagedLogPolicy::kRefuse;
  return options;
}

std::string StorePathOf(const ServerConfig& config) { return config.data_dir + "/store"; }

StatusOr<std::shared_ptr<const Vocabulary>> OpenVocabulary(const std::string& configured,
                                                           const std::string& bundled) {
  const std::string path = configured.empty() ? bundled : configured;
  RECOG_ASSIGN_OR_RETURN(Vocabulary vocabulary, LoadVocabulary(path));
  spdlog::info("vocabulary {}: {} words", path, vocabulary.num_words());
  return std::make_shared<const Vocabulary>(std::move(vocabulary));
}

// A map of this shard whose group `table` places on another shard would be missing from that
// group's searches without a word: FAILED_PRECONDITION naming it.
Status CheckGroupPlacement(const PlacementTable& table, const ServerState& state) {
  const ShardConfig& shard = state.config.shard;
  for (const std::shared_ptr<PlaceMap>& map : state.maps->List()) {
    const std::optional<std::string> group_shard = table.OwnerOfGroup(map->group());
    if (!map->group().empty() && group_shard.has_value() && *group_shard != shard.name) {
      return Status::FailedPrecondition(
          "the placement table '" + shard.placement_file + "' places group '" + map->group() +
          "' on shard '" + *group_shard + "', but its map '" + map->name() +
          "' is on this shard ('" + shard.name + "'): move the map there first");
    }
  }
  return Status::Ok();
}

// The limits of config.grpc on the gRPC server (docs/server.md, "Security"), and compressed
// requests refused: only identity is enabled, so gRPC fails a call whose grpc-encoding names
// another algorithm (UNIMPLEMENTED) before it inflates anything.
void ApplyGrpcLimits(const GrpcLimitsConfig& limits, grpc::ServerBuilder& builder) {
  grpc::ResourceQuota quota("recogd");
  quota.Resize(size_t(limits.memory_quota_mb) << 20);
  builder.SetResourceQuota(quota);
  builder.AddChannelArgument(GRPC_ARG_MAX_CONCURRENT_STREAMS, int(limits.max_concurrent_streams));
  if (limits.max_connection_idle_ms != 0) {
    builder.AddChannelArgument(GRPC_ARG_MAX_CONNECTION_IDLE_MS, int(limits.max_connection_idle_ms));
  }
  if (limits.max_connection_age_ms != 0) {
    builder.AddChannelArgument(GRPC_ARG_MAX_CONNECTION_AGE_MS, int(limits.max_connection_age_ms));
    builder.AddChannelArgument(GRPC_ARG_MAX_CONNECTION_AGE_GRACE_MS,
                               int(limits.max_connection_age_grace_ms));
  }
  for (const grpc_compression_algorithm algorithm : {GRPC_COMPRESS_DEFLATE, GRPC_COMPRESS_GZIP}) {
    builder.SetCompressionAlgorithmSupportStatus(algorithm, false);
  }
}

// Says how a place map's index was built at start-up: from its snapshot (and the frames added
// after it) or from every frame.
void LogIndexOpening(const PlaceMap& map) {
  const DatabaseOpenReport& report = map.open_report();
  if (!report.snapshot_rejected.empty()) {
    spdlog::warn("place map '{}': its index snapshot was not used: {}", map.name(),
                 report.snapshot_rejected);
  }
  if (report.from_snapshot) {
    spdlog::info(
        "place map '{}': {} frames; index loaded from its snapshot, {} frames read after it",
        map.name(), map.frames(), report.entries_read);
  } else {
    spdlog::info("place map '{}': {} frames; index rebuilt from them", map.name(), map.frames());
  }
}

// Writes the index snapshot of every place map that changed since its last one, so that the next
// start loads the indexes instead of reading every frame. A failure only costs that start time.
void SaveIndexSnapshots(const MapRegistry& maps) {
  for (const std::shared_ptr<PlaceMap>& map : maps.List()) {
    const auto start = std::chrono::steady_clock::now();
    const StatusOr<uint64_t> written = map->SaveIndexSnapshot();
    if (!written.ok()) {
      spdlog::warn("place map '{}': no index snapshot: {}", map->name(),
                   written.status().ToString());
    } else if (*written > 0) {
      spdlog::info("place map '{}': index snapshot of {} MB written in {:.1f} s", map->name(),
                   double(*written) / 1e6,
                   std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    }
  }
}

}  // namespace

RecognitionServer::RecognitionServer() = default;

RecognitionServer::~RecognitionServer() { Shutdown(std::chrono::milliseconds(0)); }

int RecognitionServer::metrics_port() const { return state_->metrics.HttpPort(); }

int RecognitionServer::console_port() const { return console_ == nullptr ? 0 : console_->port(); }

StatusOr<std::unique_ptr<RecognitionServer>> RecognitionServer::Start(const ServerConfig& config) {
  RECOG_RETURN_IF_ERROR(config.Validate());
  StatusOr<TokenAuthenticator> auth = config.token_file.empty()
                                          ? TokenAuthenticator::AllowAll()
                                          : TokenAuthenticator::Load(config.token_file);
  if (!auth.ok()) return auth.status();
  std::unique_ptr<RecognitionServer> server(new RecognitionServer());
  std::shared_ptr<grpc::ServerCredentials> credentials = grpc::InsecureServerCredentials();
  if (!config.tls.cert.empty()) {
    RECOG_ASSIGN_OR_RETURN(
        server->tls_,
        ServerTls::Create(config.tls,
                          (std::filesystem::path(config.data_dir) / kLiveTlsDir).string()));
    credentials = server->tls_->credentials();
  }
  server->tokens_.emplace(*auth);  // shares the tokens the services authenticate with
  server->state_ = std::make_unique<ServerState>(config, std::move(auth).value());
  ServerState& state = *server->state_;
  state.pool = std::make_unique<WorkerPool<WorkerContext>>(
      config.WorkerCount(), config.queue_capacity,
      [&state] { return std::make_unique<WorkerContext>(state); });
  if (!config.metrics_listen.empty()) {
    RECOG_RETURN_IF_ERROR(state.metrics.StartHttp(config.metrics_listen, config.metrics));
  }
  RECOG_RETURN_IF_ERROR(server->ReloadPlacement());
  server->place_service_ = std::make_unique<PlaceService>(&state);
  server->object_service_ = std::make_unique<ObjectService>(&state);
  server->repository_service_ = std::make_unique<RepositoryService>(&state);
  server->admin_service_ = std::make_unique<AdminService>(&state);

  server->health_service_ =
      std::make_unique<HealthService>(std::vector<std::string>{kStoreHealthService});
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  ThrottleLibraryLogs();
  RECOG_ASSIGN_OR_RETURN(
      server->listener_,
      GrpcListener::Bind(
          {.address = config.listen, .reserve_descriptors = config.grpc.reserve_descriptors}));
  server->port_ = server->listener_->port();
  grpc::ServerBuilder builder;
  server->acceptor_ = builder.experimental().AddExternalConnectionAcceptor(
      grpc::ServerBuilder::experimental_type::ExternalConnectionType::FROM_FD, credentials);
  builder.SetMaxReceiveMessageSize(int(config.max_message_bytes));
  builder.SetMaxSendMessageSize(int(config.max_message_bytes));
  ApplyGrpcLimits(config.grpc, builder);
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIME_MS, int(config.keepalive.time_ms));
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, int(config.keepalive.timeout_ms));
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS,
                             config.keepalive.permit_without_calls ? 1 : 0);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS,
                             int(config.keepalive.min_ping_interval_ms));
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MAX_PING_STRIKES, 2);
  builder.RegisterService(server->place_service_.get());
  builder.RegisterService(server->object_service_.get());
  builder.RegisterService(server->repository_service_.get());
  builder.RegisterService(server->admin_service_.get());
  builder.RegisterService(server->health_service_.get());
  RegisterServiceMethods(
      state.metrics,
      {pb::PlaceRecognition::service_full_name(), pb::ObjectRecognition::service_full_name(),
       pb::ObjectRepository::service_full_name(), pb::Admin::service_full_name()});
  std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> interceptors;
  interceptors.push_back(MakeGrpcMetricsInterceptorFactory(&state.metrics));
  interceptors.push_back(MakeReflectionGuardFactory(&state.auth));
  builder.experimental().SetInterceptorCreators(std::move(interceptors));
  server->server_ = builder.BuildAndStart();
  if (server->server_ == nullptr) return Status::Internal("the gRPC server did not start");
  server->listener_->Start(server->acceptor_.get());
  spdlog::info("recogd listening on port {} ({}), opening {}", server->port(),
               config.tls.cert.empty() ? "plaintext" : "TLS", config.data_dir);
  RECOG_RETURN_IF_ERROR(server->Open());
  RECOG_RETURN_IF_ERROR(server->StartFollowing());
  if (!config.console.listen.empty()) {
    grpc::ChannelArguments arguments;
    arguments.SetMaxReceiveMessageSize(int(config.max_message_bytes));
    arguments.SetMaxSendMessageSize(int(config.max_message_bytes));
    RECOG_ASSIGN_OR_RETURN(server->console_,
                           WebConsole::Start(&state, server->server_->InProcessChannel(arguments)));
  }
  server->health_service_->Set("", true);
  server->health_service_->Set(kStoreHealthService, true);
  spdlog::info("recogd ready: {} place maps, {} objects, {} workers, metrics on {}, console on {}",
               state.maps->List().size(), state.objects->size(), state.pool->threads(),
               config.metrics_listen.empty() ? "(off)" : config.metrics_listen,
               server->console_ ? server->console_->url() : "(off)");
  return server;
}

Status RecognitionServer::Open() {
  ServerState& state = *state_;
  const ServerConfig& config = state.config;
  std::error_code error;
  std::filesystem::create_directories(config.data_dir, error);
  if (error) {
    return Status::FailedPrecondition("cannot create the data directory '" + config.data_dir +
                                      "': " + error.message());
  }
  state.metrics.WatchDisk(config.data_dir);
  // Checkpoints left by a server that died while streaming one (AdminService) are of no use.
  std::filesystem::remove_all(std::filesystem::path(config.data_dir) / "checkpoints", error);
  StoreRecovery& recovery = state.recovery;
  RECOG_ASSIGN_OR_RETURN(
      state.store, OpenRocksDbIndexStore(StorePathOf(config), StoreOptionsOf(config), &recovery));
  state.metrics.SetStoreRecoveryLoss(recovery.entries_lost(), recovery.maps_lost(),
                                     recovery.blobs_lost.size());

  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<const Vocabulary> place_vocabulary,
                         OpenVocabulary(config.place_vocabulary, DefaultPlaceVocabularyPath()));
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<const Vocabulary> object_vocabulary,
                         OpenVocabulary(config.object_vocabulary, DefaultObjectVocabularyPath()));
  RECOG_ASSIGN_OR_RETURN(
      state.maps,
      MapRegistry::Open(state.store.get(), place_vocabulary, [](size_t done, size_t total) {
        spdlog::info("opened place map {}/{}", done, total);
      }));
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<ObjectDatabase> objects,
                         ObjectDatabase::Open(state.store.get(), object_vocabulary));
  state.objects = std::move(objects);
  RECOG_ASSIGN_OR_RETURN(state.repository,
                         ModelRepository::Open(state.store.get(), state.objects, Sha256Hex));
  RECOG_ASSIGN_OR_RETURN(state.thumbnails, FrameThumbnails::Open(state.store.get()));
  if (const std::shared_ptr<const PlacementTable> placement = state.placement()) {
    RECOG_RETURN_IF_ERROR(CheckGroupPlacement(*placement, state));
  }
  for (const std::shared_ptr<PlaceMap>& map : state.maps->List()) {
    LogIndexOpening(*map);
    state.metrics.SetMapIndexOpening(map->name(), map->open_report().from_snapshot,
                                     map->open_report().entries_read);
    state.metrics.SetMapEntries(map->name(), map->frames());
  }
  state.metrics.SetObjects(state.objects->size());
  state.verifier = std::make_unique<StoreVerifier>(
      state.store.get(), std::chrono::seconds(config.store.verify_interval_s),
      uint64_t(config.store.verify_mb_per_s) << 20,
      [this](const StoreVerifier::Result& result, std::chrono::duration<double> took) {
        StoreChecked(result, took);
      });
  state.ready = true;
  return Status::Ok();
}

void RecognitionServer::StoreChecked(const StoreVerifier::Result& result,
                                     std::chrono::duration<double> took) {
  state_->set_last_store_check({std::chrono::system_clock::now(), result, took});
  const bool damaged = result.status().code() == StatusCode::kDataLoss;
  const uint64_t bytes = result.ok() ? result->bytes : 0;
  state_->metrics.StoreVerified(damaged, bytes, took.count());
  if (damaged) health_service_->Set(kStoreHealthService, false);
  if (result.ok()) {
    health_service_->Set(kStoreHealthService, true);
    spdlog::info("store verified: {} files, {:.1f} MiB in {:.1f} s ({:.1f} MiB/s), no damage",
                 result->files, double(bytes) / (1 << 20), took.count(),
                 double(bytes) / (1 << 20) / std::max(took.count(), 1e-9));
  } else {
    spdlog::error("store check failed: {}", result.status().ToString());
  }
}

StatusOr<IndexStore::VerifyReport> RecognitionServer::VerifyOffline(const ServerConfig& config) {
  RocksDbStoreOptions options = StoreOptionsOf(config);
  options.create_if_missing = false;
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<IndexStore> store,
                         OpenRocksDbIndexStore(StorePathOf(config), options));
  return store->Verify(0);
}

Status RecognitionServer::StartFollowing() {
  const RepositoryConfig& repository = state_->config.repository;
  if (repository.primary.empty()) return Status::Ok();
  RepositoryFollower::Options options;
  options.primary.target = repository.primary;
  options.primary.token_file = repository.token_file;
  options.primary.tls.enabled = !repository.tls_ca.empty();
  options.primary.tls.ca_file = repository.tls_ca;
  options.primary.max_message_bytes = state_->config.max_message_bytes;
  options.staging_dir = (std::filesystem::path(state_->config.data_dir) / "replication").string();
  RECOG_ASSIGN_OR_RETURN(follower_, RepositoryFollower::Start(std::move(options), state_.get()));
  return Status::Ok();
}

void RecognitionServer::Shutdown(std::chrono::milliseconds grace) {
  std::call_once(shutdown_once_, [&] {
    if (state_ == nullptr) return;
    console_.reset();   // its requests call the services and read the state
    follower_.reset();  // it writes into the repository
    ServerState& state = *state_;
    state.draining = true;
    if (server_ != nullptr) {
      spdlog::info("recogd draining (up to {} ms)", grace.count());
      listener_.reset();  // no new connections
      health_service_->Shutdown();
      repository_service_->CloseWatchers();
      server_->Shutdown(std::chrono::system_clock::now() + grace);
    }
    state.verifier.reset();  // waits for a check in progress
    if (state.pool != nullptr) state.pool->Stop();
    state.thumbnails.reset();  // writes the queued ones before the store is flushed
    if (state.maps != nullptr) SaveIndexSnapshots(*state.maps);
    if (state.store != nullptr) {
      const Status flushed = state.store->Flush();
      if (!flushed.ok()) spdlog::error("flushing the store failed: {}", flushed.ToString());
    }
    // Close in dependency order: the repository and databases write through the store.
    state.repository.reset();
    state.objects.reset();
    state.maps.reset();
    state.store.reset();
    if (server_ != nullptr) spdlog::info("recogd stopped");
  });
}

Status RecognitionServer::Reload() {
  Status first = Status::Ok();
  const auto reload = [&first](const char* kept, const Status& status) {
    if (status.ok()) return;
    spdlog::error("recogd: reload: {}; {}", status.ToString(), kept);
    if (first.ok()) first = status;
  };
  reload("the placement table in use is kept", ReloadPlacement());
  const Status tokens = tokens_->Reload();
  reload("the tokens in use are kept", tokens);
  if (tokens.ok() && !state_->config.token_file.empty()) {
    spdlog::info("recogd: tokens reloaded from {}", state_->config.token_file);
  }
  if (tls_ != nullptr) {
    const Status certificates = tls_->Reload();
    reload("the certificates in use are kept", certificates);
    if (certificates.ok()) {
      spdlog::info("recogd: certificates reloaded from {}; new connections use them within {} s",
                   state_->config.tls.cert, ServerTls::kRefreshSeconds);
    }
  }
  return first;
}

Status RecognitionServer::ReloadPlacement() {
  const ShardConfig& shard = state_->config.shard;
  if (shard.placement_file.empty()) return Status::Ok();
  RECOG_ASSIGN_OR_RETURN(PlacementTable table, PlacementTable::Load(shard.placement_file));
  if (state_->maps != nullptr) RECOG_RETURN_IF_ERROR(CheckGroupPlacement(table, *state_));
  spdlog::info("recogd: shard '{}', placement table '{}': {} maps, {} groups", shard.name,
               shard.placement_file, table.size(), table.groups());
  state_->set_placement(std::make_shared<const PlacementTable>(std::move(table)));
  return Status::Ok();
}

}  // namespace recog::server
