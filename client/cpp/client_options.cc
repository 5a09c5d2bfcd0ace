#include "client/cpp/client_options.h"

#include <algorithm>
#include <cctype>

namespace recog::client {
namespace {

constexpr uint32_t kMinMessageBytes = 1u << 20;
constexpr uint32_t kMaxMessageBytes = 0x7fffffffu;
constexpr uint32_t kMaxFramesInFlight = 1024;

grpc::Status Invalid(const std::string& message) {
  return {grpc::StatusCode::INVALID_ARGUMENT, message};
}

bool VisibleAscii(const std::string& text) {
  return std::all_of(text.begin(), text.end(), [](char c) { return c > ' ' && c < 127; });
}

grpc::Status ValidateTls(const TlsOptions& tls) {
  if (!tls.enabled && (!tls.ca_file.empty() || !tls.cert_file.empty() || !tls.key_file.empty())) {
    return Invalid("tls.ca_file, tls.cert_file and tls.key_file need tls.enabled");
  }
  if (tls.cert_file.empty() != tls.key_file.empty()) {
    return Invalid("tls.cert_file and tls.key_file go together (mutual TLS) or not at all");
  }
  return grpc::Status::OK;
}

}  // namespace

grpc::Status ClientOptions::Validate() const {
  if (target.empty()) return Invalid("target must not be empty");
  if (grpc::Status status = ValidateTls(tls); !status.ok()) return status;
  if (!token.empty() && !token_file.empty()) {
    return Invalid("token and token_file exclude each other");
  }
  if (!VisibleAscii(token)) {
    return Invalid("token must consist of visible ASCII characters (no spaces)");
  }
  const bool shard_ok = shard.size() <= 64 && std::all_of(shard.begin(), shard.end(), [](char c) {
                          return std::isalnum(static_cast<unsigned char>(c)) || c == '_';
                        });
  if (!shard_ok) return Invalid("shard must have at most 64 characters of [A-Za-z0-9_]");
  if (deadline.count() < 1) {
    return Invalid("deadline must be at least 1 ms, got " + std::to_string(deadline.count()));
  }
  if (transfer_deadline.count() < 1) {
    return Invalid("transfer_deadline must be at least 1 ms, got " +
                   std::to_string(transfer_deadline.count()));
  }
  if (max_message_bytes < kMinMessageBytes || max_message_bytes > kMaxMessageBytes) {
    return Invalid("max_message_bytes must be between 1 MiB and 2 GiB - 1, got " +
                   std::to_string(max_message_bytes));
  }
  if (max_frames_in_flight < 1 || max_frames_in_flight > kMaxFramesInFlight) {
    return Invalid("max_frames_in_flight must be between 1 and " +
                   std::to_string(kMaxFramesInFlight) + ", got " +
                   std::to_string(max_frames_in_flight));
  }
  return grpc::Status::OK;
}

}  // namespace recog::client
