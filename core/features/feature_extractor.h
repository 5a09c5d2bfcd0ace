// Local features of an image: keypoints plus one descriptor row each.
//
// Three extractors share one interface:
//  - ORB (OpenCV): the default for places and objects. Optional grid bucketing spreads the
//    features over the image: the image is cut into grid_rows x grid_cols cells and each cell
//    keeps its strongest max_features / cells keypoints, so a textured corner cannot take every
//    feature. The share that cells short of corners leave is unused, or, with grid_fill_cap,
//    goes to the strongest keypoints left in cells that hold fewer than grid_fill_cap times a
//    cell's share (an object on a plain background keeps its features; clutter cannot take
//    them all).
//  - FAST + BRIEF as in thesis §4.2: FAST-9 corners, 256 intensity tests in a 48x48 patch of the
//    Gaussian-smoothed image, with the "close pairs" pattern (a ~ N(0, S^2/25),
//    b ~ N(a, 4 S^2/625)) drawn once from a fixed seed. No orientation, one scale.
//  - SIFT (OpenCV 4.6 main module): 128 floats, for the float-descriptor code path.
//
// Every extractor accepts 8-bit grey or 8-bit BGR images and returns INVALID_ARGUMENT for an
// empty image or another pixel type. Features are returned sorted by decreasing response, then
// by position, so results are deterministic. An extractor is not thread-safe: use one per thread.
#pragma once

#include <cstdint>
#include <memory>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/descriptor.h"
#include "core/common/feature_set.h"
#include "core/common/status.h"

namespace recog {

enum class FeatureType { kOrb, kFastBrief, kSift };
std::string_view FeatureTypeName(FeatureType type);  // "orb", "brief", "sift"
StatusOr<FeatureType> ParseFeatureType(std::string_view name);

struct OrbOptions {
  int max_features = 1000;
  float scale_factor = 1.2f;  // between pyramid levels, > 1
  int levels = 8;             // pyramid levels, >= 1
  int fast_threshold = 20;    // FAST intensity threshold, 1..255
  int edge_threshold = 31;    // border without features, in pixels (>= patch size 31)
  int grid_rows = 0;          // 0 = no bucketing
  int grid_cols = 0;
  // With a grid: 0 = a cell's unused share stays unused; > 0 = it goes to the strongest keypoints
  // left in cells holding fewer than grid_fill_cap x max_features / cells.
  double grid_fill_cap = 0;
  // Small frames: an image whose shorter side is under min_short_side pixels is enlarged
  // (bilinear) until its shorter side is min_short_side before ORB runs, and the keypoints are
  // mapped back to the image's own pixels (positions and sizes). ORB's 31-pixel border and patch
  // leave little of a 160x120 frame; on the enlarged one its corners are found. 0 = never
  // enlarge (the default: object crops are enlarged by their own rules). Places use
  // PlaceFeatureOptions() below.
  int min_short_side = 0;

  // OK, or INVALID_ARGUMENT naming the first field out of its range; `name` names the options in
  // the message (a holder passes the member's path, "RecognitionOptions.orb").
  Status Validate(std::string_view name = "OrbOptions") const;
};

struct BriefOptions {
  int max_features = 1000;         // strongest FAST corners kept
  int fast_threshold = 10;         // FAST-9 intensity threshold, 1..255
  int patch_size = 48;             // S_b
  double smoothing_sigma = 2;      // Gaussian smoothing of the image before the tests
  bool close_pairs = true;         // thesis pattern; false = original BRIEF (both ~ N(0, S^2/25))
  uint64_t pattern_seed = 0x5eed;  // fixed: descriptors are only comparable with one pattern
};

struct SiftOptions {
  int max_features = 1000;
};

struct FeatureOptions {
  FeatureType type = FeatureType::kOrb;
  OrbOptions orb;
  BriefOptions brief;
  SiftOptions sift;

  Status Validate() const;
};

class FeatureExtractor {
 public:
  virtual ~FeatureExtractor() = default;
  virtual DescriptorFormat format() const = 0;
  // Fills `out` (cleared first). INVALID_ARGUMENT for an empty or non-8-bit image.
  virtual Status Extract(const cv::Mat& image, FeatureSet* out) = 0;
};

// The features of place frames, the server's and the tools' default: FeatureOptions{} with
// orb.min_short_side = kPlaceMinShortSide, so that a low-resolution camera's frames are enlarged.
inline constexpr int kPlaceMinShortSide = 352;
FeatureOptions PlaceFeatureOptions();

// Builds the extractor described by `options` (validated first).
StatusOr<std::unique_ptr<FeatureExtractor>> CreateFeatureExtractor(const FeatureOptions& options);

// Reads an image file as 8-bit grey. NOT_FOUND for a missing file, INVALID_ARGUMENT for a file
// that is not a decodable image.
StatusOr<cv::Mat> ReadGrayImage(const std::string& path);

}  // namespace recog
