#include "tools/evaluation/sequence_generator.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <list>
#include <mutex>
#include <numbers>
#include <random>
#include <set>
#include <thread>
#include <utility>

#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/features/feature_extractor.h"
#include "tools/common/cli_support.h"
#include "tools/evaluation/synthetic_images.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

// Independent random streams derived from the one seed.
enum Stream : uint64_t { kTourStream = 1, kVisitStream = 2, kFrameStream = 3 };

constexpr int kMaxFrames = 50'000'000;
constexpr double kRevisitStrength = 1.5;  // revisits: 1.5x blur, noise and illumination limits
constexpr double kMaxZoom = 1.5;          // beyond this, BORDER_REFLECT fills the view's edges

int NumRevisits(const SequenceOptions& o) {
  return int(std::min<double>(o.places, std::llround(o.revisit_fraction * o.places)));
}

// Everything about one visit that stays fixed across its frames.
struct VisitParams {
  double strength = 1;            // 1 on first visits, kRevisitStrength on revisits
  double pan_dx = 0, pan_dy = 0;  // total pan over the visit, in output pixels
  double offset_x = 0, offset_y = 0, rotation = 0, scale = 0;  // revisit viewpoint
  double tilt_x = 0, tilt_y = 0;                               // perspective (revisits)
  double gain = 1;
  double gradient_x = 0, gradient_y = 0;  // illumination gradient, centre to edge (revisits)
};

VisitParams MakeVisitParams(const SequenceOptions& o, uint64_t visit, bool revisit) {
  std::mt19937_64 rng(StreamSeed(o.seed, kVisitStream, visit));
  // Always draw every value in the same order, so the stream does not depend on the visit kind.
  const double pan_angle = Uniform(rng, 0, 2 * std::numbers::pi);
  const double offset_x = Symmetric(rng, 2 * o.max_shift_px);
  const double offset_y = Symmetric(rng, 2 * o.max_shift_px);
  const double rotation = Symmetric(rng, o.max_rotation_deg * std::numbers::pi / 180);
  const double scale = Symmetric(rng, o.max_scale);
  const double tilt_x = Symmetric(rng, o.max_scale);
  const double tilt_y = Symmetric(rng, o.max_scale);
  const double strength = revisit ? kRevisitStrength : 1.0;
  const double gain = 1 + Symmetric(rng, 0.75 * strength * o.illumination_max);
  const double gradient_x = Symmetric(rng, 0.5 * o.illumination_max);
  const double gradient_y = Symmetric(rng, 0.5 * o.illumination_max);

  VisitParams v;
  v.strength = strength;
  const double pan = std::min((o.frames_per_place - 1) * o.max_shift_px, 0.15 * double(o.width));
  v.pan_dx = pan * std::cos(pan_angle);
  v.pan_dy = pan * std::sin(pan_angle);
  v.gain = gain;
  if (revisit) {
    v.offset_x = offset_x;
    v.offset_y = offset_y;
    v.rotation = rotation;
    v.scale = scale;
    v.tilt_x = tilt_x;
    v.tilt_y = tilt_y;
    v.gradient_x = gradient_x;
    v.gradient_y = gradient_y;
  }
  return v;
}

// Largest translation of the view centre (output pixels) any frame can have.
double MaxTranslation(const SequenceOptions& o) {
  const double pan = std::min((o.frames_per_place - 1) * o.max_shift_px, 0.15 * double(o.width));
  return pan / 2 + o.max_shift_px + 2 * o.max_shift_px;
}

cv::Mat ResizeToCover(const cv::Mat& photo, const SequenceOptions& o) {
  // Scale at which the photo just covers width x height, then a zoom that leaves room for the
  // largest view (rotated, zoomed out, moved) inside the photo, so that BORDER_REFLECT is rarely
  // needed.
  const double base = std::max(double(o.width) / photo.cols, double(o.height) / photo.rows);
  const double half_w = photo.cols * base / 2, half_h = photo.rows * base / 2;
  const double angle = 2 * o.max_rotation_deg * std::numbers::pi / 180;
  const double grow = 1 / (1 - 2 * o.max_scale);
  const double view_x = grow * (o.width / 2.0 * std::cos(angle) + o.height / 2.0 * std::sin(angle));
  const double view_y = grow * (o.width / 2.0 * std::sin(angle) + o.height / 2.0 * std::cos(angle));
  const double t = MaxTranslation(o);
  double zoom = std::max({1.0, (view_x + t) / half_w, (view_y + t) / half_h});
  zoom = std::min(zoom, kMaxZoom);
  const int cols = std::max(1, int(std::lround(photo.cols * base * zoom)));
  const int rows = std::max(1, int(std::lround(photo.rows * base * zoom)));
  cv::Mat cover;
  const bool shrink = cols < photo.cols;
  cv::resize(photo, cover, cv::Size(cols, rows), 0, 0, shrink ? cv::INTER_AREA : cv::INTER_LINEAR);
  return cover;
}

