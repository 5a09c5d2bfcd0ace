// LiveSampler: the console's "Live" charts — throughput, latency percentiles, queue depth and
// errors over the last minutes, sampled from recogd's own metrics.
//
// A background thread reads ServerMetrics::ReadTotals every `interval` and keeps the differences
// between consecutive readings as samples (the last `keep` of them): calls, frames and failed
// calls per second, the 50th/90th/99th percentile of the calls that finished in the interval
// (interpolated in the RPC duration histogram's buckets, as Prometheus' histogram_quantile does),
// and the queue depth at the reading. It reads the metrics only: the gRPC path does nothing for it.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include "server/metrics/metrics.h"

namespace recog::server {

struct LiveSample {
  int64_t unix_ms = 0;  // when the interval ended
  double calls_per_s = 0;
  double frames_per_s = 0;
  double errors_per_s = 0;  // calls that ended with another code than OK
  // Of the calls that ended in the interval; none when no call did.
  std::optional<double> latency_p50_ms, latency_p90_ms, latency_p99_ms;
  double queue_depth = 0;
};

class LiveSampler {
 public:
  using Read = std::function<ServerMetrics::Totals()>;

  LiveSampler(Read read, std::chrono::milliseconds interval, size_t keep);
  ~LiveSampler();  // stops the thread
  LiveSampler(const LiveSampler&) = delete;
  LiveSampler& operator=(const LiveSampler&) = delete;

  // Oldest first.
  std::vector<LiveSample> Samples() const;

  // The sample of the `seconds` between two readings.
  static LiveSample Between(const ServerMetrics::Totals& before, const ServerMetrics::Totals& after,
                            double seconds, int64_t unix_ms);
  // The `q` quantile (0..1) of the calls counted by cumulative `counts` over `bounds` (seconds),
  // in milliseconds; none for no calls. Calls above the last bound count as at it.
  static std::optional<double> Quantile(const std::vector<double>& bounds,
                                        const std::vector<uint64_t>& counts, uint64_t total,
                                        double q);

 private:
  void Run();

  const Read read_;
  const std::chrono::milliseconds interval_;
  const size_t keep_;
  mutable std::mutex mutex_;
  std::condition_variable stop_signal_;
  bool stopping_ = false;
  std::deque<LiveSample> samples_;
  std::thread thread_;  // last: starts once the members above exist
};

}  // namespace recog::server
