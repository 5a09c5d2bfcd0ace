#include "client/cpp/frame_stream.h"

#include <type_traits>

#include "client/cpp/ordered_stream.h"
#include "wire/routing.h"

namespace recog::client {
namespace {

// Starts the stream's RPC on `stub` with `reactor`.
void StartRpc(pb::PlaceRecognition::Stub& stub, grpc::ClientContext* context,
              grpc::ClientBidiReactor<pb::StreamFramesRequest, pb::StreamFramesResponse>* reactor) {
  stub.async()->StreamFrames(context, reactor);
}
void StartRpc(pb::ObjectRecognition::Stub& stub, grpc::ClientContext* context,
              grpc::ClientBidiReactor<pb::StreamRecognizeObjectsRequest,
                                      pb::StreamRecognizeObjectsResponse>* reactor) {
  stub.async()->StreamRecognizeObjects(context, reactor);
}

}  // namespace

template <class Rpc>
BasicFrameStream<Rpc>::BasicFrameStream(std::unique_ptr<typename Rpc::Service::Stub> stub,
                                        size_t max_in_flight)
    : stub_(std::move(stub)),
      stream_(
          std::make_unique<internal::OrderedStream<typename Rpc::Request, typename Rpc::Response>>(
              max_in_flight)) {}

template <class Rpc>
BasicFrameStream<Rpc>::~BasicFrameStream() = default;

template <class Rpc>
Result<std::unique_ptr<BasicFrameStream<Rpc>>> BasicFrameStream<Rpc>::Open(
    RecognitionClient& client, const Config& config) {
  if constexpr (std::is_same_v<Rpc, internal::PlaceStreamRpc>) {
    if (config.map().empty()) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "config.map must name a map");
    }
  }
  std::unique_ptr<BasicFrameStream> stream(new BasicFrameStream(
      Rpc::Service::NewStub(client.channel_), client.options_.max_frames_in_flight));
  client.PrepareContext(stream->stream_->context(), nullptr);
  if constexpr (std::is_same_v<Rpc, internal::PlaceStreamRpc>) {
    stream->stream_->context().AddMetadata(kMapHeader, config.map());
  }
  auto first = std::make_shared<typename Rpc::Request>();
  *first->mutable_config() = config;
  typename Rpc::Service::Stub* stub = stream->stub_.get();
  stream->stream_->Start(
      [stub](grpc::ClientContext* context, auto* reactor) { StartRpc(*stub, context, reactor); },
      std::move(first));
  return stream;
}

template <class Rpc>
typename BasicFrameStream<Rpc>::PreparedFrame BasicFrameStream<Rpc>::Prepare(pb::Frame frame) {
  auto request = std::make_shared<typename Rpc::Request>();
  *request->mutable_frame() = std::move(frame);
  return request;
}

template <class Rpc>
std::future<typename BasicFrameStream<Rpc>::Answer> BasicFrameStream<Rpc>::Send(pb::Frame frame) {
  return stream_->Send(Prepare(std::move(frame)));
}

template <class Rpc>
void BasicFrameStream<Rpc>::Send(pb::Frame frame, std::function<void(Answer)> on_answer) {
  stream_->Send(Prepare(std::move(frame)), std::move(on_answer));
}

template <class Rpc>
void BasicFrameStream<Rpc>::Send(PreparedFrame frame, std::function<void(Answer)> on_answer) {
  stream_->Send(std::move(frame), std::move(on_answer));
}

template <class Rpc>
size_t BasicFrameStream<Rpc>::in_flight() const {
  return stream_->in_flight();
}
template <class Rpc>
grpc::Status BasicFrameStream<Rpc>::Close() {
  return stream_->Close();
}
template <class Rpc>
void BasicFrameStream<Rpc>::Cancel() {
  stream_->Cancel();
}

template class BasicFrameStream<internal::PlaceStreamRpc>;
template class BasicFrameStream<internal::ObjectStreamRpc>;

}  // namespace recog::client
