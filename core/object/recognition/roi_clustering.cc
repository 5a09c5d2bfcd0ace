#include "core/object/recognition/roi_clustering.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>

#include "core/common/option_checks.h"

namespace recog {
namespace {

constexpr uint32_t kNoCluster = std::numeric_limits<uint32_t>::max();

// Medoidshifts modes closer than this many bandwidths are joined (see FindModes).
constexpr double kJoinBandwidths = 0.5;

// Uniform double in [0, 1) from the top 53 bits of the generator. std distributions are not
// specified bit for bit and differ between standard libraries; the regions must not.
double UniformDouble(std::mt19937_64& rng) { return double(rng() >> 11) * 0x1.0p-53; }

float SquaredDistance(float ax, float ay, float bx, float by) {
  const float dx = ax - bx;
  const float dy = ay - by;
  return dx * dx + dy * dy;
}

cv::Rect2f Bounds(const std::vector<cv::Point2f>& points, const std::vector<uint32_t>& indices) {
  float min_x = std::numeric_limits<float>::infinity();
  float min_y = min_x;
  float max_x = -min_x;
  float max_y = -min_x;
  for (uint32_t i : indices) {
    min_x = std::min(min_x, points[i].x);
    min_y = std::min(min_y, points[i].y);
    max_x = std::max(max_x, points[i].x);
    max_y = std::max(max_y, points[i].y);
  }
  return {min_x, min_y, max_x - min_x, max_y - min_y};
}

}  // namespace

Status RoiOptions::Validate(std::string_view name) const {
  OptionChecks check(name);
  check.InRange("seeds", seeds, 1, kMaxSeeds);
  check.AtLeast("kmeans_iterations", kmeans_iterations, 0);
  check.InRange("bandwidth_px", bandwidth_px, RealRange::AtLeast(0));
  check.AtLeast("min_features", min_features, 0);
  return check.status();
}

RoiClusterer::RoiClusterer(RoiOptions options) : options_(options) {}

void RoiClusterer::Cluster(const std::vector<cv::Point2f>& points,
                           std::vector<RegionOfInterest>* regions) {
  const size_t n = points.size();
  if (n == 0) {
    regions->clear();
    return;
  }
  xs_.resize(n);
  ys_.resize(n);
  for (size_t p = 0; p < n; ++p) {
    xs_[p] = points[p].x;
    ys_[p] = points[p].y;
  }
  assignment_.resize(n);

  const size_t k = size_t(std::max(1, options_.seeds));
  if (n <= k) {
    // Few enough points for Medoidshifts to run on them directly.
    centre_x_.assign(xs_.begin(), xs_.end());
    centre_y_.assign(ys_.begin(), ys_.end());
    weights_.assign(n, 1.f);
    std::iota(assignment_.begin(), assignment_.end(), 0u);
  } else {
    SeedCentres(k);
    AssignToNearestCentre();
    const int iterations = std::max(0, options_.kmeans_iterations);
    for (int it = 0; it < iterations; ++it) {
      if (it > 0) AssignToNearestCentre();
      TallyCentres(/*move_to_means=*/true);
    }
    // Without Lloyd iterations the centres stay on the seeds; they still need their weights.
    if (iterations == 0) TallyCentres(/*move_to_means=*/false);
  }
  FindModes();
  BuildRegions(points, regions);
}

// k-means++ seeding (Arthur & Vassilvitskii 2007): the first centre uniformly, each next one with
// probability proportional to the squared distance to the nearest centre chosen so far, which
// spreads the centres over the whole area covered by the features. Stops early when every point
// coincides with a centre.
void RoiClusterer::SeedCentres(size_t k) {
  const size_t n = xs_.size();
  std::mt19937_64 rng(options_.seed);
  centre_x_.clear();
  centre_y_.clear();
  nearest_.resize(n);

  size_t pick = std::min(n - 1, size_t(UniformDouble(rng) * double(n)));
  centre_x_.push_back(xs_[pick]);
  centre_y_.push_back(ys_[pick]);
  for (size_t p = 0; p < n; ++p)
    nearest_[p] = SquaredDistance(xs_[p], ys_[p], xs_[pick], ys_[pick]);
  while (centre_x_.size() < k) {
    // In double: in float, the total of a thousand squared distances would swallow small terms.
    double total = 0.0;
    for (size_t p = 0; p < n; ++p) total += nearest_[p];
    if (total <= 0.0) break;
    double target = UniformDouble(rng) * total;
    pick = n;
    for (size_t p = 0; p < n; ++p) {
      target -= nearest_[p];
      if (target < 0.0) {
        pick = p;
        break;
      }
    }
    if (pick == n) {  // rounding ran past the last point: take the farthest one
      pick = size_t(std::max_element(nearest_.begin(), nearest_.end()) - nearest_.begin());
    }
    const float cx = xs_[pick];
    const float cy = ys_[pick];
    centre_x_.push_back(cx);
    centre_y_.push_back(cy);
    for (size_t p = 0; p < n; ++p) {
      nearest_[p] = std::min(nearest_[p], SquaredDistance(xs_[p], ys_[p], cx, cy));
    }
  }
}

// Each point goes to its nearest centre, the first one on a tie. The loop runs centre by centre
// over all points so that the inner loop has no dependency between iterations and vectorises.
void RoiClusterer::AssignToNearestCentre() {
  const size_t n = xs_.size();
  nearest_.assign(n, std::numeric_limits<float>::infinity());
  std::fill(assignment_.begin(), assignment_.end(), 0u);  // a valid label even for a NaN point
  for (size_t c = 0; c < centre_x_.size(); ++c) {
    const float cx = centre_x_[c];
    const float cy = centre_y_[c];
    const uint32_t label = uint32_t(c);
    for (size_t p = 0; p < n; ++p) {
      const float d = SquaredDistance(xs_[p], ys_[p], cx, cy);
      const bool closer = d < nearest_[p];
      nearest_[p] = closer ? d : nearest_[p];
      assignment_[p] = closer ? label : assignment_[p];
    }
  }
}

// Counts the points of every centre (its weight), drops the centres left without points and, for
// a Lloyd update step, moves every centre to the mean of its points.
void RoiClusterer::TallyCentres(bool move_to_means) {
  const size_t m = centre_x_.size();
  weights_.assign(m, 0.f);
  sum_x_.assign(m, 0.0);
  sum_y_.assign(m, 0.0);
  for (size_t p = 0; p < xs_.size(); ++p) {
    const uint32_t c = assignment_[p];
    weights_[c] += 1.f;
    sum_x_[c] += xs_[p];
    sum_y_[c] += ys_[p];
  }
  relabel_.resize(m);
  size_t kept = 0;
  for (size_t c = 0; c < m; ++c) {
    if (weights_[c] == 0.f) continue;
    relabel_[c] = uint32_t(kept);
    centre_x_[kept] = move_to_means ? float(sum_x_[c] / weights_[c]) : centre_x_[c];
    centre_y_[kept] = move_to_means ? float(sum_y_[c] / weights_[c]) : centre_y_[c];
    weights_[kept] = weights_[c];
    ++kept;
  }
  centre_x_.resize(kept);
  centre_y_.resize(kept);
  weights_.resize(kept);
  for (uint32_t& c : assignment_) c = relabel_[c];
}

// Medoidshifts (Sheikh, Khan & Kanade 2007) on the M weighted centres. Centre i shifts to the
// centre j minimising sum_k w_k K_ik d_jk^2: column i of the product D * (W K) with D the squared
// distances, W the weights and K the Gaussian kernel. That step never lowers the kernel density
// estimate, so following the shifts from any centre ends at a fixed point, a mode.
//
// A Medoidshifts mode has to be one of the centres. Where the density peaks in empty space (two
// blobs closer than the kernel separates), the centres on either rim of the gap are both fixed
// points: each is the centre nearest to its own weighted mean, which the kernel pulls only part of
// the way across. The shifts alone never join them, whatever the bandwidth. So, as mean shift
// implementations group convergence points closer than the bandwidth (Comaniciu & Meer 2002),
// modes closer than kJoinBandwidths * h are joined afterwards. Half a bandwidth rather than a
// whole one: with single linkage, a whole bandwidth chains most of a textured image into one
// region at the default 60 px (tests/data/corridor/1.jpg: 5 regions become 1), while half of it
// still joins two blobs 100 px apart at h = 200 px and keeps the corridor regions.
void RoiClusterer::FindModes() {
  const size_t m = centre_x_.size();
  distances_.resize(m * m);
  kernel_.resize(m * m);
  cost_.resize(m);
  mode_.resize(m);

  for (size_t i = 0; i < m; ++i) {
    for (size_t j = 0; j < m; ++j) {
      distances_[i * m + j] =
          SquaredDistance(centre_x_[i], centre_y_[i], centre_x_[j], centre_y_[j]);
    }
  }
  // A bandwidth <= 0 (or NaN) makes the kernel a Dirac: each centre is its own mode.
  const double h = options_.bandwidth_px;
  const float inv_two_h2 =
      h > 0 ? float(1.0 / (2.0 * h * h)) : std::numeric_limits<float>::infinity();
  for (size_t i = 0; i < m; ++i) {
    for (size_t k = 0; k < m; ++k) {
      const float d = distances_[i * m + k];
      kernel_[i * m + k] = weights_[k] * (d == 0.f ? 1.f : std::exp(-d * inv_two_h2));
    }
  }
  for (size_t i = 0; i < m; ++i) {
    // cost_[j] = sum_k D_jk (w_k K_ik), accumulated row by row of D (symmetric) so that the inner
    // loop is a contiguous multiply-add. Far centres whose kernel underflowed add nothing.
    std::fill(cost_.begin(), cost_.end(), 0.f);
    const float* a = &kernel_[i * m];
    for (size_t k = 0; k < m; ++k) {
      if (a[k] == 0.f) continue;
      const float* row = &distances_[k * m];
      const float ak = a[k];
      for (size_t j = 0; j < m; ++j) cost_[j] += ak * row[j];
    }
    // The smallest index on a tie: coincident centres then pick the same medoid.
    mode_[i] = uint32_t(std::min_element(cost_.begin(), cost_.end()) - cost_.begin());
  }

  // Follow the medoid pointers to their fixed points. With exact arithmetic there is no cycle: a
  // shift raises the density strictly unless it is a tie, and ties go to smaller indices. A cycle
  // from rounding is cut at its smallest index so that the result stays deterministic.
  visited_.assign(m, kNoCluster);
  for (size_t i = 0; i < m; ++i) {
    if (visited_[i] != kNoCluster) continue;
    path_.clear();
    uint32_t v = uint32_t(i);
    while (visited_[v] == kNoCluster) {
      visited_[v] = uint32_t(i);
      path_.push_back(v);
      v = mode_[v];
    }
    uint32_t root;
    if (visited_[v] != i) {
      root = mode_[v];  // reached a centre resolved by an earlier walk
    } else if (mode_[v] == v) {
      root = v;  // reached a fixed point
    } else {
      const auto cycle = std::find(path_.begin(), path_.end(), v);
      root = *std::min_element(cycle, path_.end());
    }
    for (uint32_t c : path_) mode_[c] = root;
  }

  // Join modes closer than kJoinBandwidths * h (single linkage). Every mode points to itself, so
  // mode_ serves as the union-find parent array, the smallest index becoming the representative.
  path_.clear();
  for (size_t c = 0; c < m; ++c) {
    if (mode_[c] == c) path_.push_back(uint32_t(c));
  }
  auto find = [this](uint32_t c) {
    while (mode_[c] != c) c = mode_[c];
    return c;
  };
  const float join_d2 = h > 0 ? float(kJoinBandwidths * kJoinBandwidths * h * h) : 0.f;
  for (size_t i = 0; i < path_.size(); ++i) {
    for (size_t j = i + 1; j < path_.size(); ++j) {
      if (distances_[path_[i] * m + path_[j]] >= join_d2) continue;
      const uint32_t a = find(path_[i]);
      const uint32_t b = find(path_[j]);
      mode_[std::max(a, b)] = std::min(a, b);
    }
  }
  for (size_t c = 0; c < m; ++c) mode_[c] = find(mode_[c]);
}

void RoiClusterer::BuildRegions(const std::vector<cv::Point2f>& points,
                                std::vector<RegionOfInterest>* regions) {
  const size_t n = points.size();
  const size_t m = centre_x_.size();
  size_.assign(m, 0);
  first_.assign(m, kNoCluster);
  for (size_t p = 0; p < n; ++p) {
    const uint32_t mode = mode_[assignment_[p]];
    ++size_[mode];
    first_[mode] = std::min(first_[mode], uint32_t(p));
  }
  order_.clear();
  for (size_t c = 0; c < m; ++c) {
    if (size_[c] > 0 && int64_t(size_[c]) >= options_.min_features) order_.push_back(uint32_t(c));
  }
  std::sort(order_.begin(), order_.end(), [this](uint32_t a, uint32_t b) {
    return size_[a] != size_[b] ? size_[a] > size_[b] : first_[a] < first_[b];
  });
  slot_.assign(m, kNoCluster);
  for (size_t r = 0; r < order_.size(); ++r) slot_[order_[r]] = uint32_t(r);

  // A single cluster holding every feature already is the whole image: no duplicate query.
  const bool one_covers_all = order_.size() == 1 && size_[order_[0]] == n;
  const bool append_whole = options_.add_whole_image && !one_covers_all;
  // resize() keeps the surviving inner vectors, and with them their capacity.
  regions->resize(order_.size() + (append_whole ? 1 : 0));
  for (size_t r = 0; r < order_.size(); ++r) (*regions)[r].features.clear();
  for (size_t p = 0; p < n; ++p) {
    const uint32_t s = slot_[mode_[assignment_[p]]];
    if (s != kNoCluster) (*regions)[s].features.push_back(uint32_t(p));
  }
  for (size_t r = 0; r < order_.size(); ++r) {
    RegionOfInterest& region = (*regions)[r];
    region.bounds = Bounds(points, region.features);
    region.whole_image = one_covers_all && options_.add_whole_image;
  }
  if (append_whole) {
    RegionOfInterest& whole = regions->back();
    whole.features.resize(n);
    std::iota(whole.features.begin(), whole.features.end(), 0u);
    whole.bounds = Bounds(points, whole.features);
    whole.whole_image = true;
  }
}

}  // namespace recog
