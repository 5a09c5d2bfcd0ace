// Metric loops on synthetic RGB-D and stereo sequences with exactly known geometry (thesis
// §3.3.3): three textured planes at 1.6, 2.6 (tilted 25°) and 4 m, a camera panning along x, then
// coming back 0.25 m closer, 0.08 m lower and turned 3°. Every loop the detector finds on the way
// back is checked against the true relative pose; the figures are printed (docs/places.md,
// "Metric loops from depth and stereo").
#include "tools/evaluation/metric_sequence.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/common/elapsed.h"
#include "core/features/feature_extractor.h"
#include "core/geometry/frame_points.h"
#include "core/index/memory_index_store.h"
#include "core/place/loop_detector.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tests/testing/data_paths.h"
#include "tools/evaluation/place_evaluation.h"

namespace recog::cli {
namespace {

using Clock = std::chrono::steady_clock;

const cv::Matx33d kK(525, 0, 319.5, 0, 525, 239.5, 0, 0, 1);
const cv::Size kSize(640, 480);
constexpr double kBaseline = 0.12;
constexpr int kLapFrames = 16;

cv::Mat Photo(const char* name) {
  cv::Mat photo =
      cv::imread(testing::ProjectTestData(std::string("corridor/") + name), cv::IMREAD_GRAYSCALE);
  EXPECT_FALSE(photo.empty()) << name;
  return photo;
}

// Background 6 x 4.5 m at 4 m (a 2 x 2 mosaic of two photos and their upside-down copies),
// a 1.6 m photo at 2.6 m turned 25° about y, a 0.9 m photo at 1.6 m.
std::vector<TexturedPlane> Scene(double near_depth = 1.6, double middle_depth = 2.6,
                                 double far_depth = 4.0) {
  cv::Mat a = Photo("41.jpg"), b = Photo("60.jpg"), a_flipped, b_flipped, top, bottom, mosaic;
  cv::flip(a, a_flipped, 0);
  cv::flip(b, b_flipped, 0);
  cv::hconcat(a, b, top);
  cv::hconcat(b_flipped, a_flipped, bottom);
  cv::vconcat(top, bottom, mosaic);
  const cv::Matx33d turn = Yaw(25);
  return {
      {mosaic, {0, 0, far_depth}, {1, 0, 0}, {0, 1, 0}, 6.0, 4.5},
      {Photo("1.jpg"), {-0.7, 0.1, middle_depth}, turn * cv::Vec3d(1, 0, 0), {0, 1, 0}, 1.6, 1.2},
      {Photo("20.jpg"), {0.55, -0.2, near_depth}, {1, 0, 0}, {0, 1, 0}, 0.9, 0.675},
  };
}

// Lap 1 pans from x = -0.45 to 0.45 m; lap 2 comes back 0.25 m closer, 0.08 m lower, 3° turned.
std::vector<CameraPose> Path() {
  std::vector<CameraPose> poses;
  for (int lap = 0; lap < 2; ++lap) {
    for (int i = 0; i < kLapFrames; ++i) {
      const int step = lap == 0 ? i : kLapFrames - 1 - i;
      const double yaw = 2.0 * std::sin(0.4 * step) + (lap == 0 ? 0.0 : 3.0);
      const cv::Vec3d offset = lap == 0 ? cv::Vec3d(0, 0, 0) : cv::Vec3d(0, 0.08, 0.25);
      poses.push_back({Yaw(yaw), cv::Vec3d(-0.45 + 0.06 * step, 0, 0) + offset});
    }
  }
  return poses;
}

enum class Source { kNone, kDepth, kStereo, kPosterMap };

struct DetectorRun {
  std::vector<LoopResult> results;        // one per frame of the sequence
  size_t processed = 0;                   // frames given to the detector (Process or Query)
  double points_ms = 0, detector_ms = 0;  // per frame given
};

// Relocalise: lap 1 is uploaded (Add), each frame of lap 2 asks where it is (Query); the
// side given `depth` has its 3D points, the other only its camera matrix (or, with
// `map_camera` false, a map that has nothing: no metric check can be made).
struct RelocalisationSides {
  bool map_depth = false;
  bool query_depth = false;
  bool map_camera = true;
};

class MetricSequenceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto v = LoadVocabulary(DefaultPlaceVocabularyPath());
    ASSERT_TRUE(v.ok()) << v.status().ToString();
    vocabulary_ = new std::shared_ptr<const Vocabulary>(
        std::make_shared<const Vocabulary>(std::move(v).value()));
    poses_ = new std::vector<CameraPose>(Path());
    frames_ = new std::vector<RenderedFrame>();
    features_ = new std::vector<FeatureSet>();
    right_features_ = new std::vector<FeatureSet>();
    const std::vector<TexturedPlane> scene = Scene();
    auto extractor = CreateFeatureExtractor(FeatureOptions{});
    ASSERT_TRUE(extractor.ok());
    double extraction_ms = 0;
    for (const CameraPose& pose : *poses_) {
      auto frame = RenderPlanes(scene, kK, kSize, pose, kBaseline);
      ASSERT_TRUE(frame.ok()) << frame.status().ToString();
      FeatureSet features;
      const auto start = Clock::now();
      ASSERT_TRUE((*extractor)->Extract(frame->image, &features).ok());
      extraction_ms += MillisecondsSince(start);
      // The stereo source's right images, described once by the same extractor (not timed).
      FeatureSet right_features;
      ASSERT_TRUE((*extractor)->Extract(frame->right, &right_features).ok());
      frames_->push_back(std::move(frame).value());
      features_->push_back(std::move(features));
      right_features_->push_back(std::move(right_features));
    }
    std::printf("ORB extraction: %.2f ms per 640x480 frame\n", extraction_ms / poses_->size());
  }
  static void TearDownTestSuite() {
    delete vocabulary_;
    delete poses_;
    delete frames_;
    delete features_;
    delete right_features_;
  }

