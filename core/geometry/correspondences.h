// Feature correspondences between two images, and their verification with epipolar geometry.
//
// Two ways to find putative matches between the features of image A and image B:
//  - through the direct index (thesis Algorithm 2): walk both images' FeatureVectors at once and
//    compare only features under the same vocabulary node; fast, approximate;
//  - exhaustively: every feature of A against every feature of B.
// Both keep a match when the nearest neighbour is close enough (max_distance), clearly better than
// the second nearest (ratio test, thesis §4.4.6: 0.6), and one-to-one (a feature of B taken by
// two features of A goes to the nearer one); optionally mutual (B's feature has A's as its own
// nearest, among the same candidates). Binary descriptors use the Hamming distance.
//
// VerifyEpipolar fits a fundamental matrix with RANSAC (OpenCV's, which is deterministic) and
// keeps the inliers. Two measures say how much those inliers are worth as evidence:
// SelectTwoViewModel compares F with a homography on the same correspondences (a planar scene or
// a pure rotation makes F degenerate: it fits, but proves nothing beyond what H explains), and
// InlierSpread says how much of both images the inliers cover.
#pragma once

#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/bow/feature_vector.h"
#include "core/common/status.h"

namespace recog {

struct Match {
  uint32_t a;         // feature index in image A
  uint32_t b;         // feature index in image B
  uint32_t distance;  // Hamming distance
  friend bool operator==(const Match&, const Match&) = default;
};

struct MatchOptions {
  double ratio = 0.6;          // best < ratio * second best, in (0, 1]; 1 disables the test
  uint32_t max_distance = 50;  // Hamming distance of an acceptable match (of 256 bits)
  // True: a match a -> b is kept only when a is also the nearest to b of A's features compared
  // with it (the cross check). It keeps a looser ratio from pairing a repeated element (one of a
  // façade's windows) with whichever copy happened to be nearest. Ties go to the first feature.
  bool mutual = false;

