// The motion of a multi-camera rig's body between two rig frames, from the correspondences of
// several camera pairs at once (thesis §3.3.2: features of one camera checked against the
// epipolar lines of another, through the rig's known extrinsics).
//
// A camera pair (query camera q of one rig frame, match camera m of the other) sees the body
// motion X_body_q = R X_body_m + t as the camera motion X_q = R_p X_m + t_p with
//   R_p = R_qᵀ R R_m,  t_p = R_qᵀ (R c_m + t - c_q)
// (R_q, c_q: camera q's pose in the body frame; likewise m), so each correspondence (x_q, x_m)
// must lie on the epipolar line of E_p = [t_p]x R_p. One pair alone fixes its rotation only up to
// the rotation-translation ambiguity of a narrow view (a small turn looks like a small sideways
// step); cameras looking different ways resolve it, because one body translation must explain
// them all. Wrong extrinsics leave no body motion that fits every pair.
#pragma once

#include <span>
#include <vector>

#include <opencv2/core.hpp>

namespace recog {

// One camera pair's correspondences, as normalised rays K^-1 (u, v, 1) of each camera.
struct RigPairRays {
  cv::Matx33d query_R = cv::Matx33d::eye(), match_R = cv::Matx33d::eye();  // body_R_camera
  cv::Vec3d query_t = cv::Vec3d(0, 0, 0), match_t = cv::Vec3d(0, 0, 0);    // body_t_camera
  std::vector<cv::Vec3d> query, match;  // one ray each per correspondence
  double focal_px = 1;                  // pixels per normalised unit (errors are in pixels)
};

// The Sampson distance (pixels) of each correspondence of `pair` to the epipolar geometry the
// body motion (R, t) gives it, into `errors_px` (resized). A motion that leaves the pair's
// cameras at one place (t_p = 0) gives every correspondence an infinite error.
void RigPairEpipolarErrors(const RigPairRays& pair, const cv::Matx33d& R, const cv::Vec3d& t,
                           std::vector<double>* errors_px);

// The body motion that best fits the epipolar geometry of every pair: the robust (Huber,
// `huber_px`) sum of squared Sampson distances, minimised by Levenberg-Marquardt from (*R, *t),
// which are updated. The starting translation may be any guess of the right direction; its
// length is fixed only by the cameras' offsets on the body (weakly for cameras on a line along
// the motion), so only the rotation and the direction of t are to be trusted without depth.
void RefineRigMotion(std::span<const RigPairRays> pairs, double huber_px, cv::Matx33d* R,
                     cv::Vec3d* t);

// A starting point for RefineRigMotion: the rotation `R` of one pair's essential matrix carried
// into the body frame, and the body translation t = R_q (s d) + c_q - R c_m of pair `reference`
// whose camera translation direction is `direction` (unit, X_q = R_p X_m + s d), with the scale
// s (from 5 cm to 50 m, on a logarithmic grid) that fits all the pairs best.
cv::Vec3d InitialRigTranslation(std::span<const RigPairRays> pairs, size_t reference,
                                const cv::Vec3d& direction, const cv::Matx33d& R, double huber_px);

}  // namespace recog
