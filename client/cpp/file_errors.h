// The status of a local file the client library cannot write (a download, a checkpoint).
// Internal to the client library.
#pragma once

#include <string>

#include <grpcpp/support/status.h>

namespace recog::client::internal {

// FAILED_PRECONDITION naming the file and, when given, why.
inline grpc::Status CannotWrite(const std::string& path, const std::string& why = {}) {
  return {grpc::StatusCode::FAILED_PRECONDITION,
          "cannot write '" + path + "'" + (why.empty() ? "" : ": " + why)};
}

}  // namespace recog::client::internal
