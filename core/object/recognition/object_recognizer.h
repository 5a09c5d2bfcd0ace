// ObjectRecognizer: finds known objects in an image and their 6-DoF pose (thesis Algorithm 4).
//
//  1. ORB features of the image over a scale pyramid, spread over the image by grid bucketing
//     (DefaultQueryOrb: the defaults were chosen by measurement, see docs/objects.md);
//  2. regions of interest by two-stage clustering of the keypoints (roi_clustering.h), plus the
//     whole image;
//  3. per region: every feature's word and level-1 node are computed once per image, and the
//     region's bag of words is assembled from them; the object database is queried with BC
//     matching (Bhattacharyya candidates within beta of the best, ranked by chi-square);
//  4. correspondences between the region's features and the descriptors of the best object, and
//     of the runner-up when its score is close (candidates_per_roi, runner_up_score_ratio),
//     through the direct index (same level-1 node, nearest-neighbour ratio test);
//  5. geometric verification: 3D objects by RANSAC over P3P on minimal samples (seeded, so the
//     same input gives the same output) then Levenberg-Marquardt on the inliers; planar objects by
//     a RANSAC homography on the face with most correspondences, the pose following from it
//     (IPPE on the inliers). A detection needs at least `min_inliers` inliers (3D objects) or
//     `min_planar_inliers` (planar ones).
//  6. second pass (Recognize only, SecondPassOptions): a small object in a cluttered frame gets
//     few of the image's features, so its region proposes it but its verification fails (with a
//     pose of at least second_pass.min_partial_inliers inliers, short of a detection) or is weak.
//     Such regions (clusters, not the whole image) are cropped from the image with a margin,
//     enlarged when small, and searched again with their own, denser ORB features (mapped back to
//     image pixels): bag of words, BC matching, correspondences and verification as above.
//     RecognizeFeatures has no image, so it runs steps 2-5 only.
//  7. refinement (RefinementOptions): each detection is looked for again near its pose by guided
//     matching (guided_matcher.h: ORB in the box of the projected model, every projected model
//     feature matched to the keypoints around it, RANSAC PnP + LM); the refined pose replaces the
//     first when it has more inliers. Matching by position finds several times the inliers that
//     the direct index finds on a small object, and a pose resting on them is more accurate.
//     RecognizeFeatures refines on the frame's own features.
// Each object is reported once (its best detection) unless `report_duplicates` is set; detections
// come best first: most inliers first, ties in the order they were found. A detection most of
// whose inliers lie inside the outline of another object's detection with more inliers is
// dropped (that part of the image is explained by the stronger object).
//
// A call may name the objects it wants (ObjectFilter, by name or class): candidates the filter
// leaves out are dropped before verification, so they cost no correspondences and no RANSAC. The
// filter is a parameter of each call, not of the recogniser, because it belongs to a request (or
// a stream) while a recogniser is reused across requests (one per worker thread in recogd).
//
// For a SLAM that inserts detections as landmarks (thesis §5.6), a call may also ask
// (DetectionOptions, per call for the same reason) for each detection's inlier 2D-3D
// correspondences and the 6×6 covariance of its pose (geometry/pose_covariance.h: rotation-vector
// perturbation first, then translation; sigma² from the inliers' residuals, floored at
// (0.5 px)²). Both are off by default and then cost nothing.
//
// Not thread-safe (it reuses scratch memory): use one recogniser per thread; they can share one
// ObjectDatabase.
#pragma once

#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "core/features/feature_extractor.h"
#include "core/geometry/correspondences.h"
#include "core/geometry/pose_covariance.h"
#include "core/object/recognition/detection.h"
#include "core/object/recognition/guided_matcher.h"
#include "core/object/recognition/object_database.h"
#include "core/object/recognition/roi_clustering.h"