  static DetectorRun Detect(Source source) {
    DetectorRun run;
    MemoryIndexStore store;
    auto db = Database::Create(&store, "metric", *vocabulary_);
    EXPECT_TRUE(db.ok()) << db.status().ToString();
    LoopDetectorParams params;
    params.recent_frames = 6;
    params.temporal_matches = 1;
    auto detector = LoopDetector::Create(db->get(), params);
    EXPECT_TRUE(detector.ok()) << detector.status().ToString();
    const cv::Mat poster(kSize, CV_16U, cv::Scalar(3000));  // a flat picture 3 m away
    for (size_t i = 0; i < frames_->size(); ++i) {
      const RenderedFrame& frame = (*frames_)[i];
      const FeatureSet& features = (*features_)[i];
      FrameGeometry geometry{kK, {}};
      auto start = Clock::now();
      Status s = Status::Ok();
      if (source == Source::kDepth) {
        s = PointsFromDepth(features.keypoints, kSize, kK, frame.depth_mm, 0.001, &geometry.points);
      } else if (source == Source::kStereo) {
        s = PointsFromStereo(features, frame.image, (*right_features_)[i], frame.right, kK,
                             kBaseline, {}, &geometry.points);
      } else if (source == Source::kPosterMap) {
        const bool map_frame = i < size_t(kLapFrames);
        s = PointsFromDepth(features.keypoints, kSize, kK, map_frame ? poster : frame.depth_mm,
                            0.001, &geometry.points);
      }
      EXPECT_TRUE(s.ok()) << s.ToString();
      run.points_ms += MillisecondsSince(start);
      start = Clock::now();
      auto r = detector->Process(features, std::nullopt, {},
                                 source == Source::kNone ? nullptr : &geometry);
      run.detector_ms += MillisecondsSince(start);
      EXPECT_TRUE(r.ok()) << r.status().ToString();
      run.results.push_back(std::move(r).value());
    }
    run.processed = frames_->size();
    run.points_ms /= double(frames_->size());
    run.detector_ms /= double(frames_->size());
    return run;
  }

  static DetectorRun Relocalise(const RelocalisationSides& sides) {
    MemoryIndexStore store;
    auto db = Database::Create(&store, "metric", *vocabulary_);
    EXPECT_TRUE(db.ok()) << db.status().ToString();
    auto detector = LoopDetector::Create(db->get(), LoopDetectorParams{});
    EXPECT_TRUE(detector.ok()) << detector.status().ToString();
    auto geometry_of = [](size_t i, bool depth) {
      FrameGeometry geometry{kK, {}};
      if (depth) {
        EXPECT_TRUE(PointsFromDepth((*features_)[i].keypoints, kSize, kK, (*frames_)[i].depth_mm,
                                    0.001, &geometry.points)
                        .ok());
      }
      return geometry;
    };
    for (size_t i = 0; i < size_t(kLapFrames); ++i) {
      const FrameGeometry geometry = geometry_of(i, sides.map_depth);
      EXPECT_TRUE(
          detector->Add((*features_)[i], std::nullopt, {}, sides.map_camera ? &geometry : nullptr)
              .ok());
    }
    DetectorRun run;
    run.results.resize(size_t(kLapFrames));  // lap 1: not queried
    run.processed = size_t(kLapFrames);
    for (size_t i = kLapFrames; i < features_->size(); ++i) {
      const FrameGeometry geometry = geometry_of(i, sides.query_depth);
      const auto start = Clock::now();
      auto r = detector->Query((*features_)[i], &geometry);
      run.detector_ms += MillisecondsSince(start) / kLapFrames;
      EXPECT_TRUE(r.ok()) << r.status().ToString();
      EXPECT_EQ(r->status, LoopStatus::kLoopDetected) << i;
      run.results.push_back(std::move(r).value());
    }
    return run;
  }

