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
#pragma once

#include <chrono>
#include <functional>
#include <string>
#include <string_view>

#include <google/protobuf/message.h>
#include <grpcpp/grpcpp.h>

#include "server/auth/token_auth.h"
#include "server/services/server_state.h"

namespace recog::server {

struct CallInfo {
  std::string method;      // "/recognition.v1.PlaceRecognition/QueryPlace"
  std::string request_id;  // the client's x-request-id, or one made up here
  Caller caller;
  std::chrono::steady_clock::time_point start;
  std::string map;      // the place map the call is about, for the log (set by the handler)
  double queue_ms = 0;  // time the call waited for a worker
};

// Request id (sent back as `x-request-id` trailing metadata), authentication (`right`) and
// readiness. Not OK: finish the call with it.
grpc::Status BeginCall(ServerState& state, grpc::CallbackServerContext* context,
                       std::string_view method, Right right, CallInfo* call);
// Metrics and the log line of a finished call (or of one stream message).
void EndCall(ServerState& state, const CallInfo& call, const grpc::Status& status);

// Updates the queue-depth and busy-worker gauges (sampled whenever a call or frame ends).
void SampleWorkerGauges(ServerState& state);

// Not OK when the call should not run: its client cancelled or its deadline passed.
grpc::Status CheckStillWanted(grpc::CallbackServerContext* context);

// RESOURCE_EXHAUSTED with the retry hint (`grpc-retry-pushback-ms`) added to the call's trailing
// metadata.
grpc::Status Busy(ServerState& state, grpc::CallbackServerContext* context);

// `status` unchanged; when it is RESOURCE_EXHAUSTED, a pushback of -1 is added to the call's
// trailing metadata so that gRPC does not retry it (for refusals that a retry cannot cure).
grpc::Status Final(grpc::CallbackServerContext* context, grpc::Status status);

// OK for an empty or valid request_id (RequestLog::ValidRequestId), INVALID_ARGUMENT otherwise.
grpc::Status CheckRequestId(const std::string& request_id);

// Runs `work` (which fills `response`) at most once per (caller, method, `request_id`) within the
// request log's window: a repeat gets the first call's response without running `work`, and a
// repeat that arrives while the first still runs waits for it (ABORTED when the call's deadline
// passes first). Only successful answers are remembered; a repeat of a failed call runs again.
// An empty `request_id` just runs `work`; an invalid one is INVALID_ARGUMENT.
grpc::Status RunOnce(ServerState& state, grpc::CallbackServerContext* context, const CallInfo& call,
                     const std::string& request_id, google::protobuf::Message* response,
                     const std::function<grpc::Status()>& work);

// OK when this server serves place map `map`: always without a shard configuration; with one,
// when the placement table gives the map to this shard. FAILED_PRECONDITION naming the owner (or
// saying that the table does not list the map) otherwise.
grpc::Status CheckMapOwner(const ServerState& state, const std::string& map);
// The same for every map of `group`: the placement table must place the group (`group:NAME`) on
// this shard, so that its maps are created and searched here only.
grpc::Status CheckGroupOwner(const ServerState& state, const std::string& group);

// The work of a unary call, on a worker, with that worker's context.
using UnaryWork = std::function<grpc::Status(CallInfo&, WorkerContext&)>;
grpc::ServerUnaryReactor* RunUnary(ServerState& state, grpc::CallbackServerContext* context,
                                   std::string_view method, Right right, UnaryWork work);
// A mutating call: RunUnary with `work` inside RunOnce (`response` lives as long as the call).
grpc::ServerUnaryReactor* RunUnary(ServerState& state, grpc::CallbackServerContext* context,
                                   std::string_view method, Right right, std::string request_id,
                                   google::protobuf::Message* response, UnaryWork work);

}  // namespace recog::server
