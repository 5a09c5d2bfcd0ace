// FrameStream and ObjectStream: a robot's streaming session — one bidirectional gRPC call
// (StreamFrames on one place map, or StreamRecognizeObjects) carrying frame after frame, each
// answered by the server in order. Both are one class template, BasicFrameStream, over the two
// RPCs (their config, request and answer types).
//
// Send() never blocks: the frame is queued and written as soon as the previous one is, so several
// frames can be in flight (up to ClientOptions::max_frames_in_flight; a frame beyond that is
// answered at once with RESOURCE_EXHAUSTED and not sent). The server answers one frame at a time
// and holds further frames back with gRPC flow control. Answers come back in the order the frames
// were sent, through a future or a callback. Both run on the gRPC callback API (no thread of the
// library's own): callbacks are called on a gRPC thread, one at a time, in order; they must not
// block for long and must not destroy the stream.
//
// A frame sent many times (a replayed sequence, a load test) can be prepared once: Prepare()
// wraps it in its request, and sending the PreparedFrame shares it instead of copying its
// keypoints and descriptors each time.
//
// A frame that fails on its own (an undecodable image, missing intrinsics) is answered normally,
// with the error inside the answer (`error`), and the stream goes on. When the stream itself fails
// (an unknown map, a missing right, a broken connection, a server shutting down), every frame
// still waiting for an answer gets the stream's status as its Result, and so does every later
// Send. Close() half-closes, waits for the remaining answers and returns the stream's final
// status; destroying a stream that was not closed cancels it. A FrameStream is never retried (its
// frames carry no request id; proto/service_config.json); gRPC retries an ObjectStream only before
// its first answer. Streams have no deadline. Thread-safe: any thread may Send, while another
// closes.
//
// A stream keeps its own reference to the client's connection and may outlive the client.
#pragma once

#include <cstddef>
#include <functional>
#include <future>
#include <memory>

#include "client/cpp/recognition_client.h"
#include "client/cpp/result.h"

namespace recog::client {

namespace internal {
template <class Request, class Response>
class OrderedStream;

// StreamFrames: frames of one place map, each answered with its loop result.
struct PlaceStreamRpc {
  using Service = pb::PlaceRecognition;
  using Config = pb::StreamConfig;  // the map, whether to create it, query-only, result options
  using Request = pb::StreamFramesRequest;
  using Response = pb::StreamFramesResponse;
};

// StreamRecognizeObjects: frames (with intrinsics), each answered with the objects it shows.
// Objects found are tracked into the next frames (DetectedObject::tracked() says which were
// tracked, which recognised) unless the config sets disable_tracking.
struct ObjectStreamRpc {
  using Service = pb::ObjectRecognition;
  // Which objects are of interest (default: all), what each detection carries, tracking on/off.
  using Config = pb::RecognitionConfig;
  using Request = pb::StreamRecognizeObjectsRequest;
  using Response = pb::StreamRecognizeObjectsResponse;
};
}  // namespace internal

template <class Rpc>
class BasicFrameStream {
 public:
  using Config = typename Rpc::Config;
  using Answer = Result<typename Rpc::Response>;
  // A frame wrapped in its request once, to be sent any number of times.
  using PreparedFrame = std::shared_ptr<const typename Rpc::Request>;

  // Starts the stream with `config`. For FrameStream, INVALID_ARGUMENT when config.map is empty;
  // every other error (NOT_FOUND for an unknown map without create_if_missing, PERMISSION_DENIED)
  // arrives with the first answers and Close().
  static Result<std::unique_ptr<BasicFrameStream>> Open(RecognitionClient& client,
                                                        const Config& config = {});
  static PreparedFrame Prepare(pb::Frame frame);

  ~BasicFrameStream();
  BasicFrameStream(const BasicFrameStream&) = delete;
  BasicFrameStream& operator=(const BasicFrameStream&) = delete;

  // Sends a frame; its answer completes the future.
  std::future<Answer> Send(pb::Frame frame);
  // Sends a frame; `on_answer` gets its answer.
  void Send(pb::Frame frame, std::function<void(Answer)> on_answer);
  void Send(PreparedFrame frame, std::function<void(Answer)> on_answer);
  // Frames sent and not yet answered.
  size_t in_flight() const;
  // Half-closes, waits for every answer and returns the stream's final status (OK when the
  // server answered every frame). Later Sends are refused with FAILED_PRECONDITION.
  grpc::Status Close();
  // Ends the stream at once; waiting frames get CANCELLED.
  void Cancel();

 private:
  BasicFrameStream(std::unique_ptr<typename Rpc::Service::Stub> stub, size_t max_in_flight);
  std::unique_ptr<typename Rpc::Service::Stub> stub_;
  std::unique_ptr<internal::OrderedStream<typename Rpc::Request, typename Rpc::Response>> stream_;
};

extern template class BasicFrameStream<internal::PlaceStreamRpc>;
extern template class BasicFrameStream<internal::ObjectStreamRpc>;

using FrameStream = BasicFrameStream<internal::PlaceStreamRpc>;
using ObjectStream = BasicFrameStream<internal::ObjectStreamRpc>;

}  // namespace recog::client
