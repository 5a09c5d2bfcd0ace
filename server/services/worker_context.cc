#include "server/services/worker_context.h"

#include "server/services/server_state.h"

namespace recog::server {

Status WorkerContext::ExtractPlaceFeatures(const cv::Mat& image, FeatureSet* out) {
  if (place_extractor_ == nullptr) {
    RECOG_ASSIGN_OR_RETURN(place_extractor_, CreateFeatureExtractor(state_.place_features));
  }
  return place_extractor_->Extract(image, out);
}

ObjectRecognizer& WorkerContext::Recognizer() {
  if (recognizer_ == nullptr) {
    recognizer_ = std::make_unique<ObjectRecognizer>(state_.objects, state_.recognition);
  }
  return *recognizer_;
}

}  // namespace recog::server