// --- Distinct places: the same-scene test (see the header). It shares nothing with the loop
// detector: SIFT instead of ORB, a global descriptor instead of the ORB bag of words, Lowe's
// ratio test on L2 distances, and a homography instead of a fundamental matrix. ---

constexpr int kSceneFeatures = 500;                   // SIFT features per photo
constexpr int kSceneWidth = 640, kSceneHeight = 480;  // larger photos are shrunk to cover this
// Chosen photos of highest global similarity that get matched.
constexpr int kSceneCandidates = 30;
constexpr float kSceneRatio = 0.8f;      // Lowe's ratio test
constexpr double kSceneThresholdPx = 5;  // homography RANSAC reprojection error of an inlier
constexpr int kSceneMinInliers = 12;
// A homography that scales areas by more than this (or less than its inverse) is degenerate.
constexpr double kSceneMaxAreaChange = 16;
constexpr size_t kSceneBatch = 32;  // photos described ahead of the (sequential) selection
// Global descriptor: orientation histograms (8 bins, magnitude-weighted) of the grey photo
// shrunk to 64x64, in 4x4 cells, and the mean-free colour of a 4x4 thumbnail, each part of unit
// length, concatenated and scaled to unit length (cosine similarity = dot product).
constexpr int kGlobalSide = 64, kGlobalCells = 4, kGlobalBins = 8;
constexpr int kGlobalGradientSize = kGlobalCells * kGlobalCells * kGlobalBins;
constexpr int kGlobalSize = kGlobalGradientSize + kGlobalCells * kGlobalCells * 3;
// Second candidate search, by the SIFT features themselves: each descriptor (less its own mean)
// is hashed by the signs of kHashBits fixed random projections, in kHashTables tables; the
// kSceneCandidates chosen photos sharing the most buckets with the photo, each bucket weighted by
// its rarity (idf), are matched too.
constexpr int kHashTables = 4, kHashBits = 16;
constexpr uint64_t kHashSeed = 0x5eedf00d;

// SIFT features and global descriptor of one photo.
struct SceneView {
  Status status;  // of reading and describing the photo
  FeatureSet features;
  cv::Mat global;  // 1 x kGlobalSize CV_32F, unit length
  std::vector<uint32_t>
      hashes;  // kHashTables per feature: feature i, table t at i * kHashTables + t
};

// The fixed random projections of the feature hashes: one row of 128 Gaussian values per bit.
const cv::Mat& HashProjections() {
  static const cv::Mat projections = [] {
    cv::Mat m(kHashTables * kHashBits, 128, CV_32F);
    cv::RNG rng(kHashSeed);
    rng.fill(m, cv::RNG::NORMAL, 0, 1);
    return m;
  }();
  return projections;
}

std::vector<uint32_t> FeatureHashes(const cv::Mat& descriptors) {
  std::vector<uint32_t> hashes(size_t(descriptors.rows) * kHashTables, 0);
  if (descriptors.empty()) return hashes;
  cv::Mat centred = descriptors.clone(), projected;
  for (int i = 0; i < centred.rows; ++i) centred.row(i) -= cv::mean(centred.row(i))[0];
  cv::gemm(centred, HashProjections(), 1, cv::noArray(), 0, projected, cv::GEMM_2_T);
  for (int i = 0; i < projected.rows; ++i) {
    const float* row = projected.ptr<float>(i);
    for (int t = 0; t < kHashTables; ++t) {
      uint32_t key = 0;
      for (int b = 0; b < kHashBits; ++b) key |= uint32_t(row[t * kHashBits + b] > 0) << b;
      hashes[size_t(i) * kHashTables + size_t(t)] = key;
    }
  }
  return hashes;
}

// A chosen photo that shows the same scene as the one tested, with its homography inliers.
struct SceneMatch {
  int place = -1;  // -1: none
  int inliers = 0;
};

