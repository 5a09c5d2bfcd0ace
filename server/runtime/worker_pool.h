// WorkerPool: the bounded pool of threads that does the server's CPU work.
//
// gRPC's reaction threads only hand work over; decoding, feature extraction, recognition and
// store writes run here, on a fixed number of threads. Tasks wait in one FIFO queue. Unary calls
// are admitted only while the queue holds fewer than `capacity` tasks (TrySubmit fails otherwise,
// and the caller answers RESOURCE_EXHAUSTED with a retry hint), so a burst of requests cannot
// grow memory without bound. Stream frames are always admitted (Submit): a stream has at most one
// frame in flight, so they are bounded by the number of open streams.
//
// Each worker owns a `Context` (what it keeps between tasks: feature extractors, recognisers and
// their scratch memory), made by the pool's factory on that worker's thread before its first
// task and destroyed when the worker ends (Stop); a task gets the context of the worker that runs
// it. Contexts never outlive the pool, so none outlives what its factory captured.
//
// Thread safety: every method may be called from any thread. Stop() runs the tasks already queued,
// then joins the threads; later submissions are refused. A context is only used by its worker.
#pragma once

#include <algorithm>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace recog::server {

template <class Context>
class WorkerPool {
 public:
  using Task = std::function<void(Context&)>;
  using ContextFactory = std::function<std::unique_ptr<Context>()>;

  // `threads` >= 1 workers; `capacity` >= 1 tasks may wait in the queue for TrySubmit.
  // `factory` makes each worker's context (called once per worker, on its thread).
  WorkerPool(size_t threads, size_t capacity, ContextFactory factory)
      : capacity_(std::max<size_t>(capacity, 1)), factory_(std::move(factory)) {
    const size_t count = std::max<size_t>(threads, 1);
    workers_.reserve(count);
    for (size_t i = 0; i < count; ++i) workers_.emplace_back([this] { Run(); });
  }
  ~WorkerPool() { Stop(); }
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  // Queues a task unless the queue is full or the pool stopped; false then (the task is dropped).
  bool TrySubmit(Task task) { return Enqueue(std::move(task), true); }
  // Queues a task whatever the queue length; false only when the pool stopped.
  bool Submit(Task task) { return Enqueue(std::move(task), false); }

  // Tasks waiting for a worker, and tasks running now.
  size_t queued() const {
    std::lock_guard lock(mutex_);
    return queue_.size();
  }
  size_t busy() const {
    std::lock_guard lock(mutex_);
    return busy_;
  }
  size_t capacity() const { return capacity_; }
  size_t threads() const { return workers_.size(); }

  // Runs what is queued, then joins the workers. Idempotent; call it from one thread.
  void Stop() {
    std::call_once(stop_once_, [this] {
      {
        std::lock_guard lock(mutex_);
        stopping_ = true;
      }
      wake_.notify_all();
      for (std::thread& worker : workers_) worker.join();
    });
  }

 private:
  bool Enqueue(Task task, bool bounded) {
    {
      std::lock_guard lock(mutex_);
      if (stopping_ || (bounded && queue_.size() >= capacity_)) return false;
      queue_.push_back(std::move(task));
    }
    wake_.notify_one();
    return true;
  }

  void Run() {
    std::unique_ptr<Context> context;  // made before the first task, on this thread
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
      if (context == nullptr) context = factory_();
      task(*context);
      std::lock_guard lock(mutex_);
      --busy_;
    }
  }

  const size_t capacity_;
  const ContextFactory factory_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<Task> queue_;
  size_t busy_ = 0;
  bool stopping_ = false;
  std::vector<std::thread> workers_;  // fixed at construction
  std::once_flag stop_once_;
};

}  // namespace recog::server
