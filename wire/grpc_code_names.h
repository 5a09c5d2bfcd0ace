// GrpcCodeName: the name of a gRPC status code as the gRPC documentation spells it
// ("INVALID_ARGUMENT"), for logs, metrics and one-line errors of the server and the clients.
// (gRPC's C++ API has no such function.)
#pragma once

#include <string_view>

#include <grpcpp/support/status.h>

namespace recog {

std::string_view GrpcCodeName(grpc::StatusCode code);

}  // namespace recog
