#include "server/api/status_mapping.h"

#include <spdlog/spdlog.h>

#include "core/common/text.h"

namespace recog::server {

grpc::StatusCode ToGrpcCode(StatusCode code) {
  switch (code) {
    case StatusCode::kOk:
      return grpc::StatusCode::OK;
    case StatusCode::kInvalidArgument:
      return grpc::StatusCode::INVALID_ARGUMENT;
    case StatusCode::kNotFound:
      return grpc::StatusCode::NOT_FOUND;
    case StatusCode::kAlreadyExists:
      return grpc::StatusCode::ALREADY_EXISTS;
    case StatusCode::kFailedPrecondition:
      return grpc::StatusCode::FAILED_PRECONDITION;
    case StatusCode::kResourceExhausted:
      return grpc::StatusCode::RESOURCE_EXHAUSTED;
    case StatusCode::kUnavailable:
      return grpc::StatusCode::UNAVAILABLE;
    case StatusCode::kUnauthenticated:
      return grpc::StatusCode::UNAUTHENTICATED;
    case StatusCode::kPermissionDenied:
      return grpc::StatusCode::PERMISSION_DENIED;
    case StatusCode::kDataLoss:
      return grpc::StatusCode::DATA_LOSS;
    case StatusCode::kInternal:
      return grpc::StatusCode::INTERNAL;
  }
  return grpc::StatusCode::INTERNAL;
}

grpc::Status ToGrpcStatus(const Status& status, std::string_view request_id) {
  const grpc::StatusCode code = ToGrpcCode(status.code());
  if (code == grpc::StatusCode::OK) return grpc::Status::OK;
  if (code == grpc::StatusCode::INTERNAL || code == grpc::StatusCode::DATA_LOSS) {
    const char* what =
        code == grpc::StatusCode::DATA_LOSS ? "corrupt stored data" : "internal error";
    spdlog::error("request={} {}: {}", EscapeForLog(request_id), what,
                  EscapeForLog(status.ToString(), 1024));
    return {code, std::string(what) + " (request " + std::string(request_id) +
                      "; the server log has the details)"};
  }
  return {code, status.message()};
}

}  // namespace recog::server
