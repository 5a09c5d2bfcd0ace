#include "tools/evaluation/rig_evaluation.h"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <Eigen/Geometry>
#include <opencv2/imgcodecs.hpp>

#include "core/common/elapsed.h"
#include "core/common/rotation_angle.h"
#include "core/geometry/frame_points.h"
#include "core/index/memory_index_store.h"

namespace recog::cli {
namespace {

using Clock = std::chrono::steady_clock;

// The indices of the cameras to keep, in the order asked (all of them when none is named).
StatusOr<std::vector<size_t>> CamerasKept(const RigDataset& dataset,
                                          const std::vector<std::string>& names) {
  std::vector<size_t> kept;
  if (names.empty()) {
    for (size_t c = 0; c < dataset.cameras.size(); ++c) kept.push_back(c);
    return kept;
  }
  for (const std::string& name : names) {
    const auto it = std::find_if(dataset.cameras.begin(), dataset.cameras.end(),
                                 [&](const RigCamera& c) { return c.name == name; });
    if (it == dataset.cameras.end()) {
      std::string known;
      for (const RigCamera& c : dataset.cameras) known += (known.empty() ? "" : ", ") + c.name;
      return Status::InvalidArgument("the rig has no camera '" + name + "' (it has " + known + ")");
    }
    kept.push_back(size_t(it - dataset.cameras.begin()));
  }
  return kept;
}

Status CameraFault(const RigCamera& camera, const std::string& file, const std::string& what) {
  return Status::InvalidArgument("rig camera '" + camera.name + "': '" + file + "' " + what);
}

}  // namespace

StatusOr<RigSequenceFeatures> ExtractRigSequence(
    const RigDataset& dataset, const RigExtractionOptions& options,
    const std::function<void(size_t done, size_t total)>& progress) {
  RECOG_ASSIGN_OR_RETURN(const std::vector<size_t> kept, CamerasKept(dataset, options.cameras));
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<FeatureExtractor> extractor,
                         CreateFeatureExtractor(options.features));
  RigSequenceFeatures sequence;
  for (size_t c : kept) sequence.cameras.push_back(dataset.cameras[c]);
  const size_t frames = dataset.images.size();
  bool any_depth = false;
  for (size_t f = 0; f < frames; ++f) {
    RigFrame frame;
    frame.timestamp = f < dataset.timestamps.size() ? dataset.timestamps[f] : std::nullopt;
    frame.cameras.resize(kept.size());
    frame.points.resize(kept.size());
    double feature_ms = 0, points_ms = 0;
    for (size_t k = 0; k < kept.size(); ++k) {
      const RigCamera& camera = dataset.cameras[kept[k]];
      const std::string& path = dataset.images[f][kept[k]];
      const cv::Mat image = cv::imread(path, cv::IMREAD_GRAYSCALE);
      if (image.empty()) return CameraFault(camera, path, "is not a readable image");
      if (image.size() != camera.size) {
        return CameraFault(camera, path,
                           "is " + std::to_string(image.cols) + "x" + std::to_string(image.rows) +
                               ", its camera's images are " + std::to_string(camera.size.width) +
                               "x" + std::to_string(camera.size.height));
      }
      const auto start = Clock::now();
      RECOG_RETURN_IF_ERROR(extractor->Extract(image, &frame.cameras[k]));
      UndistortKeypoints(camera, &frame.cameras[k].keypoints);
      feature_ms += MillisecondsSince(start);
      const std::string& depth_path =
          f < dataset.depths.size() ? dataset.depths[f][kept[k]] : std::string();
      if (!options.use_depth || depth_path.empty()) continue;
      const cv::Mat depth = cv::imread(depth_path, cv::IMREAD_UNCHANGED);
      if (depth.empty()) return CameraFault(camera, depth_path, "is not a readable depth image");
      const auto points_start = Clock::now();
      RECOG_RETURN_IF_ERROR(
          PointsFromDepth(frame.cameras[k].keypoints, image.size(), camera.K, depth,
                          options.depth_scale, &frame.points[k])
              .WithContext("rig camera '" + camera.name + "': '" + depth_path + "'"));
      points_ms += MillisecondsSince(points_start);
      any_depth = true;
    }
    sequence.frames.push_back(std::move(frame));
    sequence.feature_ms.push_back(feature_ms);
    sequence.points_ms.push_back(points_ms);
    sequence.names.push_back(dataset.images[f][kept.front()]);
    if (progress) progress(f + 1, frames);
  }
  if (sequence.frames.empty()) return Status::InvalidArgument("the rig sequence has no frames");
  if (!any_depth) {
    sequence.points_ms.clear();
    for (RigFrame& frame : sequence.frames) frame.points.clear();
  }
  return sequence;
}