  // Checks the metric loops of lap 2 against the true poses and prints the figures.
  static void CheckMetricLoops(const char* name, const DetectorRun& run) {
    std::vector<double> translation_errors, rotation_errors, distances;
    double min_ratio = 1, metric_ms = 0;
    for (size_t i = 0; i < run.results.size(); ++i) {
      const LoopResult& r = run.results[i];
      if (r.status != LoopStatus::kLoopDetected) continue;
      EXPECT_TRUE(r.metric.checked && r.metric.verified) << name << " frame " << i;
      metric_ms += r.timings.metric_verification;
      min_ratio = std::min(min_ratio, double(r.metric.inliers.size()) / r.metric.correspondences);
      cv::Matx33d R_true;
      cv::Vec3d t_true;
      RelativePose((*poses_)[i], (*poses_)[r.match], &R_true, &t_true);
      const double distance = cv::norm((*poses_)[i].center - (*poses_)[r.match].center);
      translation_errors.push_back(cv::norm(r.metric.t - t_true) / distance);
      cv::Vec3d rvec;
      cv::Rodrigues(r.metric.R * R_true.t(), rvec);
      rotation_errors.push_back(cv::norm(rvec) * 180.0 / CV_PI);
      distances.push_back(distance);
      // The covariance is symmetric positive definite.
      cv::Matx66d c(r.metric.covariance.data());
      EXPECT_LT(cv::norm(c - c.t()), 1e-12 * cv::norm(c)) << name << " frame " << i;
      cv::Mat eigenvalues;
      cv::eigen(cv::Mat(c), eigenvalues);
      EXPECT_GT(eigenvalues.at<double>(5), 0.0) << name << " frame " << i;
    }
    ASSERT_GE(translation_errors.size(), size_t(kLapFrames)) << name << ": too few loops";
    const auto median = [](std::vector<double> v) {
      std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
      return v[v.size() / 2];
    };
    const double t_median = median(translation_errors), r_median = median(rotation_errors);
    std::printf(
        "%s: %zu metric loops in %zu frames given to the detector; camera distance %.3f-%.3f m; "
        "median translation "
        "error %.2f %% of it (max %.2f %%), median rotation error %.3f deg (max %.3f); %.2f ms "
        "per frame for the points, %.2f ms in the detector (of which %.2f ms per loop in the 3D "
        "check); PnP inliers at least %.0f %% of the 2D-3D "
        "correspondences\n",
        name, translation_errors.size(), run.processed,
        *std::min_element(distances.begin(), distances.end()),
        *std::max_element(distances.begin(), distances.end()), 100.0 * t_median,
        100.0 * *std::max_element(translation_errors.begin(), translation_errors.end()), r_median,
        *std::max_element(rotation_errors.begin(), rotation_errors.end()), run.points_ms,
        run.detector_ms, metric_ms / double(translation_errors.size()), 100.0 * min_ratio);
    EXPECT_LE(t_median, 0.02) << name;
    EXPECT_LE(r_median, 1.0) << name;
  }

  static std::shared_ptr<const Vocabulary>* vocabulary_;
  static std::vector<CameraPose>* poses_;
  static std::vector<RenderedFrame>* frames_;
  static std::vector<FeatureSet>* features_;
  static std::vector<FeatureSet>* right_features_;
};

std::shared_ptr<const Vocabulary>* MetricSequenceTest::vocabulary_ = nullptr;
std::vector<CameraPose>* MetricSequenceTest::poses_ = nullptr;
std::vector<RenderedFrame>* MetricSequenceTest::frames_ = nullptr;
std::vector<FeatureSet>* MetricSequenceTest::features_ = nullptr;
std::vector<FeatureSet>* MetricSequenceTest::right_features_ = nullptr;

