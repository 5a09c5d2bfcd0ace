// StoreVerifier (see store_verifier.h).
#include "server/runtime/store_verifier.h"

namespace recog::server {

StoreVerifier::StoreVerifier(IndexStore* store, std::chrono::seconds period,
                             uint64_t bytes_per_second, OnResult on_result)
    : store_(store),
      period_(period),
      bytes_per_second_(bytes_per_second),
      on_result_(std::move(on_result)) {
  if (period_.count() > 0) thread_ = std::thread([this] { Loop(); });
}

StoreVerifier::~StoreVerifier() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  stop_cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

StoreVerifier::Result StoreVerifier::RunNow(uint64_t bytes_per_second) {
  std::lock_guard check(check_mutex_);
  const auto start = std::chrono::steady_clock::now();
  Result result = store_->Verify(bytes_per_second);
  on_result_(result, std::chrono::steady_clock::now() - start);
  return result;
}

void StoreVerifier::Loop() {
  std::unique_lock lock(mutex_);
  while (!stop_cv_.wait_for(lock, period_, [this] { return stopping_; })) {
    lock.unlock();
    (void)RunNow(bytes_per_second_);  // reported through on_result_
    lock.lock();
  }
}

}  // namespace recog::server