// Scales `part` (a row range of a 1 x n CV_32F row) to unit length, when it is not all zero.
void Normalize(cv::Mat part) {
  const double norm = cv::norm(part);
  if (norm > 0) part /= norm;
}

// The global descriptor (see kGlobalSide) of an 8-bit grey or BGR photo.
cv::Mat GlobalDescriptor(const cv::Mat& photo) {
  cv::Mat grey = photo, colour = photo;  // cvtColor gives the other one its own pixels
  if (photo.channels() == 3) {
    cv::cvtColor(photo, grey, cv::COLOR_BGR2GRAY);
  } else {
    cv::cvtColor(photo, colour, cv::COLOR_GRAY2BGR);
  }
  cv::Mat descriptor(1, kGlobalSize, CV_32F, cv::Scalar(0));
  cv::Mat small, dx, dy, magnitude, angle;
  cv::resize(grey, small, cv::Size(kGlobalSide, kGlobalSide), 0, 0, cv::INTER_AREA);
  small.convertTo(small, CV_32F);
  cv::Sobel(small, dx, CV_32F, 1, 0);
  cv::Sobel(small, dy, CV_32F, 0, 1);
  cv::cartToPolar(dx, dy, magnitude, angle);  // angle in [0, 2 pi)
  const int cell = kGlobalSide / kGlobalCells;
  float* out = descriptor.ptr<float>();
  for (int y = 0; y < kGlobalSide; ++y) {
    for (int x = 0; x < kGlobalSide; ++x) {
      const int bin = std::min(
          kGlobalBins - 1, int(angle.at<float>(y, x) / float(2 * std::numbers::pi) * kGlobalBins));
      out[((y / cell) * kGlobalCells + x / cell) * kGlobalBins + bin] += magnitude.at<float>(y, x);
    }
  }
  Normalize(descriptor.colRange(0, kGlobalGradientSize));
  cv::Mat thumbnail;
  cv::resize(colour, thumbnail, cv::Size(kGlobalCells, kGlobalCells), 0, 0, cv::INTER_AREA);
  cv::Mat colour_part = descriptor.colRange(kGlobalGradientSize, kGlobalSize);
  thumbnail.reshape(1, 1).convertTo(colour_part, CV_32F);
  colour_part -= cv::mean(colour_part)[0];
  Normalize(colour_part);
  descriptor /= std::sqrt(2.0);
  return descriptor;
}

// The gradient part of a global descriptor with opposite orientations folded together (8 bins to
// 4 per cell) and no colour, unit length: the same object on a darker or a brighter background
// (edge polarity reversed, colours changed) still looks alike.
cv::Mat ShapeDescriptor(const cv::Mat& global) {
  constexpr int kHalf = kGlobalBins / 2;
  cv::Mat shape(1, kGlobalCells * kGlobalCells * kHalf, CV_32F);
  const float* in = global.ptr<float>();
  float* out = shape.ptr<float>();
  for (int c = 0; c < kGlobalCells * kGlobalCells; ++c) {
    for (int k = 0; k < kHalf; ++k) {
      out[c * kHalf + k] = in[c * kGlobalBins + k] + in[c * kGlobalBins + k + kHalf];
    }
  }
  Normalize(shape);
  return shape;
}

// Lowe's ratio test on every feature of `a` against `b` (L2), made one-to-one (a feature of `b`,
// or a position of `a` shared by SIFT's several orientations, keeps its nearest match), then a
// homography (RANSAC; OpenCV's is deterministic). Returns its inliers; 0 when there are too few
// matches to fit one or when the homography is degenerate (it changes areas by more than
// kSceneMaxAreaChange, e.g. collapses the matches onto a point).
int HomographyInliers(const FeatureSet& a, const FeatureSet& b, const cv::BFMatcher& matcher) {
  if (a.descriptors.rows < 2 || b.descriptors.rows < 2) return 0;
  std::vector<std::vector<cv::DMatch>> knn;
  matcher.knnMatch(a.descriptors, b.descriptors, knn, 2);
  std::vector<cv::DMatch> passed;
  for (const std::vector<cv::DMatch>& pair : knn) {
    if (pair.size() == 2 && pair[0].distance < kSceneRatio * pair[1].distance) {
      passed.push_back(pair[0]);
    }
  }
  std::sort(passed.begin(), passed.end(), [](const cv::DMatch& x, const cv::DMatch& y) {
    return x.distance != y.distance ? x.distance < y.distance : x.queryIdx < y.queryIdx;
  });
  std::set<int> b_taken;
  std::set<std::pair<float, float>> a_taken;
  std::vector<cv::Point2f> a_points, b_points;
  for (const cv::DMatch& m : passed) {
    const cv::Point2f pa = a.keypoints[size_t(m.queryIdx)].pt;
    if (!b_taken.insert(m.trainIdx).second || !a_taken.emplace(pa.x, pa.y).second) continue;
    a_points.push_back(pa);
    b_points.push_back(b.keypoints[size_t(m.trainIdx)].pt);
  }
  if (a_points.size() < size_t(kSceneMinInliers)) return 0;
  cv::Mat mask;
  const cv::Mat homography =
      cv::findHomography(a_points, b_points, cv::RANSAC, kSceneThresholdPx, mask);
  if (homography.empty()) return 0;
  const cv::Matx33d h = cv::Matx33d(homography) * (1 / homography.at<double>(2, 2));
  const double area_change = std::abs(h(0, 0) * h(1, 1) - h(0, 1) * h(1, 0));
  if (area_change * kSceneMaxAreaChange < 1 || area_change > kSceneMaxAreaChange) return 0;
  return cv::countNonZero(mask);
}