namespace recog {

// The second pass (step 6 above). The defaults were measured on visp-cube and RoboEarth
// (docs/objects.md, "Evaluation"): more crop features, crop levels, regions or candidates, or a
// wider margin, found no more; enlarging to 480 or 240 px, or 2 crop levels, found fewer.
struct SecondPassOptions {
  bool enabled = true;
  size_t max_regions = 4;  // regions re-examined per image, most correspondences first
  // A first-pass detection with fewer inliers than this is weak: its region is searched again.
  size_t weak_inliers = 20;
  // A region whose candidate was not detected is searched again when RANSAC came close there: a
  // pose with at least this many inliers, fewer than a detection needs (RANSAC PnP reports none
  // below 5). 0 searches every region whose candidate failed, whatever it had. The rule before,
  // every region with 8 correspondences, found a few more rotated RoboEarth views (in regions
  // where the first pass had 8-9 correspondences and no pose) but made the real cluttered frames
  // without an object slower (bench_objects and recog eval objects; the figures are in
  // docs/objects.md, "Evaluation").
  size_t min_partial_inliers = 5;
  double margin = 0.25;    // added to each side of the region's box, as a fraction of its size
  int min_margin_px = 16;  // and at least this many pixels
  // Crops whose longer side is shorter than enlarge_to_px are enlarged towards it (0: never; at
  // most kMaxEnlargeToPx, which bounds the enlarged crop), by a factor of at most max_enlarge.
  static constexpr int kMaxEnlargeToPx = 4096;
  int enlarge_to_px = 320;
  double max_enlarge = 3.0;  // >= 1
  size_t candidates = 1;     // objects verified per crop (BC matching on the crop's features)
  OrbOptions orb = DefaultCropOrb();

  // OK, or INVALID_ARGUMENT naming the first field out of its range; `name` names the struct in
  // the message (a holder passes the member's path, "RecognitionOptions.second_pass").
  Status Validate(std::string_view name = "SecondPassOptions") const;

  static OrbOptions DefaultCropOrb() {
    OrbOptions orb;
    orb.max_features = 500;
    orb.levels = 4;
    return orb;
  }
};

// Step 7. Defaults measured on visp-rbt-cube (docs/objects.md, "Evaluation").
struct RefinementOptions {
  bool enabled = true;
  // Detections with at least this many inliers are kept as they are: their pose rests on enough
  // (an object that fills the view has hundreds, and its guided matching would cost most).
  size_t max_inliers = 60;
  GuidedMatchOptions matching;

  // OK, or INVALID_ARGUMENT naming the first field out of its range (its matching's included);
  // `name` names the struct in the message.
  Status Validate(std::string_view name = "RefinementOptions") const;
};

struct RecognitionOptions {
  OrbOptions orb = DefaultQueryOrb();
  RoiOptions roi;
  double beta = 0.5;  // BC matching (thesis §5.4.4.2)
  // Objects verified per region, best chi-square score first (the thesis verifies the best one).
  // A runner-up is verified only when its score is at least runner_up_score_ratio of the best's.
  // The runner-up finds more RoboEarth views in leave-one-view-out (as taken, halved and rotated),
  // with no wrong object, for a little more time on real cluttered frames without an object; every
  // runner-up that became a detection there scored above runner_up_score_ratio of the best (the
  // figures are in docs/objects.md, "Evaluation").
  size_t candidates_per_roi = 2;
  double runner_up_score_ratio = 0.65;
  MatchOptions match = {0.8, 64};  // ratio test and Hamming bound for correspondences
  int ransac_iterations = 100;     // thesis Table 5.4
  double reprojection_px = 4.0;    // inlier threshold
  // PnP, 3D objects. The thesis (§5.7.2.1) takes 6; with the pyramid and the second pass, 6 and
  // 7 let the RoboEarth box be reported on lion and bio views (6-7 inliers, wrong pose), 8 none.
  size_t min_inliers = 8;
  // Homographies (planar objects) need more: with 8 degrees of freedom fitted to 4-point samples,
  // a printed label shared by two products (the bottle1 and bio packs of the RoboEarth set) gave
  // an 11-inlier homography on the wrong object.
  size_t min_planar_inliers = 12;
  uint64_t seed = 1;               // RANSAC sampling
  bool report_duplicates = false;  // report an object once per region instead of once per image
  SecondPassOptions second_pass;
  RefinementOptions refinement;

  // OK, or INVALID_ARGUMENT naming the first field out of its range, its members' included
  // ("RecognitionOptions.match.ratio = nan: must be in (0, 1]"); `name` names the struct in the
  // message.
  Status Validate(std::string_view name = "RecognitionOptions") const;

