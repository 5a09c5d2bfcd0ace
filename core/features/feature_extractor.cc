#include "core/features/feature_extractor.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <numeric>
#include <random>
#include <string>
#include <system_error>
#include <utility>

#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace recog {
namespace {

// Upper limits that keep OpenCV's internal buffers reasonable; far above any useful setting.
constexpr int kMaxFeaturesLimit = 1'000'000;
constexpr double kMaxSmoothingSigma = 16.0;
constexpr int kMaxOrbLevels = 32;
constexpr int kMaxGridSide = 256;
constexpr int kMaxMinShortSide = 4096;

// With grid bucketing ORB first detects more candidates than it keeps (this many times
// max_features, and at least this many per cell), so that weakly textured cells still have corners
// to choose from once the strong ones are spread out.
constexpr int64_t kGridOversampling = 5;
constexpr int64_t kGridCandidatesPerCell = 64;
constexpr int64_t kMaxGridCandidates = 1 << 18;

constexpr int kBriefBits = 256;
constexpr int kBriefBytes = kBriefBits / 8;

// Deterministic order of features: strongest first, then top to bottom, left to right. The
// remaining fields only separate keypoints that share a position (ORB octaves, SIFT orientations).
bool StrongerFirst(const cv::KeyPoint& a, const cv::KeyPoint& b) {
  if (a.response != b.response) return a.response > b.response;
  if (a.pt.y != b.pt.y) return a.pt.y < b.pt.y;
  if (a.pt.x != b.pt.x) return a.pt.x < b.pt.x;
  if (a.octave != b.octave) return a.octave < b.octave;
  if (a.size != b.size) return a.size < b.size;
  return a.angle < b.angle;
}

cv::Mat EmptyDescriptors(const DescriptorFormat& format) {
  return cv::Mat(0, format.cols(), format.cv_type());
}

// Moves `keypoints` and the matching rows of `descriptors` into `out`, sorted by StrongerFirst
// and cut to the `max_count` strongest.
void SortIntoFeatureSet(std::vector<cv::KeyPoint>& keypoints, const cv::Mat& descriptors,
                        const DescriptorFormat& format, size_t max_count, FeatureSet* out) {
  std::vector<size_t> order(keypoints.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return StrongerFirst(keypoints[a], keypoints[b]); });
  if (order.size() > max_count) order.resize(max_count);

  out->keypoints.reserve(order.size());
  if (order.empty()) {
    out->descriptors = EmptyDescriptors(format);
    return;
  }
  out->descriptors.create(int(order.size()), format.cols(), format.cv_type());
  for (size_t i = 0; i < order.size(); ++i) {
    out->keypoints.push_back(keypoints[order[i]]);
    descriptors.row(int(order[i])).copyTo(out->descriptors.row(int(i)));
  }
}

// Checks the pixel type and returns a grey view of `image`: the image itself when it is already
// grey, otherwise a conversion written into `buffer`.
Status ToGray(const cv::Mat& image, cv::Mat* buffer, cv::Mat* gray) {
  if (image.empty()) return Status::InvalidArgument("image is empty");
  if (image.dims != 2) {
    return Status::InvalidArgument("image must have 2 dimensions, got " +
                                   std::to_string(image.dims));
  }
  if (image.type() == CV_8UC1) {
    *gray = image;
    return Status::Ok();
  }
  if (image.type() == CV_8UC3) {
    cv::cvtColor(image, *buffer, cv::COLOR_BGR2GRAY);
    *gray = *buffer;
    return Status::Ok();
  }
  return Status::InvalidArgument("image has pixel type " + cv::typeToString(image.type()) +
                                 "; expected 8-bit grey (CV_8UC1) or 8-bit BGR (CV_8UC3)");
}

std::string OutOfRange(const std::string& field, const std::string& rule, const std::string& got) {
  return field + " must be " + rule + ", got " + got;
}

std::string ToText(double value) {
  std::string text = std::to_string(value);
  // std::to_string prints six decimals; drop the trailing zeros ("1.500000" -> "1.5").
  if (text.find('.') != std::string::npos) {
    text.erase(text.find_last_not_of('0') + 1);
    if (text.back() == '.') text.pop_back();
  }
  return text;
}

