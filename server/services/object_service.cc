#include "server/services/object_service.h"

#include <algorithm>
#include <chrono>

#include "server/api/converters.h"
#include "server/api/status_mapping.h"
#include "server/services/call.h"
#include "server/services/frame_stream.h"

namespace recog::server {
namespace {

constexpr char kService[] = "/recognition.v1.ObjectRecognition/";
std::string Method(const char* name) { return std::string(kService) + name; }

bool Passes(const pb::ObjectFilter& filter, const Detection& detection,
            const ObjectMetadata& object) {
  if (filter.names_size() == 0 && filter.classes_size() == 0) return true;
  return std::find(filter.names().begin(), filter.names().end(), detection.name) !=
             filter.names().end() ||
         std::find(filter.classes().begin(), filter.classes().end(), object.object_class) !=
             filter.classes().end();
}

// This worker thread's recogniser over the server's object database.
ObjectRecognizer& ThreadRecognizer(const ServerState& state) {
  thread_local std::unique_ptr<ObjectRecognizer> recognizer;
  thread_local const ServerState* owner = nullptr;
  if (recognizer == nullptr || owner != &state) {
    recognizer = std::make_unique<ObjectRecognizer>(state.objects, state.recognition);
    owner = &state;
  }
  return *recognizer;
}

Status RunRecognition(ServerState& state, const pb::Frame& request, const pb::ObjectFilter& filter,
                      google::protobuf::RepeatedPtrField<pb::DetectedObject>* out,
                      pb::Timing* timing) {
  RECOG_ASSIGN_OR_RETURN(DecodedFrame frame,
                         DecodeFrame(request, state.objects->vocabulary().info().descriptor));
  if (!frame.intrinsics.has_value()) {
    return Status::InvalidArgument(
        "frame.intrinsics is required for object recognition (the pose is solved with them)");
  }
  timing->set_decode_ms(frame.decode_ms);
  ObjectRecognizer& recognizer = ThreadRecognizer(state);
  std::vector<Detection> detections;
  RecognitionTiming stages;
  if (frame.has_image()) {
    RECOG_RETURN_IF_ERROR(
        recognizer.Recognize(frame.image, *frame.intrinsics, &detections, &stages));
  } else {
    RECOG_RETURN_IF_ERROR(
        recognizer.RecognizeFeatures(frame.features, *frame.intrinsics, &detections, &stages));
  }
  timing->set_features_ms(stages.orb);
  timing->set_recognition_ms(stages.total - stages.orb);
  std::stable_sort(detections.begin(), detections.end(),
                   [](const Detection& a, const Detection& b) { return a.inliers > b.inliers; });
  uint64_t reported = 0;
  for (const Detection& detection : detections) {
    const std::shared_ptr<const IndexedObject> object = state.objects->Find(detection.id);
    const ObjectMetadata metadata = object != nullptr ? object->metadata : ObjectMetadata{};
    if (!Passes(filter, detection, metadata)) continue;
    ToProto(detection, metadata, out->Add());
    ++reported;
  }
  state.metrics.AddFrames(FrameKind::kObject);
  state.metrics.AddObjectDetections(reported);
  return Status::Ok();
}

class ObjectFrameStream final
    : public FrameStream<pb::StreamRecognizeObjectsRequest, pb::StreamRecognizeObjectsResponse> {
 public:
  ObjectFrameStream(ServerState& state, grpc::CallbackServerContext* context)
      : FrameStream(state, context, Method("StreamRecognizeObjects"), "StreamRecognizeObjects") {}

 private:
  grpc::Status Configure(const pb::StreamRecognizeObjectsRequest& first) override {
    if (!first.has_config()) {
      return {grpc::StatusCode::FAILED_PRECONDITION,
              "the first message of StreamRecognizeObjects must be a RecognitionConfig"};
    }
    filter_ = first.config().filter();
    return grpc::Status::OK;
  }

  Status Answer(const pb::Frame& frame, pb::StreamRecognizeObjectsResponse* response) override {
    // RunRecognition adds objects only once nothing can fail any more.
    return RunRecognition(state_, frame, filter_, response->mutable_objects(),
                          response->mutable_timing());
  }

  pb::ObjectFilter filter_;
};

}  // namespace

grpc::ServerUnaryReactor* ObjectService::RecognizeObjects(
    grpc::CallbackServerContext* context, const pb::RecognizeObjectsRequest* request,
    pb::RecognizeObjectsResponse* response) {
  return RunUnary(state_, context, Method("RecognizeObjects"), Right::kRead,
                  [=, this](CallInfo& call) {
                    RECOG_RETURN_IF_ERROR_AS_GRPC(
                        RunRecognition(state_, request->frame(), request->filter(),
                                       response->mutable_objects(), response->mutable_timing()),
                        call.request_id);
                    response->set_client_frame_id(request->frame().client_frame_id());
                    response->mutable_timing()->set_queue_ms(call.queue_ms);
                    return grpc::Status::OK;
                  });
}

grpc::ServerBidiReactor<pb::StreamRecognizeObjectsRequest, pb::StreamRecognizeObjectsResponse>*
ObjectService::StreamRecognizeObjects(grpc::CallbackServerContext* context) {
  auto* stream = new ObjectFrameStream(state_, context);
  stream->Start(Right::kRead);
  return stream;
}

}  // namespace recog::server
