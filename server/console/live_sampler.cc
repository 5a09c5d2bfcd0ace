#include "server/console/live_sampler.h"

#include <algorithm>

namespace recog::server {

LiveSampler::LiveSampler(Read read, std::chrono::milliseconds interval, size_t keep)
    : read_(std::move(read)), interval_(interval), keep_(keep), thread_([this] { Run(); }) {}

LiveSampler::~LiveSampler() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  stop_signal_.notify_all();
  thread_.join();
}

std::vector<LiveSample> LiveSampler::Samples() const {
  std::lock_guard lock(mutex_);
  return {samples_.begin(), samples_.end()};
}

std::optional<double> LiveSampler::Quantile(const std::vector<double>& bounds,
                                            const std::vector<uint64_t>& counts, uint64_t total,
                                            double q) {
  if (total == 0 || bounds.empty()) return std::nullopt;
  const double target = q * double(total);
  double lower = 0;
  uint64_t below = 0;
  for (size_t b = 0; b < bounds.size() && b < counts.size(); ++b) {
    if (double(counts[b]) >= target && counts[b] > below) {
      const double fraction = (target - double(below)) / double(counts[b] - below);
      return 1000 * (lower + (bounds[b] - lower) * std::clamp(fraction, 0.0, 1.0));
    }
    lower = bounds[b];
    below = counts[b];
  }
  return 1000 * bounds.back();
}

LiveSample LiveSampler::Between(const ServerMetrics::Totals& before,
                                const ServerMetrics::Totals& after, double seconds,
                                int64_t unix_ms) {
  const auto delta = [](uint64_t a, uint64_t b) { return b >= a ? b - a : b; };  // b: a reset
  LiveSample sample;
  sample.unix_ms = unix_ms;
  const double per_second = seconds > 0 ? 1 / seconds : 0;
  const uint64_t calls = delta(before.calls, after.calls);
  sample.calls_per_s = double(calls) * per_second;
  sample.frames_per_s = double(delta(before.frames, after.frames)) * per_second;
  sample.errors_per_s = double(delta(before.errors, after.errors)) * per_second;
  sample.queue_depth = after.queue_depth;
  std::vector<uint64_t> counts(after.bucket_counts.size());
  for (size_t b = 0; b < counts.size(); ++b) {
    const uint64_t earlier = b < before.bucket_counts.size() ? before.bucket_counts[b] : 0;
    counts[b] = delta(earlier, after.bucket_counts[b]);
  }
  sample.latency_p50_ms = Quantile(after.bucket_bounds, counts, calls, 0.50);
  sample.latency_p90_ms = Quantile(after.bucket_bounds, counts, calls, 0.90);
  sample.latency_p99_ms = Quantile(after.bucket_bounds, counts, calls, 0.99);
  return sample;
}

void LiveSampler::Run() {
  using Clock = std::chrono::steady_clock;
  ServerMetrics::Totals before = read_();
  Clock::time_point then = Clock::now();
  std::unique_lock lock(mutex_);
  while (!stop_signal_.wait_for(lock, interval_, [this] { return stopping_; })) {
    lock.unlock();
    const ServerMetrics::Totals now = read_();
    const Clock::time_point at = Clock::now();
    const int64_t unix_ms = std::chrono::duration_cast<std::chrono::milliseconds>(
                                std::chrono::system_clock::now().time_since_epoch())
                                .count();
    const LiveSample sample =
        Between(before, now, std::chrono::duration<double>(at - then).count(), unix_ms);
    before = now;
    then = at;
    lock.lock();
    samples_.push_back(sample);
    while (samples_.size() > keep_) samples_.pop_front();
  }
}

}  // namespace recog::server
