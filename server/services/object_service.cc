#include "server/services/object_service.h"

#include <chrono>
#include <memory>

#include "core/object/tracking/object_tracker.h"
#include "server/api/frame_decoding.h"
#include "server/api/object_converters.h"
#include "server/services/call.h"
#include "server/services/frame_stream.h"

namespace recog::server {
namespace {

constexpr char kObjectService[] = "/recognition.v1.ObjectRecognition/";
std::string ObjectMethod(const char* name) { return std::string(kObjectService) + name; }

// Decodes one frame, recognises the filter's objects with this worker's recogniser (through the
// stream's tracker when there is one) and encodes the detections (core gives them best first)
// with the extras `extras` asks for; with `explanations` (unary calls only, no tracker), where
// every object dropped out.
Status RunRecognition(ServerState& state, WorkerContext& worker, const pb::Frame& request,
                      const ObjectFilter& filter, const DetectionOptions& extras,
                      ObjectTracker* tracker,
                      google::protobuf::RepeatedPtrField<pb::DetectedObject>* out,
                      pb::Timing* timing,
                      google::protobuf::RepeatedPtrField<pb::ObjectExplanation>* explanations) {
  PixelBudget budget = CallPixelBudget(state);
  RECOG_ASSIGN_OR_RETURN(
      DecodedFrame frame,
      DecodeFrame(request, state.objects->vocabulary().info().descriptor, budget));
  if (!frame.intrinsics.has_value()) {
    return Status::InvalidArgument(
        "frame.intrinsics is required for object recognition (the pose is solved with them)");
  }
  timing->set_decode_ms(frame.decode_ms);
  RECOG_ASSIGN_OR_RETURN(ObjectRecognizer * recognizer, worker.Recognizer());
  std::vector<Detection> detections;
  std::vector<ObjectExplanation> explained;
  std::vector<ObjectExplanation>* explain = explanations != nullptr ? &explained : nullptr;
  RecognitionTiming stages;
  if (tracker != nullptr) {
    // The tracker extracts features only in the tracked objects' boxes: no separate ORB stage.
    TrackingTiming tracking;
    RECOG_RETURN_IF_ERROR(
        frame.has_image() ? tracker->Track(*recognizer, frame.image, *frame.intrinsics, &detections,
                                           &tracking, filter, extras)
                          : tracker->TrackFeatures(*recognizer, frame.features, *frame.intrinsics,
                                                   &detections, &tracking, filter, extras));
    stages.total = tracking.total;
  } else if (frame.has_image()) {
    RECOG_RETURN_IF_ERROR(recognizer->Recognize(frame.image, *frame.intrinsics, &detections,
                                                &stages, filter, extras, explain));
  } else {
    RECOG_RETURN_IF_ERROR(recognizer->RecognizeFeatures(
        frame.features, *frame.intrinsics, &detections, &stages, filter, extras, explain));
  }
  timing->set_features_ms(stages.orb);
  timing->set_recognition_ms(stages.total - stages.orb);
  for (const Detection& detection : detections) ToProto(detection, out->Add());
  for (const ObjectExplanation& e : explained) ToProto(e, explanations->Add());
  state.metrics.AddFrames(FrameKind::kObject);
  state.metrics.AddObjectDetections(detections.size());
  return Status::Ok();
}

class ObjectFrameStream final
    : public FrameStream<pb::StreamRecognizeObjectsRequest, pb::StreamRecognizeObjectsResponse> {
 public:
  ObjectFrameStream(ServerState& state, grpc::CallbackServerContext* context)
      : FrameStream(state, context, ObjectMethod("StreamRecognizeObjects"),
                    "StreamRecognizeObjects") {}

 private:
  Status Configure(const pb::StreamRecognizeObjectsRequest& first) override {
    if (!first.has_config()) {
      return Status::FailedPrecondition(
          "the first message of StreamRecognizeObjects must be a RecognitionConfig");
    }
    filter_ = FromProto(first.config().filter());
    extras_ = FromProto(first.config().detection_options());
    // The stream owns its tracks; each frame borrows the recogniser of the worker that runs it.
    if (!first.config().disable_tracking()) {
      tracker_ = std::make_unique<ObjectTracker>(state_.objects);
    }
    return Status::Ok();
  }

  Status Answer(const pb::Frame& frame, WorkerContext& worker,
                pb::StreamRecognizeObjectsResponse* response) override {
    // RunRecognition adds objects only once nothing can fail any more.
    return RunRecognition(state_, worker, frame, filter_, extras_, tracker_.get(),
                          response->mutable_objects(), response->mutable_timing(), nullptr);
  }

  ObjectFilter filter_;
  DetectionOptions extras_;
  std::unique_ptr<ObjectTracker> tracker_;  // null when the config disables tracking
};

}  // namespace

grpc::ServerUnaryReactor* ObjectService::RecognizeObjects(
    grpc::CallbackServerContext* context, const pb::RecognizeObjectsRequest* request,
    pb::RecognizeObjectsResponse* response) {
  return RunUnary(state_, context, ObjectMethod("RecognizeObjects"), Right::kRead, *request,
                  [=, this](CallInfo& call, WorkerContext& worker) {
                    RECOG_RETURN_IF_ERROR(RunRecognition(
                        state_, worker, request->frame(), FromProto(request->filter()),
                        FromProto(request->detection_options()), nullptr,
                        response->mutable_objects(), response->mutable_timing(),
                        request->explain() ? response->mutable_explanations() : nullptr));
                    response->set_client_frame_id(request->frame().client_frame_id());
                    response->mutable_timing()->set_queue_ms(call.queue_ms);
                    return Status::Ok();
                  });
}

grpc::ServerBidiReactor<pb::StreamRecognizeObjectsRequest, pb::StreamRecognizeObjectsResponse>*
ObjectService::StreamRecognizeObjects(grpc::CallbackServerContext* context) {
  auto* stream = new ObjectFrameStream(state_, context);
  stream->Start(Right::kRead);
  return stream;
}

}  // namespace recog::server
