#include "core/object/recognition/object_recognizer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <numeric>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/elapsed.h"
#include "core/common/option_checks.h"
#include "core/object/recognition/object_pose.h"

namespace recog {
namespace {

using Clock = std::chrono::steady_clock;

// A homography on the face with most correspondences, then the pose by IPPE on its inliers.
bool HomographyPose(const cv::Matx33d& K, const IndexedObject& object,
                    const std::vector<uint32_t>& model_features,
                    const std::vector<cv::Point2f>& image, int iterations, double threshold_px,
                    RigidTransform* pose, std::vector<uint32_t>* inliers) {
  std::vector<size_t> per_face(object.faces.size(), 0);
  for (uint32_t f : model_features) ++per_face[object.face_of_feature[f]];
  const uint32_t face =
      uint32_t(std::max_element(per_face.begin(), per_face.end()) - per_face.begin());
  if (per_face[face] < 4) return false;
  const RigidTransform face_from_object = object.faces[face].object_from_face.Inverse();
  std::vector<uint32_t> on_face;
  std::vector<cv::Point2f> face_points, face_pixels;
  for (uint32_t i = 0; i < model_features.size(); ++i) {
    if (object.face_of_feature[model_features[i]] != face) continue;
    const cv::Point3d q = face_from_object.Apply(cv::Point3d(object.points[model_features[i]]));
    on_face.push_back(i);
    face_points.emplace_back(float(q.x), float(q.y));
    face_pixels.push_back(image[i]);
  }
  // The homography maps face coordinates to pixels; its RANSAC threshold is in pixels.
  cv::Mat mask;
  const cv::Mat H = cv::findHomography(face_points, face_pixels, cv::RANSAC, threshold_px, mask,
                                       std::max(iterations, 1), 0.995);
  if (H.empty()) return false;
  std::vector<uint32_t> homography_inliers;
  for (int i = 0; i < mask.rows; ++i) {
    if (mask.at<uint8_t>(i)) homography_inliers.push_back(on_face[size_t(i)]);
  }
  if (homography_inliers.size() < 4) return false;
  std::vector<cv::Point3f> object_points;
  std::vector<cv::Point2f> pixels;
  for (uint32_t i : homography_inliers) {
    object_points.push_back(object.points[model_features[i]]);
    pixels.push_back(image[i]);
  }
  cv::Vec3d rvec, tvec;
  try {
    if (!cv::solvePnP(object_points, pixels, K, cv::noArray(), rvec, tvec, false,
                      cv::SOLVEPNP_IPPE)) {
      return false;
    }
  } catch (const cv::Exception&) {
    return false;
  }
  *pose = RefinePose(K, PoseFromRodrigues(rvec, tvec), object_points, pixels);
  std::vector<cv::Point3f> all_points;
  for (uint32_t f : model_features) all_points.push_back(object.points[f]);
  ReprojectionInliers(K, *pose, all_points, image, threshold_px, inliers);
  return true;
}

// Keeps each object's best detection (most inliers, then lowest error) unless `duplicates`, then
// orders them best first (the documented order). Last, a detection is dropped when most of its
// inliers lie inside the outline of a kept detection of another object with more inliers: that
// part of the image is explained by the stronger object (a few of its features fitted by another
// model, e.g. a label printed on two products).
// The ids of the detections dropped as covered go to *suppressed.
void SortDetections(bool duplicates, std::vector<Detection>* detections,
                    std::vector<EntryId>* suppressed) {
  suppressed->clear();
  if (!duplicates) {
    std::stable_sort(detections->begin(), detections->end(),
                     [](const Detection& a, const Detection& b) {
                       if (a.id != b.id) return a.id < b.id;
                       if (a.inliers != b.inliers) return a.inliers > b.inliers;
                       return a.reprojection_error_px < b.reprojection_error_px;
                     });
    detections->erase(
        std::unique(detections->begin(), detections->end(),
                    [](const Detection& a, const Detection& b) { return a.id == b.id; }),
        detections->end());
  }
  std::stable_sort(detections->begin(), detections->end(),
                   [](const Detection& a, const Detection& b) { return a.inliers > b.inliers; });
  std::vector<Detection> kept;
  kept.reserve(detections->size());
  for (Detection& detection : *detections) {
    const bool covered = std::any_of(kept.begin(), kept.end(), [&](const Detection& stronger) {
      if (stronger.id == detection.id || stronger.inliers <= detection.inliers ||
          stronger.outline.size() < 3) {
        return false;
      }
      const size_t inside =
          size_t(std::count_if(detection.inlier_pixels.begin(), detection.inlier_pixels.end(),
                               [&](const cv::Point2f& p) {
                                 return cv::pointPolygonTest(stronger.outline, p, false) >= 0;
                               }));
      return 2 * inside > detection.inlier_pixels.size();
    });
    if (covered) {
      suppressed->push_back(detection.id);
    } else {
      kept.push_back(std::move(detection));
    }
  }
  detections->swap(kept);
}

}  // namespace

std::string_view ObjectOutcomeName(ObjectOutcome outcome) {
  switch (outcome) {
    case ObjectOutcome::kNotProposed:
      return "not_proposed";
    case ObjectOutcome::kFewCorrespondences:
      return "few_correspondences";
    case ObjectOutcome::kFewInliers:
      return "few_inliers";
    case ObjectOutcome::kSuppressed:
      return "suppressed";
    case ObjectOutcome::kDetected:
      return "detected";
  }
  return "unknown";
}

bool ObjectFilter::Passes(const ObjectMetadata& object) const {
  if (names.empty() && classes.empty()) return true;
  return std::find(names.begin(), names.end(), object.name) != names.end() ||
         std::find(classes.begin(), classes.end(), object.object_class) != classes.end();
}

Status SecondPassOptions::Validate(std::string_view name) const {
  OptionChecks check(name);
  check.InRange("margin", margin, RealRange::AtLeast(0));
  check.AtLeast("min_margin_px", min_margin_px, 0);
  check.InRange("enlarge_to_px", enlarge_to_px, 0, kMaxEnlargeToPx);
  check.InRange("max_enlarge", max_enlarge, RealRange::AtLeast(1));
  check.AtLeast("candidates", candidates, 1);
  check.Member("orb", orb);
  return check.status();
}

Status RefinementOptions::Validate(std::string_view name) const {
  OptionChecks check(name);
  check.Member("matching", matching);
  return check.status();
}

Status RecognitionOptions::Validate(std::string_view name) const {
  OptionChecks check(name);
  check.Member("orb", orb);
  check.Member("roi", roi);
  // BC matching keeps the candidates scoring at least beta times the best.
  check.InRange("beta", beta, RealRange::Closed(0, 1));
  check.AtLeast("candidates_per_roi", candidates_per_roi, 1);
  // Above 1 even the best candidate would fall short of it.
  check.InRange("runner_up_score_ratio", runner_up_score_ratio, RealRange::Closed(0, 1));
  check.Member("match", match);
  check.AtLeast("ransac_iterations", ransac_iterations, 1);
  check.InRange("reprojection_px", reprojection_px, RealRange::Above(0));
  check.AtLeast("min_inliers", min_inliers, 1);
  check.AtLeast("min_planar_inliers", min_planar_inliers, 1);
  check.Member("second_pass", second_pass);
  check.Member("refinement", refinement);
  return check.status();
}

StatusOr<ObjectRecognizer> ObjectRecognizer::Create(std::shared_ptr<const ObjectDatabase> database,
                                                    RecognitionOptions options) {
  if (database == nullptr) {
    return Status::InvalidArgument("an object recogniser needs an object database");
  }
  RECOG_RETURN_IF_ERROR(options.Validate());
  return ObjectRecognizer(std::move(database), std::move(options));
}

ObjectRecognizer::ObjectRecognizer(std::shared_ptr<const ObjectDatabase> database,
                                   RecognitionOptions options)
    : database_(std::move(database)),
      options_(std::move(options)),
      clusterer_(options_.roi),
      refiner_(options_.refinement.matching) {}

Status ObjectRecognizer::Recognize(const cv::Mat& image, const CameraIntrinsics& camera,
                                   std::vector<Detection>* detections, RecognitionTiming* timing,
                                   const ObjectFilter& filter, const DetectionOptions& extras,
                                   std::vector<ObjectExplanation>* explanation) {
  const auto start = Clock::now();
  detections->clear();
  if (explanation != nullptr) explanation->clear();
  RECOG_RETURN_IF_ERROR(camera.Validate());
  explaining_ = explanation != nullptr;
  explained_.clear();
  if (!extractor_) {
    FeatureOptions feature_options;
    feature_options.orb = options_.orb;
    RECOG_ASSIGN_OR_RETURN(extractor_, CreateFeatureExtractor(feature_options));
  }
  RECOG_RETURN_IF_ERROR(extractor_->Extract(image, &features_));
  RecognitionTiming local;
  RecognitionTiming* t = timing != nullptr ? timing : &local;
  *t = RecognitionTiming();
  t->orb = MillisecondsSince(start);
  RECOG_RETURN_IF_ERROR(Run(features_, camera, filter, extras, detections, t, &revisits_));
  if (options_.second_pass.enabled && !revisits_.empty()) {
    const auto phase = Clock::now();
    RECOG_RETURN_IF_ERROR(SecondPass(image, camera, filter, extras, revisits_, detections, t));
    t->second_pass = MillisecondsSince(phase);
  }
  SortDetections(options_.report_duplicates, detections, &suppressed_);
  const auto phase = Clock::now();
  Refine(image, nullptr, camera, extras, detections);
  t->refinement = MillisecondsSince(phase);
  t->total = MillisecondsSince(start);
  if (explaining_) Explain(*detections, suppressed_, filter, explanation);
  return Status::Ok();
}

Status ObjectRecognizer::RecognizeFeatures(const FeatureSet& features,
                                           const CameraIntrinsics& camera,
                                           std::vector<Detection>* detections,
                                           RecognitionTiming* timing, const ObjectFilter& filter,
                                           const DetectionOptions& extras,
                                           std::vector<ObjectExplanation>* explanation) {
  const auto start = Clock::now();
  detections->clear();
  if (explanation != nullptr) explanation->clear();
  RECOG_RETURN_IF_ERROR(camera.Validate());
  explaining_ = explanation != nullptr;
  explained_.clear();
  RECOG_RETURN_IF_ERROR(CheckFeatureSet(features, database_->vocabulary().info().descriptor)
                            .WithContext("query features"));
  RecognitionTiming local;
  RecognitionTiming* t = timing != nullptr ? timing : &local;
  *t = RecognitionTiming();
  RECOG_RETURN_IF_ERROR(Run(features, camera, filter, extras, detections, t, &revisits_));
  SortDetections(options_.report_duplicates, detections, &suppressed_);
  const auto phase = Clock::now();
  Refine(cv::Mat(), &features, camera, extras, detections);
  t->refinement = MillisecondsSince(phase);
  t->total = MillisecondsSince(start);
  if (explaining_) Explain(*detections, suppressed_, filter, explanation);
  return Status::Ok();
}

Status ObjectRecognizer::Prepare(const CameraIntrinsics& camera, QueryFeatures* query) const {
  const FeatureSet& features = *query->features;
  query->positions.resize(features.size());
  for (size_t i = 0; i < features.size(); ++i) query->positions[i] = features.keypoints[i].pt;
  query->pinhole = query->positions;
  ToPinhole(camera, query->pinhole);
  return database_->vocabulary().TransformEach(features.descriptors, &query->words, &query->nodes,
                                               database_->direct_levels_up());
}

Status ObjectRecognizer::QueryRegion(const QueryFeatures& query,
                                     const std::vector<uint32_t>& region, size_t candidates,
                                     std::vector<BcMatch>* matches, RecognitionTiming* t) {
  const Vocabulary& vocabulary = database_->vocabulary();
  auto phase = Clock::now();
  std::vector<BowEntry> entries;
  entries.reserve(region.size());
  for (uint32_t f : region) {
    const float weight = vocabulary.WordWeight(query.words[f]);
    if (weight > 0) entries.push_back({query.words[f], weight});
  }
  BowVector bow(entries);
  bow.Normalize(BowNormalization::kL1);
  t->conversion += MillisecondsSince(phase);
  phase = Clock::now();
  RECOG_RETURN_IF_ERROR(
      database_->index().QueryBcMatching(bow, options_.beta, candidates, matches));
  t->query += MillisecondsSince(phase);
  return Status::Ok();
}

void ObjectRecognizer::VerifyCandidates(const std::vector<BcMatch>& candidates,
                                        const QueryFeatures& query,
                                        const std::vector<uint32_t>& region, int region_index,
                                        const CameraIntrinsics& camera, const ObjectFilter& filter,
                                        const DetectionOptions& extras,
                                        std::vector<Detection>* detections, RecognitionTiming* t,
                                        bool* weak, size_t* evidence) {
  *weak = false;
  *evidence = 0;
  bool gathered = false;
  for (const BcMatch& candidate : candidates) {
    // Ranked best first: the runners-up that follow score lower still.
    if (candidate.chi_square < options_.runner_up_score_ratio * candidates.front().chi_square) {
      break;
    }
    // Found already with enough inliers: a duplicate (skipped unless asked for). A weak earlier
    // detection does not stop a better one.
    const bool found_already =
        std::any_of(detections->begin(), detections->end(), [&](const Detection& d) {
          return d.id == candidate.id && d.inliers >= options_.second_pass.weak_inliers;
        });
    if (found_already && !options_.report_duplicates) continue;
    const std::shared_ptr<const IndexedObject> object = database_->Find(candidate.id);
    if (!object) continue;  // removed meanwhile
    if (!filter.Passes(object->metadata)) continue;
    ++t->verified;
    if (!gathered) {
      const auto phase = Clock::now();
      GatherRegion(query, region, &region_features_);
      t->correspondences += MillisecondsSince(phase);
      gathered = true;
    }
    Detection detection;
    const Verification verification =
        Verify(*object, query, region_features_, camera, extras, t, &detection);
    if (explaining_) {
      ObjectExplanation& explained = explained_[object->metadata.name];
      ++explained.regions;
      explained.best_score = std::max(explained.best_score, candidate.chi_square);
      explained.correspondences = std::max(explained.correspondences, verification.correspondences);
      explained.inliers = std::max(explained.inliers, verification.inliers);
    }
    if (verification.detected) {
      detection.score = candidate.chi_square;
      detection.region = region_index;
      if (detection.inliers < options_.second_pass.weak_inliers) {
        *weak = true;
        *evidence = std::max(*evidence, verification.correspondences);
      }
      detections->push_back(std::move(detection));
    } else {
      // Failed: worth a closer look only when RANSAC came close to a pose of the object there.
      if (verification.inliers >= options_.second_pass.min_partial_inliers) {
        *weak = true;
        *evidence = std::max(*evidence, verification.correspondences);
      }
    }
  }
}

Status ObjectRecognizer::Run(const FeatureSet& features, const CameraIntrinsics& camera,
                             const ObjectFilter& filter, const DetectionOptions& extras,
                             std::vector<Detection>* detections, RecognitionTiming* t,
                             std::vector<Revisit>* revisits) {
  revisits->clear();
  auto phase = Clock::now();
  query_.features = &features;
  RECOG_RETURN_IF_ERROR(Prepare(camera, &query_));
  // Prepare computed the words too; they count as conversion.
  const double prepared = MillisecondsSince(phase);
  phase = Clock::now();
  clusterer_.Cluster(query_.positions, &regions_);
  t->clustering = MillisecondsSince(phase);
  t->conversion = prepared;
  t->regions = regions_.size();

  std::vector<BcMatch> candidates;
  // The whole image (last region) goes first: it holds every correspondence of an object that
  // fills the view, so its pose is the best one; the clusters then find the smaller objects.
  for (size_t k = 0; k < regions_.size(); ++k) {
    const size_t r = (k + regions_.size() - 1) % regions_.size();
    const RegionOfInterest& region = regions_[r];
    RECOG_RETURN_IF_ERROR(
        QueryRegion(query_, region.features, options_.candidates_per_roi, &candidates, t));
    bool weak = false;
    size_t evidence = 0;
    VerifyCandidates(candidates, query_, region.features, int(r), camera, filter, extras,
                     detections, t, &weak, &evidence);
    if (weak && !region.whole_image) revisits->push_back({r, region.bounds, evidence});
  }
  // The regions with most correspondences first: the second pass looks at the best few.
  std::stable_sort(revisits->begin(), revisits->end(),
                   [](const Revisit& a, const Revisit& b) { return a.evidence > b.evidence; });
  return Status::Ok();
}

Status ObjectRecognizer::SecondPass(const cv::Mat& image, const CameraIntrinsics& camera,
                                    const ObjectFilter& filter, const DetectionOptions& extras,
                                    const std::vector<Revisit>& revisits,
                                    std::vector<Detection>* detections, RecognitionTiming* t) {
  const SecondPassOptions& pass = options_.second_pass;
  if (!crop_extractor_) {
    FeatureOptions feature_options;
    feature_options.orb = pass.orb;
    RECOG_ASSIGN_OR_RETURN(crop_extractor_, CreateFeatureExtractor(feature_options));
  }
  const cv::Rect image_rect(0, 0, image.cols, image.rows);
  // The stages of the second pass are counted in t->second_pass, not in the first pass's.
  RecognitionTiming stages;
  std::vector<BcMatch> candidates;
  std::vector<uint32_t> all;
  const size_t count = std::min(revisits.size(), pass.max_regions);
  for (size_t i = 0; i < count; ++i) {
    const cv::Rect2f& bounds = revisits[i].bounds;
    const double margin_x = std::max(pass.margin * bounds.width, double(pass.min_margin_px));
    const double margin_y = std::max(pass.margin * bounds.height, double(pass.min_margin_px));
    const cv::Rect box = cv::Rect(cv::Point(int(std::floor(bounds.x - margin_x)),
                                            int(std::floor(bounds.y - margin_y))),
                                  cv::Point(int(std::ceil(bounds.br().x + margin_x)),
                                            int(std::ceil(bounds.br().y + margin_y)))) &
                         image_rect;
    if (box.empty()) continue;
    const double scale = std::clamp(double(pass.enlarge_to_px) / std::max(box.width, box.height),
                                    1.0, pass.max_enlarge);
    if (scale > 1.0) {
      cv::resize(image(box), crop_, cv::Size(), scale, scale, cv::INTER_LINEAR);
    } else {
      crop_ = image(box);
    }
    RECOG_RETURN_IF_ERROR(crop_extractor_->Extract(crop_, &crop_features_));
    ++t->second_pass_regions;
    // Back to image pixels (cv::resize maps pixel centres: x_crop + 0.5 = s (x_box + 0.5)).
    for (cv::KeyPoint& keypoint : crop_features_.keypoints) {
      keypoint.pt.x = float(box.x + (keypoint.pt.x + 0.5) / scale - 0.5);
      keypoint.pt.y = float(box.y + (keypoint.pt.y + 0.5) / scale - 0.5);
      keypoint.size = float(keypoint.size / scale);
    }
    crop_query_.features = &crop_features_;
    RECOG_RETURN_IF_ERROR(Prepare(camera, &crop_query_));
    all.resize(crop_features_.size());
    std::iota(all.begin(), all.end(), 0u);
    RECOG_RETURN_IF_ERROR(QueryRegion(crop_query_, all, pass.candidates, &candidates, &stages));
    bool weak = false;
    size_t evidence = 0;
    VerifyCandidates(candidates, crop_query_, all, int(revisits[i].region), camera, filter, extras,
                     detections, &stages, &weak, &evidence);
  }
  t->verified += stages.verified;
  return Status::Ok();
}

void ObjectRecognizer::Refine(const cv::Mat& image, const FeatureSet* features,
                              const CameraIntrinsics& camera, const DetectionOptions& extras,
                              std::vector<Detection>* detections) {
  if (!options_.refinement.enabled || detections->empty()) return;
  for (Detection& detection : *detections) {
    if (detection.inliers >= options_.refinement.max_inliers) continue;
    const std::shared_ptr<const IndexedObject> object = database_->Find(detection.id);
    if (!object) continue;  // removed meanwhile
    Detection refined;
    if (!refiner_.Match(*object, detection.camera_from_object, image, features, camera, extras,
                        &refined) ||
        refined.inliers <= detection.inliers) {
      continue;
    }
    refined.score = detection.score;
    refined.region = detection.region;
    detection = std::move(refined);
  }
  // Refinement changes the inlier counts: best first again.
  std::stable_sort(detections->begin(), detections->end(),
                   [](const Detection& a, const Detection& b) { return a.inliers > b.inliers; });
}

void ObjectRecognizer::GatherRegion(const QueryFeatures& query, const std::vector<uint32_t>& region,
                                    RegionFeatures* out) {
  const FeatureSet& features = *query.features;
  const int row_bytes = features.descriptors.cols;
  out->indices = &region;
  out->descriptors.create(int(region.size()), row_bytes, CV_8U);
  out->by_node.resize(region.size());
  for (size_t i = 0; i < region.size(); ++i) {
    std::memcpy(out->descriptors.ptr(int(i)), features.descriptors.ptr(int(region[i])),
                size_t(row_bytes));
    out->by_node[i] = {query.nodes[region[i]], uint32_t(i)};
  }
  std::sort(out->by_node.begin(), out->by_node.end());
  out->direct.AssignSorted(out->by_node);
}

ObjectRecognizer::Verification ObjectRecognizer::Verify(
    const IndexedObject& object, const QueryFeatures& query, const RegionFeatures& region_features,
    const CameraIntrinsics& camera, const DetectionOptions& extras, RecognitionTiming* timing,
    Detection* detection) {
  Verification verification;
  auto phase = Clock::now();
  const std::vector<uint32_t>& region = *region_features.indices;
  std::vector<Match> matches;
  const Status matched =
      MatchByDirectIndexInOrder(region_features.direct, region_features.descriptors, object.direct,
                                object.direct_descriptors, options_.match, &matches);
  timing->correspondences += MillisecondsSince(phase);
  verification.correspondences = matched.ok() ? matches.size() : 0;
  if (verification.correspondences < options_.min_inliers) return verification;

  phase = Clock::now();
  std::vector<cv::Point3f> object_points(matches.size());
  std::vector<cv::Point2f> image_points(matches.size());
  std::vector<uint32_t> model_features(matches.size());
  for (size_t i = 0; i < matches.size(); ++i) {
    model_features[i] = matches[i].b;
    object_points[i] = object.points[matches[i].b];
    image_points[i] = query.pinhole[region[matches[i].a]];
  }
  const cv::Matx33d K = camera.K();
  RigidTransform pose;
  std::vector<uint32_t> inliers;
  const bool solved =
      object.metadata.type == ObjectType::kPlanar
          ? HomographyPose(K, object, model_features, image_points, options_.ransac_iterations,
                           options_.reprojection_px, &pose, &inliers)
          : RansacPnp(K, object_points, image_points, options_.ransac_iterations,
                      options_.reprojection_px, options_.seed, &pose, &inliers);
  timing->ransac += MillisecondsSince(phase);
  const size_t needed = object.metadata.type == ObjectType::kPlanar ? options_.min_planar_inliers
                                                                    : options_.min_inliers;
  verification.inliers = solved ? inliers.size() : 0;
  if (!solved || inliers.size() < needed) return verification;

  std::vector<cv::Point2f> keypoints(matches.size());
  for (size_t i = 0; i < matches.size(); ++i) keypoints[i] = query.positions[region[matches[i].a]];
  CompleteDetection(object, camera, pose, inliers, model_features, object_points, image_points,
                    keypoints, extras, detection);
  verification.detected = true;
  return verification;
}

void ObjectRecognizer::Explain(const std::vector<Detection>& detections,
                               const std::vector<EntryId>& suppressed, const ObjectFilter& filter,
                               std::vector<ObjectExplanation>* explanation) const {
  for (const ObjectMetadata& object : database_->List()) {
    if (!filter.Passes(object)) continue;
    const auto known = explained_.find(object.name);
    ObjectExplanation entry = known != explained_.end() ? known->second : ObjectExplanation();
    entry.name = object.name;
    entry.min_inliers =
        object.type == ObjectType::kPlanar ? options_.min_planar_inliers : options_.min_inliers;
    const auto named = [&](const Detection& d) { return d.name == object.name; };
    const bool was_suppressed = std::any_of(suppressed.begin(), suppressed.end(), [&](EntryId id) {
      const std::shared_ptr<const IndexedObject> found = database_->Find(id);
      return found && found->metadata.name == object.name;
    });
    if (std::any_of(detections.begin(), detections.end(), named)) {
      entry.outcome = ObjectOutcome::kDetected;
    } else if (was_suppressed) {
      entry.outcome = ObjectOutcome::kSuppressed;
    } else if (entry.regions == 0) {
      entry.outcome = ObjectOutcome::kNotProposed;
    } else if (entry.correspondences < options_.min_inliers) {
      entry.outcome = ObjectOutcome::kFewCorrespondences;
    } else {
      entry.outcome = ObjectOutcome::kFewInliers;
    }
    explanation->push_back(std::move(entry));
  }
}

}  // namespace recog