StatusOr<RigPlaceEvaluation> EvaluateRigPlace(const RigSequenceFeatures& sequence,
                                              const GroundTruth& truth,
                                              std::shared_ptr<const Vocabulary> vocabulary,
                                              const RigPlaceOptions& options,
                                              const std::vector<CameraPose>* body_poses) {
  const size_t frames = sequence.frames.size();
  RECOG_RETURN_IF_ERROR(CheckTruthCovers(truth, frames, "rig sequence"));
  if (body_poses != nullptr && body_poses->size() != frames) {
    return Status::InvalidArgument("the body poses cover " + std::to_string(body_poses->size()) +
                                   " frames but the rig sequence has " + std::to_string(frames));
  }
  MemoryIndexStore store;
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<Database> db,
                         Database::Create(&store, "rig-evaluation", std::move(vocabulary),
                                          options.scoring, options.direct_index_levels_up));
  RECOG_ASSIGN_OR_RETURN(RigLoopDetector detector,
                         RigLoopDetector::Create(db.get(), sequence.cameras, options.detector));
  RigPlaceEvaluation eval;
  eval.frames = int(frames);
  eval.query_frames_with_truth = truth.QueriesWithMatches();
  LoopTally tally(&eval);
  std::vector<double> rotation_errors, translation_errors;
  std::vector<uint64_t> frame_ids;  // the id each rig frame got, by sequence index
  for (size_t i = 0; i < frames; ++i) {
    RECOG_ASSIGN_OR_RETURN(RigLoopResult r, detector.Process(sequence.frames[i]));
    frame_ids.push_back(*r.frame);
    const double points_ms = sequence.points_ms.empty() ? 0.0 : sequence.points_ms[i];
    const double detector_ms =
        r.timings.conversion + r.timings.query + r.timings.verification + r.timings.insertion;
    tally.AddTime("features", sequence.feature_ms[i]);
    if (!sequence.points_ms.empty()) tally.AddTime("points", points_ms);
    tally.AddTime("conversion", r.timings.conversion);
    tally.AddTime("query", r.timings.query);
    tally.AddTime("verification", r.timings.verification);
    tally.AddTime("insertion", r.timings.insertion);
    tally.AddTime("detector", detector_ms);
    tally.AddTime("total", sequence.feature_ms[i] + points_ms + detector_ms);
    tally.CountStatus(RigLoopStatusName(r.status));
    if (!r.match_frame.has_value()) continue;
    RigDetectedLoop loop;
    loop.query = int(i);
    loop.match = int(std::lower_bound(frame_ids.begin(), frame_ids.end(), *r.match_frame) -
                     frame_ids.begin());
    loop.status = r.status;
    loop.correct = truth.Matches(loop.query, loop.match);
    for (const RigCameraMatch& pair : r.pairs) {
      loop.camera_pairs.push_back(sequence.cameras[pair.query_camera].name + ">" +
                                  sequence.cameras[pair.match_camera].name);
      loop.inliers += uint32_t(pair.verification.inliers.size());
    }
    loop.rotation_disagreement_deg = r.rotation_disagreement_deg;
    loop.posed = r.posed;
    loop.metric = r.metric;
    if (body_poses != nullptr && r.posed) {
      // X_body_query = R X_body_match + t, from world_from_body of both frames.
      const CameraPose& q = (*body_poses)[i];
      const CameraPose& m = (*body_poses)[size_t(loop.match)];
      const cv::Matx33d R_true = q.world_from_camera.t() * m.world_from_camera;
      const cv::Vec3d t_true = q.world_from_camera.t() * (m.center - q.center);
      loop.rotation_error_deg = RotationAngleDeg(r.R, R_true);
      if (r.metric && cv::norm(t_true) > 0) {
        loop.translation_error_pct = 100.0 * cv::norm(r.t - t_true) / cv::norm(t_true);
      }
    }
    if (r.status == RigLoopStatus::kLoopDetected) {
      // Over rig frames, pairs listed as ambiguous are judged like the others.
      tally.CountDetection(loop.correct, /*ambiguous=*/false);
      if (loop.correct && loop.rotation_error_deg) {
        rotation_errors.push_back(*loop.rotation_error_deg);
      }
      if (loop.correct && loop.translation_error_pct) {
        translation_errors.push_back(*loop.translation_error_pct);
      }
    }
    loop.result = std::move(r);
    eval.loops.push_back(std::move(loop));
  }
  tally.Finish();
  eval.posed_correct = int(rotation_errors.size());
  eval.metric_correct = int(translation_errors.size());
  eval.median_rotation_error_deg = Median(rotation_errors);
  eval.median_translation_error_pct = Median(translation_errors);
  return eval;
}

StatusOr<std::vector<CameraPose>> ReadTrajectory(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Status::NotFound("trajectory file '" + path + "' cannot be read");
  std::vector<CameraPose> poses;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream fields(line);
    double v[8];
    std::string extra;
    bool ok = true;
    for (double& x : v) ok = ok && (fields >> x) && std::isfinite(x);
    if (!ok || (fields >> extra)) {
      return Status::InvalidArgument("trajectory file '" + path + "' line " +
                                     std::to_string(number) +
                                     ": expected 'timestamp tx ty tz qx qy qz qw'");
    }
    const Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);
    if (std::abs(q.norm() - 1.0) > 1e-3) {
      return Status::InvalidArgument("trajectory file '" + path + "' line " +
                                     std::to_string(number) + ": the quaternion is not unit");
    }
    const Eigen::Matrix3d R = q.normalized().toRotationMatrix();
    CameraPose pose;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) pose.world_from_camera(r, c) = R(r, c);
    }
    pose.center = {v[1], v[2], v[3]};
    poses.push_back(pose);
  }
  if (poses.empty()) return Status::InvalidArgument("trajectory file '" + path + "' has no pose");
  return poses;
}

}  // namespace recog::cli
