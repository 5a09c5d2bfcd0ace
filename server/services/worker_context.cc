#include "server/services/worker_context.h"

#include "server/services/server_state.h"

namespace recog::server {

Status WorkerContext::ExtractPlaceFeatures(const cv::Mat& image, FeatureSet* out) {
  if (place_extractor_ == nullptr) {
    RECOG_ASSIGN_OR_RETURN(place_extractor_, CreateFeatureExtractor(state_.place_features));
  }
  return place_extractor_->Extract(image, out);
}

StatusOr<ObjectRecognizer*> WorkerContext::Recognizer() {
  if (recognizer_ == nullptr) {
    StatusOr<ObjectRecognizer> created =
        ObjectRecognizer::Create(state_.objects, state_.recognition);
    // The settings are the server's, not the caller's: refused, they are the server's fault.
    if (!created.ok()) {
      return created.status().WithContext("recognition settings", StatusCode::kInternal);
    }
    recognizer_ = std::make_unique<ObjectRecognizer>(std::move(created).value());
  }
  return recognizer_.get();
}

}  // namespace recog::server