// The photos chosen so far: their global descriptors (one row each) to find candidates, and their
// SIFT features to verify them.
class SceneIndex {
 public:
  // Reads and describes photos [begin, end) into views[0 .. end - begin), on a few threads. Each
  // view depends on its photo alone, so the thread count does not change any result.
  static void Describe(const std::vector<std::string>& photos, size_t begin, size_t end,
                       std::vector<SceneView>* views) {
    views->clear();
    views->resize(end - begin);
    std::atomic<size_t> next{begin};
    const auto work = [&] {
      FeatureOptions options;
      options.type = FeatureType::kSift;
      options.sift.max_features = kSceneFeatures;
      auto extractor = CreateFeatureExtractor(options);
      for (size_t i = next++; i < end; i = next++) {
        SceneView& view = (*views)[i - begin];
        if (!extractor.ok()) {
          view.status = extractor.status();
          continue;
        }
        view.status = DescribeOne(**extractor, photos[i], &view);
      }
    };
    const size_t threads =
        std::min<size_t>({end - begin, std::max(1u, std::thread::hardware_concurrency()), 4});
    std::vector<std::thread> helpers;
    for (size_t t = 1; t < threads; ++t) helpers.emplace_back(work);
    work();
    for (std::thread& helper : helpers) helper.join();
  }

  // The first candidate that a homography maps onto `view` with at least kSceneMinInliers
  // inliers. Candidates: the kSceneCandidates chosen photos most similar by global descriptor,
  // then by its shape part (ShapeDescriptor), then the kSceneCandidates sharing the most feature
  // hash buckets (each at most once).
  SceneMatch FindSameScene(const SceneView& view) const {
    if (globals_.empty()) return SceneMatch{};
    const cv::Mat similarity = globals_ * view.global.t();  // one row per chosen photo
    // A shared bucket votes by its rarity (idf, log(places / places in the bucket)): buckets that
    // half the photos share (plain texture, foliage) say little, a rare one says much.
    std::vector<float> votes(size_t(globals_.rows), 0.0f);
    const double places = double(globals_.rows);
    for (size_t h = 0; h < view.hashes.size(); ++h) {
      const std::vector<int>& bucket = buckets_[h % kHashTables][view.hashes[h]];
      const float weight = float(std::log((places + 1.0) / (double(bucket.size()) + 1.0)));
      if (weight <= 0.0f) continue;
      int last = -1;  // one vote per place and feature hash
      for (const int place : bucket) {
        if (place != last) votes[size_t(place)] += weight;
        last = place;
      }
    }
    std::vector<int> candidates = Best(similarity.ptr<float>(), globals_.rows);
    const auto add = [&candidates](int place) {
      if (std::find(candidates.begin(), candidates.end(), place) == candidates.end()) {
        candidates.push_back(place);
      }
    };
    const cv::Mat shape_similarity = shapes_ * ShapeDescriptor(view.global).t();
    for (const int place : Best(shape_similarity.ptr<float>(), shapes_.rows)) add(place);
    for (const int place : Best(votes.data(), globals_.rows)) {
      if (votes[size_t(place)] > 0) add(place);
    }
    const cv::BFMatcher matcher(cv::NORM_L2);
    for (const int place : candidates) {
      const int inliers = HomographyInliers(view.features, places_[size_t(place)], matcher);
      if (inliers >= kSceneMinInliers) return SceneMatch{place, inliers};
    }
    return SceneMatch{};
  }