Status CheckIntRange(const std::string& field, int value, int lo, int hi) {
  if (value < lo || value > hi) {
    return Status::InvalidArgument(
        OutOfRange(field, "between " + std::to_string(lo) + " and " + std::to_string(hi),
                   std::to_string(value)));
  }
  return Status::Ok();
}

// `name` is the options' path in the messages ("orb", "RecognitionOptions.orb").
Status ValidateOrb(const OrbOptions& o, std::string_view name) {
  const auto field = [&](const char* member) { return std::string(name) + "." + member; };
  RECOG_RETURN_IF_ERROR(CheckIntRange(field("max_features"), o.max_features, 1, kMaxFeaturesLimit));
  if (!(o.scale_factor > 1.f) || !std::isfinite(o.scale_factor)) {
    return Status::InvalidArgument(OutOfRange(
        field("scale_factor"), "a finite number greater than 1", ToText(o.scale_factor)));
  }
  RECOG_RETURN_IF_ERROR(CheckIntRange(field("levels"), o.levels, 1, kMaxOrbLevels));
  RECOG_RETURN_IF_ERROR(CheckIntRange(field("fast_threshold"), o.fast_threshold, 1, 255));
  if (o.edge_threshold < 0) {
    return Status::InvalidArgument(
        OutOfRange(field("edge_threshold"), ">= 0", std::to_string(o.edge_threshold)));
  }
  if (o.grid_rows < 0 || o.grid_cols < 0 || (o.grid_rows == 0) != (o.grid_cols == 0)) {
    return Status::InvalidArgument(field("grid_rows") + " and " + field("grid_cols") +
                                   " must both be 0 (no bucketing) or both be positive, got " +
                                   std::to_string(o.grid_rows) + " x " +
                                   std::to_string(o.grid_cols));
  }
  RECOG_RETURN_IF_ERROR(CheckIntRange(field("grid_rows"), o.grid_rows, 0, kMaxGridSide));
  RECOG_RETURN_IF_ERROR(CheckIntRange(field("grid_cols"), o.grid_cols, 0, kMaxGridSide));
  RECOG_RETURN_IF_ERROR(
      CheckIntRange(field("min_short_side"), o.min_short_side, 0, kMaxMinShortSide));
  if (!(std::isfinite(o.grid_fill_cap) && o.grid_fill_cap >= 0)) {
    return Status::InvalidArgument(OutOfRange(
        field("grid_fill_cap"), "0 (no fill) or a positive number", ToText(o.grid_fill_cap)));
  }
  return Status::Ok();
}

Status ValidateBrief(const BriefOptions& o) {
  RECOG_RETURN_IF_ERROR(CheckIntRange("brief.max_features", o.max_features, 1, kMaxFeaturesLimit));
  RECOG_RETURN_IF_ERROR(CheckIntRange("brief.fast_threshold", o.fast_threshold, 1, 255));
  if (o.patch_size < 16 || o.patch_size > 64 || o.patch_size % 2 != 0) {
    return Status::InvalidArgument(OutOfRange(
        "brief.patch_size", "an even number between 16 and 64", std::to_string(o.patch_size)));
  }
  if (!(o.smoothing_sigma >= 0.0) || !(o.smoothing_sigma <= kMaxSmoothingSigma)) {
    return Status::InvalidArgument(OutOfRange("brief.smoothing_sigma",
                                              "between 0 and " + ToText(kMaxSmoothingSigma),
                                              ToText(o.smoothing_sigma)));
  }
  return Status::Ok();
}

// ---------------------------------------------------------------------------------------------
// ORB

class OrbExtractor final : public FeatureExtractor {
 public:
  explicit OrbExtractor(const OrbOptions& options)
      : options_(options), use_grid_(options.grid_rows > 0 && options.grid_cols > 0) {
    int detect_count = options.max_features;
    if (use_grid_) {
      const int64_t cells = int64_t{options.grid_rows} * options.grid_cols;
      const int64_t wanted = std::max(int64_t{options.max_features} * kGridOversampling,
                                      cells * kGridCandidatesPerCell);
      detect_count = int(
          std::max<int64_t>(options.max_features, std::min<int64_t>(wanted, kMaxGridCandidates)));
    }
    orb_ = cv::ORB::create(detect_count, options.scale_factor, options.levels,
                           options.edge_threshold, /*firstLevel=*/0, /*WTA_K=*/2,
                           cv::ORB::HARRIS_SCORE, /*patchSize=*/31, options.fast_threshold);
  }

