// FrameStream: the reactor shape shared by the two bidirectional frame streams (StreamFrames and
// StreamRecognizeObjects).
//
// The first request configures the stream (Configure), every later one is a frame answered in
// order (Answer). Both run on the worker pool, never on a gRPC thread. At most one read or one
// write is outstanding: the next frame is read only after the previous answer was written, so a
// sender faster than the server is held back by HTTP/2 flow control instead of filling memory.
// A frame's own failure is part of its answer; only a bad config, the client going away or the
// server shutting down end the stream. Frames are not bounded by the pool's queue capacity (one
// per stream at most), so a stream is never refused a frame for being busy.
//
// Metrics: the RPC histogram gets one observation per frame under "<method>#frame" (the answer's
// latency, what a robot feels) and one for the whole stream under the method's name.
#pragma once

#include <atomic>
#include <string>

#include <grpcpp/grpcpp.h>

#include "server/api/frame_decoding.h"
#include "server/api/status_mapping.h"
#include "server/services/call.h"

namespace recog::server {

template <typename Request, typename Response>
class FrameStream : public grpc::ServerBidiReactor<Request, Response> {
 public:
  // `stream_name` labels the metrics gauge ("StreamFrames").
  FrameStream(ServerState& state, grpc::CallbackServerContext* context, std::string_view method,
              std::string_view stream_name)
      : state_(state),
        context_(context),
        stream_name_(stream_name),
        frame_metric_(std::string(method) + "#frame") {
    call_.method = std::string(method);
  }

  // Authenticates with `right` and reads the config; finishes at once when refused.
  void Start(Right right) {
    state_.metrics.StreamOpened(stream_name_);
    const grpc::Status status = BeginCall(state_, context_, call_.method, right, &call_);
    if (!status.ok()) {
      End(status);
      return;
    }
    this->StartRead(&request_);
  }

 protected:
  // Checks the first request (on a worker). Not OK ends the stream with that status.
  virtual Status Configure(const Request& first) = 0;
  // Answers one frame (on a worker, with its context) into `response`, which has its sequence
  // number and client frame id already. A failure becomes the answer's FrameError.
  virtual Status Answer(const pb::Frame& frame, WorkerContext& worker, Response* response) = 0;

  ServerState& state_;
  grpc::CallbackServerContext* const context_;
  CallInfo call_;

 private:
  void OnReadDone(bool ok) override {
    if (!ok) {  // the client closed its side: every frame was answered
      End(grpc::Status::OK);
      return;
    }
    const auto submitted_at = std::chrono::steady_clock::now();
    const bool submitted = state_.pool->Submit([this, submitted_at](WorkerContext& worker) {
      if (!configured_) {
        const Status status = Configure(request_);
        if (!status.ok()) {
          End(ToCallStatus(context_, call_, status));
          return;
        }
        configured_ = true;
        this->StartRead(&request_);
        return;
      }
      const auto start = std::chrono::steady_clock::now();
      response_.Clear();
      response_.set_sequence(sequence_++);
      Status status = Status::InvalidArgument("only the first message of a stream is a config");
      if (request_.has_frame()) {
        response_.set_client_frame_id(
            request_.frame().client_frame_id().substr(0, kMaxFrameIdBytes));
        status = Answer(request_.frame(), worker, &response_);
      }
      if (!status.ok()) {  // the frame's answer, not the stream's end: no trailing metadata
        const grpc::Status error = ToGrpcStatus(status, call_.request_id);
        response_.mutable_error()->set_code(int(error.error_code()));
        response_.mutable_error()->set_message(error.error_message());
      }
      response_.mutable_timing()->set_queue_ms(
          std::chrono::duration<double, std::milli>(start - submitted_at).count());
      state_.metrics.ObserveRpc(
          frame_metric_, "OK",
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
      SampleWorkerGauges(state_);
      this->StartWrite(&response_);
    });
    if (!submitted) End({grpc::StatusCode::UNAVAILABLE, "the server is shutting down"});
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      End({grpc::StatusCode::CANCELLED, "the client went away"});
    } else if (state_.draining.load()) {
      End({grpc::StatusCode::UNAVAILABLE,
           "the server is shutting down; every frame sent so far was answered"});
    } else {
      this->StartRead(&request_);
    }
  }

  void OnDone() override {
    state_.metrics.StreamClosed(stream_name_);
    delete this;
  }

  void End(const grpc::Status& status) {
    EndCall(state_, call_, status);
    this->Finish(status);
  }

  const std::string stream_name_;
  const std::string frame_metric_;  // per-frame latency: "<method>#frame"
  Request request_;
  Response response_;
  bool configured_ = false;  // touched by one operation at a time
  uint64_t sequence_ = 0;
};

}  // namespace recog::server
