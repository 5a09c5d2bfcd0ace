// The one place where core statuses become gRPC statuses.
//
// Every code of core's Status maps to the canonical gRPC code of the same name. The two that say
// the server itself failed are sanitised: DATA_LOSS (corrupt stored data) and INTERNAL (a bug)
// reach the client with their code and a message naming the request id only; the details go to
// the server log with the request id. An RPC's core status reaches this through ToCallStatus
// (server/services/call.h), once, where the call ends.
#pragma once

#include <string_view>

#include <grpcpp/support/status.h>

#include "core/common/status.h"
#include "wire/grpc_code_names.h"  // GrpcCodeName

namespace recog::server {

// The gRPC code for a core status code.
grpc::StatusCode ToGrpcCode(StatusCode code);

// The gRPC status for a core status; `request_id` goes into the log line of sanitised errors.
grpc::Status ToGrpcStatus(const Status& status, std::string_view request_id = {});

}  // namespace recog::server