  DescriptorFormat format() const override { return DescriptorFormat::Orb(); }

  Status Extract(const cv::Mat& image, FeatureSet* out) override {
    out->keypoints.clear();
    out->image_size = image.size();
    out->descriptors = EmptyDescriptors(format());
    cv::Mat gray;
    RECOG_RETURN_IF_ERROR(ToGray(image, &gray_buffer_, &gray));
    const cv::Size original_size = gray.size();
    if (std::min(gray.rows, gray.cols) < options_.min_short_side) {
      const double scale = double(options_.min_short_side) / std::min(gray.rows, gray.cols);
      cv::resize(gray, enlarged_,
                 cv::Size(int(std::lround(gray.cols * scale)), int(std::lround(gray.rows * scale))),
                 0, 0, cv::INTER_LINEAR);
      gray = enlarged_;
    }

    // OpenCV's pyramid fails on levels that round to zero pixels; only build the levels that exist
    // for this image (all of them for any image of useful size).
    orb_->setNLevels(UsableLevels(gray.size()));

    keypoints_.clear();
    try {
      if (!use_grid_) {
        orb_->detectAndCompute(gray, cv::noArray(), keypoints_, descriptors_);
      } else {
        orb_->detect(gray, keypoints_);
        BucketByGrid(gray.size());
        if (!keypoints_.empty()) orb_->compute(gray, keypoints_, descriptors_);
      }
    } catch (const cv::Exception& e) {
      return Status::Internal(std::string("ORB extraction failed: ") + e.what());
    }
    if (keypoints_.empty()) return Status::Ok();
    if (descriptors_.rows != int(keypoints_.size()) || descriptors_.type() != CV_8U ||
        descriptors_.cols != format().cols()) {
      return Status::Internal("ORB returned " + std::to_string(descriptors_.rows) +
                              " descriptors for " + std::to_string(keypoints_.size()) +
                              " keypoints");
    }
    if (gray.size() != original_size) MapToOriginal(gray.size(), original_size);
    SortIntoFeatureSet(keypoints_, descriptors_, format(), size_t(options_.max_features), out);
    return Status::Ok();
  }

 private:
  // Moves the keypoints found on an enlarged image back to the pixels of the image itself. A
  // bilinear resize puts the centre of pixel x at (x + 0.5) * scale - 0.5 of the enlarged one.
  void MapToOriginal(cv::Size enlarged, cv::Size original) {
    const float sx = float(enlarged.width) / float(original.width);
    const float sy = float(enlarged.height) / float(original.height);
    for (cv::KeyPoint& kp : keypoints_) {
      kp.pt.x = std::clamp((kp.pt.x + 0.5f) / sx - 0.5f, 0.f, float(original.width - 1));
      kp.pt.y = std::clamp((kp.pt.y + 0.5f) / sy - 0.5f, 0.f, float(original.height - 1));
      kp.size /= sx;
    }
  }

  int UsableLevels(cv::Size size) const {
    int levels = 0;
    double scale = 1.0;
    while (levels < options_.levels && cvRound(size.width / scale) >= 1 &&
           cvRound(size.height / scale) >= 1) {
      ++levels;
      scale *= options_.scale_factor;
    }
    return std::max(levels, 1);
  }

