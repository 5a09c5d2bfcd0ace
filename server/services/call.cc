#include "server/services/call.h"

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <optional>

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>
#include <spdlog/spdlog.h>

#include "core/common/elapsed.h"
#include "core/common/text.h"
#include "server/api/status_mapping.h"
#include "wire/sha256.h"

namespace recog::server {
namespace {

// gRFC A6: how long (ms) gRPC's retry waits before the next attempt; negative = do not retry.
constexpr char kPushback[] = "grpc-retry-pushback-ms";

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

// `text` escaped for a log line (EscapeForLog, at most kMaxCallIdBytes), its spaces too, so that a
// client's header cannot pass for further fields of the line ("id caller=admin").
std::string EscapedWithoutSpaces(std::string_view text) {
  std::string escaped;
  for (const char c : EscapeForLog(text, kMaxCallIdBytes)) {
    escaped += c == ' ' ? std::string("\\x20") : std::string(1, c);
  }
  return escaped;
}

// Feeds what protobuf serialises into a SHA-256, without a copy of the message.
class DigestStream : public google::protobuf::io::CopyingOutputStream {
 public:
  explicit DigestStream(Sha256* digest) : digest_(digest) {}
  bool Write(const void* buffer, int size) override {
    digest_->Update({static_cast<const char*>(buffer), size_t(size)});
    return true;
  }

