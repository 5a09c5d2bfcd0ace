// What every RPC does around its work: a request id, authentication, the readiness check, the
// hand-over to the worker pool, metrics and one log line.
//
// RunUnary is the whole life of a unary call: checks on the gRPC thread (cheap), then `work` on a
// worker; a full queue answers RESOURCE_EXHAUSTED with gRPC's `grpc-retry-pushback-ms` trailer
// (gRFC A6: gRPC's own retry waits that long), a call whose client cancelled or whose deadline
// passed while it waited is finished without running `work`. Any other RESOURCE_EXHAUSTED (disk
// full, a map full, a model too large) is final and says so with a pushback of -1, which stops
// gRPC's retries. Mutating calls pass their request's `request_id` and response: RunOnce answers
// a repeat from the server's RequestLog (server/runtime/request_log.h).
// Streaming reactors use BeginCall/EndCall and the pool themselves.
//
// Handlers speak core's Status; it becomes the call's gRPC status in one place, ToCallStatus,
// where the call ends (RunUnary, RunOnce, a stream reactor's end). Only what is gRPC's own stays
// grpc::Status here: the refusals that carry a retry hint (Busy, a server starting or draining),
// a client gone or out of time, and the request log's ABORTED.
#pragma once

#include <chrono>
#include <functional>
#include <string>
#include <string_view>

#include <google/protobuf/message.h>
#include <grpcpp/grpcpp.h>

#include "server/api/frame_decoding.h"
#include "server/auth/token_auth.h"
#include "server/services/server_state.h"

namespace recog::server {

struct CallInfo {
  std::string method;  // "/recognition.v1.PlaceRecognition/QueryPlace"
  // The client's x-request-id when it is 1 to kMaxCallIdBytes printable ASCII characters without
  // spaces, else one made up here (the client's is then logged, escaped): it is sent back as
  // trailing metadata and stands in log lines, so nothing else may pass.
  std::string request_id;
  Caller caller;
  std::chrono::steady_clock::time_point start;
  std::string map;      // the place map the call is about, for the log (set by the handler)
  double queue_ms = 0;  // time the call waited for a worker
};

// The longest x-request-id kept (CallInfo::request_id).
inline constexpr size_t kMaxCallIdBytes = 64;
// Whether `id` may stand as a call's request id: 1 to kMaxCallIdBytes characters '!' to '~'.
bool ValidCallId(std::string_view id);

// Request id (sent back as `x-request-id` trailing metadata), authentication (`right`) and
// readiness. Not OK: finish the call with it.
grpc::Status BeginCall(ServerState& state, grpc::CallbackServerContext* context,
                       std::string_view method, Right right, CallInfo* call);
// Metrics and the log line of a finished call (or of one stream message).
void EndCall(ServerState& state, const CallInfo& call, const grpc::Status& status);

// Updates the queue-depth and busy-worker gauges (sampled whenever a call or frame ends).
void SampleWorkerGauges(ServerState& state);

// The images one call may decode: grpc.decode_memory_mb (PixelBudget).
PixelBudget CallPixelBudget(const ServerState& state);

// Not OK when the call should not run: its client cancelled or its deadline passed.
grpc::Status CheckStillWanted(grpc::CallbackServerContext* context);

// RESOURCE_EXHAUSTED with the retry hint (`grpc-retry-pushback-ms`) added to the call's trailing
// metadata.
grpc::Status Busy(ServerState& state, grpc::CallbackServerContext* context);

// The gRPC status that `call` ends with for a handler's core `status` (ToGrpcStatus with the
// call's request id). A core RESOURCE_EXHAUSTED is a refusal that a retry cannot cure (the ones a
// retry can, like Busy, are made in gRPC's terms): a pushback of -1 is added to the call's
// trailing metadata so that gRPC does not retry it.
grpc::Status ToCallStatus(grpc::CallbackServerContext* context, const CallInfo& call,
                          const Status& status);

// OK for an empty or valid request_id (RequestLog::ValidRequestId), INVALID_ARGUMENT otherwise.
Status CheckRequestId(const std::string& request_id);

// What the request log (RunOnce) needs of a mutating call besides its work.
struct Replay {
  std::string request_id;  // the request's request_id; "" = no protection against repeats
  // The whole request, digested: a request_id reused with another request is refused instead of
  // answered. Not null when request_id is set.
  const google::protobuf::Message* request = nullptr;
  // The caller's rights on what the request names (its map: the checks its work starts with),
  // run before a repeat is answered or a reuse refused, so that the log never answers what the
  // caller may no longer reach. For a repeat, NOT_FOUND is not an error: the map may be gone
  // because of the very call repeated. Null: BeginCall's check of the method's right suffices.
  std::function<Status(CallInfo&)> authorize;
};

// Runs `work` (which fills `response`) at most once per (caller, method, request_id) within the
// request log's window: a repeat (the same request) gets the first call's response without
// running `work`, and a repeat that arrives while the first still runs waits for it (ABORTED when
// the call's deadline passes first). A different request with a request_id in use is
// INVALID_ARGUMENT, and changes nothing. Only successful answers are remembered; a repeat of a
// failed call runs again. An empty request_id just runs `work`; an invalid one is
// INVALID_ARGUMENT. The answer is the call's gRPC status (`work`'s through ToCallStatus).
grpc::Status RunOnce(ServerState& state, grpc::CallbackServerContext* context, CallInfo& call,
                     const Replay& replay, google::protobuf::Message* response,
                     const std::function<Status()>& work);

// OK when this server serves place map `map`: always without a shard configuration; with one,
// when the placement table gives the map to this shard. FAILED_PRECONDITION naming the owner (or
// saying that the table does not list the map) otherwise.
Status CheckMapOwner(const ServerState& state, const std::string& map);
// The same for every map of `group`: the placement table must place the group (`group:NAME`) on
// this shard, so that its maps are created and searched here only.
Status CheckGroupOwner(const ServerState& state, const std::string& group);

// The work of a unary call, on a worker, with that worker's context; RunUnary turns its status
// into the call's (ToCallStatus).
using UnaryWork = std::function<Status(CallInfo&, WorkerContext&)>;
// `request` (which lives as long as the call) is charged to the server's pending request bytes
// from the hand-over to the pool until the work ends: RESOURCE_EXHAUSTED with the retry hint when
// they would pass grpc.pending_requests_mb.
grpc::ServerUnaryReactor* RunUnary(ServerState& state, grpc::CallbackServerContext* context,
                                   std::string_view method, Right right,
                                   const google::protobuf::Message& request, UnaryWork work);
// A mutating call: RunUnary of replay.request with `work` inside RunOnce (`response` lives as long
// as the call).
grpc::ServerUnaryReactor* RunUnary(ServerState& state, grpc::CallbackServerContext* context,
                                   std::string_view method, Right right, Replay replay,
                                   google::protobuf::Message* response, UnaryWork work);

}  // namespace recog::server
