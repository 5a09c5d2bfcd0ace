#include "tools/evaluation/place_evaluation.h"

#include <algorithm>
#include <charconv>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <string_view>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/elapsed.h"
#include "core/index/memory_index_store.h"
#include "tools/common/cli_support.h"

namespace recog::cli {

namespace fs = std::filesystem;

constexpr std::string_view kCameraPrefix = "camera:";

StatusOr<FrameSource> FrameSource::Open(const std::string& spec,
                                        std::optional<DatasetLayout> layout) {
  FrameSource source;
  std::error_code ec;
  if (fs::is_directory(spec, ec)) {
    source.layout_ = layout ? *layout : DetectDatasetLayout(spec);
    if (source.layout_ == DatasetLayout::kFolder) {
      RECOG_ASSIGN_OR_RETURN(source.files_, ListImages(spec));
      return source;
    }
    RECOG_ASSIGN_OR_RETURN(const std::vector<DatasetFrame> frames,
                           ReadDatasetFrames(spec, source.layout_));
    for (const DatasetFrame& frame : frames) {
      source.files_.push_back(frame.image);
      source.timestamps_.push_back(frame.timestamp);
      source.depths_.push_back(frame.depth);
      source.rights_.push_back(frame.right);
    }
    return source;
  }
  if (layout) {
    return Status::InvalidArgument("'" + spec + "' is not a folder: only a folder has a layout (" +
                                   std::string(DatasetLayoutName(*layout)) + ")");
  }
  if (spec.rfind(kCameraPrefix, 0) == 0) {
    const std::string_view digits = std::string_view(spec).substr(kCameraPrefix.size());
    int index = -1;
    const auto [end, error] = std::from_chars(digits.data(), digits.data() + digits.size(), index);
    if (digits.empty() || error != std::errc() || end != digits.data() + digits.size() ||
        index < 0) {
      return Status::InvalidArgument("'" + spec + "': a camera is camera:N, N >= 0 (/dev/videoN)");
    }
    RECOG_ASSIGN_OR_RETURN(std::unique_ptr<VideoInput> camera, OpenCamera(index));
    source.video_ = std::move(camera);
    source.video_name_ = spec;
    return source;
  }
  if (!fs::exists(spec, ec)) return Status::NotFound("'" + spec + "' does not exist");
  const std::string ext = fs::path(spec).extension().string();
  if (ext == ".txt" || ext == ".lst" || ext == ".list") {
    std::ifstream in(spec);
    std::string line;
    while (std::getline(in, line)) {
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (line.empty() || line[0] == '#') continue;
      fs::path p(line);
      if (p.is_relative()) p = fs::path(spec).parent_path() / p;
      source.files_.push_back(p.string());
    }
    if (source.files_.empty()) return Status::InvalidArgument("image list '" + spec + "' is empty");
    return source;
  }
  StatusOr<std::unique_ptr<VideoInput>> video = OpenVideoFile(spec);
  if (video.status().code() == StatusCode::kInvalidArgument) {
    return Status::InvalidArgument("'" + spec + "' is neither a folder, an image list nor a video");
  }
  RECOG_RETURN_IF_ERROR(video.status());
  source.video_ = std::move(*video);
  source.video_name_ = fs::path(spec).filename().string();
  return source;
}

StatusOr<FrameSource> FrameSource::OpenBag(const std::string& path, const BagTopics& topics,
                                           const BagReadOptions& options) {
  RECOG_ASSIGN_OR_RETURN(RosBagReader reader, RosBagReader::Open(path, topics, options));
  FrameSource source;
  source.bag_ = std::make_shared<RosBagReader>(std::move(reader));
  source.video_name_ = fs::path(path).filename().string();
  return source;
}

StatusOr<bool> FrameSource::Next(cv::Mat* gray, std::string* name) {
  if (bag_) {
    bag_frame_ = BagFrame();
    RECOG_ASSIGN_OR_RETURN(const bool more, bag_->Next(&bag_frame_));
    if (!more) return false;
    *gray = bag_frame_.gray;
    *name = video_name_ + "#" + std::to_string(++next_);
    return true;
  }
  if (video_) {
    cv::Mat frame;
    if (!video_->Read(&frame)) return false;
    if (frame.channels() == 3) {
      cv::cvtColor(frame, *gray, cv::COLOR_BGR2GRAY);
    } else {
      *gray = frame;
    }
    *name = video_name_ + "#" + std::to_string(next_++ + 1);
    return true;
  }
  if (next_ >= files_.size()) return false;
  *name = files_[next_++];
  RECOG_ASSIGN_OR_RETURN(*gray, ReadGrayImage(*name));
  return true;
}

std::optional<double> FrameSource::timestamp() const {
  if (bag_) return next_ > 0 ? std::optional<double>(bag_frame_.stamp) : std::nullopt;
  if (next_ > 0 && next_ <= timestamps_.size()) return timestamps_[next_ - 1];
  return std::nullopt;
}

std::string FrameSource::depth_path() const {
  return next_ > 0 && next_ <= depths_.size() ? depths_[next_ - 1] : std::string();
}

std::string FrameSource::right_path() const {
  return next_ > 0 && next_ <= rights_.size() ? rights_[next_ - 1] : std::string();
}

StatusOr<cv::Mat> FrameSource::depth() const {
  if (bag_) return bag_frame_.depth;
  const std::string path = depth_path();
  if (path.empty()) return cv::Mat();
  cv::Mat depth = cv::imread(path, cv::IMREAD_ANYDEPTH);
  if (depth.empty()) return Status::InvalidArgument("cannot read depth image '" + path + "'");
  return depth;
}

StatusOr<cv::Mat> FrameSource::right() const {
  if (bag_) return bag_frame_.right;
  const std::string path = right_path();
  if (path.empty()) return cv::Mat();
  return ReadGrayImage(path);
}

size_t FrameSource::size() const {
  if (bag_) return bag_->size();
  return video_ ? video_->FrameCount() : files_.size();
}

namespace {

// The 3D points of the frame `source` returned last (none without a depth or right image).
// The right image of a stereo pair is described by `extractor`, the left image's.
Status FramePoints(const FrameSource& source, const cv::Mat& image, const FeatureSet& features,
                   const SequenceGeometryOptions& options, FeatureExtractor& extractor,
                   FrameGeometry* geometry) {
  geometry->K = options.camera.K();
  geometry->points.clear();
  RECOG_ASSIGN_OR_RETURN(const cv::Mat depth, source.depth());
  RECOG_ASSIGN_OR_RETURN(const cv::Mat right, source.right());
  if (!depth.empty()) {
    return PointsFromDepth(features.keypoints, image.size(), options.camera, depth,
                           options.depth_scale, &geometry->points);
  }
  if (!right.empty() && !options.camera.IsPinhole()) {
    return Status::InvalidArgument(
        "a right image needs a rectified pair, without lens "
        "distortion; the camera is " +
        options.camera.Describe());
  }
  if (!right.empty()) {
    FeatureSet right_features;
    RECOG_RETURN_IF_ERROR(extractor.Extract(right, &right_features));
    return PointsFromStereo(features, image, right_features, right, geometry->K, options.baseline_m,
                            options.stereo, &geometry->points);
  }
  return Status::Ok();
}

}  // namespace

StatusOr<SequenceFeatures> ExtractSequence(FrameSource& source, const FeatureOptions& options,
                                           bool keep_images,
                                           const std::function<void(size_t)>& progress,
                                           const std::optional<SequenceGeometryOptions>& geometry) {
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<FeatureExtractor> extractor,
                         CreateFeatureExtractor(options));
  SequenceFeatures sequence;
  cv::Mat image;
  std::string name;
  for (;;) {
    RECOG_ASSIGN_OR_RETURN(const bool more, source.Next(&image, &name));
    if (!more) break;
    FeatureSet features;
    const auto start = std::chrono::steady_clock::now();
    RECOG_RETURN_IF_ERROR(extractor->Extract(image, &features));
    sequence.feature_ms.push_back(MillisecondsSince(start));
    if (geometry) {
      const auto points_start = std::chrono::steady_clock::now();
      FrameGeometry frame_geometry;
      RECOG_RETURN_IF_ERROR(
          FramePoints(source, image, features, *geometry, *extractor, &frame_geometry)
              .WithContext("frame '" + name + "'"));
      ToPinhole(geometry->camera, features.keypoints);  // where loops are checked
      sequence.points_ms.push_back(MillisecondsSince(points_start));
      sequence.geometry.push_back(std::move(frame_geometry));
    }
    sequence.features.push_back(std::move(features));
    sequence.names.push_back(name);
    sequence.timestamps.push_back(source.timestamp());
    if (keep_images) sequence.images.push_back(image.clone());
    if (progress) progress(sequence.features.size());
  }
  if (sequence.features.empty()) return Status::InvalidArgument("the sequence has no frames");
  return sequence;
}

