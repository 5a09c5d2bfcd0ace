// CameraTrajectory: the metric pose of every frame of a place sequence and its camera, and what
// they say of a detected loop (`recog eval place --poses FILE --camera fx,fy,cx,cy`).
//
// A loop's matched frames may be the same place by the ground-truth matrix and still be a false
// loop: its inliers may fit some geometry, just not the true one (the look-alike façades of a
// courtyard). With the poses, a loop is scored by its inliers: each is checked against the true
// epipolar geometry of the two cameras (its Sampson distance to the fundamental matrix the poses
// give), and the loop holds when at least 30 % of them agree (kMinAgreeingShare): ORB keypoints
// of coarse pyramid levels sit a few pixels off, and a right loop's essential matrix takes some
// of those in; on the Strecha walks of shared/data, the share separates ORB pairs of different
// places from pairs of one place (the shares are in docs/places.md, "Evaluation against camera
// poses").
//
// The pose file is Strecha's, as shared/data/places/strecha-keyframes has it: '#' starts a
// comment, blank lines are skipped, and line k (k-th frame, from 1) is
//   r11 r12 r13 r21 r22 r23 r31 r32 r33 cx cy cz
// the camera-to-world rotation (row-major) and the camera centre (metres): a world point X is at
// R^T (X - c) in the camera.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/feature_set.h"
#include "core/common/status.h"
#include "core/geometry/correspondences.h"

namespace recog::cli {

// A camera in the world: X_world = world_from_camera * X_camera + center.
struct CameraPose {
  cv::Matx33d world_from_camera = cv::Matx33d::eye();
  cv::Vec3d center = cv::Vec3d(0, 0, 0);  // metres
};

// The poses of a sequence's frames (one per frame, in order) and their camera.
struct CameraTrajectory {
  std::vector<CameraPose> poses;
  cv::Matx33d K = cv::Matx33d::eye();
};

// NOT_FOUND for a missing file; INVALID_ARGUMENT naming the file and line for a line that is not
// 12 finite numbers or whose rotation is not one (IsRotationMatrix).
StatusOr<std::vector<CameraPose>> ReadCameraPoses(const std::string& path);

// What the poses say of a loop between two frames.
struct LoopGeometryTruth {
  double distance_m = 0;  // between the camera centres
  double angle_deg = 0;   // between the optical axes
  uint32_t inliers = 0;   // the loop's inliers
  uint32_t agreeing = 0;  // of them, within kMaxSampsonPx of the true epipolar geometry
  bool agrees = false;    // agreeing >= kMinAgreeingShare of the inliers (and > 0)
};

inline constexpr double kMaxSampsonPx = 2.0;
inline constexpr double kMinAgreeingShare = 0.3;

// The fundamental matrix of the two cameras: x_query^T F x_match = 0 (pixels of camera K).
cv::Matx33d TrueFundamental(const CameraPose& query, const CameraPose& match, const cv::Matx33d& K);

// The loop from frame `query` (features `query_features`) to `match`, whose inliers pair
// query feature a with match feature b.
LoopGeometryTruth ScoreLoopGeometry(const CameraPose& query, const CameraPose& match,
                                    const cv::Matx33d& K, const FeatureSet& query_features,
                                    const FeatureSet& match_features,
                                    const std::vector<Match>& inliers);

// One loop drawn over the trajectory: frames (0-based) and how it was judged.
struct DrawnLoop {
  int query = 0, match = 0;
  enum class Verdict { kCorrect, kFalse, kAmbiguous } verdict = Verdict::kCorrect;
};

// A PNG (size x size pixels) of the camera centres seen from above (the plane of their two main
// directions), in order, each labelled with its frame number and its viewing direction, and the
// loops as lines between the two cameras: green correct, red false, orange ambiguous; a legend
// and the scale in metres. INTERNAL when it cannot be written.
Status WriteTrajectoryPlot(const std::vector<CameraPose>& poses,
                           const std::vector<DrawnLoop>& loops, const std::string& title,
                           const std::string& path, int size = 900);

}  // namespace recog::cli