  // OK, or INVALID_ARGUMENT naming the field out of range; `name` names the struct in the message
  // (a holder passes the member's path, "RecognitionOptions.match").
  Status Validate(std::string_view name = "MatchOptions") const;
};

// Putative matches through the direct index. `a_direct`/`b_direct` index the rows of
// `a_descriptors`/`b_descriptors` (binary, CV_8U, same width). Matches come sorted by a.
// INVALID_ARGUMENT for descriptors that are not binary or not of one width; DATA_LOSS when a
// direct index names a feature its descriptors do not have: a direct index and its descriptors
// come from a stored record, which the caller names in the message.
Status MatchByDirectIndex(const FeatureVector& a_direct, const cv::Mat& a_descriptors,
                          const FeatureVector& b_direct, const cv::Mat& b_descriptors,
                          const MatchOptions& options, std::vector<Match>* matches);

// B's descriptors rearranged node by node in the order of `b_direct`: row p is the descriptor of
// the p-th feature b_direct lists (every node's features in turn). DATA_LOSS when b_direct names a
// row `descriptors` does not have.
StatusOr<cv::Mat> DescriptorsInDirectOrder(const FeatureVector& b_direct,
                                           const cv::Mat& descriptors);

// MatchByDirectIndex with B's descriptors given node by node (DescriptorsInDirectOrder): the
// same matches, but each node's candidates are read from contiguous memory, which is much faster
// for a large B read once per query (an object model out of the cache; docs/evaluation.md,
// "Benchmarks").
// Errors as MatchByDirectIndex's; DATA_LOSS too when `b_in_direct_order` does not have one row per
// feature of b_direct.
Status MatchByDirectIndexInOrder(const FeatureVector& a_direct, const cv::Mat& a_descriptors,
                                 const FeatureVector& b_direct, const cv::Mat& b_in_direct_order,
                                 const MatchOptions& options, std::vector<Match>* matches);

// Putative matches by comparing every pair of features.
Status MatchExhaustive(const cv::Mat& a_descriptors, const cv::Mat& b_descriptors,
                       const MatchOptions& options, std::vector<Match>* matches);

struct EpipolarOptions {
  double threshold_px = 2.0;  // distance to the epipolar line of an inlier
  double confidence = 0.99;
  int max_iterations = 1000;
  size_t min_inliers = 12;  // thesis Table 4.4
};

struct EpipolarResult {
  bool verified = false;       // a fundamental matrix with at least min_inliers inliers
  std::vector<Match> inliers;  // the matches consistent with it
  cv::Matx33d fundamental = cv::Matx33d::zeros();
};

// Fits F with RANSAC to the matched keypoints (x_b^T F x_a = 0). Fewer than 8 matches: not
// verified.
EpipolarResult VerifyEpipolar(const std::vector<cv::KeyPoint>& a_keypoints,
                              const std::vector<cv::KeyPoint>& b_keypoints,
                              const std::vector<Match>& matches, const EpipolarOptions& options);

struct ModelSelectionOptions {
  // Standard deviation of a keypoint's position: errors are measured in units of sigma^2 against
  // the chi-square cutoffs of ORB-SLAM's initialisation (3.84 for F's one-dimensional distance to
  // the epipolar line, 5.99 for H's two-dimensional transfer error, both at 95 %).
  double sigma_px = 1.0;
  // RANSAC of the homography (OpenCV's findHomography, deterministic).
  double threshold_px = 2.0;
  double confidence = 0.99;
  int max_iterations = 1000;
};

struct ModelSelection {
  double fundamental_score = 0;  // S_F
  double homography_score = 0;   // S_H
  // R_H = S_H / (S_H + S_F), 0 when both scores are 0. About 0.5 when H explains the
  // correspondences as well as F (a plane, a pure rotation); well below when only F does (a 3D
  // scene seen with translation). ORB-SLAM's initialisation picks H above 0.40-0.45.
  double homography_ratio = 0;
  cv::Matx33d homography = cv::Matx33d::zeros();  // x_b ~ H x_a (zero when none was found)
};

// Scores `fundamental` (x_b^T F x_a = 0) and a homography fitted by RANSAC to the same matches,
// as ORB-SLAM's initialisation does: every match adds, for each of the two images, the cutoff
// 5.99 minus its squared error over sigma^2 when that error is under the model's cutoff (F: the
// squared distance to the epipolar line, cutoff 3.84; H: the squared transfer error, cutoff
// 5.99), so both scores are on one scale. Fewer than 4 matches, or an out-of-range match: all 0.
ModelSelection SelectTwoViewModel(const std::vector<cv::KeyPoint>& a_keypoints,
                                  const std::vector<cv::KeyPoint>& b_keypoints,
                                  const std::vector<Match>& matches, const cv::Matx33d& fundamental,
                                  const ModelSelectionOptions& options);

// How much of both images the matches cover: each image's keypoints' bounding box is cut into a
// grid x grid array of cells, and the share of cells holding at least one matched keypoint is
// measured in both images; the smaller share is returned (0 without matches or with a match out
// of range). Matches bunched in one corner say less than as many spread over the whole view.
double InlierSpread(const std::vector<cv::KeyPoint>& a_keypoints,
                    const std::vector<cv::KeyPoint>& b_keypoints, const std::vector<Match>& matches,
                    int grid);

// The relative pose of two views, by cameras of intrinsics K_a and K_b (the same camera: pass its
// K twice), from their fundamental matrix (x_b^T F x_a = 0) and its inlier matches:
// X_b = R * X_a + t with |t| = 1 (two views fix the translation up to scale). The essential matrix
// K_b^T F K_a is decomposed and the one of its four solutions that puts the most inliers (pixels
// normalised by their own camera) in front of both cameras is kept. False when F is zero or fewer
// than 5 inliers triangulate in front of both cameras.
bool RelativePoseFromFundamental(const cv::Matx33d& fundamental, const cv::Matx33d& K_a,
                                 const cv::Matx33d& K_b,
                                 const std::vector<cv::KeyPoint>& a_keypoints,
                                 const std::vector<cv::KeyPoint>& b_keypoints,
                                 const std::vector<Match>& inliers, cv::Matx33d* R, cv::Vec3d* t);

struct EssentialOptions {
  double threshold_px = 1.0;  // distance to the epipolar line, pixels at the cameras' mean focal
  double confidence = 0.999;
  int max_iterations = 1000;
};

// What the matches of two calibrated views say through their essential matrix: its RANSAC
// inliers, the relative pose X_b = R * X_a + t (|t| = 1) of the decomposition that puts the most
// inliers in front of both cameras, and how the inliers triangulate with it.
struct EssentialResult {
  bool found = false;          // an essential matrix with at least 5 inliers
  std::vector<Match> inliers;  // consistent with E (in front or not)
  cv::Matx33d essential = cv::Matx33d::zeros();
  cv::Matx33d R = cv::Matx33d::eye();
  cv::Vec3d t = cv::Vec3d(0, 0, 0);
  // Inliers whose two rays meet in front of both cameras, or are parallel and point the same way
  // (a point at infinity, as every point of a pure rotation is).
  uint32_t in_front = 0;
  // The median angle between an inlier's two rays (degrees): 0 for a pure rotation, larger the
  // more the baseline shows. It is what makes the depths, and F itself, well defined.
  double parallax_deg = 0;
  // Inliers the rotation alone explains: within threshold_px once x_b is mapped by K_b R K_a^-1.
  uint32_t rotation_only = 0;
};

// Fits an essential matrix with RANSAC (OpenCV's five-point solver, deterministic) to the matches,
// their pixels normalised by each camera, and measures the result (see EssentialResult). Fewer
// than 5 matches, or an out-of-range match: not found.
EssentialResult VerifyEssential(const cv::Matx33d& K_a, const cv::Matx33d& K_b,
                                const std::vector<cv::KeyPoint>& a_keypoints,
                                const std::vector<cv::KeyPoint>& b_keypoints,
                                const std::vector<Match>& matches, const EssentialOptions& options);

// What a given essential matrix (x_b^T E x_a = 0 in normalised pixels; K_b^T F K_a of a
// fundamental matrix) says of its `inliers`: the decomposition that puts the most of them in front
// of both cameras and how they triangulate with it (EssentialResult; `inliers` as given). Fewer
// than 5 inliers, or one out of range: not found.
EssentialResult MeasureEssential(const cv::Matx33d& essential, const cv::Matx33d& K_a,
                                 const cv::Matx33d& K_b,
                                 const std::vector<cv::KeyPoint>& a_keypoints,
                                 const std::vector<cv::KeyPoint>& b_keypoints,
                                 const std::vector<Match>& inliers, double threshold_px);

// The relative pose of two calibrated views (X_b = R * X_a + t, |t| = 1) from their matches,
// by the five-point algorithm (VerifyEssential): an essential matrix fitted with RANSAC (OpenCV's,
// deterministic) to the pixels normalised by each camera, `threshold_px` from its epipolar lines,
// then the one of its four decompositions with the most RANSAC inliers in front of both cameras.
// Unlike RelativePoseFromFundamental, which decomposes K_bᵀ F K_a, the fit itself knows the
// cameras: on the rig drives of tools/evaluation/rig_place_test.cc this cuts the rotation error
// several times. False with fewer than 5 matches, or fewer than 5 points in front.
bool RelativePoseFromMatches(const cv::Matx33d& K_a, const cv::Matx33d& K_b,
                             const std::vector<cv::KeyPoint>& a_keypoints,
                             const std::vector<cv::KeyPoint>& b_keypoints,
                             const std::vector<Match>& matches, double threshold_px, cv::Matx33d* R,
                             cv::Vec3d* t);

}  // namespace recog