namespace {

std::optional<double> TimestampOf(const SequenceFeatures& sequence, size_t i) {
  return i < sequence.timestamps.size() ? sequence.timestamps[i] : std::nullopt;
}
const FrameGeometry* GeometryOf(const SequenceFeatures& sequence, size_t i) {
  return i < sequence.geometry.size() ? &sequence.geometry[i] : nullptr;
}

}  // namespace

bool RevisitsMap(const GroundTruth& truth, int query, MapFrames map) {
  const std::vector<int>& matches = truth.matches[size_t(query)];
  return std::any_of(matches.begin(), matches.end(),
                     [&](int j) { return map.first <= j && j < map.end; });
}

MissedRevisit ExplainMiss(const LoopResult& result, int query, MapFrames map,
                          const GroundTruth& truth) {
  const auto frame_of = [&](EntryId entry) { return map.first + int(entry); };
  MissedRevisit miss;
  miss.query = query;
  miss.status = std::string(LoopStatusName(result.status));
  if (result.match != kInvalidEntryId) miss.candidate = frame_of(result.match);
  for (size_t rank = 0; rank < result.candidates.size(); ++rank) {
    const int frame = frame_of(result.candidates[rank].entry);
    if (truth.Matches(query, frame)) {
      miss.true_candidate = frame;
      miss.true_rank = int(rank) + 1;
      break;
    }
  }
  const auto verified = [&] {
    miss.inliers = uint32_t(result.inliers.size());
    miss.correspondences = result.correspondences;
  };
  switch (result.status) {
    case LoopStatus::kTooFewFeatures:
    case LoopStatus::kLowScoreWithPrevious:
      miss.reason = MissReason::kNotQueried;
      return miss;
    case LoopStatus::kLoopDetected:
      miss.reason = MissReason::kWrongLoop;
      verified();
      return miss;
    case LoopStatus::kNoCandidates:
    case LoopStatus::kLowScore:
    case LoopStatus::kNoConsistentIsland:
      miss.reason = miss.true_rank ? MissReason::kLowScore : MissReason::kNoCandidate;
      return miss;
    case LoopStatus::kFailedGeometry:
    case LoopStatus::kCandidate:
      verified();
      break;
    case LoopStatus::kFailedTemporalConsistency:
      break;
  }
  // A best candidate was chosen (and, but for failed_temporal_consistency, verified).
  if (!miss.true_rank) {
    miss.reason = MissReason::kNoCandidate;
  } else if (!miss.candidate || !truth.Matches(query, *miss.candidate)) {
    miss.reason = MissReason::kWrongTopCandidate;
  } else if (result.status == LoopStatus::kFailedGeometry) {
    miss.reason = MissReason::kFailedGeometry;
    miss.failed_metric = result.metric.checked && !result.metric.verified;
  } else {
    miss.reason = MissReason::kNotConsistent;
    if (result.status == LoopStatus::kFailedTemporalConsistency) {
      miss.consistent_queries = result.consistent_queries;
    }
  }
  return miss;
}

