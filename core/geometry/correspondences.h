// Feature correspondences between two images, and their verification with epipolar geometry.
//
// Two ways to find putative matches between the features of image A and image B:
//  - through the direct index (thesis Algorithm 2): walk both images' FeatureVectors at once and
//    compare only features under the same vocabulary node; fast, approximate;
//  - exhaustively: every feature of A against every feature of B.
// Both keep a match when the nearest neighbour is close enough (max_distance), clearly better than
// the second nearest (ratio test, thesis §4.4.6: 0.6), and one-to-one (a feature of B taken by
// two features of A goes to the nearer one). Binary descriptors use the Hamming distance.
//
// VerifyEpipolar fits a fundamental matrix with RANSAC (OpenCV's, which is deterministic) and
// keeps the inliers.
#pragma once

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
  double ratio = 0.6;          // best < ratio * second best; 1 disables the test
  uint32_t max_distance = 50;  // Hamming distance of an acceptable match (of 256 bits)
};

// Putative matches through the direct index. `a_direct`/`b_direct` index the rows of
// `a_descriptors`/`b_descriptors` (binary, CV_8U, same width). Matches come sorted by a.
Status MatchByDirectIndex(const FeatureVector& a_direct, const cv::Mat& a_descriptors,
                          const FeatureVector& b_direct, const cv::Mat& b_descriptors,
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

// The relative pose of two views of one camera (intrinsics K) from their fundamental matrix
// (x_b^T F x_a = 0) and its inlier matches: X_b = R * X_a + t with |t| = 1 (two views fix the
// translation up to scale). The essential matrix K^T F K is decomposed and the one of its four
// solutions that puts the most inliers in front of both cameras is kept. False when F is zero or
// fewer than 5 inliers triangulate in front of both cameras.
bool RelativePoseFromFundamental(const cv::Matx33d& fundamental, const cv::Matx33d& K,
                                 const std::vector<cv::KeyPoint>& a_keypoints,
                                 const std::vector<cv::KeyPoint>& b_keypoints,
                                 const std::vector<Match>& inliers, cv::Matx33d* R, cv::Vec3d* t);

}  // namespace recog
