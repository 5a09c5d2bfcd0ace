// WorkerPool: the bounded pool of threads that does the server's CPU work.
//
// gRPC's reaction threads only hand work over; decoding, feature extraction, recognition and
// store writes run here, on a fixed number of threads. Tasks wait in one FIFO queue. Unary calls
// are admitted only while the queue holds fewer than `capacity` tasks (TrySubmit fails otherwise,
// and the caller answers RESOURCE_EXHAUSTED with a retry hint), so a burst of requests cannot
// grow memory without bound. Stream frames are always admitted (Submit): a stream has at most one
// frame in flight, so they are bounded by the number of open streams.
//
// Thread safety: every method may be called from any thread. Stop() runs the tasks already queued,
// then joins the threads; later submissions are refused.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace recog::server {

class WorkerPool {
 public:
  using Task = std::function<void()>;

  // `threads` >= 1 workers; `capacity` >= 1 tasks may wait in the queue for TrySubmit.
  WorkerPool(size_t threads, size_t capacity);
  ~WorkerPool();  // Stop()
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  // Queues a task unless the queue is full or the pool stopped; false then (the task is dropped).
  bool TrySubmit(Task task);
  // Queues a task whatever the queue length; false only when the pool stopped.
  bool Submit(Task task);

  // Tasks waiting for a worker, and tasks running now.
  size_t queued() const;
  size_t busy() const;
  size_t capacity() const { return capacity_; }
  size_t threads() const { return workers_.size(); }

  // Runs what is queued, then joins the workers. Idempotent; call it from one thread.
  void Stop();

 private:
  bool Enqueue(Task task, bool bounded);
  void Run();

  const size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<Task> queue_;
  size_t busy_ = 0;
  bool stopping_ = false;
  std::vector<std::thread> workers_;  // fixed at construction
  std::once_flag stop_once_;
};

}  // namespace recog::server