StatusOr<std::vector<LoopResult>> DetectLoops(const SequenceFeatures& sequence,
                                              std::shared_ptr<const Vocabulary> vocabulary,
                                              const PlaceEvaluationOptions& options) {
  MemoryIndexStore store;
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<Database> db,
                         Database::Create(&store, "evaluation", std::move(vocabulary),
                                          options.scoring, options.direct_index_levels_up));
  RECOG_ASSIGN_OR_RETURN(LoopDetector detector, LoopDetector::Create(db.get(), options.detector));
  std::vector<LoopResult> results;
  results.reserve(sequence.features.size());
  for (size_t i = 0; i < sequence.features.size(); ++i) {
    RECOG_ASSIGN_OR_RETURN(LoopResult r,
                           detector.Process(sequence.features[i], TimestampOf(sequence, i), {},
                                            GeometryOf(sequence, i)));
    results.push_back(std::move(r));
  }
  return results;
}

namespace {

// The detector's time spent on one frame, per stage (what timing_ms summarises).
void AddTimings(const LoopTimings& t, double features_ms, const double* points_ms,
                LoopTally* tally) {
  tally->AddTime("features", features_ms);
  tally->AddTime("conversion", t.conversion);
  tally->AddTime("query", t.query);
  tally->AddTime("islands", t.islands);
  tally->AddTime("insertion", t.insertion);
  tally->AddTime("verification", t.verification);
  if (t.verified_candidates > 0) {
    tally->AddTime("verification_per_candidate", t.verification / t.verified_candidates);
  }
  if (points_ms != nullptr) {
    tally->AddTime("points", *points_ms);
    tally->AddTime("metric_verification", t.metric_verification);
  }
  tally->AddTime("total", features_ms + (points_ms ? *points_ms : 0.0) + t.conversion + t.query +
                              t.islands + t.insertion + t.verification + t.metric_verification);
}

// Counts frame `query`'s result in `map`: its status, its match (when it has one) scored against
// the ground truth and, with a trajectory, against the true geometry of its inliers, into
// `loops`, and, when the frame revisits the map without a loop counted correct, why.
void CountResult(const LoopResult& r, int query, MapFrames map, const GroundTruth& truth,
                 const SequenceFeatures& sequence, const CameraTrajectory* trajectory,
                 LoopTally* tally, std::vector<DetectedLoop>* loops) {
  tally->CountStatus(LoopStatusName(r.status));
  bool counted_correct = false;
  if (r.match != kInvalidEntryId) {
    const int match = map.first + int(r.match);
    DetectedLoop loop;
    loop.query = query;
    loop.match = match;
    loop.status = r.status;
    loop.correct = truth.Matches(query, match);
    loop.ambiguous = truth.IsAmbiguous(query, match);
    if (trajectory != nullptr && !r.inliers.empty()) {
      loop.geometry = ScoreLoopGeometry(
          trajectory->poses[size_t(query)], trajectory->poses[size_t(match)], trajectory->K,
          sequence.features[size_t(query)], sequence.features[size_t(match)], r.inliers);
      loop.correct = loop.correct && loop.geometry->agrees;
      // A pair listed as ambiguous is still false when the loop's own inliers miss the true
      // geometry: they matched something else (a look-alike façade).
      loop.ambiguous = loop.ambiguous && loop.geometry->agrees;
    }
    loop.normalized_score = r.normalized_score;
    loop.acceptance = r.acceptance;
    loop.inliers = uint32_t(r.inliers.size());
    loop.metric = r.metric;
    loop.evidence = r.evidence;
    if (r.status == LoopStatus::kLoopDetected) {
      counted_correct = tally->CountDetection(loop.correct, loop.ambiguous);
    }
    loops->push_back(loop);
  }
  if (!counted_correct && RevisitsMap(truth, query, map)) {
    tally->CountMiss(ExplainMiss(r, query, map, truth));
  }
}

const double* PointsMsOf(const SequenceFeatures& sequence, size_t i) {
  return sequence.points_ms.empty() ? nullptr : &sequence.points_ms[i];
}

}  // namespace

