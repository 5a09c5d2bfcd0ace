#include "core/geometry/correspondences.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include <opencv2/calib3d.hpp>

#include "core/common/descriptor.h"
#include "core/common/option_checks.h"

namespace recog {
namespace {

// DATA_LOSS unless every feature that `features` (a node of a direct index) names is a row of
// `rows` descriptors; `side` says whose index it is ("A", "B").
Status CheckDirectFeatures(std::span<const uint32_t> features, uint32_t rows,
                           std::string_view side) {
  if (features.empty()) return Status::Ok();
  const uint32_t last = *std::max_element(features.begin(), features.end());
  if (last < rows) return Status::Ok();
  return Status::DataLoss("the direct index of " + std::string(side) + " names feature " +
                          std::to_string(last) + ", but " + std::string(side) + " has " +
                          std::to_string(rows) + " features");
}

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
  uint32_t index = 0;  // the nearest feature of B, as its caller numbers it

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

// The cross check of MatchOptions::mutual over one set of candidates: for each feature of B
// (numbered 0..n-1 by the caller), the nearest feature of A offered to it. Reused between sets.
class NearestOfB {
 public:
  void Reset(size_t n) {
    distance_.assign(n, std::numeric_limits<uint32_t>::max());
    a_.assign(n, 0);
  }
  void Offer(size_t b, uint32_t distance, uint32_t a) {
    if (distance < distance_[b]) {
      distance_[b] = distance;
      a_[b] = a;
    }
  }
  bool IsNearest(size_t b, uint32_t a) const { return a_[b] == a; }

