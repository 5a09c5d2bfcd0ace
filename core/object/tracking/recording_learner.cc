#include "core/object/tracking/recording_learner.h"

#include <cmath>

#include "core/common/option_checks.h"
#include "core/index/memory_index_store.h"
#include "core/object/recognition/object_database.h"
#include "core/object/recognition/object_recognizer.h"

namespace recog {
namespace {

// Unit vector from the object frame's origin to the camera centre, in the object frame.
cv::Vec3d ViewDirection(const RigidTransform& camera_from_object) {
  const cv::Vec3d centre = -(camera_from_object.R.t() * camera_from_object.t);
  const double norm = cv::norm(centre);
  return norm > 0 ? centre / norm : cv::Vec3d(0, 0, 1);
}

}  // namespace

Status RecordingLearningOptions::Validate(std::string_view name) const {
  OptionChecks check(name);
  check.InRange("min_view_angle_deg", min_view_angle_deg, RealRange::Open(0, 180));
  check.AtLeast("min_inliers", min_inliers, 1);
  check.AtLeast("max_views", max_views, 1);
  check.Member("tracking", tracking);
  return check.status();
}

StatusOr<LearnedModel> LearnFromRecording(const ModelFromViews& build,
                                          std::shared_ptr<const Vocabulary> vocabulary,
                                          const PosedImage& first,
                                          const std::vector<RecordingFrame>& frames,
                                          const RecordingLearningOptions& options,
                                          const LearningProgress& progress) {
  RECOG_RETURN_IF_ERROR(options.Validate());
  for (size_t i = 0; i < frames.size(); ++i) {
    if (frames[i].image.empty() || frames[i].image.depth() != CV_8U) {
      return Status::InvalidArgument("frame " + std::to_string(i) + " ('" + frames[i].name +
                                     "') of the recording is not an 8-bit image");
    }
  }
  LearnedModel learned;
  learned.views = {first};
  RECOG_ASSIGN_OR_RETURN(learned.model, build(learned.views));
  MemoryIndexStore store;
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<ObjectDatabase> database,
                         ObjectDatabase::Open(&store, vocabulary));
  RECOG_RETURN_IF_ERROR(database->Put(learned.model).status());
  RECOG_ASSIGN_OR_RETURN(ObjectRecognizer recognizer, ObjectRecognizer::Create(database));
  ObjectTracker tracker(database, options.tracking);
  std::vector<cv::Vec3d> directions = {ViewDirection(first.camera_from_object)};
  const double min_cosine = std::cos(options.min_view_angle_deg * CV_PI / 180.0);
  std::vector<Detection> detections;
  for (size_t i = 0; i < frames.size(); ++i) {
    RECOG_RETURN_IF_ERROR(tracker.Track(recognizer, frames[i].image, first.camera, &detections));
    if (!detections.empty()) {
      ++learned.frames_found;
      const Detection& found = detections.front();  // the database holds this object alone
      const cv::Vec3d direction = ViewDirection(found.camera_from_object);
      bool new_direction = true;
      for (const cv::Vec3d& seen : directions) new_direction &= direction.dot(seen) < min_cosine;
      if (new_direction && found.inliers >= options.min_inliers &&
          learned.views.size() < options.max_views) {
        PosedImage view = first;
        view.name = frames[i].name;
        view.image = frames[i].image;
        view.camera_from_object = found.camera_from_object;
        learned.views.push_back(std::move(view));
        learned.view_frames.push_back(i);
        directions.push_back(direction);
        RECOG_ASSIGN_OR_RETURN(learned.model, build(learned.views));
        RECOG_RETURN_IF_ERROR(database->Put(learned.model).status());
        tracker.Reset();  // the tracks point at the replaced model
      }
    }
    if (progress) progress(i + 1, frames.size(), learned.views.size());
  }
  return learned;
}

}  // namespace recog