  // 1300 features over 3 levels at 1.2, spread over the image by an 8x8 grid whose cells short
  // of corners give their share to the strongest keypoints of cells holding fewer than 3 shares.
  // ORB's own ranking is over the whole image: in a real cluttered scene the high-contrast
  // clutter (a fiducial board, a keyboard) takes every feature and a small, softly textured
  // object gets none (visp-rbt-cube's frame 0: not one feature on the cube). A plain grid starves
  // an object that fills a view on a plain background instead (fewer RoboEarth views found); the
  // capped fill serves both. Measured (docs/objects.md, "Evaluation") against no grid,
  // a plain grid, caps of 2 and no cap, and 1000 and 1500 features.
  static OrbOptions DefaultQueryOrb() {
    OrbOptions orb;
    orb.max_features = 1300;
    orb.levels = 3;
    orb.grid_rows = orb.grid_cols = 8;
    orb.grid_fill_cap = 3;
    return orb;
  }
};

// Which objects a call is interested in: those whose name is in `names` or whose class is in
// `classes`. Both empty (the default) = every object.
struct ObjectFilter {
  std::vector<std::string> names;
  std::vector<std::string> classes;
  bool Passes(const ObjectMetadata& object) const;
};

// Where an object that a call considered dropped out (or that it was reported), for a user
// whose object is not found: the recogniser's counterpart of the place side's query statuses.
enum class ObjectOutcome {
  kNotProposed,         // no region's BC matching made it a candidate
  kFewCorrespondences,  // a candidate, but the direct index found fewer than min_inliers
  kFewInliers,          // enough correspondences, but no pose with the minimum of inliers
  kSuppressed,          // found, but most of its inliers lie in a stronger object's outline
  kDetected,            // reported
};
std::string_view ObjectOutcomeName(ObjectOutcome outcome);  // "not_proposed", "detected", ...

// One object of the database (that the call's filter lets through) and what became of it.
struct ObjectExplanation {
  std::string name;
  ObjectOutcome outcome = ObjectOutcome::kNotProposed;
  size_t regions = 0;          // regions (both passes) whose BC matching proposed it
  double best_score = 0;       // its best chi-square score in them
  size_t correspondences = 0;  // most correspondences in one verification
  size_t inliers = 0;          // most RANSAC inliers in one verification (before refinement)
  size_t min_inliers = 0;      // what a detection needs (min_inliers or min_planar_inliers)
};

// Milliseconds per stage for one image (thesis Table 5.6). The stages from orb to ransac are the
// first pass's; second_pass is all of the second pass (crops, their ORB and every later step);
// refinement is step 7 for every detection.
struct RecognitionTiming {
  double orb = 0, clustering = 0, conversion = 0, query = 0, correspondences = 0, ransac = 0,
         second_pass = 0, refinement = 0, total = 0;
  size_t regions = 0;
  size_t second_pass_regions = 0;  // regions re-examined by the second pass
  size_t verified = 0;             // candidate objects that went to geometric verification
};

class ObjectRecognizer {
 public:
  // A recogniser over `database` (not null) with `options`; INVALID_ARGUMENT, naming the field,
  // for options out of range (RecognitionOptions::Validate).
  static StatusOr<ObjectRecognizer> Create(std::shared_ptr<const ObjectDatabase> database,
                                           RecognitionOptions options = {});

  // The objects of `filter` found in the image, best first, with the extras `extras` asks for.
  // With `explanation`, also every object of the database that the filter lets through, by
  // name, with where it dropped out (costs a little bookkeeping per verified candidate).
  // INVALID_ARGUMENT for an empty or non-8-bit image, or invalid intrinsics.
  Status Recognize(const cv::Mat& image, const CameraIntrinsics& camera,
                   std::vector<Detection>* detections, RecognitionTiming* timing = nullptr,
                   const ObjectFilter& filter = {}, const DetectionOptions& extras = {},
                   std::vector<ObjectExplanation>* explanation = nullptr);
  // The same from features already extracted (with the database's descriptor format), without
  // the second pass (it needs the image).
  Status RecognizeFeatures(const FeatureSet& features, const CameraIntrinsics& camera,
                           std::vector<Detection>* detections, RecognitionTiming* timing = nullptr,
                           const ObjectFilter& filter = {}, const DetectionOptions& extras = {},
                           std::vector<ObjectExplanation>* explanation = nullptr);

  const RecognitionOptions& options() const { return options_; }

 private:
  ObjectRecognizer(std::shared_ptr<const ObjectDatabase> database, RecognitionOptions options);

