#include "server/runtime/recent_loops.h"

namespace recog::server {

void RecentLoops::Record(const std::string& map, RecordedLoop loop) {
  std::lock_guard lock(mutex_);
  std::deque<RecordedLoop>& loops = loops_[map];
  loops.push_back(std::move(loop));
  while (loops.size() > per_map_) loops.pop_front();
}

std::vector<RecordedLoop> RecentLoops::Of(const std::string& map) const {
  std::lock_guard lock(mutex_);
  const auto found = loops_.find(map);
  if (found == loops_.end()) return {};
  return {found->second.rbegin(), found->second.rend()};
}

size_t RecentLoops::Count(const std::string& map) const {
  std::lock_guard lock(mutex_);
  const auto found = loops_.find(map);
  return found == loops_.end() ? 0 : found->second.size();
}

void RecentLoops::Forget(const std::string& map) {
  std::lock_guard lock(mutex_);
  loops_.erase(map);
}

}  // namespace recog::server
