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

namespace recog::server {

struct ServerState;

class WorkerContext {
 public:
  explicit WorkerContext(const ServerState& state) : state_(state) {}

  // Extracts the image's features with the server's place settings (a place frame's, or the
  // right image of its stereo pair: server/api/prepared_frame.h).
  Status ExtractPlaceFeatures(const cv::Mat& image, FeatureSet* out);
  // The recogniser over the server's object database, with its recognition settings (INTERNAL
  // when they are out of range). Only once the server is ready.
  StatusOr<ObjectRecognizer*> Recognizer();

 private:
  const ServerState& state_;
  std::unique_ptr<FeatureExtractor> place_extractor_;
  std::unique_ptr<ObjectRecognizer> recognizer_;
};

}  // namespace recog::server