  // Keeps, in each grid cell, its strongest max_features / cells candidates. The remainder of
  // that division goes one keypoint each to the cells whose next candidate is strongest. With
  // grid_fill_cap, the share that cells short of corners leave unused goes to the strongest
  // candidates left, each cell holding at most grid_fill_cap x max_features / cells in all. The
  // total never exceeds max_features.
  void BucketByGrid(cv::Size size) {
    const int rows = options_.grid_rows;
    const int cols = options_.grid_cols;
    const int cells = rows * cols;
    std::sort(keypoints_.begin(), keypoints_.end(), StrongerFirst);

    cell_members_.resize(size_t(cells));
    for (auto& members : cell_members_) members.clear();
    for (size_t i = 0; i < keypoints_.size(); ++i) {
      const cv::Point2f& p = keypoints_[i].pt;
      const int r = std::clamp(int(double(p.y) * rows / size.height), 0, rows - 1);
      const int c = std::clamp(int(double(p.x) * cols / size.width), 0, cols - 1);
      cell_members_[size_t(r * cols + c)].push_back(i);  // strongest first within the cell
    }

    const size_t budget = size_t(options_.max_features);
    const size_t base = budget / size_t(cells);
    taken_.assign(size_t(cells), 0);
    selected_.clear();
    std::vector<std::pair<size_t, size_t>> runners_up;  // (candidate, cell) with one to spare
    for (size_t c = 0; c < cell_members_.size(); ++c) {
      const auto& members = cell_members_[c];
      taken_[c] = std::min(base, members.size());
      selected_.insert(selected_.end(), members.begin(), members.begin() + ptrdiff_t(taken_[c]));
      if (members.size() > base) runners_up.emplace_back(members[base], c);
    }
    // Candidate indices follow StrongerFirst order, so the smallest index is the strongest.
    std::sort(runners_up.begin(), runners_up.end());
    const size_t extra = std::min(budget % size_t(cells), runners_up.size());
    for (size_t k = 0; k < extra; ++k) {
      selected_.push_back(runners_up[k].first);
      ++taken_[runners_up[k].second];
    }

    if (options_.grid_fill_cap > 0 && selected_.size() < budget) {
      const size_t cap = size_t(options_.grid_fill_cap * double(budget) / double(cells));
      fill_.clear();
      for (size_t c = 0; c < cell_members_.size(); ++c) {
        const auto& members = cell_members_[c];
        const size_t end = std::min(members.size(), std::max(cap, taken_[c]));
        fill_.insert(fill_.end(), members.begin() + ptrdiff_t(taken_[c]),
                     members.begin() + ptrdiff_t(end));
      }
      std::sort(fill_.begin(), fill_.end());
      const size_t more = std::min(budget - selected_.size(), fill_.size());
      selected_.insert(selected_.end(), fill_.begin(), fill_.begin() + ptrdiff_t(more));
    }

    std::sort(selected_.begin(), selected_.end());
    std::vector<cv::KeyPoint> kept;
    kept.reserve(selected_.size());
    for (size_t i : selected_) kept.push_back(keypoints_[i]);
    keypoints_.swap(kept);
  }

  OrbOptions options_;
  bool use_grid_;
  cv::Ptr<cv::ORB> orb_;
  // Buffers reused between calls.
  cv::Mat gray_buffer_;
  cv::Mat enlarged_;
  cv::Mat descriptors_;
  std::vector<cv::KeyPoint> keypoints_;
  std::vector<std::vector<size_t>> cell_members_;
  std::vector<size_t> selected_;
  std::vector<size_t> taken_;  // per cell: candidates selected
  std::vector<size_t> fill_;   // candidates that may fill the unused share
};

// ---------------------------------------------------------------------------------------------
// FAST + BRIEF (thesis §4.2)

class BriefExtractor final : public FeatureExtractor {
 public:
  explicit BriefExtractor(const BriefOptions& options) : options_(options) {
    const int half = options.patch_size / 2;
    if (options.smoothing_sigma > 0) {
      kernel_size_ = 2 * int(std::ceil(3.0 * options.smoothing_sigma)) + 1;
    }
    // Every tested pixel lies within `half` of the keypoint, and its smoothed value should only
    // depend on real pixels, not on the border extrapolation of the blur.
    border_ = half + kernel_size_ / 2;
    DrawPattern();
  }

  DescriptorFormat format() const override { return DescriptorFormat::Brief256(); }