  // Makes `view` the next chosen photo (place number size()).
  void Add(SceneView view) {
    const int place = globals_.rows;
    globals_.push_back(view.global);
    shapes_.push_back(ShapeDescriptor(view.global));
    for (size_t h = 0; h < view.hashes.size(); ++h) {
      buckets_[h % kHashTables][view.hashes[h]].push_back(place);
    }
    places_.push_back(std::move(view.features));
  }

 private:
  static Status DescribeOne(FeatureExtractor& extractor, const std::string& path, SceneView* view) {
    RECOG_ASSIGN_OR_RETURN(cv::Mat photo, ReadPhoto(path));
    // Large photos are looked at at about frame size (a fixed one, so that the chosen photos do
    // not depend on the options), which also bounds the time spent on them.
    const double scale =
        std::max(double(kSceneWidth) / photo.cols, double(kSceneHeight) / photo.rows);
    if (scale < 1) {
      cv::resize(photo, photo,
                 cv::Size(std::max(1, int(std::lround(photo.cols * scale))),
                          std::max(1, int(std::lround(photo.rows * scale)))),
                 0, 0, cv::INTER_AREA);
    }
    view->global = GlobalDescriptor(photo);
    RECOG_RETURN_IF_ERROR(extractor.Extract(photo, &view->features));
    view->hashes = FeatureHashes(view->features.descriptors);
    return Status::Ok();
  }

  // The kSceneCandidates places of highest score (ties: lower place first), best first.
  template <typename T>
  static std::vector<int> Best(const T* scores, int places) {
    std::vector<int> order(static_cast<size_t>(places));
    for (int p = 0; p < places; ++p) order[size_t(p)] = p;
    const size_t best = std::min(order.size(), size_t(kSceneCandidates));
    std::partial_sort(
        order.begin(), order.begin() + std::ptrdiff_t(best), order.end(),
        [&](int a, int b) { return scores[a] != scores[b] ? scores[a] > scores[b] : a < b; });
    order.resize(best);
    return order;
  }

  cv::Mat globals_;                 // one row per place, CV_32F
  cv::Mat shapes_;                  // ShapeDescriptor of each place's global descriptor
  std::vector<FeatureSet> places_;  // by place
  // Per table, per hash key: the places with a feature of that key, increasing.
  std::vector<std::vector<std::vector<int>>> buckets_ = std::vector<std::vector<std::vector<int>>>(
      kHashTables, std::vector<std::vector<int>>(size_t(1) << kHashBits));
};

// The first `places` photos that show distinct scenes, and the photos skipped on the way.
Status ChooseDistinctPhotos(const std::vector<std::string>& photos, const SequenceOptions& options,
                            std::vector<std::string>* chosen, std::vector<SkippedPhoto>* skipped) {
  const int places = options.places;
  const size_t wanted = size_t(places);
  if (photos.size() < wanted) {
    return Status::InvalidArgument(
        std::to_string(photos.size()) + " photos for " + std::to_string(places) +
        " places: distinct places need a different photo per place (turn distinct places off, "
        "--allow-duplicate-places, to reuse photos)");
  }
  SceneIndex index;
  std::vector<SceneView> views;
  size_t next = 0;
  while (chosen->size() < wanted && next < photos.size()) {
    // Describe about as many photos as are still needed; most of them will be taken.
    const size_t batch =
        std::min({kSceneBatch, photos.size() - next, std::max<size_t>(wanted - chosen->size(), 2)});
    SceneIndex::Describe(photos, next, next + batch, &views);
    for (size_t k = 0; k < batch && chosen->size() < wanted; ++k) {
      SceneView& view = views[k];
      const std::string& photo = photos[next + k];
      RECOG_RETURN_IF_ERROR(view.status);
      const SceneMatch same = index.FindSameScene(view);
      if (same.place >= 0) {
        skipped->push_back(SkippedPhoto{photo, same.place, same.inliers});
        continue;
      }
      index.Add(std::move(view));
      chosen->push_back(photo);
    }
    next += batch;
  }
  if (chosen->size() < wanted) {
    return Status::InvalidArgument(
        "only " + std::to_string(chosen->size()) + " of the " + std::to_string(photos.size()) +
        " photos show distinct scenes (" + std::to_string(skipped->size()) +
        " show the scene of an earlier photo), fewer than the " + std::to_string(places) +
        " places: distinct places need more photos (or turn them off, --allow-duplicate-places)");
  }
  return Status::Ok();
}

}  // namespace

