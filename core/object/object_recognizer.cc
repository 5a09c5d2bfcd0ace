#include "core/object/object_recognizer.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "core/object/object_pose.h"

namespace recog {
namespace {

using Clock = std::chrono::steady_clock;

double MillisecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

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

}  // namespace

bool ObjectFilter::Passes(const ObjectMetadata& object) const {
  if (names.empty() && classes.empty()) return true;
  return std::find(names.begin(), names.end(), object.name) != names.end() ||
         std::find(classes.begin(), classes.end(), object.object_class) != classes.end();
}

ObjectRecognizer::ObjectRecognizer(std::shared_ptr<const ObjectDatabase> database,
                                   RecognitionOptions options)
    : database_(std::move(database)), options_(std::move(options)), clusterer_(options_.roi) {}

Status ObjectRecognizer::Recognize(const cv::Mat& image, const CameraIntrinsics& camera,
                                   std::vector<Detection>* detections, RecognitionTiming* timing,
                                   const ObjectFilter& filter, const DetectionOptions& extras) {
  const auto start = Clock::now();
  detections->clear();
  RECOG_RETURN_IF_ERROR(camera.Validate());
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
  RECOG_RETURN_IF_ERROR(Run(features_, camera, filter, extras, detections, t));
  t->total = MillisecondsSince(start);
  return Status::Ok();
}

Status ObjectRecognizer::RecognizeFeatures(const FeatureSet& features,
                                           const CameraIntrinsics& camera,
                                           std::vector<Detection>* detections,
                                           RecognitionTiming* timing, const ObjectFilter& filter,
                                           const DetectionOptions& extras) {
  const auto start = Clock::now();
  detections->clear();
  RECOG_RETURN_IF_ERROR(camera.Validate());
  const DescriptorFormat format = database_->vocabulary().info().descriptor;
  if (features.size() > 0 && (features.descriptors.type() != format.cv_type() ||
                              features.descriptors.cols != format.cols() ||
                              size_t(features.descriptors.rows) != features.size())) {
    return Status::InvalidArgument("query descriptors do not match the object vocabulary (" +
                                   std::to_string(format.size_bytes) +
                                   "-byte rows, one per keypoint)");
  }
  RecognitionTiming local;
  RecognitionTiming* t = timing != nullptr ? timing : &local;
  *t = RecognitionTiming();
  RECOG_RETURN_IF_ERROR(Run(features, camera, filter, extras, detections, t));
  t->total = MillisecondsSince(start);
  return Status::Ok();
}

Status ObjectRecognizer::Run(const FeatureSet& features, const CameraIntrinsics& camera,
                             const ObjectFilter& filter, const DetectionOptions& extras,
                             std::vector<Detection>* detections, RecognitionTiming* t) {
  const Vocabulary& vocabulary = database_->vocabulary();
  // Pixel positions without lens distortion: every later step assumes a pinhole camera.
  auto phase = Clock::now();
  positions_.resize(features.size());
  for (size_t i = 0; i < features.size(); ++i) positions_[i] = features.keypoints[i].pt;
  pinhole_ = positions_;
  if (!camera.distortion.empty() && !pinhole_.empty()) {
    cv::undistortPoints(positions_, pinhole_, camera.K(), camera.distortion, cv::noArray(),
                        camera.K());
  }
  clusterer_.Cluster(positions_, &regions_);
  t->clustering = MillisecondsSince(phase);
  t->regions = regions_.size();

  // Words and level-1 nodes of every feature, once for all regions.
  phase = Clock::now();
  const int levels_up = database_->direct_levels_up();
  word_of_feature_.resize(features.size());
  node_of_feature_.resize(features.size());
  for (size_t i = 0; i < features.size(); ++i) {
    word_of_feature_[i] =
        vocabulary.TransformOne(features.descriptors.ptr(int(i)), &node_of_feature_[i], levels_up);
  }
  t->conversion = MillisecondsSince(phase);

  std::vector<BowEntry> entries;
  std::vector<BcMatch> candidates;
  // The whole image (last region) goes first: it holds every correspondence of an object that
  // fills the view, so its pose is the best one; the clusters then find the smaller objects.
  for (size_t k = 0; k < regions_.size(); ++k) {
    const size_t r = (k + regions_.size() - 1) % regions_.size();
    const std::vector<uint32_t>& region = regions_[r].features;
    phase = Clock::now();
    entries.clear();
    for (uint32_t f : region) {
      const float weight = vocabulary.WordWeight(word_of_feature_[f]);
      if (weight > 0) entries.push_back({word_of_feature_[f], weight});
    }
    BowVector bow(entries);
    bow.Normalize(BowNormalization::kL1);
    t->conversion += MillisecondsSince(phase);

    phase = Clock::now();
    RECOG_RETURN_IF_ERROR(database_->index().QueryBcMatching(
        bow, options_.beta, options_.candidates_per_roi, &candidates));
    t->query += MillisecondsSince(phase);

    for (const BcMatch& candidate : candidates) {
      const bool found_already =
          std::any_of(detections->begin(), detections->end(),
                      [&candidate](const Detection& d) { return d.id == candidate.id; });
      if (found_already && !options_.report_duplicates) continue;
      const std::shared_ptr<const IndexedObject> object = database_->Find(candidate.id);
      if (!object) continue;  // removed meanwhile
      if (!filter.Passes(object->metadata)) continue;
      ++t->verified;
      Detection detection;
      if (Verify(*object, features, region, camera, extras, t, &detection)) {
        detection.score = candidate.chi_square;
        detection.region = int(r);
        detections->push_back(std::move(detection));
      }
    }
  }

  if (!options_.report_duplicates) {
    // Keep each object's best detection (most inliers, then lowest error).
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
  // Best first (the documented order), whether or not duplicates were merged.
  std::stable_sort(detections->begin(), detections->end(),
                   [](const Detection& a, const Detection& b) { return a.inliers > b.inliers; });
  return Status::Ok();
}

bool ObjectRecognizer::Verify(const IndexedObject& object, const FeatureSet& features,
                              const std::vector<uint32_t>& region, const CameraIntrinsics& camera,
                              const DetectionOptions& extras, RecognitionTiming* timing,
                              Detection* detection) {
  auto phase = Clock::now();
  const int row_bytes = features.descriptors.cols;
  cv::Mat region_descriptors(int(region.size()), row_bytes, CV_8U);
  std::vector<std::pair<NodeId, uint32_t>> pairs(region.size());
  for (size_t i = 0; i < region.size(); ++i) {
    std::memcpy(region_descriptors.ptr(int(i)), features.descriptors.ptr(int(region[i])),
                size_t(row_bytes));
    pairs[i] = {node_of_feature_[region[i]], uint32_t(i)};
  }
  std::sort(pairs.begin(), pairs.end());
  FeatureVector region_direct;
  region_direct.AssignSorted(pairs);
  std::vector<Match> matches;
  const Status matched = MatchByDirectIndex(region_direct, region_descriptors, object.direct,
                                            object.descriptors, options_.match, &matches);
  timing->correspondences += MillisecondsSince(phase);
  if (!matched.ok() || matches.size() < options_.min_inliers) return false;

  phase = Clock::now();
  std::vector<cv::Point3f> object_points(matches.size());
  std::vector<cv::Point2f> image_points(matches.size());
  std::vector<uint32_t> model_features(matches.size());
  for (size_t i = 0; i < matches.size(); ++i) {
    model_features[i] = matches[i].b;
    object_points[i] = object.points[matches[i].b];
    image_points[i] = pinhole_[region[matches[i].a]];
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
  if (!solved || inliers.size() < needed) return false;

  std::vector<cv::Point2f> keypoints(matches.size());
  for (size_t i = 0; i < matches.size(); ++i) keypoints[i] = positions_[region[matches[i].a]];
  CompleteDetection(object, camera, pose, inliers, model_features, object_points, image_points,
                    keypoints, extras, detection);
  return true;
}

}  // namespace recog