TEST_F(MetricSequenceTest, RgbdLoopsGiveTheMetricRelativePose) {
  CheckMetricLoops("rgbd", Detect(Source::kDepth));
}

TEST_F(MetricSequenceTest, StereoLoopsGiveTheMetricRelativePose) {
  CheckMetricLoops("stereo", Detect(Source::kStereo));
}

TEST_F(MetricSequenceTest, AQueryWithoutDepthInAnRgbdMapGetsTheMetricPose) {
  CheckMetricLoops("query", Relocalise({.map_depth = true}));
}

// The other way round: a map built without depth (its frames keep their camera matrix), an RGB-D
// query. The pose is solved from the query's points and inverted, in the same convention.
TEST_F(MetricSequenceTest, AnRgbdQueryInAMapWithoutDepthGetsTheMetricPose) {
  CheckMetricLoops("query with depth", Relocalise({.query_depth = true}));
}

TEST_F(MetricSequenceTest, AnRgbdQueryInAMapWithoutCamerasHasNoMetricCheck) {
  const DetectorRun run = Relocalise({.query_depth = true, .map_camera = false});
  for (size_t i = kLapFrames; i < run.results.size(); ++i) {
    EXPECT_EQ(run.results[i].status, LoopStatus::kLoopDetected) << i;
    EXPECT_FALSE(run.results[i].metric.checked) << i;
  }
}