StatusOr<PlaceEvaluation> EvaluatePlace(const SequenceFeatures& sequence, const GroundTruth& truth,
                                        std::shared_ptr<const Vocabulary> vocabulary,
                                        const PlaceEvaluationOptions& options,
                                        std::vector<LoopResult>* results,
                                        const CameraTrajectory* trajectory) {
  RECOG_RETURN_IF_ERROR(CheckTruthCovers(truth, sequence.features.size(), "sequence"));
  if (trajectory != nullptr && trajectory->poses.size() != sequence.features.size()) {
    return Status::InvalidArgument("the poses cover " + std::to_string(trajectory->poses.size()) +
                                   " frames but the sequence has " +
                                   std::to_string(sequence.features.size()));
  }
  RECOG_ASSIGN_OR_RETURN(std::vector<LoopResult> detected,
                         DetectLoops(sequence, std::move(vocabulary), options));

  PlaceEvaluation eval;
  eval.frames = truth.frames;
  eval.query_frames_with_truth = truth.QueriesWithMatches();
  LoopTally tally(&eval);
  for (int i = 0; i < eval.frames; ++i) {
    const LoopResult& r = detected[size_t(i)];
    AddTimings(r.timings, sequence.feature_ms[size_t(i)], PointsMsOf(sequence, size_t(i)), &tally);
    CountResult(r, i, {0, eval.frames}, truth, sequence, trajectory, &tally, &eval.loops);
  }
  tally.Finish();
  if (results != nullptr) *results = std::move(detected);
  return eval;
}

