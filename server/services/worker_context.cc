#include "server/services/worker_context.h"

#include "core/geometry/frame_points.h"
#include "server/services/server_state.h"

namespace recog::server {

Status WorkerContext::ExtractPlaceFeatures(const cv::Mat& image, FeatureSet* out) {
  if (place_extractor_ == nullptr) {
    RECOG_ASSIGN_OR_RETURN(place_extractor_, CreateFeatureExtractor(state_.place_features));
  }
  return place_extractor_->Extract(image, out);
}

Status WorkerContext::PlaceFrameGeometry(const DecodedFrame& frame, const FeatureSet& features,
                                         FrameGeometry* out) {
  out->K = frame.intrinsics->K();
  if (!frame.depth.empty()) {
    const cv::Size size = frame.has_image() ? frame.image.size() : frame.depth.size();
    return PointsFromDepth(features.keypoints, size, out->K, frame.depth, frame.depth_scale,
                           &out->points);
  }
  FeatureSet right_features;
  RECOG_RETURN_IF_ERROR(ExtractPlaceFeatures(frame.right, &right_features));
  return PointsFromStereo(features, frame.image, right_features, frame.right, out->K,
                          frame.baseline_m, StereoOptions{}, &out->points);
}

ObjectRecognizer& WorkerContext::Recognizer() {
  if (recognizer_ == nullptr) {
    recognizer_ = std::make_unique<ObjectRecognizer>(state_.objects, state_.recognition);
  }
  return *recognizer_;
}

}  // namespace recog::server