  Status Extract(const cv::Mat& image, FeatureSet* out) override {
    out->keypoints.clear();
    out->image_size = image.size();
    out->descriptors = EmptyDescriptors(format());
    cv::Mat gray;
    RECOG_RETURN_IF_ERROR(ToGray(image, &gray_buffer_, &gray));
    if (gray.cols <= 2 * border_ || gray.rows <= 2 * border_) return Status::Ok();

    keypoints_.clear();
    cv::FAST(gray, keypoints_, options_.fast_threshold, /*nonmaxSuppression=*/true,
             cv::FastFeatureDetector::TYPE_9_16);
    const float lo = float(border_);
    const float max_x = float(gray.cols - 1 - border_);
    const float max_y = float(gray.rows - 1 - border_);
    std::erase_if(keypoints_, [&](const cv::KeyPoint& kp) {
      return kp.pt.x < lo || kp.pt.y < lo || kp.pt.x > max_x || kp.pt.y > max_y;
    });
    if (keypoints_.empty()) return Status::Ok();

    const size_t keep = std::min(keypoints_.size(), size_t(options_.max_features));
    std::partial_sort(keypoints_.begin(), keypoints_.begin() + ptrdiff_t(keep), keypoints_.end(),
                      StrongerFirst);
    keypoints_.resize(keep);

    // BORDER_ISOLATED keeps OpenCV on its bit-exact fixed-point blur for every input; without it
    // an image view (a submatrix) takes a floating-point path whose rounding differs.
    if (kernel_size_ > 1) {
      cv::GaussianBlur(gray, smoothed_, cv::Size(kernel_size_, kernel_size_),
                       options_.smoothing_sigma, options_.smoothing_sigma,
                       cv::BORDER_REFLECT_101 | cv::BORDER_ISOLATED);
    } else {
      gray.copyTo(smoothed_);
    }

    // Pattern offsets in bytes for this image's row stride.
    const ptrdiff_t step = ptrdiff_t(smoothed_.step1());
    for (int i = 0; i < kBriefBits; ++i) {
      offset_a_[size_t(i)] = pattern_[size_t(i)].ay * step + pattern_[size_t(i)].ax;
      offset_b_[size_t(i)] = pattern_[size_t(i)].by * step + pattern_[size_t(i)].bx;
    }

    out->descriptors.create(int(keep), kBriefBytes, CV_8U);
    out->keypoints.reserve(keep);
    for (size_t k = 0; k < keep; ++k) {
      cv::KeyPoint kp = keypoints_[k];
      kp.size = float(options_.patch_size);
      kp.angle = -1.f;
      kp.octave = 0;
      const uint8_t* center = smoothed_.ptr<uint8_t>(cvRound(kp.pt.y)) + cvRound(kp.pt.x);
      uint8_t* row = out->descriptors.ptr<uint8_t>(int(k));
      for (int byte = 0; byte < kBriefBytes; ++byte) {
        unsigned bits = 0;
        for (int j = 0; j < 8; ++j) {
          const size_t i = size_t(byte * 8 + j);
          bits = (bits << 1) | unsigned(center[offset_a_[i]] < center[offset_b_[i]]);
        }
        row[byte] = uint8_t(bits);  // test byte*8 sits in the most significant bit
      }
      out->keypoints.push_back(kp);
    }
    return Status::Ok();
  }

 private:
  struct TestPair {
    int ax, ay, bx, by;
  };

  // Draws the 256 test pairs from the seed. Coordinates are rounded to whole pixels and clamped
  // to the patch [-S/2, S/2]. A pair whose two points coincide would always give 0, so its
  // second point is drawn again.
  void DrawPattern() {
    const double size = options_.patch_size;
    const int half = options_.patch_size / 2;
    const double sigma_a = size / 5.0;                                          // N(0, S^2/25)
    const double sigma_b = options_.close_pairs ? 2.0 * size / 25.0 : sigma_a;  // N(a, 4S^2/625)
    std::mt19937_64 rng(options_.pattern_seed);
    std::normal_distribution<double> normal(0.0, 1.0);
    auto to_pixel = [half](double v) {
      return int(std::clamp<long>(std::lround(v), -long{half}, long{half}));
    };
    for (TestPair& pair : pattern_) {
      const double ax = sigma_a * normal(rng);
      const double ay = sigma_a * normal(rng);
      pair.ax = to_pixel(ax);
      pair.ay = to_pixel(ay);
      const double mean_x = options_.close_pairs ? ax : 0.0;
      const double mean_y = options_.close_pairs ? ay : 0.0;
      do {
        pair.bx = to_pixel(mean_x + sigma_b * normal(rng));
        pair.by = to_pixel(mean_y + sigma_b * normal(rng));
      } while (pair.bx == pair.ax && pair.by == pair.ay);
    }
  }

  BriefOptions options_;
  int kernel_size_ = 1;
  int border_ = 0;
  std::array<TestPair, kBriefBits> pattern_{};
  std::array<ptrdiff_t, kBriefBits> offset_a_{};
  std::array<ptrdiff_t, kBriefBits> offset_b_{};
  // Buffers reused between calls.
  cv::Mat gray_buffer_;
  cv::Mat smoothed_;
  std::vector<cv::KeyPoint> keypoints_;
};

// ---------------------------------------------------------------------------------------------
// SIFT