Status SequenceOptions::Validate() const {
  if (places < 1 || places > kMaxFrames) {
    return Status::InvalidArgument("places = " + std::to_string(places) + " is outside [1, " +
                                   std::to_string(kMaxFrames) + "]");
  }
  if (frames_per_place < 1 || frames_per_place > 100000) {
    return Status::InvalidArgument("frames per place = " + std::to_string(frames_per_place) +
                                   " is outside [1, 100000]");
  }
  RECOG_RETURN_IF_ERROR(CheckRange("revisit fraction", revisit_fraction, 0, 1));
  if (width < 16 || width > 16384 || height < 16 || height > 16384) {
    return Status::InvalidArgument("frame size " + std::to_string(width) + "x" +
                                   std::to_string(height) + " is outside 16..16384 pixels");
  }
  RECOG_RETURN_IF_ERROR(CheckRange("max shift (px)", max_shift_px, 0, std::min(width, height) / 4));
  RECOG_RETURN_IF_ERROR(CheckRange("max rotation (degrees)", max_rotation_deg, 0, 45));
  RECOG_RETURN_IF_ERROR(CheckRange("max scale", max_scale, 0, 0.3));
  RECOG_RETURN_IF_ERROR(CheckRange("blur sigma", blur_sigma_max, 0, 20));
  RECOG_RETURN_IF_ERROR(CheckRange("noise sigma", noise_sigma, 0, 100));
  RECOG_RETURN_IF_ERROR(CheckRange("illumination change", illumination_max, 0, 0.5));
  const long long frames = (static_cast<long long>(places) + NumRevisits(*this)) * frames_per_place;
  if (frames > kMaxFrames) {
    return Status::InvalidArgument("the sequence would have " + std::to_string(frames) +
                                   " frames, more than " + std::to_string(kMaxFrames));
  }
  return Status::Ok();
}

// The last few cover images (most recent first). Frames of a visit are consecutive, so a handful
// of entries serves sequential generation; random access only costs decoding time.
struct SequenceGenerator::PhotoCache {
  static constexpr size_t kCapacity = 8;
  std::mutex mutex;
  std::list<std::pair<int, cv::Mat>> entries;
};

SequenceGenerator::SequenceGenerator(std::vector<std::string> photos,
                                     const SequenceOptions& options)
    : photos_(std::move(photos)), options_(options), cache_(std::make_shared<PhotoCache>()) {
  const int places = options_.places;
  // Revisited places: the first NumRevisits of a seeded Fisher-Yates shuffle, in shuffled order.
  std::vector<int> order(static_cast<size_t>(places));
  for (int p = 0; p < places; ++p) order[size_t(p)] = p;
  std::mt19937_64 rng(StreamSeed(options_.seed, kTourStream, 0));
  for (int i = places - 1; i > 0; --i) {
    const int j = int(rng() % uint64_t(i + 1));
    std::swap(order[size_t(i)], order[size_t(j)]);
  }
  const int revisits = NumRevisits(options_);
  visit_place_.reserve(size_t(places + revisits));
  for (int p = 0; p < places; ++p) visit_place_.push_back(p);
  for (int r = 0; r < revisits; ++r) visit_place_.push_back(order[size_t(r)]);
}

StatusOr<SequenceGenerator> SequenceGenerator::Create(std::vector<std::string> photos,
                                                      const SequenceOptions& options) {
  if (photos.empty()) return Status::InvalidArgument("no photos to build the sequence from");
  RECOG_RETURN_IF_ERROR(options.Validate());
  if (options.distinct_places) {
    std::vector<std::string> chosen;
    std::vector<SkippedPhoto> skipped;
    RECOG_RETURN_IF_ERROR(ChooseDistinctPhotos(photos, options, &chosen, &skipped));
    SequenceGenerator generator(std::move(chosen), options);
    generator.skipped_ = std::move(skipped);
    return generator;
  }
  // Only the first `places` photos are used.
  if (photos.size() > size_t(options.places)) photos.resize(size_t(options.places));
  for (const std::string& photo : photos) {
    std::error_code ec;
    if (!fs::exists(photo, ec)) return Status::NotFound("photo '" + photo + "' does not exist");
  }
  return SequenceGenerator(std::move(photos), options);
}

