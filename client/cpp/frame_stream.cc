#include "client/cpp/frame_stream.h"

#include "client/cpp/ordered_stream.h"

namespace recog::client {

// --- FrameStream ---

FrameStream::FrameStream(std::unique_ptr<pb::PlaceRecognition::Stub> stub, size_t max_in_flight)
    : stub_(std::move(stub)),
      stream_(std::make_unique<
              internal::OrderedStream<pb::StreamFramesRequest, pb::StreamFramesResponse>>(
          max_in_flight)) {}

FrameStream::~FrameStream() = default;

Result<std::unique_ptr<FrameStream>> FrameStream::Open(RecognitionClient& client,
                                                       const pb::StreamConfig& config) {
  if (config.map().empty()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "config.map must name a map");
  }
  std::unique_ptr<FrameStream> stream(new FrameStream(
      pb::PlaceRecognition::NewStub(client.channel_), client.options_.max_frames_in_flight));
  client.PrepareContext(stream->stream_->context(), nullptr);
  pb::StreamFramesRequest first;
  *first.mutable_config() = config;
  pb::PlaceRecognition::Stub* stub = stream->stub_.get();
  stream->stream_->Start([stub](grpc::ClientContext* context,
                                auto* reactor) { stub->async()->StreamFrames(context, reactor); },
                         std::move(first));
  return stream;
}

std::future<FrameStream::Answer> FrameStream::Send(pb::Frame frame) {
  pb::StreamFramesRequest request;
  *request.mutable_frame() = std::move(frame);
  return stream_->Send(std::move(request));
}

void FrameStream::Send(pb::Frame frame, std::function<void(Answer)> on_answer) {
  pb::StreamFramesRequest request;
  *request.mutable_frame() = std::move(frame);
  stream_->Send(std::move(request), std::move(on_answer));
}

size_t FrameStream::in_flight() const { return stream_->in_flight(); }
grpc::Status FrameStream::Close() { return stream_->Close(); }
void FrameStream::Cancel() { stream_->Cancel(); }

// --- ObjectStream ---

ObjectStream::ObjectStream(std::unique_ptr<pb::ObjectRecognition::Stub> stub, size_t max_in_flight)
    : stub_(std::move(stub)),
      stream_(std::make_unique<internal::OrderedStream<pb::StreamRecognizeObjectsRequest,
                                                       pb::StreamRecognizeObjectsResponse>>(
          max_in_flight)) {}

ObjectStream::~ObjectStream() = default;

Result<std::unique_ptr<ObjectStream>> ObjectStream::Open(RecognitionClient& client,
                                                         const pb::RecognitionConfig& config) {
  std::unique_ptr<ObjectStream> stream(new ObjectStream(
      pb::ObjectRecognition::NewStub(client.channel_), client.options_.max_frames_in_flight));
  client.PrepareContext(stream->stream_->context(), nullptr);
  pb::StreamRecognizeObjectsRequest first;
  *first.mutable_config() = config;
  pb::ObjectRecognition::Stub* stub = stream->stub_.get();
  stream->stream_->Start(
      [stub](grpc::ClientContext* context, auto* reactor) {
        stub->async()->StreamRecognizeObjects(context, reactor);
      },
      std::move(first));
  return stream;
}

std::future<ObjectStream::Answer> ObjectStream::Send(pb::Frame frame) {
  pb::StreamRecognizeObjectsRequest request;
  *request.mutable_frame() = std::move(frame);
  return stream_->Send(std::move(request));
}

void ObjectStream::Send(pb::Frame frame, std::function<void(Answer)> on_answer) {
  pb::StreamRecognizeObjectsRequest request;
  *request.mutable_frame() = std::move(frame);
  stream_->Send(std::move(request), std::move(on_answer));
}

size_t ObjectStream::in_flight() const { return stream_->in_flight(); }
grpc::Status ObjectStream::Close() { return stream_->Close(); }
void ObjectStream::Cancel() { stream_->Cancel(); }

}  // namespace recog::client