class SiftExtractor final : public FeatureExtractor {
 public:
  explicit SiftExtractor(const SiftOptions& options)
      : options_(options), sift_(cv::SIFT::create(options.max_features)) {}

  DescriptorFormat format() const override { return DescriptorFormat::Sift(); }

  Status Extract(const cv::Mat& image, FeatureSet* out) override {
    out->keypoints.clear();
    out->image_size = image.size();
    out->descriptors = EmptyDescriptors(format());
    cv::Mat gray;
    RECOG_RETURN_IF_ERROR(ToGray(image, &gray_buffer_, &gray));
    keypoints_.clear();
    try {
      sift_->detectAndCompute(gray, cv::noArray(), keypoints_, descriptors_);
    } catch (const cv::Exception& e) {
      return Status::Internal(std::string("SIFT extraction failed: ") + e.what());
    }
    if (keypoints_.empty()) return Status::Ok();
    if (descriptors_.rows != int(keypoints_.size()) || descriptors_.type() != CV_32F ||
        descriptors_.cols != format().cols()) {
      return Status::Internal("SIFT returned " + std::to_string(descriptors_.rows) +
                              " descriptors for " + std::to_string(keypoints_.size()) +
                              " keypoints");
    }
    SortIntoFeatureSet(keypoints_, descriptors_, format(), size_t(options_.max_features), out);
    return Status::Ok();
  }

 private:
  SiftOptions options_;
  cv::Ptr<cv::SIFT> sift_;
  cv::Mat gray_buffer_;
  cv::Mat descriptors_;
  std::vector<cv::KeyPoint> keypoints_;
};

}  // namespace

std::string_view FeatureTypeName(FeatureType type) {
  switch (type) {
    case FeatureType::kOrb:
      return "orb";
    case FeatureType::kFastBrief:
      return "brief";
    case FeatureType::kSift:
      return "sift";
  }
  return "unknown";
}

StatusOr<FeatureType> ParseFeatureType(std::string_view name) {
  for (FeatureType type : {FeatureType::kOrb, FeatureType::kFastBrief, FeatureType::kSift}) {
    if (name == FeatureTypeName(type)) return type;
  }
  return Status::InvalidArgument("unknown feature type '" + std::string(name) +
                                 "'; expected 'orb', 'brief' or 'sift'");
}

Status OrbOptions::Validate(std::string_view name) const { return ValidateOrb(*this, name); }

Status FeatureOptions::Validate() const {
  if (type != FeatureType::kOrb && type != FeatureType::kFastBrief && type != FeatureType::kSift) {
    return Status::InvalidArgument("unknown feature type " + std::to_string(int(type)));
  }
  RECOG_RETURN_IF_ERROR(orb.Validate("orb"));
  RECOG_RETURN_IF_ERROR(ValidateBrief(brief));
  RECOG_RETURN_IF_ERROR(
      CheckIntRange("sift.max_features", sift.max_features, 1, kMaxFeaturesLimit));
  return Status::Ok();
}

FeatureOptions PlaceFeatureOptions() {
  FeatureOptions options;
  options.orb.min_short_side = kPlaceMinShortSide;
  return options;
}

StatusOr<std::unique_ptr<FeatureExtractor>> CreateFeatureExtractor(const FeatureOptions& options) {
  RECOG_RETURN_IF_ERROR(options.Validate());
  std::unique_ptr<FeatureExtractor> extractor;
  switch (options.type) {
    case FeatureType::kOrb:
      extractor = std::make_unique<OrbExtractor>(options.orb);
      break;
    case FeatureType::kFastBrief:
      extractor = std::make_unique<BriefExtractor>(options.brief);
      break;
    case FeatureType::kSift:
      extractor = std::make_unique<SiftExtractor>(options.sift);
      break;
  }
  return extractor;
}

StatusOr<cv::Mat> ReadGrayImage(const std::string& path) {
  std::error_code error;
  if (!std::filesystem::exists(path, error)) {
    return Status::NotFound("image file '" + path + "' does not exist");
  }
  cv::Mat image;
  try {
    image = cv::imread(path, cv::IMREAD_GRAYSCALE);
  } catch (const cv::Exception& e) {
    return Status::InvalidArgument("image file '" + path + "' could not be decoded: " + e.what());
  }
  if (image.empty()) {
    return Status::InvalidArgument("image file '" + path + "' is not a decodable image");
  }
  return image;
}

}  // namespace recog
