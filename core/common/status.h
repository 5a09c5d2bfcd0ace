// Status and StatusOr: how core reports failures caused by its input.
//
// Anything in core that can fail because of data it was given (a file, an image, a descriptor
// matrix, a parameter) returns a Status or a StatusOr<T> instead of throwing or aborting. The codes
// follow the canonical gRPC set so that the server can map them one-to-one; the message is a single
// sentence meant for the user ("vocabulary file 'x.rvoc' is truncated: expected 1200 bytes, got
// 10").
#pragma once

#include <cassert>
#include <string>
#include <string_view>
#include <utility>
#include <variant>

namespace recog {

enum class StatusCode {
  kOk = 0,
  kInvalidArgument,     // the input itself is wrong (bad parameter, wrong descriptor length)
  kNotFound,            // a named file/map/object does not exist
  kAlreadyExists,       // creating something that is already there
  kFailedPrecondition,  // the input is fine but does not fit the current state (vocabulary
                        // mismatch)
  kResourceExhausted,   // a quota, queue or size limit was reached
  kUnavailable,         // temporarily unable to serve
  kDataLoss,            // stored data is corrupt or truncated (bad checksum, short file)
  kInternal,            // a bug or an unexpected failure of a dependency
  kUnauthenticated,     // the caller did not prove who it is (no, malformed or unknown credentials)
  kPermissionDenied,    // the caller is known but may not do this
};

// Name of a code, e.g. "INVALID_ARGUMENT".
std::string_view StatusCodeName(StatusCode code);

class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

  static Status Ok() { return Status(); }
  static Status InvalidArgument(std::string m) {
    return {StatusCode::kInvalidArgument, std::move(m)};
  }
  static Status NotFound(std::string m) { return {StatusCode::kNotFound, std::move(m)}; }
  static Status AlreadyExists(std::string m) { return {StatusCode::kAlreadyExists, std::move(m)}; }
  static Status FailedPrecondition(std::string m) {
    return {StatusCode::kFailedPrecondition, std::move(m)};
  }
  static Status ResourceExhausted(std::string m) {
    return {StatusCode::kResourceExhausted, std::move(m)};
  }
  static Status Unavailable(std::string m) { return {StatusCode::kUnavailable, std::move(m)}; }
  static Status DataLoss(std::string m) { return {StatusCode::kDataLoss, std::move(m)}; }
  static Status Internal(std::string m) { return {StatusCode::kInternal, std::move(m)}; }
  static Status Unauthenticated(std::string m) {
    return {StatusCode::kUnauthenticated, std::move(m)};
  }
  static Status PermissionDenied(std::string m) {
    return {StatusCode::kPermissionDenied, std::move(m)};
  }

  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }
  // "INVALID_ARGUMENT: <message>", or "OK".
  std::string ToString() const;

  // The same failure with `context` before its message, "context: message" (e.g. the file or the
  // map it happened in); the second form also gives it another code (a parse error found in a
  // stored file is DATA_LOSS). An OK status stays OK.
  Status WithContext(std::string_view context) const;
  Status WithContext(std::string_view context, StatusCode code) const;

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

// Either a value or a non-OK Status. Accessing the value of an error is a programming error.
template <typename T>
class [[nodiscard]] StatusOr {
 public:
  StatusOr(Status status) : data_(std::move(status)) {  // NOLINT: implicit by design
    assert(!std::get<Status>(data_).ok() && "StatusOr built from an OK status");
  }
  StatusOr(T value) : data_(std::move(value)) {}  // NOLINT: implicit by design

  bool ok() const { return std::holds_alternative<T>(data_); }
  Status status() const { return ok() ? Status::Ok() : std::get<Status>(data_); }

  T& value() & { return std::get<T>(data_); }
  const T& value() const& { return std::get<T>(data_); }
  T&& value() && { return std::get<T>(std::move(data_)); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  T&& operator*() && { return std::move(*this).value(); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }

 private:
  std::variant<Status, T> data_;
};

}  // namespace recog

#define RECOG_STATUS_CONCAT_INNER(a, b) a##b
#define RECOG_STATUS_CONCAT(a, b) RECOG_STATUS_CONCAT_INNER(a, b)

// Returns the status from the enclosing function when `expr` is not OK.
#define RECOG_RETURN_IF_ERROR(expr)                \
  do {                                             \
    ::recog::Status recog_status_ = (expr);        \
    if (!recog_status_.ok()) return recog_status_; \
  } while (false)

// RECOG_ASSIGN_OR_RETURN(auto x, MaybeX()): unwraps a StatusOr or returns its error.
#define RECOG_ASSIGN_OR_RETURN(lhs, expr) \
  RECOG_ASSIGN_OR_RETURN_IMPL(RECOG_STATUS_CONCAT(recog_statusor_, __LINE__), lhs, expr)
#define RECOG_ASSIGN_OR_RETURN_IMPL(tmp, lhs, expr) \
  auto tmp = (expr);                                \
  if (!tmp.ok()) return tmp.status();               \
  lhs = std::move(tmp).value()
