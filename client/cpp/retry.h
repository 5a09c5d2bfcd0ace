// The retry rule of ClientOptions (see client_options.h), as pure functions, so that it can be
// tested without a server: which failures are retried, and how long to wait before the next try.
// Internal to the client library.
#pragma once

#include <chrono>
#include <optional>

#include <grpcpp/grpcpp.h>

#include "client/cpp/client_options.h"

namespace recog::client::internal {

// Whether sending a call twice could do something twice on the server.
enum class CallKind {
  kRepeatable,  // reads, relocalisation queries, recognition, downloads
  kChanging,    // creates, deletes, added frames, uploads
};

// The server's `retry-after-ms` trailer of a finished call, when there is one.
std::optional<std::chrono::milliseconds> RetryAfter(const grpc::ClientContext& context);

// Whether a failed attempt may be tried again: `sent` is false when the attempt failed before
// anything was sent (no connection), `retry_after` is the server's hint.
bool ShouldRetry(const grpc::Status& status, CallKind kind, bool sent,
                 std::optional<std::chrono::milliseconds> retry_after);

// The delay before retry `retry` (1 for the first), for a uniform random number `unit` in
// [0, 1): backoff, jitter, then at least `retry_after`.
std::chrono::milliseconds RetryDelay(const RetryPolicy& policy, int retry, double unit,
                                     std::optional<std::chrono::milliseconds> retry_after);

// A uniform random number in [0, 1) from a per-thread generator.
double UnitRandom();

}  // namespace recog::client::internal
