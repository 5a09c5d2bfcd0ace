// What recognition reports of an object found in an image (Detection), and the extras a call may
// ask for in it (DetectionOptions). The recogniser (object_recognizer.h), the tracker
// (object_tracker.h) and guided matching (guided_matcher.h) all produce detections.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/index/database.h"
#include "core/object/model/object_model.h"

namespace recog {

// What a call wants in each detection beyond its pose (both off = the plain detection).
struct DetectionOptions {
  bool include_inliers = false;     // Detection::inliers_2d3d
  bool include_covariance = false;  // Detection::covariance
};

// One RANSAC inlier of a detection: an image keypoint and the model point it matched.
struct InlierCorrespondence {
  cv::Point2f pixel;  // the keypoint in the image (as detected, lens distortion included)
  // The model feature that matched: a row of the model's descriptors (IndexedObject::points is
  // indexed the same way). In the model file, that feature describes point
  // points[point_of_feature[point_id]]; the features of one point share `point`.
  uint32_t point_id = 0;
  cv::Point3f point;  // the feature's 3D point, object frame, the model's units
};

struct Detection {
  EntryId id = kInvalidEntryId;
  // The recognised model's metadata (name, version, type, class, units).
  std::string name;
  uint32_t version = 0;
  ObjectType type = ObjectType::k3D;
  std::string object_class;
  std::string units;                  // of camera_from_object's translation
  RigidTransform camera_from_object;  // X_camera = R X_object + t, in the model's units
  size_t inliers = 0;
  size_t correspondences = 0;
  double reprojection_error_px = 0;        // mean over the inliers
  double score = 0;                        // chi-square score of the region against the object
  std::vector<cv::Point2f> outline;        // convex hull of the projected model, image pixels
  std::vector<cv::Point2f> inlier_pixels;  // the image points of the inliers
  int region = -1;                         // index of the region it was found in
  // True when an ObjectTracker followed it from a previous frame's pose (object_tracker.h); false
  // when it was recognised in this frame.
  bool tracked = false;
  // Only when DetectionOptions::include_inliers: every inlier, in no particular order.
  std::vector<InlierCorrespondence> inliers_2d3d;
  // Only when DetectionOptions::include_covariance: the 6×6 covariance of camera_from_object,
  // row-major, rotation (rotation-vector perturbation of R, radians) first, then translation (the
  // model's units). Empty when asked but the inliers are degenerate (e.g. all on one line).
  std::vector<double> covariance;
};

}  // namespace recog