int SequenceGenerator::VisitPlace(int v) const {
  return v < 0 || v >= num_visits() ? -1 : visit_place_[size_t(v)];
}

int SequenceGenerator::FramePlace(int i) const {
  return i < 0 || i >= num_frames() ? -1 : visit_place_[size_t(i / options_.frames_per_place)];
}

const std::string& SequenceGenerator::PlacePhoto(int place) const {
  return photos_[size_t(place) % photos_.size()];
}

bool SequenceGenerator::PlaceMirrored(int place) const {
  return (size_t(place) / photos_.size()) % 2 == 1;
}

StatusOr<cv::Mat> SequenceGenerator::CoverImage(int place) const {
  {
    std::lock_guard<std::mutex> lock(cache_->mutex);
    auto& entries = cache_->entries;
    for (auto it = entries.begin(); it != entries.end(); ++it) {
      if (it->first == place) {
        entries.splice(entries.begin(), entries, it);
        return entries.front().second;
      }
    }
  }
  RECOG_ASSIGN_OR_RETURN(cv::Mat photo, ReadPhoto(PlacePhoto(place)));
  if (PlaceMirrored(place)) cv::flip(photo, photo, 1);
  cv::Mat cover = ResizeToCover(photo, options_);

  std::lock_guard<std::mutex> lock(cache_->mutex);
  auto& entries = cache_->entries;
  if (std::none_of(entries.begin(), entries.end(),
                   [&](const auto& e) { return e.first == place; })) {
    entries.emplace_front(place, cover);
    if (entries.size() > PhotoCache::kCapacity) entries.pop_back();
  }
  return cover;
}

StatusOr<SequenceFrame> SequenceGenerator::Frame(int i) const {
  if (i < 0 || i >= num_frames()) {
    return Status::InvalidArgument("frame " + std::to_string(i) + " is outside 0.." +
                                   std::to_string(num_frames() - 1));
  }
  const SequenceOptions& o = options_;
  const int visit = i / o.frames_per_place;
  SequenceFrame frame;
  frame.index = i;
  frame.place = visit_place_[size_t(visit)];
  frame.visit = visit < o.places ? 0 : 1;
  frame.frame_in_visit = i % o.frames_per_place;
  RECOG_ASSIGN_OR_RETURN(const cv::Mat cover, CoverImage(frame.place));

  const VisitParams v = MakeVisitParams(o, uint64_t(visit), frame.visit > 0);
  std::mt19937_64 rng(StreamSeed(o.seed, kFrameStream, uint64_t(i)));
  const double jitter_x = Symmetric(rng, o.max_shift_px);
  const double jitter_y = Symmetric(rng, o.max_shift_px);
  const double rotation = v.rotation + Symmetric(rng, o.max_rotation_deg * std::numbers::pi / 180);
  const double scale = v.scale + Symmetric(rng, o.max_scale);
  const double tilt_x = v.tilt_x + Symmetric(rng, 0.25 * o.max_scale);
  const double tilt_y = v.tilt_y + Symmetric(rng, 0.25 * o.max_scale);
  const double blur_sigma = Uniform(rng, 0, v.strength * o.blur_sigma_max);
  const double flicker = 1 + Symmetric(rng, 0.25 * v.strength * o.illumination_max);
  const uint64_t noise_seed = rng();

  // Homography from output pixels to cover pixels: centre the output, tilt (perspective), rotate
  // and scale, then move to the cover's centre plus pan, viewpoint offset and jitter.
  const double ox = (o.width - 1) / 2.0, oy = (o.height - 1) / 2.0;
  const double progress =
      o.frames_per_place > 1 ? double(frame.frame_in_visit) / (o.frames_per_place - 1) - 0.5 : 0;
  const double tx = (cover.cols - 1) / 2.0 + progress * v.pan_dx + v.offset_x + jitter_x;
  const double ty = (cover.rows - 1) / 2.0 + progress * v.pan_dy + v.offset_y + jitter_y;
  const cv::Matx33d centre(1, 0, -ox, 0, 1, -oy, 0, 0, 1);
  const cv::Matx33d tilt(1, 0, 0, 0, 1, 0, tilt_x / std::max(1.0, o.width / 2.0),
                         tilt_y / std::max(1.0, o.height / 2.0), 1);
  const double c = std::cos(rotation) / (1 + scale), s = std::sin(rotation) / (1 + scale);
  const cv::Matx33d rotate(c, -s, 0, s, c, 0, 0, 0, 1);
  const cv::Matx33d move(1, 0, tx, 0, 1, ty, 0, 0, 1);
  const cv::Matx33d homography = move * rotate * tilt * centre;

  cv::Mat warped;
  cv::warpPerspective(cover, warped, cv::Mat(homography), cv::Size(o.width, o.height),
                      cv::INTER_LINEAR | cv::WARP_INVERSE_MAP, cv::BORDER_REFLECT);
  CameraEffects effects;
  effects.blur_sigma = blur_sigma;
  effects.gain = v.gain * flicker;
  effects.gradient_x = v.gradient_x;
  effects.gradient_y = v.gradient_y;
  effects.noise_sigma = v.strength * o.noise_sigma;
  effects.noise_seed = noise_seed;
  ApplyCameraEffects(effects, &warped);
  frame.image = std::move(warped);
  return frame;
}

