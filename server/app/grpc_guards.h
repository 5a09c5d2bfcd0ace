// What recogd adds around gRPC's own handling of calls, where no service of its own runs:
//
//  - Server reflection (gRPC's plugin, which has no notion of tokens) answers only callers with a
//    valid token when tokens are on: the reflection guard cancels any other reflection call as
//    soon as its metadata arrives, before a schema is sent. Without a token file it is open, like
//    every call.
//  - The lines libprotobuf and gRPC's core write themselves, one per bad request (a string field
//    of invalid UTF-8, which gRPC 1.51 answers itself with UNIMPLEMENTED and no message; a
//    compressed request, refused), go to the server's log at most once every 10 s from each
//    place in their code, saying how many were not shown, instead of one line each on stderr.
#pragma once

#include <memory>

#include <grpcpp/support/server_interceptor.h>

#include "server/auth/token_auth.h"

namespace recog::server {

// For grpc::ServerBuilder::experimental().SetInterceptorCreators: the reflection guard of
// `auth` (which must outlive the server).
std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> MakeReflectionGuardFactory(
    const TokenAuthenticator* auth);

// Routes libprotobuf's and gRPC's log lines to spdlog, throttled (see the header comment).
// Process-wide; idempotent.
void ThrottleLibraryLogs();

}  // namespace recog::server
