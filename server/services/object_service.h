// ObjectService: the ObjectRecognition RPCs (proto/recognition/v1/object.proto).
//
// A frame is decoded, given with the request's ObjectFilter to the ObjectRecognizer of the worker
// that runs it (its WorkerContext: recognisers reuse scratch memory and are not thread-safe), and
// the detections are encoded as core gives them (best first, only the filter's objects). Every
// recogniser shares the server's ObjectDatabase, so a model uploaded through the repository is
// recognised by the next frame. The stream is a FrameStream (frame_stream.h).
#pragma once

#include "recognition/v1/object.grpc.pb.h"
#include "server/services/server_state.h"

namespace recog::server {

class ObjectService final : public ::recognition::v1::ObjectRecognition::CallbackService {
 public:
  explicit ObjectService(ServerState* state) : state_(*state) {}

  grpc::ServerUnaryReactor* RecognizeObjects(
      grpc::CallbackServerContext* context,
      const ::recognition::v1::RecognizeObjectsRequest* request,
      ::recognition::v1::RecognizeObjectsResponse* response) override;
  grpc::ServerBidiReactor<::recognition::v1::StreamRecognizeObjectsRequest,
                          ::recognition::v1::StreamRecognizeObjectsResponse>*
  StreamRecognizeObjects(grpc::CallbackServerContext* context) override;

 private:
  ServerState& state_;
};

}  // namespace recog::server