bool SequenceGenerator::SamePlace(int a, int b) const {
  const int n = num_frames();
  if (a < 0 || a >= n || b < 0 || b >= a) return false;
  const int va = a / options_.frames_per_place, vb = b / options_.frames_per_place;
  return va != vb && visit_place_[size_t(va)] == visit_place_[size_t(vb)];
}

std::vector<int> SequenceGenerator::Matches(int a) const {
  std::vector<int> matches;
  if (a < 0 || a >= num_frames()) return matches;
  const int f = options_.frames_per_place;
  const int visit = a / f;
  if (visit < options_.places) return matches;        // a first visit has nothing earlier
  const int first = visit_place_[size_t(visit)] * f;  // first visit of place p is visit p
  for (int b = first; b < first + f; ++b) matches.push_back(b);
  return matches;
}

GroundTruth SequenceGenerator::BuildGroundTruth() const {
  GroundTruth truth;
  truth.frames = num_frames();
  truth.matches.resize(size_t(truth.frames));
  for (int a = options_.places * options_.frames_per_place; a < truth.frames; ++a) {
    truth.matches[size_t(a)] = Matches(a);
  }
  return truth;
}

StatusOr<SequenceImageFormat> ParseSequenceImageFormat(std::string_view name) {
  if (name == "png") return SequenceImageFormat::kPng;
  if (name == "jpg" || name == "jpeg") return SequenceImageFormat::kJpeg;
  return Status::InvalidArgument("unknown image format '" + std::string(name) + "' (png or jpg)");
}

StatusOr<SequenceWriteResult> WriteSequence(const SequenceGenerator& generator,
                                            const std::string& out_dir, bool sparse_truth,
                                            SequenceImageFormat format,
                                            const SequenceProgress& progress) {
  RECOG_RETURN_IF_ERROR(PrepareOutputFolder(out_dir));
  SequenceWriteResult result;
  result.images_dir = (fs::path(out_dir) / "images").string();
  result.frames = generator.num_frames();
  result.sparse_truth = sparse_truth || result.frames > kMaxDenseGroundTruthFrames;
  result.ground_truth_path =
      (fs::path(out_dir) / (result.sparse_truth ? "ground_truth.sparse.txt" : "ground_truth.txt"))
          .string();
  std::error_code ec;
  fs::create_directories(result.images_dir, ec);
  if (ec) {
    return Status::Internal("cannot create folder '" + result.images_dir + "': " + ec.message());
  }

  const char* extension = format == SequenceImageFormat::kJpeg ? "jpg" : "png";
  const std::vector<int> params = format == SequenceImageFormat::kJpeg
                                      ? std::vector<int>{cv::IMWRITE_JPEG_QUALITY, 95}
                                      : std::vector<int>{};
  for (int i = 0; i < result.frames; ++i) {
    RECOG_ASSIGN_OR_RETURN(const SequenceFrame frame, generator.Frame(i));
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.%s", i + 1, extension);
    const std::string path = (fs::path(result.images_dir) / name).string();
    RECOG_RETURN_IF_ERROR(WriteImage(path, frame.image, params));
    if (progress) progress(uint64_t(i + 1), uint64_t(result.frames));
  }

  const GroundTruth truth = generator.BuildGroundTruth();
  result.queries_with_matches = truth.QueriesWithMatches();
  RECOG_RETURN_IF_ERROR(result.sparse_truth
                            ? WriteSparseGroundTruth(truth, result.ground_truth_path)
                            : WriteDenseGroundTruth(truth, result.ground_truth_path));
  return result;
}

}  // namespace recog::cli