  // A set of features with what every region needs of them: their words, level-1 nodes and
  // pixels without lens distortion.
  struct QueryFeatures {
    const FeatureSet* features = nullptr;
    std::vector<WordId> words;
    std::vector<NodeId> nodes;
    std::vector<cv::Point2f> positions;  // keypoint pixels
    std::vector<cv::Point2f> pinhole;    // the same without lens distortion
  };
  // One region's features as the direct-index matching reads them, gathered once for all of
  // the region's candidates.
  struct RegionFeatures {
    const std::vector<uint32_t>* indices = nullptr;    // into the query's features
    cv::Mat descriptors;                               // row i: feature indices[i]'s descriptor
    FeatureVector direct;                              // the rows by level-l node
    std::vector<std::pair<NodeId, uint32_t>> by_node;  // scratch: (node, row), sorted
  };
  // What one verification found.
  struct Verification {
    bool detected = false;
    size_t correspondences = 0;  // from the direct index
    size_t inliers = 0;          // of the best pose (0 when RANSAC did not run or found none)
  };
  // A region whose first-pass search found nothing or only weak detections.
  struct Revisit {
    size_t region;
    cv::Rect2f bounds;
    size_t evidence;  // most correspondences of its weak or failed candidates
  };

  // The pipeline after feature extraction; fills every field of *timing but orb, second_pass and
  // total. Regions for the second pass go to *revisits.
  Status Run(const FeatureSet& features, const CameraIntrinsics& camera, const ObjectFilter& filter,
             const DetectionOptions& extras, std::vector<Detection>* detections,
             RecognitionTiming* timing, std::vector<Revisit>* revisits);
  // Step 6 on the regions of `revisits`.
  Status SecondPass(const cv::Mat& image, const CameraIntrinsics& camera,
                    const ObjectFilter& filter, const DetectionOptions& extras,
                    const std::vector<Revisit>& revisits, std::vector<Detection>* detections,
                    RecognitionTiming* timing);
  // Positions, pinhole pixels, words and nodes of query->features.
  Status Prepare(const CameraIntrinsics& camera, QueryFeatures* query) const;
  // BC matching of the bag of words of `region` (indices into query.features).
  Status QueryRegion(const QueryFeatures& query, const std::vector<uint32_t>& region,
                     size_t candidates, std::vector<BcMatch>* matches, RecognitionTiming* timing);
  // Verifies the candidates against a region: passing detections are appended, with `region` as
  // their region. *weak is set when a candidate was detected with fewer than
  // second_pass.weak_inliers inliers, or not detected although RANSAC found a pose of
  // second_pass.min_partial_inliers inliers; *evidence is then the most correspondences of those
  // candidates.
  void VerifyCandidates(const std::vector<BcMatch>& candidates, const QueryFeatures& query,
                        const std::vector<uint32_t>& region, int region_index,
                        const CameraIntrinsics& camera, const ObjectFilter& filter,
                        const DetectionOptions& extras, std::vector<Detection>* detections,
                        RecognitionTiming* timing, bool* weak, size_t* evidence);
  // Step 7 on every detection, against `image` or, when it is empty, `features`.
  void Refine(const cv::Mat& image, const FeatureSet* features, const CameraIntrinsics& camera,
              const DetectionOptions& extras, std::vector<Detection>* detections);
  // Fills *out with the features `region` lists (indices into query.features).
  static void GatherRegion(const QueryFeatures& query, const std::vector<uint32_t>& region,
                           RegionFeatures* out);
  // Verifies one candidate object against a region; *detection is filled when it passes.
  Verification Verify(const IndexedObject& object, const QueryFeatures& query,
                      const RegionFeatures& region, const CameraIntrinsics& camera,
                      const DetectionOptions& extras, RecognitionTiming* timing,
                      Detection* detection);
  // The explanation of the call that just ran (explained_ and the suppressed objects), one entry
  // per object of the database that `filter` lets through.
  void Explain(const std::vector<Detection>& detections, const std::vector<EntryId>& suppressed,
               const ObjectFilter& filter, std::vector<ObjectExplanation>* explanation) const;

  std::shared_ptr<const ObjectDatabase> database_;
  RecognitionOptions options_;
  std::unique_ptr<FeatureExtractor> extractor_;
  std::unique_ptr<FeatureExtractor> crop_extractor_;
  RoiClusterer clusterer_;
  GuidedMatcher refiner_;
  // Scratch reused across images.
  bool explaining_ = false;                             // the call asked for an explanation
  std::map<std::string, ObjectExplanation> explained_;  // by name, filled while explaining_
  std::vector<EntryId> suppressed_;                     // objects SortDetections dropped as covered
  FeatureSet features_;
  QueryFeatures query_;
  std::vector<RegionOfInterest> regions_;
  std::vector<Revisit> revisits_;
  cv::Mat crop_;
  FeatureSet crop_features_;
  QueryFeatures crop_query_;
  RegionFeatures region_features_;
};

}  // namespace recog
