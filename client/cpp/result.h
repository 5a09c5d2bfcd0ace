// Result<T>: what the client's calls return — a value, or the grpc::Status of the failure.
//
// Every error of the client library is a grpc::Status with a canonical code: the server's
// (proto/recognition/v1/place.proto lists them) or one made on the client (INVALID_ARGUMENT for
// bad options or frames, NOT_FOUND for a missing file, DATA_LOSS for a download whose checksum
// does not match, ...). Calls that produce no value return the grpc::Status itself.
#pragma once

#include <cassert>
#include <utility>
#include <variant>

#include <grpcpp/support/status.h>

namespace recog::client {

// Either a value or a non-OK grpc::Status. Accessing the value of an error is a programming error.
template <typename T>
class [[nodiscard]] Result {
 public:
  Result(grpc::Status status) : data_(std::move(status)) {  // NOLINT: implicit by design
    assert(!std::get<grpc::Status>(data_).ok() && "Result built from an OK status");
    if (std::get<grpc::Status>(data_).ok()) {
      data_ = grpc::Status(grpc::StatusCode::INTERNAL, "Result built from an OK status");
    }
  }
  Result(T value) : data_(std::move(value)) {}  // NOLINT: implicit by design

  bool ok() const { return std::holds_alternative<T>(data_); }
  // OK when there is a value.
  grpc::Status status() const { return ok() ? grpc::Status::OK : std::get<grpc::Status>(data_); }

  T& value() & { return std::get<T>(data_); }
  const T& value() const& { return std::get<T>(data_); }
  T&& value() && { return std::get<T>(std::move(data_)); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  T&& operator*() && { return std::move(*this).value(); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }

 private:
  std::variant<grpc::Status, T> data_;
};

}  // namespace recog::client
