// OrderedStream: the engine of FrameStream and ObjectStream — a bidirectional gRPC call whose
// first message is a config and every later one a frame, answered by the server in order.
// Internal to the client library.
//
// It is a gRPC callback-API reactor (grpc::ClientBidiReactor): no thread of its own. Send queues
// the frame and its answer callback; one write is outstanding at a time (the next starts from
// OnWriteDone), one read is always outstanding, and each answer read is handed to the oldest
// waiting callback, so answers are delivered in order, on a gRPC thread, one at a time. When the
// call ends, every callback still waiting gets the call's status (or ABORTED when the server
// ended it successfully without answering them). Close() half-closes and waits for the end.
//
// Locking: `mutex_` guards the queues and flags; it is never held while calling a Start* method
// of gRPC or a user callback. A hold (AddHold) keeps the call from finishing while a user thread
// may still start a write; it is released once no further write can start: the write side was
// closed or broke, or the read side ended with no write outstanding.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <utility>

#include <grpcpp/grpcpp.h>

#include "client/cpp/result.h"

namespace recog::client::internal {

template <class Request, class Response>
class OrderedStream final : public grpc::ClientBidiReactor<Request, Response> {
 public:
  using Callback = std::function<void(Result<Response>)>;
  // Requests are shared, not copied: a caller may send one request many times.
  using RequestPtr = std::shared_ptr<const Request>;
  // Starts the RPC on `context` with this reactor (the stub's async() method).
  using StartRpc =
      std::function<void(grpc::ClientContext*, grpc::ClientBidiReactor<Request, Response>*)>;

  explicit OrderedStream(size_t max_in_flight) : max_in_flight_(max_in_flight) {}
  // Cancels the call if it is still running and waits for its end.
  ~OrderedStream() {
    Cancel();
    Wait();
  }
  OrderedStream(const OrderedStream&) = delete;
  OrderedStream& operator=(const OrderedStream&) = delete;

  // To set metadata before Start.
  grpc::ClientContext& context() { return context_; }

  // Starts the call with `config` as its first message. Once only.
  void Start(const StartRpc& start_rpc, RequestPtr config) {
    start_rpc(&context_, this);
    {
      std::lock_guard lock(mutex_);
      writes_.push_back(std::move(config));
      writing_ = true;
    }
    this->AddHold();
    this->StartWrite(writes_.front().get());
    this->StartRead(&response_);
    this->StartCall();
  }

  void Send(RequestPtr request, Callback callback) {
    grpc::Status refusal;
    const Request* write = nullptr;
    {
      std::lock_guard lock(mutex_);
      if (finished_) {
        refusal = final_status_.ok()
                      ? grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, "the stream has ended")
                      : final_status_;
      } else if (closing_) {
        refusal = {grpc::StatusCode::FAILED_PRECONDITION, "the stream is closing"};
      } else if (pending_.size() >= max_in_flight_) {
        refusal = {grpc::StatusCode::RESOURCE_EXHAUSTED,
                   std::to_string(pending_.size()) +
                       " frames are waiting for their answers (max_frames_in_flight); this one "
                       "was not sent"};
      } else {
        pending_.push_back(std::move(callback));
        // After the read side ended, the frame waits in pending_ for the call's status.
        if (!broken_ && !read_closed_) {
          writes_.push_back(std::move(request));
          if (!writing_) {
            writing_ = true;
            write = writes_.front().get();
          }
        }
      }
    }
    if (!refusal.ok()) {
      callback(refusal);
    } else if (write != nullptr) {
      this->StartWrite(write);
    }
  }

  std::future<Result<Response>> Send(RequestPtr request) {
    auto promise = std::make_shared<std::promise<Result<Response>>>();
    std::future<Result<Response>> answer = promise->get_future();
    Send(std::move(request),
         [promise](Result<Response> result) { promise->set_value(std::move(result)); });
    return answer;
  }

  size_t in_flight() const {
    std::lock_guard lock(mutex_);
    return pending_.size();
  }

  // Half-closes once the queued frames are written, then waits for the end of the call.
  grpc::Status Close() {
    bool writes_done = false;
    {
      std::lock_guard lock(mutex_);
      closing_ = true;
      writes_done = CloseWriteSideLocked();
    }
    if (writes_done) {
      this->StartWritesDone();
      this->RemoveHold();
    }
    return Wait();
  }

