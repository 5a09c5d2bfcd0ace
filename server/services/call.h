// What every RPC does around its work: a request id, authentication, the readiness check, the
// hand-over to the worker pool, metrics and one log line.
//
// RunUnary is the whole life of a unary call: checks on the gRPC thread (cheap), then `work` on a
// worker; a full queue answers RESOURCE_EXHAUSTED with a `retry-after-ms` trailer, a call whose
// client cancelled or whose deadline passed while it waited is finished without running `work`.
// Streaming reactors use BeginCall/EndCall and the pool themselves.
#pragma once

#include <chrono>
#include <functional>
#include <string>
#include <string_view>

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

// RESOURCE_EXHAUSTED with the retry hint added to the call's trailing metadata.
grpc::Status Busy(ServerState& state, grpc::CallbackServerContext* context);

// OK when this server serves place map `map`: always without a shard configuration; with one,
// when the placement table gives the map to this shard. FAILED_PRECONDITION naming the owner (or
// saying that the table does not list the map) otherwise.
grpc::Status CheckMapOwner(const ServerState& state, const std::string& map);

// The work of a unary call, on a worker, with that worker's context.
using UnaryWork = std::function<grpc::Status(CallInfo&, WorkerContext&)>;
grpc::ServerUnaryReactor* RunUnary(ServerState& state, grpc::CallbackServerContext* context,
                                   std::string_view method, Right right, UnaryWork work);

}  // namespace recog::server
