// WorkerContext: what one worker thread of recogd keeps between the calls it runs — the place
// feature extractor and the object recogniser with their scratch memory — so that a call reuses
// them instead of building them.
//
// The worker pool (server/runtime/worker_pool.h) makes one per worker from the server state and
// hands it to every task that worker runs; it lives no longer than the pool, which the state
// owns. Both members are made on first use: the state's domain members (object database, place
// settings) are set only when the server becomes ready, after the pool started.
//
// Thread safety: none; only its worker uses it.
#pragma once

#include <memory>

#include "core/common/status.h"
#include "core/features/feature_extractor.h"
#include "core/object/recognition/object_recognizer.h"
#include "core/place/loop_detector.h"
#include "server/api/converters.h"

namespace recog::server {

struct ServerState;

class WorkerContext {
 public:
  explicit WorkerContext(const ServerState& state) : state_(state) {}

  // Extracts the image's features with the server's place settings.
  Status ExtractPlaceFeatures(const cv::Mat& image, FeatureSet* out);
  // The 3D structure of a place frame (core/geometry/frame_points.h) from its depth or right
  // image, for its `features` (the right image is described with the server's place settings).
  // Only for frames with depth or a right image (and so intrinsics); errors as the core's.
  Status PlaceFrameGeometry(const DecodedFrame& frame, const FeatureSet& features,
                            FrameGeometry* out);
  // The recogniser over the server's object database, with its recognition settings. Only once
  // the server is ready.
  ObjectRecognizer& Recognizer();

 private:
  const ServerState& state_;
  std::unique_ptr<FeatureExtractor> place_extractor_;
  std::unique_ptr<ObjectRecognizer> recognizer_;
};

}  // namespace recog::server
