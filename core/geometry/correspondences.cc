#include "core/geometry/correspondences.h"

#include <algorithm>
#include <limits>

#include <opencv2/calib3d.hpp>

#include "core/common/descriptor.h"

namespace recog {
namespace {

Status CheckBinary(const cv::Mat& a, const cv::Mat& b) {
  const bool a_ok = a.empty() || (a.type() == CV_8UC1 && a.isContinuous() && a.cols % 8 == 0);
  const bool b_ok = b.empty() || (b.type() == CV_8UC1 && b.isContinuous() && b.cols % 8 == 0);
  if (!a_ok || !b_ok || (!a.empty() && !b.empty() && a.cols != b.cols)) {
    return Status::InvalidArgument(
        "matching needs continuous binary descriptors (CV_8U, a multiple of 8 columns) of one "
        "width");
  }
  return Status::Ok();
}

// Best and second-best candidate of one feature of A.
struct Nearest {
  uint32_t best = std::numeric_limits<uint32_t>::max();
  uint32_t second = std::numeric_limits<uint32_t>::max();
  uint32_t index = 0;

  void Offer(uint32_t distance, uint32_t b) {
    if (distance < best) {
      second = best;
      best = distance;
      index = b;
    } else if (distance < second) {
      second = distance;
    }
  }
  bool Accept(const MatchOptions& o) const {
    if (best > o.max_distance) return false;
    return second == std::numeric_limits<uint32_t>::max() ||
           double(best) < o.ratio * double(second);
  }
};

uint32_t Distance(const cv::Mat& a, uint32_t i, const cv::Mat& b, uint32_t j) {
  const uint8_t* p = a.ptr<uint8_t>(int(i));
  const uint8_t* q = b.ptr<uint8_t>(int(j));
  return a.cols == 32 ? Hamming256(p, q) : HammingDistance(p, q, size_t(a.cols));
}

// Keeps one match per feature of B (the nearest), then sorts by feature of A.
void MakeOneToOne(std::vector<Match>* matches) {
  std::sort(matches->begin(), matches->end(), [](const Match& x, const Match& y) {
    return x.b != y.b ? x.b < y.b
                      : (x.distance != y.distance ? x.distance < y.distance : x.a < y.a);
  });
  matches->erase(std::unique(matches->begin(), matches->end(),
                             [](const Match& x, const Match& y) { return x.b == y.b; }),
                 matches->end());
  std::sort(matches->begin(), matches->end(),
            [](const Match& x, const Match& y) { return x.a < y.a; });
}

}  // namespace

Status MatchByDirectIndex(const FeatureVector& a_direct, const cv::Mat& a_descriptors,
                          const FeatureVector& b_direct, const cv::Mat& b_descriptors,
                          const MatchOptions& options, std::vector<Match>* matches) {
  matches->clear();
  RECOG_RETURN_IF_ERROR(CheckBinary(a_descriptors, b_descriptors));
  const uint32_t a_rows = uint32_t(a_descriptors.rows), b_rows = uint32_t(b_descriptors.rows);
  size_t i = 0, j = 0;
  while (i < a_direct.size() && j < b_direct.size()) {
    if (a_direct.node(i) < b_direct.node(j)) {
      ++i;
    } else if (a_direct.node(i) > b_direct.node(j)) {
      ++j;
    } else {
      for (uint32_t fa : a_direct.features(i)) {
        if (fa >= a_rows) return Status::InvalidArgument("direct index of A exceeds its features");
        Nearest nearest;
        for (uint32_t fb : b_direct.features(j)) {
          if (fb >= b_rows)
            return Status::InvalidArgument("direct index of B exceeds its features");
          nearest.Offer(Distance(a_descriptors, fa, b_descriptors, fb), fb);
        }
        if (nearest.Accept(options)) matches->push_back({fa, nearest.index, nearest.best});
      }
      ++i;
      ++j;
    }
  }
  MakeOneToOne(matches);
  return Status::Ok();
}

Status MatchExhaustive(const cv::Mat& a_descriptors, const cv::Mat& b_descriptors,
                       const MatchOptions& options, std::vector<Match>* matches) {
  matches->clear();
  RECOG_RETURN_IF_ERROR(CheckBinary(a_descriptors, b_descriptors));
  for (uint32_t fa = 0; fa < uint32_t(a_descriptors.rows); ++fa) {
    Nearest nearest;
    for (uint32_t fb = 0; fb < uint32_t(b_descriptors.rows); ++fb) {
      nearest.Offer(Distance(a_descriptors, fa, b_descriptors, fb), fb);
    }
    if (nearest.Accept(options)) matches->push_back({fa, nearest.index, nearest.best});
  }
  MakeOneToOne(matches);
  return Status::Ok();
}

EpipolarResult VerifyEpipolar(const std::vector<cv::KeyPoint>& a_keypoints,
                              const std::vector<cv::KeyPoint>& b_keypoints,
                              const std::vector<Match>& matches, const EpipolarOptions& options) {
  EpipolarResult result;
  if (matches.size() < std::max<size_t>(8, options.min_inliers)) return result;
  std::vector<cv::Point2f> pa, pb;
  pa.reserve(matches.size());
  pb.reserve(matches.size());
  for (const Match& m : matches) {
    if (m.a >= a_keypoints.size() || m.b >= b_keypoints.size()) return result;
    pa.push_back(a_keypoints[m.a].pt);
    pb.push_back(b_keypoints[m.b].pt);
  }
  std::vector<uchar> mask;
  cv::Mat f;
  try {
    f = cv::findFundamentalMat(pa, pb, cv::FM_RANSAC, options.threshold_px, options.confidence,
                               options.max_iterations, mask);
  } catch (const cv::Exception&) {
    return result;  // degenerate configuration: not verified
  }
  if (f.rows != 3 || f.cols != 3) return result;
  for (size_t k = 0; k < matches.size(); ++k) {
    if (mask[k]) result.inliers.push_back(matches[k]);
  }
  result.fundamental = cv::Matx33d(f.ptr<double>(0));
  result.verified = result.inliers.size() >= options.min_inliers;
  return result;
}

bool RelativePoseFromFundamental(const cv::Matx33d& fundamental, const cv::Matx33d& K,
                                 const std::vector<cv::KeyPoint>& a_keypoints,
                                 const std::vector<cv::KeyPoint>& b_keypoints,
                                 const std::vector<Match>& inliers, cv::Matx33d* R, cv::Vec3d* t) {
  if (cv::norm(fundamental) == 0.0 || inliers.size() < 5) return false;
  std::vector<cv::Point2d> pa, pb;
  pa.reserve(inliers.size());
  pb.reserve(inliers.size());
  for (const Match& m : inliers) {
    if (m.a >= a_keypoints.size() || m.b >= b_keypoints.size()) return false;
    pa.emplace_back(a_keypoints[m.a].pt);
    pb.emplace_back(b_keypoints[m.b].pt);
  }
  const cv::Matx33d essential = K.t() * fundamental * K;
  cv::Mat rotation, translation;
  int in_front = 0;
  try {
    in_front = cv::recoverPose(cv::Mat(essential), pa, pb, cv::Mat(K), rotation, translation);
  } catch (const cv::Exception&) {
    return false;  // degenerate essential matrix
  }
  if (in_front < 5) return false;
  rotation.convertTo(rotation, CV_64F);
  translation.convertTo(translation, CV_64F);
  *R = cv::Matx33d(rotation);
  *t = cv::Vec3d(translation);
  return true;
}

}  // namespace recog
