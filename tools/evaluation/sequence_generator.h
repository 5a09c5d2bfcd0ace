// SequenceGenerator: long synthetic "recorded sequences" with exact ground truth, built from real
// photos, for scale and load tests of a loop-closure detector (`recog seqgen`, benchmarks).
//
// The tour visits P places, one photo each. With distinct_places (the default) the place photos
// are the first P photos, in the given order, that do not show the scene of an earlier place's
// photo (see "Distinct places" below); otherwise place p shows photo p % #photos, mirrored
// left-right on odd cycles so that reused photos are less alike. Visit order: places 0..P-1, then
// a seeded random subset of round(revisit_fraction * P) places a second time, in a seeded order.
// Every visit lasts `frames_per_place` consecutive frames: frame i belongs to visit
// i / frames_per_place.
//
// Each frame is the place's photo, resized to cover width x height (times a small zoom that leaves
// room for motion), warped by a homography: a slow pan across the visit (direction seeded per
// visit, at most max_shift_px per frame and 15 % of the width in total) + per-frame jitter
// (shift <= max_shift_px, rotation <= max_rotation_deg, scale <= max_scale, a little perspective)
// + for revisits a different viewpoint (extra offset up to 2 * max_shift_px, rotation and scale up
// to the same limits again, more perspective). Then a Gaussian blur of random sigma <=
// blur_sigma_max, a multiplicative illumination change of about +-illumination_max, and additive
// Gaussian noise of sigma noise_sigma. Revisits get 1.5x the blur, noise and illumination limits
// and an illumination gradient across the frame. Pixels outside the photo come from
// BORDER_REFLECT. Frames keep the source's type: 8-bit grey or 8-bit BGR.
//
// Determinism: the parameters of frame i come from std::mt19937_64 seeded by a mix of (seed, i),
// those of its visit from a mix of (seed, visit); nothing depends on earlier calls, so Frame(i) is
// the same bit for bit in any call order and from any thread (Frame is thread-safe; a small cache
// of decoded photos is shared between copies of a generator and does not affect results).
//
// Ground truth (matches the loop detector's evaluation): frame a matches frame b when b < a, both
// show the same place and they belong to different visits. Frames of one visit are not loops, so
// with revisit_fraction = 0 no frame has a match.
//
// Distinct places. The ground truth says that different places never match, which is only true
// when no two place photos show the same scene (photo collections hold near-duplicates: two shots
// of one beach, the same animals a second later). So Create() walks the photos in order and skips
// every photo that shows the scene of an already chosen one, until P places are chosen. The test
// is deterministic, independent of the options and deliberately shares nothing with the loop
// detector (whose own check is ORB, its bag of words and a fundamental matrix), so that the tours
// are not cleaned of exactly what the detector would confuse: 500 SIFT features of the photo
// (shrunk to just cover 640x480 when larger); a global descriptor (8-bin gradient orientation
// histograms in 4x4 cells of the grey photo shrunk to 64x64, plus the mean-free colour of a 4x4
// thumbnail) picks the 30 chosen photos of highest cosine similarity, its gradient part with
// opposite orientations folded (no colour) the 30 of most similar shape, and hashes of the SIFT
// descriptors (signs of 16 fixed random projections of the descriptor less its mean, 4 tables)
// the 30 that share the most hash buckets with the photo (each bucket weighted by its rarity,
// log(places / places in the bucket)); each candidate is matched with
// Lowe's ratio test (0.8, L2, every feature against every feature, one-to-one) and the photo is a
// duplicate as soon as a homography (RANSAC, 5 px) has at least 12 inliers and changes areas by
// less than a factor 16 (not degenerate). The thresholds are loose: an unrelated photo dropped
// costs little, a near-duplicate kept turns a right match into a false positive. The
// chosen list is fixed by Create(), so Frame(i) stays independent of call order.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "tools/evaluation/ground_truth.h"

namespace recog::cli {

struct SequenceOptions {
  int places = 50;                // P places; photos in the given order (see distinct_places)
  int frames_per_place = 5;       // consecutive frames per visit
  double revisit_fraction = 0.5;  // fraction of places visited a second time (0 = no loops)
  int width = 640, height = 480;  // output frame size
  // Per-frame camera motion around the slow pan.
  double max_shift_px = 12, max_rotation_deg = 3, max_scale = 0.05;
  // Appearance changes (revisits get stronger ones).
  double blur_sigma_max = 1.0, noise_sigma = 3.0, illumination_max = 0.15;
  uint64_t seed = 1;
  // Skip photos that show the scene of an earlier place and require P distinct photos. When false,
  // the first P photos are used as they are, cycled (and mirrored) when there are fewer.
  bool distinct_places = true;