  void Cancel() { context_.TryCancel(); }

 private:
  // Waits for OnDone; returns the call's status.
  grpc::Status Wait() {
    std::unique_lock lock(mutex_);
    done_changed_.wait(lock, [this] { return done_; });
    return final_status_;
  }

  // Whether the caller must now half-close (and then release the hold): closing, nothing being
  // written, and the write side neither closed nor broken.
  bool CloseWriteSideLocked() {
    if (!closing_ || writing_ || writes_done_ || broken_ || hold_released_) return false;
    writes_done_ = true;
    hold_released_ = true;
    return true;
  }

  // Whether the caller must release the hold now that no write can start any more.
  bool ReleaseHoldLocked() {
    if (hold_released_ || writing_ || !(read_closed_ || broken_)) return false;
    hold_released_ = true;
    return true;
  }

  void OnWriteDone(bool ok) override {
    const Request* next = nullptr;
    bool writes_done = false, release = false;
    {
      std::lock_guard lock(mutex_);
      writes_.pop_front();
      if (!ok || read_closed_) {
        broken_ = broken_ || !ok;
        writes_.clear();
      }
      if (!writes_.empty()) {
        next = writes_.front().get();
      } else {
        writing_ = false;
        writes_done = CloseWriteSideLocked();
        release = !writes_done && ReleaseHoldLocked();
      }
    }
    if (next != nullptr) {
      this->StartWrite(next);
    } else if (writes_done) {
      this->StartWritesDone();
      this->RemoveHold();
    } else if (release) {
      this->RemoveHold();
    }
  }

  void OnReadDone(bool ok) override {
    Callback callback;
    bool release = false;
    const bool unexpected = ok;  // when there is no callback to give the answer to
    {
      std::lock_guard lock(mutex_);
      if (ok && !pending_.empty()) {
        callback = std::move(pending_.front());
        pending_.pop_front();
      } else {
        // The call is ending (OnDone follows once the hold is released), or the server answered
        // a frame never sent and the stream cannot be trusted any more.
        unexpected_answer_ = unexpected;
        read_closed_ = true;
        release = ReleaseHoldLocked();
      }
    }
    if (!callback) {
      if (unexpected) context_.TryCancel();
      if (release) this->RemoveHold();
      return;
    }
    callback(std::move(response_));
    response_ = Response();
    this->StartRead(&response_);
  }

  void OnDone(const grpc::Status& status) override {
    std::deque<Callback> unanswered;
    grpc::Status failure;
    {
      std::lock_guard lock(mutex_);
      final_status_ = unexpected_answer_ ? grpc::Status(grpc::StatusCode::INTERNAL,
                                                        "the server answered a frame never sent")
                                         : status;
      finished_ = true;
      unanswered.swap(pending_);
      failure = final_status_.ok() ? grpc::Status(grpc::StatusCode::ABORTED,
                                                  "the stream ended before this frame's answer")
                                   : final_status_;
    }
    for (Callback& callback : unanswered) callback(failure);
    std::lock_guard lock(mutex_);
    done_ = true;
    done_changed_.notify_all();
  }

  const size_t max_in_flight_;
  grpc::ClientContext context_;
  Response response_;  // being read

  mutable std::mutex mutex_;  // guards everything below
  std::condition_variable done_changed_;
  std::deque<RequestPtr> writes_;  // the front one is being written
  std::deque<Callback> pending_;   // of the frames sent and not answered, oldest first
  bool writing_ = false;           // a StartWrite is outstanding
  bool closing_ = false;           // Close() was called: no more frames
  bool writes_done_ = false;       // StartWritesDone was called
  bool broken_ = false;            // a write failed: the call is over
  bool read_closed_ = false;       // the read side ended: the call is over
  bool hold_released_ = false;     // RemoveHold was called (or is about to be)
  bool unexpected_answer_ = false;
  bool finished_ = false;  // OnDone ran: Send refuses with final_status_
  bool done_ = false;      // OnDone delivered every unanswered callback
  grpc::Status final_status_;
};

}  // namespace recog::client::internal
