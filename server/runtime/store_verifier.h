// StoreVerifier: checks the store's files in the background, so that damage on disk (a flipped
// bit, a bad sector) is found within one period rather than when a query reads the block.
//
// A thread of its own runs IndexStore::Verify every `period` (the first time one period after
// start-up, which has just read the store), at most `bytes_per_second`, and hands each outcome
// to `on_result`: the server logs it, exports it as metrics and, on damage, reports the store
// NOT_SERVING in its health service. RunNow runs a check at once on the caller's thread (the
// Admin Verify RPC) and reports it the same way. The destructor stops the thread, waiting for a
// check in progress to end.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>

#include "core/index/index_store.h"

namespace recog::server {

class StoreVerifier {
 public:
  using Result = StatusOr<IndexStore::VerifyReport>;
  // How one check went: its result and how long it took.
  using OnResult = std::function<void(const Result& result, std::chrono::duration<double> took)>;

  // A zero `period` starts no thread (RunNow still works). `store` must outlive the verifier.
  StoreVerifier(IndexStore* store, std::chrono::seconds period, uint64_t bytes_per_second,
                OnResult on_result);
  ~StoreVerifier();
  StoreVerifier(const StoreVerifier&) = delete;
  StoreVerifier& operator=(const StoreVerifier&) = delete;

  // Checks the store now, at `bytes_per_second` (0: unlimited); checks never overlap.
  Result RunNow(uint64_t bytes_per_second);

 private:
  void Loop();

  IndexStore* const store_;
  const std::chrono::seconds period_;
  const uint64_t bytes_per_second_;
  const OnResult on_result_;
  std::mutex check_mutex_;  // one check at a time
  std::mutex mutex_;
  std::condition_variable stop_cv_;
  bool stopping_ = false;  // guarded by mutex_
  std::thread thread_;
};

}  // namespace recog::server