  // INVALID_ARGUMENT naming the first value out of range.
  Status Validate() const;
};

struct SequenceFrame {
  int index = 0;           // 0-based frame number in the sequence
  int place = 0;           // 0-based place
  int visit = 0;           // 0 on the first visit of the place, 1 on the revisit
  int frame_in_visit = 0;  // 0 .. frames_per_place - 1
  cv::Mat image;           // 8-bit grey or BGR, as the source photo
};

// A photo that Create() left out because it shows the scene of an earlier place.
struct SkippedPhoto {
  std::string photo;
  int same_as_place = 0;  // the chosen place whose photo it matched
  int inliers = 0;        // homography inliers of that match
};

class SequenceGenerator {
 public:
  // INVALID_ARGUMENT when `photos` is empty or the options are bad; NOT_FOUND when a photo that a
  // place uses does not exist. Without distinct_places, photos are decoded lazily, by Frame().
  // With distinct_places, Create() decodes photos in order until P distinct ones are found:
  // INVALID_ARGUMENT when there are fewer than P photos, when they run out before P distinct ones
  // are found, or when a photo it reaches cannot be decoded. Then Frame() decodes the chosen photos
  // again, on demand.
  static StatusOr<SequenceGenerator> Create(std::vector<std::string> photos,
                                            const SequenceOptions& options);

  int num_frames() const { return num_visits() * options_.frames_per_place; }
  int num_places() const { return options_.places; }
  int num_visits() const { return int(visit_place_.size()); }
  int num_revisits() const { return num_visits() - options_.places; }
  const SequenceOptions& options() const { return options_; }
  // The photos the places show (with distinct_places, exactly one per place).
  const std::vector<std::string>& photos() const { return photos_; }
  // Photos that distinct_places left out, in the order they were met (empty without it).
  const std::vector<SkippedPhoto>& skipped() const { return skipped_; }
  int skipped_duplicates() const { return int(skipped_.size()); }
  // Place of visit v of the tour (0-based) and of frame i; -1 when out of range.
  int VisitPlace(int v) const;
  int FramePlace(int i) const;
  // Path of the photo that place p shows, and whether it is mirrored (photo reused).
  const std::string& PlacePhoto(int place) const;
  bool PlaceMirrored(int place) const;

  // Frame i (0-based), generated on demand. INVALID_ARGUMENT for i outside [0, num_frames());
  // NOT_FOUND / INVALID_ARGUMENT when the photo is missing or cannot be decoded.
  StatusOr<SequenceFrame> Frame(int i) const;

  // True when b < a and frames a and b show the same place on different visits.
  bool SamePlace(int a, int b) const;
  // The frames b < a with SamePlace(a, b), increasing.
  std::vector<int> Matches(int a) const;
  // Matches() of every frame.
  GroundTruth BuildGroundTruth() const;

 private:
  struct PhotoCache;
  SequenceGenerator(std::vector<std::string> photos, const SequenceOptions& options);
  StatusOr<cv::Mat> CoverImage(int place) const;

  std::vector<std::string> photos_;
  std::vector<SkippedPhoto> skipped_;
  SequenceOptions options_;
  // Place of each visit of the tour: visit v < P is the first visit of place v, the others are
  // revisits (each place is revisited at most once).
  std::vector<int> visit_place_;
  std::shared_ptr<PhotoCache> cache_;
};

// Frames beyond this count always get the sparse ground truth (a dense file would be N^2 * 2
// bytes).
inline constexpr int kMaxDenseGroundTruthFrames = 5000;

enum class SequenceImageFormat { kPng, kJpeg };
// "png" or "jpg"/"jpeg"; INVALID_ARGUMENT otherwise.
StatusOr<SequenceImageFormat> ParseSequenceImageFormat(std::string_view name);

struct SequenceWriteResult {
  std::string images_dir;         // out_dir/images
  std::string ground_truth_path;  // out_dir/ground_truth.txt or out_dir/ground_truth.sparse.txt
  bool sparse_truth = false;
  int frames = 0;
  int queries_with_matches = 0;
};

// Called after every written frame with (frames written, total frames).
using SequenceProgress = std::function<void(uint64_t done, uint64_t total)>;

// Writes every frame to out_dir/images/000001.png ... (1-based, zero-padded to 6 digits; .jpg at
// quality 95 for kJpeg) and the ground truth: dense out_dir/ground_truth.txt, or sparse
// out_dir/ground_truth.sparse.txt when `sparse_truth` or when there are more than
// kMaxDenseGroundTruthFrames frames (formats: ground_truth.h). Creates out_dir; INVALID_ARGUMENT
// when it exists and is not an empty folder (never overwrites data); INTERNAL when a file cannot be
// written; errors of Frame() as they are.
StatusOr<SequenceWriteResult> WriteSequence(const SequenceGenerator& generator,
                                            const std::string& out_dir, bool sparse_truth,
                                            SequenceImageFormat format = SequenceImageFormat::kPng,
                                            const SequenceProgress& progress = {});

}  // namespace recog::cli