// recog eval place on the same frames written as a TUM RGB-D folder (depth in TUM's 1/5000 m) and
// as a KITTI folder (left and right images): the dataset readers give each frame its depth or right
// image, ExtractSequence its 3D points, and the evaluation's loops carry the metric pose.
TEST_F(MetricSequenceTest, TheEvaluationReadsDepthAndStereoDatasetsAndGivesMetricLoops) {
  namespace fs = std::filesystem;
  const fs::path root = fs::path(::testing::TempDir()) / "metric_datasets";
  fs::remove_all(root);
  fs::create_directories(root / "tum" / "rgb");
  fs::create_directories(root / "tum" / "depth");
  fs::create_directories(root / "kitti" / "image_0");
  fs::create_directories(root / "kitti" / "image_1");
  std::ofstream rgb(root / "tum" / "rgb.txt"), depth(root / "tum" / "depth.txt"),
      times(root / "kitti" / "times.txt");
  for (size_t i = 0; i < frames_->size(); ++i) {
    const RenderedFrame& frame = (*frames_)[i];
    const double t = 0.1 * double(i + 1);
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.png", int(i));
    ASSERT_TRUE(cv::imwrite((root / "tum" / "rgb" / name).string(), frame.image));
    cv::Mat tum_depth;
    frame.depth_mm.convertTo(tum_depth, CV_16U, 5.0);  // 5000 units per metre
    ASSERT_TRUE(cv::imwrite((root / "tum" / "depth" / name).string(), tum_depth));
    rgb << t << " rgb/" << name << "\n";
    depth << t + 0.005 << " depth/" << name << "\n";
    ASSERT_TRUE(cv::imwrite((root / "kitti" / "image_0" / name).string(), frame.image));
    ASSERT_TRUE(cv::imwrite((root / "kitti" / "image_1" / name).string(), frame.right));
    times << t << "\n";
  }
  rgb.close();
  depth.close();
  times.close();
  PlaceEvaluationOptions options;
  options.detector.recent_seconds = 0.65;  // tau_c: the 6 frames before, as Detect's recent_frames
  options.detector.temporal_matches = 1;
  SequenceGeometryOptions geometry;
  geometry.camera = {kK(0, 0), kK(1, 1), kK(0, 2), kK(1, 2), {}};
  geometry.baseline_m = kBaseline;  // TUM's depth scale is the default
  for (const char* layout : {"tum", "kitti"}) {
    auto source = FrameSource::Open((root / layout).string());
    ASSERT_TRUE(source.ok()) << source.status().ToString();
    auto sequence = ExtractSequence(*source, FeatureOptions{}, false, nullptr, geometry);
    ASSERT_TRUE(sequence.ok()) << sequence.status().ToString();
    ASSERT_EQ(sequence->geometry.size(), frames_->size());
    ASSERT_EQ(sequence->points_ms.size(), frames_->size());
    GroundTruth no_truth;
    no_truth.frames = int(frames_->size());
    no_truth.matches.resize(frames_->size());
    DetectorRun run;
    auto evaluation = EvaluatePlace(*sequence, no_truth, *vocabulary_, options, &run.results);
    ASSERT_TRUE(evaluation.ok()) << evaluation.status().ToString();
    run.processed = frames_->size();
    run.points_ms = evaluation->timing_ms.at("points").mean;
    for (const char* stage :
         {"conversion", "query", "islands", "insertion", "verification", "metric_verification"}) {
      run.detector_ms += evaluation->timing_ms.at(stage).mean;
    }
    EXPECT_TRUE(evaluation->timing_ms.count("points") &&
                evaluation->timing_ms.count("metric_verification"));
    CheckMetricLoops(layout, run);
  }
  // A right image without a baseline is refused, naming the frame.
  geometry.baseline_m = 0;
  auto source = FrameSource::Open((root / "kitti").string());
  ASSERT_TRUE(source.ok());
  const Status no_baseline =
      ExtractSequence(*source, FeatureOptions{}, false, nullptr, geometry).status();
  EXPECT_EQ(no_baseline.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(no_baseline.message().find("000000.png"), std::string::npos) << no_baseline.ToString();
  fs::remove_all(root);
}

TEST_F(MetricSequenceTest, WithoutGeometryTheLoopsAreTheSameWithoutAPose) {
  const DetectorRun plain = Detect(Source::kNone), rgbd = Detect(Source::kDepth);
  size_t loops = 0;
  for (size_t i = 0; i < plain.results.size(); ++i) {
    const LoopResult& p = plain.results[i];
    EXPECT_FALSE(p.metric.checked) << i;
    EXPECT_EQ(p.status, rgbd.results[i].status) << i;
    EXPECT_EQ(p.match, rgbd.results[i].match) << i;
    loops += p.status == LoopStatus::kLoopDetected;
  }
  EXPECT_GE(loops, 5u);
  std::printf("no geometry: %zu loops; %.2f ms per frame in the detector\n", loops,
              plain.detector_ms);
}

TEST_F(MetricSequenceTest, AFlatPictureOfThePlaceFailsTheStructureCheck) {
  // The map was built from a poster of the scene (every point 3 m away): the images match, the
  // structure does not.
  const DetectorRun plain = Detect(Source::kNone), poster = Detect(Source::kPosterMap);
  size_t refused = 0;
  double max_ratio = 0;
  for (size_t i = kLapFrames; i < plain.results.size(); ++i) {
    if (plain.results[i].status != LoopStatus::kLoopDetected) continue;
    const LoopResult& r = poster.results[i];
    max_ratio = std::max(max_ratio, double(r.metric.inliers.size()) / r.metric.correspondences);
    EXPECT_TRUE(r.metric.checked) << i;
    EXPECT_FALSE(r.metric.verified)
        << i << ": " << r.metric.inliers.size() << " of " << r.metric.correspondences;
    EXPECT_EQ(r.status, LoopStatus::kFailedGeometry) << i;
    refused += r.status == LoopStatus::kFailedGeometry;
  }
  EXPECT_GE(refused, 5u);
  std::printf(
      "poster map: %zu of the loops back refused; PnP inliers at most %.0f %% of the 2D-3D "
      "correspondences\n",
      refused, 100.0 * max_ratio);
}

TEST(MetricSequenceRenderTest, DepthIsThePlaneDepthAndBadInputIsRefused) {
  const std::vector<TexturedPlane> scene = Scene();
  auto frame = RenderPlanes(scene, kK, kSize, {}, kBaseline);
  ASSERT_TRUE(frame.ok()) << frame.status().ToString();
  // Low in the middle, only the background (4 m); the near photo covers x = 0.1..1.0 m at 1.6 m.
  EXPECT_EQ(frame->depth_mm.at<uint16_t>(450, 320), 4000);
  EXPECT_EQ(frame->depth_mm.at<uint16_t>(200, int(319.5 + 525 * 0.55 / 1.6)), 1600);
  EXPECT_EQ(frame->right.size(), kSize);
  EXPECT_GT(cv::norm(frame->image, frame->right, cv::NORM_L1), 0.0);
  TexturedPlane bad = scene[0];
  bad.axis_y = {0, 2, 0};
  EXPECT_EQ(RenderPlanes({bad}, kK, kSize, {}, 0).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(RenderPlanes(scene, kK, kSize, {}, -1).status().code(), StatusCode::kInvalidArgument);
  bad = scene[0];
  bad.texture = cv::Mat();
  EXPECT_EQ(RenderPlanes({bad}, kK, kSize, {}, 0).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace recog::cli
