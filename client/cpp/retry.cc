#include "client/cpp/retry.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <random>
#include <string_view>

namespace recog::client::internal {

std::optional<std::chrono::milliseconds> RetryAfter(const grpc::ClientContext& context) {
  const auto& trailers = context.GetServerTrailingMetadata();
  const auto it = trailers.find("retry-after-ms");
  if (it == trailers.end()) return std::nullopt;
  const std::string_view text(it->second.data(), it->second.size());
  int64_t ms = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), ms);
  if (error != std::errc() || end != text.data() + text.size() || ms < 0) return std::nullopt;
  return std::chrono::milliseconds(ms);
}

bool ShouldRetry(const grpc::Status& status, CallKind kind, bool sent,
                 std::optional<std::chrono::milliseconds> retry_after) {
  switch (status.error_code()) {
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
      return retry_after.has_value();  // refused from a full queue, before anything ran
    case grpc::StatusCode::UNAVAILABLE:
      return kind == CallKind::kRepeatable || !sent;
    default:
      return false;
  }
}

std::chrono::milliseconds RetryDelay(const RetryPolicy& policy, int retry, double unit,
                                     std::optional<std::chrono::milliseconds> retry_after) {
  const double initial = double(policy.initial_backoff.count());
  const double cap = double(policy.max_backoff.count());
  const double backoff = std::min(cap, initial * std::pow(policy.multiplier, retry - 1));
  const double factor = 1.0 - policy.jitter + 2.0 * policy.jitter * unit;
  auto delay = std::chrono::milliseconds(std::llround(backoff * factor));
  if (retry_after.has_value()) delay = std::max(delay, *retry_after);
  return delay;
}

double UnitRandom() {
  thread_local std::mt19937_64 generator{std::random_device{}()};
  return std::uniform_real_distribution<double>(0.0, 1.0)(generator);
}

}  // namespace recog::client::internal