 private:
  std::vector<uint32_t> distance_;
  std::vector<uint32_t> a_;
};

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

// Every pair of features under a node both direct indices share; row_of_b(j, k) is the
// descriptor of the k-th feature of b_direct's node j. The distance is the innermost loop, so it
// is chosen once, outside it.
template <class RowOfB>
Status MatchSharedNodes(const FeatureVector& a_direct, const cv::Mat& a_descriptors,
                        const FeatureVector& b_direct, uint32_t b_rows, size_t stride,
                        const RowOfB& row_of_b, const MatchOptions& options,
                        std::vector<Match>* matches) {
  matches->clear();
  const uint32_t a_rows = uint32_t(a_descriptors.rows);
  const uint8_t* a_base = a_descriptors.data;  // null when empty: no index passes the checks
  NearestOfB nearest_of_b;
  std::vector<Match> node_matches;  // b is the position in the node until the cross check
  auto match = [&](const auto& distance) -> Status {
    size_t i = 0, j = 0;
    while (i < a_direct.size() && j < b_direct.size()) {
      if (a_direct.node(i) < b_direct.node(j)) {
        ++i;
      } else if (a_direct.node(i) > b_direct.node(j)) {
        ++j;
      } else {
        const std::span<const uint32_t> a_features = a_direct.features(i);
        const std::span<const uint32_t> b_features = b_direct.features(j);
        // Checked here, not trusted: a direct index may come from a decoded record.
        RECOG_RETURN_IF_ERROR(CheckDirectFeatures(a_features, a_rows, "A"));
        RECOG_RETURN_IF_ERROR(CheckDirectFeatures(b_features, b_rows, "B"));
        nearest_of_b.Reset(options.mutual ? b_features.size() : 0);
        node_matches.clear();
        for (uint32_t fa : a_features) {
          const uint8_t* a_row = a_base + size_t(fa) * stride;
          Nearest nearest;
          for (size_t k = 0; k < b_features.size(); ++k) {
            const uint32_t d = distance(a_row, row_of_b(j, k));
            nearest.Offer(d, uint32_t(k));
            if (options.mutual) nearest_of_b.Offer(k, d, fa);
          }
          if (nearest.Accept(options)) node_matches.push_back({fa, nearest.index, nearest.best});
        }
        for (const Match& m : node_matches) {
          if (!options.mutual || nearest_of_b.IsNearest(m.b, m.a)) {
            matches->push_back({m.a, b_features[m.b], m.distance});
          }
        }
        ++i;
        ++j;
      }
    }
    return Status::Ok();
  };
  if (stride == 32) {
    RECOG_RETURN_IF_ERROR(
        match([](const uint8_t* a, const uint8_t* b) { return Hamming256(a, b); }));
  } else {
    RECOG_RETURN_IF_ERROR(match(
        [stride](const uint8_t* a, const uint8_t* b) { return HammingDistance(a, b, stride); }));
  }
  MakeOneToOne(matches);
  return Status::Ok();
}

}  // namespace

Status MatchOptions::Validate(std::string_view name) const {
  OptionChecks check(name);
  check.InRange("ratio", ratio, RealRange::OpenClosed(0, 1));
  return check.status();
}

Status MatchByDirectIndex(const FeatureVector& a_direct, const cv::Mat& a_descriptors,
                          const FeatureVector& b_direct, const cv::Mat& b_descriptors,
                          const MatchOptions& options, std::vector<Match>* matches) {
  matches->clear();
  RECOG_RETURN_IF_ERROR(CheckBinary(a_descriptors, b_descriptors));
  const size_t stride = size_t(a_descriptors.cols);
  const uint8_t* b_base = b_descriptors.data;
  return MatchSharedNodes(
      a_direct, a_descriptors, b_direct, uint32_t(b_descriptors.rows), stride,
      [&](size_t j, size_t k) { return b_base + size_t(b_direct.features(j)[k]) * stride; },
      options, matches);
}

StatusOr<cv::Mat> DescriptorsInDirectOrder(const FeatureVector& b_direct,
                                           const cv::Mat& descriptors) {
  RECOG_RETURN_IF_ERROR(CheckBinary(descriptors, descriptors));
  cv::Mat ordered(int(b_direct.num_features()), descriptors.cols, CV_8U);
  int row = 0;
  for (size_t j = 0; j < b_direct.size(); ++j) {
    RECOG_RETURN_IF_ERROR(
        CheckDirectFeatures(b_direct.features(j), uint32_t(descriptors.rows), "B"));
    for (uint32_t f : b_direct.features(j)) descriptors.row(int(f)).copyTo(ordered.row(row++));
  }
  return ordered;
}

Status MatchByDirectIndexInOrder(const FeatureVector& a_direct, const cv::Mat& a_descriptors,
                                 const FeatureVector& b_direct, const cv::Mat& b_in_direct_order,
                                 const MatchOptions& options, std::vector<Match>* matches) {
  matches->clear();
  RECOG_RETURN_IF_ERROR(CheckBinary(a_descriptors, b_in_direct_order));
  if (size_t(b_in_direct_order.rows) != b_direct.num_features()) {
    return Status::DataLoss("B's descriptors in direct order have " +
                            std::to_string(b_in_direct_order.rows) + " rows for the " +
                            std::to_string(b_direct.num_features()) +
                            " features of its direct index");
  }
  const size_t stride = size_t(a_descriptors.cols);
  const uint8_t* b_base = b_in_direct_order.data;
  return MatchSharedNodes(
      a_direct, a_descriptors, b_direct, uint32_t(b_in_direct_order.rows), stride,
      [&](size_t j, size_t k) { return b_base + (b_direct.first_position(j) + k) * stride; },
      options, matches);
}

Status MatchExhaustive(const cv::Mat& a_descriptors, const cv::Mat& b_descriptors,
                       const MatchOptions& options, std::vector<Match>* matches) {
  matches->clear();
  RECOG_RETURN_IF_ERROR(CheckBinary(a_descriptors, b_descriptors));
  NearestOfB nearest_of_b;
  nearest_of_b.Reset(options.mutual ? size_t(b_descriptors.rows) : 0);
  for (uint32_t fa = 0; fa < uint32_t(a_descriptors.rows); ++fa) {
    Nearest nearest;
    for (uint32_t fb = 0; fb < uint32_t(b_descriptors.rows); ++fb) {
      const uint32_t d = Distance(a_descriptors, fa, b_descriptors, fb);
      nearest.Offer(d, fb);
      if (options.mutual) nearest_of_b.Offer(fb, d, fa);
    }
    if (nearest.Accept(options)) matches->push_back({fa, nearest.index, nearest.best});
  }
  if (options.mutual) {
    std::erase_if(*matches, [&](const Match& m) { return !nearest_of_b.IsNearest(m.b, m.a); });
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

namespace {

// Squared distance of `x` to the line l = (a, b, c), infinite for a degenerate line.
double SquaredLineDistance(const cv::Vec3d& l, const cv::Point2d& x) {
  const double norm = l[0] * l[0] + l[1] * l[1];
  if (norm <= 0.0) return std::numeric_limits<double>::infinity();
  const double d = l[0] * x.x + l[1] * x.y + l[2];
  return d * d / norm;
}

// Squared distance between `to` and `from` mapped by M (infinite at a point at infinity).
double SquaredTransferError(const cv::Matx33d& m, const cv::Point2d& from, const cv::Point2d& to) {
  const cv::Vec3d p = m * cv::Vec3d(from.x, from.y, 1.0);
  if (std::abs(p[2]) < 1e-12) return std::numeric_limits<double>::infinity();
  const double dx = p[0] / p[2] - to.x, dy = p[1] / p[2] - to.y;
  return dx * dx + dy * dy;
}

// ORB-SLAM's score of one squared error: the 5.99 cutoff minus the error in sigma^2 units, when
// the error is under the model's cutoff.
double ChiSquareScore(double squared_error, double inv_sigma2, double cutoff) {
  constexpr double kScoreCutoff = 5.991;  // chi-square, 2 degrees of freedom, 95 %
  const double chi2 = squared_error * inv_sigma2;
  return chi2 < cutoff ? kScoreCutoff - chi2 : 0.0;
}

// The share of grid x grid cells over the bounding box of `keypoints` that hold a matched one.
double CoveredShare(const std::vector<cv::KeyPoint>& keypoints, const std::vector<uint32_t>& used,
                    int grid) {
  float x0 = std::numeric_limits<float>::max(), y0 = x0, x1 = -x0, y1 = -x0;
  for (const cv::KeyPoint& k : keypoints) {
    x0 = std::min(x0, k.pt.x);
    y0 = std::min(y0, k.pt.y);
    x1 = std::max(x1, k.pt.x);
    y1 = std::max(y1, k.pt.y);
  }
  const double w = std::max(1e-6, double(x1 - x0)), h = std::max(1e-6, double(y1 - y0));
  std::vector<bool> occupied(size_t(grid * grid), false);
  for (uint32_t i : used) {
    const int cx = std::min(grid - 1, int(double(keypoints[i].pt.x - x0) / w * grid));
    const int cy = std::min(grid - 1, int(double(keypoints[i].pt.y - y0) / h * grid));
    occupied[size_t(cy * grid + cx)] = true;
  }
  return double(std::count(occupied.begin(), occupied.end(), true)) / double(grid * grid);
}

}  // namespace

ModelSelection SelectTwoViewModel(const std::vector<cv::KeyPoint>& a_keypoints,
                                  const std::vector<cv::KeyPoint>& b_keypoints,
                                  const std::vector<Match>& matches, const cv::Matx33d& fundamental,
                                  const ModelSelectionOptions& options) {
  ModelSelection result;
  if (matches.size() < 4) return result;
  std::vector<cv::Point2d> pa, pb;
  pa.reserve(matches.size());
  pb.reserve(matches.size());
  for (const Match& m : matches) {
    if (m.a >= a_keypoints.size() || m.b >= b_keypoints.size()) return result;
    pa.emplace_back(a_keypoints[m.a].pt);
    pb.emplace_back(b_keypoints[m.b].pt);
  }
  cv::Mat h;
  try {
    h = cv::findHomography(pa, pb, cv::RANSAC, options.threshold_px, cv::noArray(),
                           options.max_iterations, options.confidence);
  } catch (const cv::Exception&) {
    h.release();  // degenerate configuration: no homography
  }
  constexpr double kLineCutoff = 3.841;      // chi-square, 1 degree of freedom, 95 %
  constexpr double kTransferCutoff = 5.991;  // chi-square, 2 degrees of freedom, 95 %
  const double inv_sigma2 = 1.0 / (options.sigma_px * options.sigma_px);
  const cv::Matx33d f_t = fundamental.t();
  for (size_t i = 0; i < pa.size(); ++i) {
    const cv::Vec3d xa(pa[i].x, pa[i].y, 1.0), xb(pb[i].x, pb[i].y, 1.0);
    result.fundamental_score +=
        ChiSquareScore(SquaredLineDistance(fundamental * xa, pb[i]), inv_sigma2, kLineCutoff) +
        ChiSquareScore(SquaredLineDistance(f_t * xb, pa[i]), inv_sigma2, kLineCutoff);
  }
  if (h.rows == 3 && h.cols == 3) {
    result.homography = cv::Matx33d(h.ptr<double>(0));
    const cv::Matx33d h_inv = result.homography.inv();
    for (size_t i = 0; i < pa.size(); ++i) {
      result.homography_score +=
          ChiSquareScore(SquaredTransferError(result.homography, pa[i], pb[i]), inv_sigma2,
                         kTransferCutoff) +
          ChiSquareScore(SquaredTransferError(h_inv, pb[i], pa[i]), inv_sigma2, kTransferCutoff);
    }
  }
  const double total = result.fundamental_score + result.homography_score;
  result.homography_ratio = total > 0.0 ? result.homography_score / total : 0.0;
  return result;
}

double InlierSpread(const std::vector<cv::KeyPoint>& a_keypoints,
                    const std::vector<cv::KeyPoint>& b_keypoints, const std::vector<Match>& matches,
                    int grid) {
  if (matches.empty() || grid < 1) return 0.0;
  std::vector<uint32_t> used_a, used_b;
  for (const Match& m : matches) {
    if (m.a >= a_keypoints.size() || m.b >= b_keypoints.size()) return 0.0;
    used_a.push_back(m.a);
    used_b.push_back(m.b);
  }
  return std::min(CoveredShare(a_keypoints, used_a, grid), CoveredShare(b_keypoints, used_b, grid));
}

namespace {

// The inliers' pixels normalised by their own camera (K^-1 x), so that one identity camera serves
// the essential matrix of two different cameras. False for a match out of range.
bool NormalisedPairs(const cv::Matx33d& K_a, const cv::Matx33d& K_b,
                     const std::vector<cv::KeyPoint>& a_keypoints,
                     const std::vector<cv::KeyPoint>& b_keypoints,
                     const std::vector<Match>& matches, std::vector<cv::Point2d>* pa,
                     std::vector<cv::Point2d>* pb) {
  const cv::Matx33d a_inverse = K_a.inv(), b_inverse = K_b.inv();
  auto normalised = [](const cv::Matx33d& inverse, const cv::Point2f& pixel) {
    const cv::Vec3d ray = inverse * cv::Vec3d(pixel.x, pixel.y, 1.0);
    return cv::Point2d(ray[0] / ray[2], ray[1] / ray[2]);
  };
  pa->reserve(matches.size());
  pb->reserve(matches.size());
  for (const Match& m : matches) {
    if (m.a >= a_keypoints.size() || m.b >= b_keypoints.size()) return false;
    pa->push_back(normalised(a_inverse, a_keypoints[m.a].pt));
    pb->push_back(normalised(b_inverse, b_keypoints[m.b].pt));
  }
  return true;
}

// The pose of the essential matrix that puts the most points (with `mask`, those it marks) in
// front of both cameras; false when fewer than 5 are or E is degenerate.
bool PoseFromEssential(const cv::Mat& essential, const std::vector<cv::Point2d>& pa,
                       const std::vector<cv::Point2d>& pb, cv::InputOutputArray mask,
                       cv::Matx33d* R, cv::Vec3d* t) {
  cv::Mat rotation, translation;
  int in_front = 0;
  try {
    in_front =
        cv::recoverPose(essential, pa, pb, cv::Mat::eye(3, 3, CV_64F), rotation, translation, mask);
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

}  // namespace

bool RelativePoseFromFundamental(const cv::Matx33d& fundamental, const cv::Matx33d& K_a,
                                 const cv::Matx33d& K_b,
                                 const std::vector<cv::KeyPoint>& a_keypoints,
                                 const std::vector<cv::KeyPoint>& b_keypoints,
                                 const std::vector<Match>& inliers, cv::Matx33d* R, cv::Vec3d* t) {
  if (cv::norm(fundamental) == 0.0 || inliers.size() < 5) return false;
  std::vector<cv::Point2d> pa, pb;
  if (!NormalisedPairs(K_a, K_b, a_keypoints, b_keypoints, inliers, &pa, &pb)) return false;
  const cv::Matx33d essential = K_b.t() * fundamental * K_a;
  return PoseFromEssential(cv::Mat(essential), pa, pb, cv::noArray(), R, t);
}

namespace {

// How the inliers (normalised pixels pa, pb; `inlier` marks them) triangulate with the pose
// X_b = R X_a + t: the ones in front of both cameras (rays meeting in front, or parallel within
// kParallelDeg and pointing the same way: a point at infinity, as all are under a pure
// rotation), the ones the rotation alone explains, and each one's ray angle.
struct Triangulation {
  uint32_t in_front = 0, rotation_only = 0;
  std::vector<double> parallax_deg;
};

constexpr double kParallelDeg = 0.1;

Triangulation Triangulate(const cv::Matx33d& R, const cv::Vec3d& t,
                          const std::vector<cv::Point2d>& pa, const std::vector<cv::Point2d>& pb,
                          const std::vector<bool>& inlier, double threshold) {
  Triangulation result;
  const cv::Vec3d centre_b = -(R.t() * t);  // camera b in a's frame
  for (size_t i = 0; i < pa.size(); ++i) {
    if (!inlier[i]) continue;
    const cv::Vec3d ray_a(pa[i].x, pa[i].y, 1.0);
    const cv::Vec3d ray_b = R.t() * cv::Vec3d(pb[i].x, pb[i].y, 1.0);
    const double cosine = ray_a.dot(ray_b) / (cv::norm(ray_a) * cv::norm(ray_b));
    const double angle = std::acos(std::clamp(cosine, -1.0, 1.0)) * 180.0 / CV_PI;
    result.parallax_deg.push_back(angle);
    bool front = cosine > 0.0;
    if (angle >= kParallelDeg) {
      // The depths along both rays where they pass closest:
      // lambda_a ray_a ~ centre_b + lambda_b ray_b.
      const double aa = ray_a.dot(ray_a), ab = ray_a.dot(ray_b), bb = ray_b.dot(ray_b);
      const double ac = ray_a.dot(centre_b), bc = ray_b.dot(centre_b);
      const double det = ab * ab - aa * bb;
      const double lambda_a = (ab * bc - bb * ac) / det;
      const double lambda_b = (aa * bc - ab * ac) / det;
      front = lambda_a > 0.0 && lambda_b > 0.0;
    }
    result.in_front += front;
    // The rotation alone: b's ray turned into a's frame lands on a's pixel.
    const cv::Point2d rotated(ray_b[0] / ray_b[2], ray_b[1] / ray_b[2]);
    result.rotation_only += ray_b[2] > 0.0 && cv::norm(rotated - pa[i]) < threshold;
  }
  return result;
}

// Of the four decompositions of result->essential, the one that puts the most of the `inlier`
// pairs (normalised pixels) in front of both cameras; on a tie (a pure rotation puts every point
// at infinity for the right R), the one whose rotation alone explains the most. Fills R, t,
// in_front, rotation_only, parallax_deg and found.
void Decompose(const std::vector<cv::Point2d>& pa, const std::vector<cv::Point2d>& pb,
               const std::vector<bool>& inlier, double threshold, EssentialResult* result) {
  cv::Mat R1, R2, t;
  cv::decomposeEssentialMat(cv::Mat(result->essential), R1, R2, t);
  Triangulation best;
  bool chosen = false;
  for (const cv::Mat& R : {R1, R2}) {
    for (const double sign : {1.0, -1.0}) {
      const cv::Matx33d rotation(R);
      const cv::Vec3d translation = cv::Vec3d(t) * sign;
      Triangulation candidate = Triangulate(rotation, translation, pa, pb, inlier, threshold);
      const bool better =
          !chosen || candidate.in_front > best.in_front ||
          (candidate.in_front == best.in_front && candidate.rotation_only > best.rotation_only);
      if (!better) continue;
      best = std::move(candidate);
      result->R = rotation;
      result->t = translation;
      chosen = true;
    }
  }
  result->found = true;
  result->in_front = best.in_front;
  result->rotation_only = best.rotation_only;
  std::nth_element(best.parallax_deg.begin(),
                   best.parallax_deg.begin() + long(best.parallax_deg.size() / 2),
                   best.parallax_deg.end());
  result->parallax_deg = best.parallax_deg[best.parallax_deg.size() / 2];
}

}  // namespace

EssentialResult VerifyEssential(const cv::Matx33d& K_a, const cv::Matx33d& K_b,
                                const std::vector<cv::KeyPoint>& a_keypoints,
                                const std::vector<cv::KeyPoint>& b_keypoints,
                                const std::vector<Match>& matches,
                                const EssentialOptions& options) {
  EssentialResult result;
  if (matches.size() < 5) return result;
  std::vector<cv::Point2d> pa, pb;
  if (!NormalisedPairs(K_a, K_b, a_keypoints, b_keypoints, matches, &pa, &pb)) return result;
  // The pixel threshold in normalised units, by the mean focal length of the two cameras.
  const double focal = (K_a(0, 0) + K_a(1, 1) + K_b(0, 0) + K_b(1, 1)) / 4.0;
  const double threshold = options.threshold_px / focal;
  cv::Mat mask;
  cv::Mat essential;
  try {
    essential = cv::findEssentialMat(pa, pb, cv::Mat::eye(3, 3, CV_64F), cv::RANSAC,
                                     options.confidence, threshold, options.max_iterations, mask);
  } catch (const cv::Exception&) {
    return result;
  }
  // Several solutions come stacked (3 x 3 each) when the 5-point problem is ambiguous on the
  // best sample: the first is RANSAC's.
  if (essential.rows < 3 || essential.cols != 3 || mask.empty()) return result;
  std::vector<bool> inlier(matches.size());
  for (size_t i = 0; i < matches.size(); ++i) {
    inlier[i] = mask.at<uchar>(int(i)) != 0;
    if (inlier[i]) result.inliers.push_back(matches[i]);
  }
  if (result.inliers.size() < 5) return result;
  result.essential = cv::Matx33d(cv::Mat(essential.rowRange(0, 3)));
  Decompose(pa, pb, inlier, threshold, &result);
  return result;
}

EssentialResult MeasureEssential(const cv::Matx33d& essential, const cv::Matx33d& K_a,
                                 const cv::Matx33d& K_b,
                                 const std::vector<cv::KeyPoint>& a_keypoints,
                                 const std::vector<cv::KeyPoint>& b_keypoints,
                                 const std::vector<Match>& inliers, double threshold_px) {
  EssentialResult result;
  if (inliers.size() < 5) return result;
  std::vector<cv::Point2d> pa, pb;
  if (!NormalisedPairs(K_a, K_b, a_keypoints, b_keypoints, inliers, &pa, &pb)) return result;
  const double focal = (K_a(0, 0) + K_a(1, 1) + K_b(0, 0) + K_b(1, 1)) / 4.0;
  result.inliers = inliers;
  result.essential = essential;
  Decompose(pa, pb, std::vector<bool>(inliers.size(), true), threshold_px / focal, &result);
  return result;
}

bool RelativePoseFromMatches(const cv::Matx33d& K_a, const cv::Matx33d& K_b,
                             const std::vector<cv::KeyPoint>& a_keypoints,
                             const std::vector<cv::KeyPoint>& b_keypoints,
                             const std::vector<Match>& matches, double threshold_px, cv::Matx33d* R,
                             cv::Vec3d* t) {
  const EssentialResult essential =
      VerifyEssential(K_a, K_b, a_keypoints, b_keypoints, matches, {.threshold_px = threshold_px});
  if (!essential.found || essential.in_front < 5) return false;
  *R = essential.R;
  *t = essential.t;
  return true;
}

}  // namespace recog
