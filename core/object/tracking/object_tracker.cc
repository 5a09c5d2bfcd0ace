#include "core/object/tracking/object_tracker.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "core/common/elapsed.h"
#include "core/common/option_checks.h"

namespace recog {
namespace {

using Clock = std::chrono::steady_clock;

}  // namespace

Status TrackingOptions::Validate(std::string_view name) const {
  OptionChecks check(name);
  check.Member("matching", matching);
  check.AtLeast("recognition_interval", recognition_interval, 0);
  return check.status();
}

ObjectTracker::ObjectTracker(std::shared_ptr<const ObjectDatabase> database,
                             TrackingOptions options)
    : database_(std::move(database)), options_(std::move(options)), matcher_(options_.matching) {}

void ObjectTracker::Reset() {
  tracks_.clear();
  frames_since_recognition_ = 0;
}

Status ObjectTracker::Track(ObjectRecognizer& recognizer, const cv::Mat& image,
                            const CameraIntrinsics& camera, std::vector<Detection>* detections,
                            TrackingTiming* timing, const ObjectFilter& filter,
                            const DetectionOptions& extras) {
  detections->clear();
  RECOG_RETURN_IF_ERROR(camera.Validate());
  if (image.empty() || image.depth() != CV_8U) {
    return Status::InvalidArgument("the image to track in must be a non-empty 8-bit image");
  }
  return Run(recognizer, image, nullptr, camera, filter, extras, detections, timing);
}

Status ObjectTracker::TrackFeatures(ObjectRecognizer& recognizer, const FeatureSet& features,
                                    const CameraIntrinsics& camera,
                                    std::vector<Detection>* detections, TrackingTiming* timing,
                                    const ObjectFilter& filter, const DetectionOptions& extras) {
  detections->clear();
  RECOG_RETURN_IF_ERROR(camera.Validate());
  RECOG_RETURN_IF_ERROR(CheckFeatureSet(features, database_->vocabulary().info().descriptor)
                            .WithContext("frame features"));
  return Run(recognizer, cv::Mat(), &features, camera, filter, extras, detections, timing);
}

Status ObjectTracker::Run(ObjectRecognizer& recognizer, const cv::Mat& image,
                          const FeatureSet* features, const CameraIntrinsics& camera,
                          const ObjectFilter& filter, const DetectionOptions& extras,
                          std::vector<Detection>* detections, TrackingTiming* timing) {
  const auto start = Clock::now();
  TrackingTiming local;
  TrackingTiming* t = timing != nullptr ? timing : &local;
  *t = TrackingTiming();

  // Follow every tracked object (none with float descriptors: window matching is binary).
  std::vector<TrackedObject> followed;
  for (const TrackedObject& track : tracks_) {
    const std::shared_ptr<const IndexedObject> object = database_->Find(track.id);
    if (!object || !filter.Passes(object->metadata)) continue;  // removed, or not asked for
    const RigidTransform predicted =
        options_.constant_velocity && track.has_motion ? track.motion * track.pose : track.pose;
    Detection detection;
    if (!matcher_.Match(*object, predicted, image, features, camera, extras, &detection)) {
      ++t->lost;
      continue;
    }
    detection.tracked = true;
    followed.push_back({track.id, detection.camera_from_object,
                        detection.camera_from_object * track.pose.Inverse(), true});
    detections->push_back(std::move(detection));
  }
  tracks_.swap(followed);
  t->tracked = tracks_.size();
  t->tracking = MillisecondsSince(start);

  // Full recognition: nothing tracked, an object lost, or the periodic search for new objects.
  ++frames_since_recognition_;
  const bool binary = database_->vocabulary().info().descriptor.type == DescriptorType::kBinary;
  if (!binary || tracks_.empty() || t->lost > 0 ||
      (options_.recognition_interval > 0 &&
       frames_since_recognition_ >= options_.recognition_interval)) {
    const auto phase = Clock::now();
    std::vector<Detection> recognized;
    RECOG_RETURN_IF_ERROR(
        features != nullptr
            ? recognizer.RecognizeFeatures(*features, camera, &recognized, nullptr, filter, extras)
            : recognizer.Recognize(image, camera, &recognized, nullptr, filter, extras));
    for (Detection& detection : recognized) {
      const bool tracked = std::any_of(tracks_.begin(), tracks_.end(), [&](const TrackedObject& k) {
        return k.id == detection.id;
      });
      if (tracked) continue;
      if (binary) tracks_.push_back({detection.id, detection.camera_from_object, {}, false});
      detections->push_back(std::move(detection));
    }
    frames_since_recognition_ = 0;
    t->recognized = true;
    t->recognition = MillisecondsSince(phase);
  }
  std::stable_sort(detections->begin(), detections->end(),
                   [](const Detection& a, const Detection& b) { return a.inliers > b.inliers; });
  t->total = MillisecondsSince(start);
  return Status::Ok();
}

}  // namespace recog