void AppendSequence(SequenceFeatures robot_b, SequenceFeatures* robot_a) {
  const size_t a_frames = robot_a->features.size(), b_frames = robot_b.features.size();
  // Appends `from` to `to`, giving the frames of the side that lacks the data `blank`.
  const auto append = [&](auto& to, auto& from, const auto& blank) {
    if (to.empty() && from.empty()) return;
    if (to.empty()) to.assign(a_frames, blank);
    if (from.empty()) from.assign(b_frames, blank);
    to.insert(to.end(), std::make_move_iterator(from.begin()), std::make_move_iterator(from.end()));
  };
  append(robot_a->features, robot_b.features, FeatureSet());
  append(robot_a->names, robot_b.names, std::string());
  append(robot_a->feature_ms, robot_b.feature_ms, 0.0);
  append(robot_a->geometry, robot_b.geometry, FrameGeometry());
  append(robot_a->points_ms, robot_b.points_ms, 0.0);
  append(robot_a->timestamps, robot_b.timestamps, std::optional<double>());
  append(robot_a->images, robot_b.images, cv::Mat());
}

StatusOr<AcrossMapsEvaluation> EvaluateAcrossMaps(const SequenceFeatures& sequence,
                                                  const GroundTruth& truth, int split,
                                                  std::shared_ptr<const Vocabulary> vocabulary,
                                                  const PlaceEvaluationOptions& options) {
  RECOG_RETURN_IF_ERROR(CheckTruthCovers(truth, sequence.features.size(), "sequence"));
  const int frames = truth.frames;
  if (split < 1 || split >= frames) {
    return Status::InvalidArgument("the split must leave frames to both robots: 1.." +
                                   std::to_string(frames - 1) + ", not " + std::to_string(split));
  }
  MemoryIndexStore store_a, store_b;
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<Database> db_a,
                         Database::Create(&store_a, "robot-a", vocabulary, options.scoring,
                                          options.direct_index_levels_up));
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<Database> db_b,
                         Database::Create(&store_b, "robot-b", std::move(vocabulary),
                                          options.scoring, options.direct_index_levels_up));
  RECOG_ASSIGN_OR_RETURN(LoopDetector map_a, LoopDetector::Create(db_a.get(), options.detector));
  RECOG_ASSIGN_OR_RETURN(LoopDetector map_b, LoopDetector::Create(db_b.get(), options.detector));
  for (int i = 0; i < split; ++i) {
    RECOG_RETURN_IF_ERROR(map_a
                              .Add(sequence.features[size_t(i)], TimestampOf(sequence, size_t(i)),
                                   {}, GeometryOf(sequence, size_t(i)))
                              .status());
  }

  AcrossMapsEvaluation eval;
  eval.inter_map.frames = eval.own_map.frames = frames - split;
  LoopTally inter_map(&eval.inter_map), own_map(&eval.own_map);
  const MapFrames map_of_a{0, split}, map_of_b{split, frames};
  for (int i = split; i < frames; ++i) {
    const size_t f = size_t(i);
    eval.inter_map.query_frames_with_truth += RevisitsMap(truth, i, map_of_a);
    eval.own_map.query_frames_with_truth += RevisitsMap(truth, i, map_of_b);
    RECOG_ASSIGN_OR_RETURN(
        LoopResult own,
        map_b.Process(sequence.features[f], TimestampOf(sequence, f), {}, GeometryOf(sequence, f)));
    AddTimings(own.timings, sequence.feature_ms[f], PointsMsOf(sequence, f), &own_map);
    CountResult(own, i, map_of_b, truth, sequence, nullptr, &own_map, &eval.own_map.loops);
    RECOG_ASSIGN_OR_RETURN(LoopResult across,
                           map_a.Query(sequence.features[f], GeometryOf(sequence, f)));
    AddTimings(across.timings, 0.0, nullptr, &inter_map);
    CountResult(across, i, map_of_a, truth, sequence, nullptr, &inter_map, &eval.inter_map.loops);
  }
  inter_map.Finish();
  own_map.Finish();
  eval.inter_map.timing_ms.erase("features");  // extracted once, counted in own_map
  return eval;
}

}  // namespace recog::cli
