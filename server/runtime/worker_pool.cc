#include "server/runtime/worker_pool.h"

#include <algorithm>

namespace recog::server {

WorkerPool::WorkerPool(size_t threads, size_t capacity) : capacity_(std::max<size_t>(capacity, 1)) {
  const size_t count = std::max<size_t>(threads, 1);
  workers_.reserve(count);
  for (size_t i = 0; i < count; ++i) workers_.emplace_back([this] { Run(); });
}

WorkerPool::~WorkerPool() { Stop(); }

bool WorkerPool::TrySubmit(Task task) { return Enqueue(std::move(task), true); }
bool WorkerPool::Submit(Task task) { return Enqueue(std::move(task), false); }

bool WorkerPool::Enqueue(Task task, bool bounded) {
  {
    std::lock_guard lock(mutex_);
    if (stopping_ || (bounded && queue_.size() >= capacity_)) return false;
    queue_.push_back(std::move(task));
  }
  wake_.notify_one();
  return true;
}

size_t WorkerPool::queued() const {
  std::lock_guard lock(mutex_);
  return queue_.size();
}

size_t WorkerPool::busy() const {
  std::lock_guard lock(mutex_);
  return busy_;
}

void WorkerPool::Stop() {
  std::call_once(stop_once_, [this] {
    {
      std::lock_guard lock(mutex_);
      stopping_ = true;
    }
    wake_.notify_all();
    for (std::thread& worker : workers_) worker.join();
  });
}

void WorkerPool::Run() {
  for (;;) {
    Task task;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
      if (queue_.empty()) return;  // stopping, and nothing left to run
      task = std::move(queue_.front());
      queue_.pop_front();
      ++busy_;
    }
    task();
    std::lock_guard lock(mutex_);
    --busy_;
  }
}

}  // namespace recog::server
