#include "server/runtime/request_log.h"

#include <algorithm>

namespace recog::server {

RequestLog::RequestLog(size_t capacity, Clock::duration window)
    : capacity_(capacity), window_(window) {}

bool RequestLog::ValidRequestId(std::string_view request_id) {
  return !request_id.empty() && request_id.size() <= kMaxRequestIdBytes &&
         std::all_of(request_id.begin(), request_id.end(),
                     [](char c) { return c >= ' ' && c <= '~'; });
}

RequestLog::Claim RequestLog::Begin(const std::string& key, const std::string& digest,
                                    Clock::time_point now, Clock::time_point wait_until) {
  if (capacity_ == 0) return {};
  std::unique_lock lock(mutex_);
  ExpireLocked(now);
  for (;;) {
    const auto it = entries_.find(key);
    if (it == entries_.end()) {
      entries_[key].digest = digest;
      return {};
    }
    if (it->second.digest != digest) return {Claim::Kind::kConflict, {}};
    if (!it->second.running) return {Claim::Kind::kRepeat, it->second.answer};
    if (ended_.wait_until(lock, wait_until) == std::cv_status::timeout && entries_.contains(key) &&
        entries_.at(key).running) {
      return {Claim::Kind::kTimedOut, {}};
    }
  }
}

void RequestLog::End(const std::string& key, std::optional<std::string> answer,
                     Clock::time_point now) {
  if (capacity_ == 0) return;
  {
    std::lock_guard lock(mutex_);
    const auto it = entries_.find(key);
    if (it == entries_.end() || !it->second.running) return;  // not a call Begin let run
    if (!answer.has_value()) {
      entries_.erase(it);
    } else {
      Entry& entry = it->second;
      entry.running = false;
      entry.answer = std::move(*answer);
      entry.stored_at = now;
      entry.order = order_.insert(order_.end(), key);
      ExpireLocked(now);
    }
  }
  ended_.notify_all();
}

size_t RequestLog::size() const {
  std::lock_guard lock(mutex_);
  return order_.size();
}

void RequestLog::ExpireLocked(Clock::time_point now) {
  while (!order_.empty()) {
    const auto it = entries_.find(order_.front());
    if (order_.size() <= capacity_ && now - it->second.stored_at < window_) break;
    entries_.erase(it);
    order_.pop_front();
  }
}

}  // namespace recog::server
