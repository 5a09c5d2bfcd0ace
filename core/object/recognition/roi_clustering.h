// Regions of interest: groups of image features that lie close together (thesis §5.4.4.1).
//
// Two-stage clustering of keypoint positions: k-means++ first reduces the N features to at most
// `seeds` cluster centres (seeded, so deterministic), then Medoidshifts (Sheikh et al. 2007) on
// those centres, with a Gaussian kernel of bandwidth `bandwidth_px`, merges them into a varying
// number of modes; modes closer than half the bandwidth are joined (a mode must be one of the
// centres, so a density peak that falls between centres leaves a mode on each side of it; see
// FindModes in the .cc). Every feature goes to the mode of its k-means cluster. Regions with fewer
// than `min_features` features are dropped. The whole image can be added as one more region.
// Same input and options, same regions.
#pragma once

#include <cstdint>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"

namespace recog {

struct RoiOptions {
  // At most this many seeds: Medoidshifts holds two seeds x seeds matrices of floats (32 MB).
  static constexpr int kMaxSeeds = 2048;

  int seeds = 100;            // k of k-means++ (thesis: ~100)
  int kmeans_iterations = 5;  // Lloyd iterations after the k-means++ seeding
  // Medoidshifts kernel bandwidth (sigma), pixels; 0 makes every k-means cluster its own mode.
  double bandwidth_px = 60;
  int min_features = 20;        // smaller regions are dropped
  bool add_whole_image = true;  // one more region with every feature
  uint64_t seed = 1;            // k-means++ seeding

  // OK, or INVALID_ARGUMENT naming the first field out of its range; `name` names the struct in
  // the message (a holder passes the member's path, "RecognitionOptions.roi").
  Status Validate(std::string_view name = "RoiOptions") const;
};

struct RegionOfInterest {
  std::vector<uint32_t> features;  // indices into the input, increasing
  cv::Rect2f bounds;               // bounding box of those features
  // The add_whole_image region; with add_whole_image, also a single cluster holding every feature.
  bool whole_image = false;
};

class RoiClusterer {
 public:
  explicit RoiClusterer(RoiOptions options = {});
  // Clusters `points` (finite coordinates); regions come in decreasing size (ties: smallest first
  // feature index), the whole-image region last. Reuses its scratch memory, and the inner vectors
  // of `regions`, between calls (not thread-safe: one clusterer per thread).
  void Cluster(const std::vector<cv::Point2f>& points, std::vector<RegionOfInterest>* regions);

 private:
  void SeedCentres(size_t k);             // k-means++ seeding
  void AssignToNearestCentre();           // Lloyd assignment step
  void TallyCentres(bool move_to_means);  // weights, empty centres dropped, optional update step
  void FindModes();                       // Medoidshifts: mode_ of every centre
  void BuildRegions(const std::vector<cv::Point2f>& points, std::vector<RegionOfInterest>* regions);

  RoiOptions options_;
  // Scratch memory, kept between calls so that a warmed-up clusterer does not allocate.
  std::vector<float> xs_, ys_;              // input points, one array per coordinate
  std::vector<float> nearest_;              // per point: squared distance to its closest centre
  std::vector<uint32_t> assignment_;        // per point: its k-means centre
  std::vector<float> centre_x_, centre_y_;  // k-means centres
  std::vector<float> weights_;              // per centre: number of points
  std::vector<double> sum_x_, sum_y_;       // per centre: coordinate sums (update step)
  std::vector<uint32_t> relabel_;           // old centre index -> index after dropping empties
  std::vector<float> distances_;            // M x M squared distances between centres
  std::vector<float> kernel_;               // M x M, row i: w_k K_ik
  std::vector<float> cost_;                 // one column of the Medoidshifts cost matrix
  std::vector<uint32_t> mode_;              // per centre: its medoid, then its mode
  std::vector<uint32_t> visited_, path_;    // walking the medoid pointers
  std::vector<uint32_t> size_, first_;      // per mode: features, first feature index
  std::vector<uint32_t> order_, slot_;      // kept modes by size; mode -> output region
};

}  // namespace recog