 private:
  Sha256* digest_;
};

// The SHA-256 of `request`'s deterministic serialisation: equal for equal requests.
std::string RequestDigest(const google::protobuf::Message& request) {
  Sha256 digest;
  DigestStream sink(&digest);
  {
    google::protobuf::io::CopyingOutputStreamAdaptor adaptor(&sink);
    google::protobuf::io::CodedOutputStream coded(&adaptor);
    coded.SetSerializationDeterministic(true);
    request.SerializeToCodedStream(&coded);
  }  // flushed
  return digest.HexDigest();
}

}  // namespace

bool ValidCallId(std::string_view id) {
  return !id.empty() && id.size() <= kMaxCallIdBytes &&
         std::all_of(id.begin(), id.end(), [](char c) { return c > ' ' && c <= '~'; });
}

grpc::Status BeginCall(ServerState& state, grpc::CallbackServerContext* context,
                       std::string_view method, Right right, CallInfo* call) {
  call->start = std::chrono::steady_clock::now();
  call->method = std::string(method);
  const std::string_view given = Metadata(context, "x-request-id");
  if (ValidCallId(given)) {
    call->request_id = std::string(given);
  } else {
    call->request_id = MakeRequestId();
    // A header gRPC let through may hold any byte; only the escaped start of it reaches the log.
    if (!given.empty()) {
      spdlog::info(
          "request={} method={}: x-request-id refused ({} bytes, not 1 to {} printable "
          "ASCII characters without spaces): \"{}\"",
          call->request_id, call->method, given.size(), kMaxCallIdBytes,
          EscapedWithoutSpaces(given));
    }
  }
  context->AddTrailingMetadata("x-request-id", call->request_id);
  StatusOr<Caller> caller = state.auth.Authenticate(Metadata(context, "authorization"));
  if (!caller.ok()) return ToCallStatus(context, *call, caller.status());
  call->caller = std::move(caller).value();
  const Status allowed = TokenAuthenticator::Check(call->caller, right);
  if (!allowed.ok()) return ToCallStatus(context, *call, allowed);
  // Refusals that nothing was applied for carry the retry hint, so that clients may retry even
  // calls that change the server.
  if (state.draining.load()) {
    context->AddTrailingMetadata(kPushback, std::to_string(state.config.retry_after_ms));
    return {grpc::StatusCode::UNAVAILABLE, "the server is shutting down"};
  }
  if (!state.ready.load()) {
    context->AddTrailingMetadata(kPushback, std::to_string(state.config.retry_after_ms));
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
  const bool server_fault = status.error_code() == grpc::StatusCode::INTERNAL ||
                            status.error_code() == grpc::StatusCode::DATA_LOSS;
  const auto level = status.ok()    ? spdlog::level::debug
                     : server_fault ? spdlog::level::err
                                    : spdlog::level::info;
  // The map and the message may hold what a client sent (a name refused for its newline).
  spdlog::log(level, "request={} method={} caller={} map={} code={} ms={:.2f}{}{}",
              EscapeForLog(call.request_id), call.method, EscapeForLog(call.caller.name),
              EscapeForLog(call.map), code, seconds * 1e3,
              status.ok() ? "" : " error=", EscapeForLog(status.error_message(), 1024));
}

void SampleWorkerGauges(ServerState& state) {
  state.metrics.SetWorkerQueueDepth(state.pool->queued());
  state.metrics.SetBusyWorkers(state.pool->busy());
}

PixelBudget CallPixelBudget(const ServerState& state) {
  return PixelBudget(uint64_t(state.config.grpc.decode_memory_mb) << 20);
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
  context->AddTrailingMetadata(kPushback, std::to_string(state.config.retry_after_ms));
  return {grpc::StatusCode::RESOURCE_EXHAUSTED,
          "the server is busy (" + std::to_string(state.pool->capacity()) +
              " calls waiting); retry after " + std::to_string(state.config.retry_after_ms) +
              " ms"};
}

grpc::Status ToCallStatus(grpc::CallbackServerContext* context, const CallInfo& call,
                          const Status& status) {
  if (status.code() == StatusCode::kResourceExhausted) {
    context->AddTrailingMetadata(kPushback, "-1");
  }
  return ToGrpcStatus(status, call.request_id);
}

Status CheckRequestId(const std::string& request_id) {
  if (request_id.empty() || RequestLog::ValidRequestId(request_id)) return Status::Ok();
  return Status::InvalidArgument("request_id must have 1 to " +
                                 std::to_string(RequestLog::kMaxRequestIdBytes) +
                                 " printable ASCII characters");
}

grpc::Status RunOnce(ServerState& state, grpc::CallbackServerContext* context, CallInfo& call,
                     const Replay& replay, google::protobuf::Message* response,
                     const std::function<Status()>& work) {
  const std::string& request_id = replay.request_id;
  if (Status checked = CheckRequestId(request_id); !checked.ok()) {
    return ToCallStatus(context, call, checked);
  }
  if (request_id.empty()) return ToCallStatus(context, call, work());
  // The caller's token is part of the key: one client cannot read another's answers by guessing
  // ids, nor can another token of the same rights or name.
  const std::string key = call.method + '\n' + call.caller.identity + '\n' + request_id;
  const auto now = RequestLog::Clock::now();
  // Wait for a running duplicate at most until this call's deadline (and the log's window).
  const auto left = std::min<std::chrono::system_clock::duration>(
      context->deadline() - std::chrono::system_clock::now(), RequestLog::kWindow);
  const RequestLog::Claim claim =
      state.requests.Begin(key, RequestDigest(*replay.request), now, now + left);
  if (claim.kind != RequestLog::Claim::Kind::kRun && replay.authorize != nullptr) {
    const Status allowed = replay.authorize(call);
    const bool gone =
        claim.kind == RequestLog::Claim::Kind::kRepeat && allowed.code() == StatusCode::kNotFound;
    if (!allowed.ok() && !gone) return ToCallStatus(context, call, allowed);
  }
  switch (claim.kind) {
    case RequestLog::Claim::Kind::kRepeat:
      spdlog::info("request={} method={} request_id={}: a repeat, answered from the request log",
                   EscapeForLog(call.request_id), call.method, EscapeForLog(request_id));
      if (!response->ParseFromString(claim.answer)) {
        return {grpc::StatusCode::INTERNAL, "the stored answer does not parse"};
      }
      return grpc::Status::OK;
    case RequestLog::Claim::Kind::kConflict:
      return {
          grpc::StatusCode::INVALID_ARGUMENT,
          "request_id was used by a different request of this caller in the last " +
              std::to_string(
                  std::chrono::duration_cast<std::chrono::minutes>(RequestLog::kWindow).count()) +
              " minutes: give each new request a new request_id (nothing was applied)"};
    case RequestLog::Claim::Kind::kTimedOut:
      return {grpc::StatusCode::ABORTED,
              "a call with the same request_id is still running; its answer was not ready "
              "before this call's deadline"};
    case RequestLog::Claim::Kind::kRun:
      break;
  }
  const Status status = work();
  state.requests.End(
      key, status.ok() ? std::optional<std::string>(response->SerializeAsString()) : std::nullopt,
      RequestLog::Clock::now());
  return ToCallStatus(context, call, status);
}

namespace {

// A unary call's work that answers in gRPC's terms already (its status converted by ToCallStatus
// or made by RunOnce).
using GrpcWork = std::function<grpc::Status(CallInfo&, WorkerContext&)>;

// Both RunUnary: the checks, the request's bytes, the hand-over to the pool, `work`, the end.
grpc::ServerUnaryReactor* StartUnary(ServerState& state, grpc::CallbackServerContext* context,
                                     std::string_view method, Right right,
                                     const google::protobuf::Message& request, GrpcWork work) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  auto call = std::make_shared<CallInfo>();
  grpc::Status status = BeginCall(state, context, method, right, call.get());
  // Held until the work ends (a std::function is copyable, a reservation is not).
  std::shared_ptr<ByteBudget::Reservation> bytes;
  if (status.ok()) {
    std::optional<ByteBudget::Reservation> reserved =
        state.pending_request_bytes.Reserve(request.ByteSizeLong());
    if (reserved.has_value()) {
      bytes = std::make_shared<ByteBudget::Reservation>(std::move(*reserved));
    } else {
      context->AddTrailingMetadata(kPushback, std::to_string(state.config.retry_after_ms));
      status = {grpc::StatusCode::RESOURCE_EXHAUSTED,
                "the server holds " + std::to_string(state.config.grpc.pending_requests_mb) +
                    " MiB of requests not yet answered (grpc.pending_requests_mb); retry after " +
                    std::to_string(state.config.retry_after_ms) + " ms"};
    }
  }
  if (status.ok()) {
    const bool queued = state.pool->TrySubmit(
        [&state, context, reactor, call, work, bytes](WorkerContext& worker) mutable {
          call->queue_ms = MillisecondsSince(call->start);
          grpc::Status result = CheckStillWanted(context);
          if (result.ok()) result = work(*call, worker);
          bytes.reset();
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

}  // namespace

grpc::ServerUnaryReactor* RunUnary(ServerState& state, grpc::CallbackServerContext* context,
                                   std::string_view method, Right right, Replay replay,
                                   google::protobuf::Message* response, UnaryWork work) {
  const google::protobuf::Message& request = *replay.request;
  return StartUnary(state, context, method, right, request,
                    [&state, context, replay = std::move(replay), response, work = std::move(work)](
                        CallInfo& call, WorkerContext& worker) {
                      return RunOnce(state, context, call, replay, response,
                                     [&] { return work(call, worker); });
                    });
}

grpc::ServerUnaryReactor* RunUnary(ServerState& state, grpc::CallbackServerContext* context,
                                   std::string_view method, Right right,
                                   const google::protobuf::Message& request, UnaryWork work) {
  return StartUnary(state, context, method, right, request,
                    [context, work = std::move(work)](CallInfo& call, WorkerContext& worker) {
                      return ToCallStatus(context, call, work(call, worker));
                    });
}

namespace {

// CheckMapOwner and CheckGroupOwner: `owner` is what the placement table says of the map or group
// `what` ("map 'x'", "group 'y'"), `entry` how to list it.
Status CheckOwner(const ServerState& state, const std::optional<std::string>& owner,
                  const std::string& what, const std::string& entry) {
  const std::string& self = state.config.shard.name;
  if (owner == self) return Status::Ok();
  if (!owner.has_value()) {
    return Status::FailedPrecondition(what + " is not in the placement table (" +
                                      state.config.shard.placement_file + "): add `" + entry +
                                      " <shard>;`, then reload nginx and the servers");
  }
  return Status::FailedPrecondition(what + " belongs to shard '" + *owner +
                                    "', not to this server (shard '" + self + "')");
}

}  // namespace

Status CheckMapOwner(const ServerState& state, const std::string& map) {
  const std::shared_ptr<const PlacementTable> placement = state.placement();
  if (placement == nullptr) return Status::Ok();
  return CheckOwner(state, placement->OwnerOf(map), "map '" + map + "'", map);
}

Status CheckGroupOwner(const ServerState& state, const std::string& group) {
  const std::shared_ptr<const PlacementTable> placement = state.placement();
  if (placement == nullptr) return Status::Ok();
  return CheckOwner(state, placement->OwnerOfGroup(group), "group '" + group + "'",
                    PlacementTable::kGroupPrefix + group);
}

}  // namespace recog::server
