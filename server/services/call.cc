#include "server/services/call.h"

#include <atomic>
#include <cstdio>

#include <spdlog/spdlog.h>

#include "server/api/status_mapping.h"

namespace recog::server {
namespace {

constexpr size_t kMaxRequestIdBytes = 64;

std::string MakeRequestId() {
  static std::atomic<uint64_t> next{1};
  static const uint64_t salt =
      uint64_t(std::chrono::system_clock::now().time_since_epoch().count()) & 0xffffff;
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%06llx-%llu", static_cast<unsigned long long>(salt),
                static_cast<unsigned long long>(next.fetch_add(1)));
  return buffer;
}

std::string_view Metadata(const grpc::CallbackServerContext* context, std::string_view key) {
  const auto& metadata = context->client_metadata();
  const auto it = metadata.find(grpc::string_ref(key.data(), key.size()));
  if (it == metadata.end()) return {};
  return {it->second.data(), it->second.size()};
}

}  // namespace

grpc::Status BeginCall(ServerState& state, grpc::CallbackServerContext* context,
                       std::string_view method, Right right, CallInfo* call) {
  call->start = std::chrono::steady_clock::now();
  call->method = std::string(method);
  const std::string_view given = Metadata(context, "x-request-id");
  call->request_id =
      !given.empty() && given.size() <= kMaxRequestIdBytes ? std::string(given) : MakeRequestId();
  context->AddTrailingMetadata("x-request-id", call->request_id);
  StatusOr<Caller> caller = state.auth.Authenticate(Metadata(context, "authorization"));
  if (!caller.ok()) return ToGrpcStatus(caller.status(), call->request_id);
  call->caller = std::move(caller).value();
  const Status allowed = TokenAuthenticator::Check(call->caller, right);
  if (!allowed.ok()) return ToGrpcStatus(allowed, call->request_id);
  // Refusals that nothing was applied for carry the retry hint, so that clients may retry even
  // calls that change the server.
  if (state.draining.load()) {
    context->AddTrailingMetadata("retry-after-ms", std::to_string(state.config.retry_after_ms));
    return {grpc::StatusCode::UNAVAILABLE, "the server is shutting down"};
  }
  if (!state.ready.load()) {
    context->AddTrailingMetadata("retry-after-ms", std::to_string(state.config.retry_after_ms));
    return {grpc::StatusCode::UNAVAILABLE, "the server is starting (opening its store)"};
  }
  return grpc::Status::OK;
}

void EndCall(ServerState& state, const CallInfo& call, const grpc::Status& status) {
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - call.start).count();
  const std::string_view code = GrpcCodeName(status.error_code());
  state.metrics.ObserveRpc(call.method, code, seconds);
  SampleWorkerGauges(state);
  const auto level = status.ok()                                         ? spdlog::level::debug
                     : status.error_code() == grpc::StatusCode::INTERNAL ? spdlog::level::err
                                                                         : spdlog::level::info;
  spdlog::log(level, "request={} method={} caller={} map={} code={} ms={:.2f}{}{}", call.request_id,
              call.method, call.caller.name, call.map, code, seconds * 1e3,
              status.ok() ? "" : " error=", status.error_message());
}

void SampleWorkerGauges(ServerState& state) {
  state.metrics.SetWorkerQueueDepth(state.pool->queued());
  state.metrics.SetBusyWorkers(state.pool->busy());
}

grpc::Status CheckStillWanted(grpc::CallbackServerContext* context) {
  // The deadline first: gRPC also marks a call whose deadline passed as cancelled.
  if (context->deadline() < std::chrono::system_clock::now()) {
    return {grpc::StatusCode::DEADLINE_EXCEEDED, "the deadline passed while the call waited"};
  }
  if (context->IsCancelled()) return {grpc::StatusCode::CANCELLED, "the client cancelled"};
  return grpc::Status::OK;
}

grpc::Status Busy(ServerState& state, grpc::CallbackServerContext* context) {
  context->AddTrailingMetadata("retry-after-ms", std::to_string(state.config.retry_after_ms));
  return {grpc::StatusCode::RESOURCE_EXHAUSTED,
          "the server is busy (" + std::to_string(state.pool->capacity()) +
              " calls waiting); retry after " + std::to_string(state.config.retry_after_ms) +
              " ms"};
}

grpc::ServerUnaryReactor* RunUnary(ServerState& state, grpc::CallbackServerContext* context,
                                   std::string_view method, Right right, UnaryWork work) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  auto call = std::make_shared<CallInfo>();
  grpc::Status status = BeginCall(state, context, method, right, call.get());
  if (status.ok()) {
    const bool queued =
        state.pool->TrySubmit([&state, context, reactor, call, work](WorkerContext& worker) {
          call->queue_ms = std::chrono::duration<double, std::milli>(
                               std::chrono::steady_clock::now() - call->start)
                               .count();
          grpc::Status result = CheckStillWanted(context);
          if (result.ok()) result = work(*call, worker);
          EndCall(state, *call, result);
          reactor->Finish(result);
        });
    if (queued) return reactor;
    status = Busy(state, context);
  }
  EndCall(state, *call, status);
  reactor->Finish(status);
  return reactor;
}

grpc::Status CheckMapOwner(const ServerState& state, const std::string& map) {
  const std::shared_ptr<const PlacementTable> placement = state.placement();
  if (placement == nullptr) return grpc::Status::OK;
  const std::optional<std::string> owner = placement->OwnerOf(map);
  const std::string& self = state.config.shard.name;
  if (owner == self) return grpc::Status::OK;
  if (!owner.has_value()) {
    return {grpc::StatusCode::FAILED_PRECONDITION,
            "map '" + map + "' is not in the placement table (" +
                state.config.shard.placement_file +
                "): add it to a shard, then reload nginx and the servers"};
  }
  return {grpc::StatusCode::FAILED_PRECONDITION, "map '" + map + "' belongs to shard '" + *owner +
                                                     "', not to this server (shard '" + self +
                                                     "')"};
}

}  // namespace recog::server
