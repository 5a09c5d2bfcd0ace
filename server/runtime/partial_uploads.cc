#include "server/runtime/partial_uploads.h"

#include <algorithm>
#include <utility>

namespace recog::server {

PartialUploads::PartialUploads(uint64_t max_bytes, Clock::duration keep_for)
    : max_bytes_(max_bytes), keep_for_(keep_for) {}

void PartialUploads::ExpireLocked(Clock::time_point now) {
  std::erase_if(entries_, [&](const auto& entry) {
    if (now - entry.second.at < keep_for_) return false;
    kept_bytes_ -= entry.second.bytes.size();
    return true;
  });
}

void PartialUploads::MakeRoomLocked(Clock::time_point now, uint64_t bytes) {
  ExpireLocked(now);
  while (!entries_.empty() &&
         (kept_bytes_ + bytes > max_bytes_ || entries_.size() >= kMaxEntries)) {
    auto oldest =
        std::min_element(entries_.begin(), entries_.end(),
                         [](const auto& a, const auto& b) { return a.second.at < b.second.at; });
    kept_bytes_ -= oldest->second.bytes.size();
    entries_.erase(oldest);
  }
}

void PartialUploads::KeepInterrupted(const Key& key, std::string bytes, Clock::time_point now) {
  if (bytes.empty() || bytes.size() >= key.size_bytes || bytes.size() > max_bytes_) return;
  std::lock_guard lock(mutex_);
  if (auto old = entries_.find(key); old != entries_.end()) {
    kept_bytes_ -= old->second.bytes.size();
    entries_.erase(old);
  }
  MakeRoomLocked(now, bytes.size());
  kept_bytes_ += bytes.size();
  entries_[key] = Entry{std::move(bytes), std::nullopt, now};
}

std::optional<std::string> PartialUploads::TakeInterrupted(const Key& key, Clock::time_point now) {
  std::lock_guard lock(mutex_);
  ExpireLocked(now);
  auto it = entries_.find(key);
  if (it == entries_.end() || it->second.bytes.empty()) return std::nullopt;
  std::string bytes = std::move(it->second.bytes);
  kept_bytes_ -= bytes.size();
  entries_.erase(it);
  return bytes;
}

void PartialUploads::RecordStored(const Key& key, Stored stored, Clock::time_point now) {
  std::lock_guard lock(mutex_);
  if (auto old = entries_.find(key); old != entries_.end()) {
    kept_bytes_ -= old->second.bytes.size();
    entries_.erase(old);
  }
  MakeRoomLocked(now, 0);
  entries_[key] = Entry{{}, std::move(stored), now};
}

PartialUploads::Progress PartialUploads::ProgressOf(const Key& key, Clock::time_point now) {
  std::lock_guard lock(mutex_);
  ExpireLocked(now);
  auto it = entries_.find(key);
  if (it == entries_.end()) return {};
  return {it->second.bytes.size(), it->second.stored};
}

uint64_t PartialUploads::kept_bytes() const {
  std::lock_guard lock(mutex_);
  return kept_bytes_;
}

}  // namespace recog::server
