// The rig detector on a rendered front + rear drive (rig_sequence.h): out along an avenue, round
// the block, back the other way. The way back's rear camera sees the way out's front views, so
// the rig closes the loops; the front camera alone closes none (the control). With depth the
// loops carry the body's metric motion; without, its rotation. A rig whose rear camera is
// calibrated 10° off fails the check across cameras.
#include "tools/evaluation/rig_evaluation.h"

#include <gtest/gtest.h>

#include "core/geometry/frame_points.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tools/common/cli_support.h"
#include "tools/evaluation/rig_sequence.h"
#include "tools/evaluation/rig_test_photos.h"

namespace recog::cli {
namespace {

// RigFrame lists from the rendered images, as ExtractRigSequence builds them from files.
RigSequenceFeatures Extract(const RigSequence& rendered, bool depth) {
  auto extractor = CreateFeatureExtractor(PlaceFeatureOptions());
  EXPECT_TRUE(extractor.ok());
  RigSequenceFeatures sequence;
  sequence.cameras = rendered.cameras;
  for (size_t f = 0; f < rendered.frames.size(); ++f) {
    RigFrame frame;
    frame.timestamp = rendered.timestamps[f];
    for (size_t c = 0; c < rendered.cameras.size(); ++c) {
      const RenderedFrame& view = rendered.frames[f][c];
      FeatureSet features;
      EXPECT_TRUE((*extractor)->Extract(view.image, &features).ok());
      std::vector<cv::Point3f> points;
      if (depth) {
        EXPECT_TRUE(PointsFromDepth(features.keypoints, view.image.size(), rendered.cameras[c].K,
                                    view.depth_mm, 0.001, &points)
                        .ok());
      }
      frame.cameras.push_back(std::move(features));
      frame.points.push_back(std::move(points));
    }
    sequence.frames.push_back(std::move(frame));
    sequence.feature_ms.push_back(0);
    sequence.names.push_back(std::to_string(f));
  }
  return sequence;
}

RigSequenceFeatures FrontOnly(RigSequenceFeatures sequence) {
  sequence.cameras.resize(1);
  for (RigFrame& frame : sequence.frames) {
    frame.cameras.resize(1);
    frame.points.resize(1);
  }
  return sequence;
}

class RigPlaceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    RigSequenceOptions options;
    options.frames_per_leg = 16;
    auto rendered =
        GenerateRigSequence(testing::ShapeTextures(int(RigPhotosNeeded(options))), options);
    ASSERT_TRUE(rendered.ok()) << rendered.status().ToString();
    rendered_ = new RigSequence(std::move(rendered).value());
    with_depth_ = new RigSequenceFeatures(Extract(*rendered_, true));
    auto v = LoadVocabulary(DefaultPlaceVocabularyPath());
    ASSERT_TRUE(v.ok()) << v.status().ToString();
    vocabulary_ = new std::shared_ptr<const Vocabulary>(
        std::make_shared<const Vocabulary>(std::move(v).value()));
  }
  static void TearDownTestSuite() {
    delete rendered_;
    delete with_depth_;
    delete vocabulary_;
  }

  static RigPlaceEvaluation Evaluate(const RigSequenceFeatures& sequence) {
    auto e = EvaluateRigPlace(sequence, rendered_->truth, *vocabulary_, {}, &rendered_->body_poses);
    EXPECT_TRUE(e.ok()) << e.status().ToString();
    return e.ok() ? *e : RigPlaceEvaluation{};
  }

  static RigSequence* rendered_;
  static RigSequenceFeatures* with_depth_;
  static std::shared_ptr<const Vocabulary>* vocabulary_;
};
RigSequence* RigPlaceTest::rendered_ = nullptr;
RigSequenceFeatures* RigPlaceTest::with_depth_ = nullptr;
std::shared_ptr<const Vocabulary>* RigPlaceTest::vocabulary_ = nullptr;

TEST_F(RigPlaceTest, TheRigClosesTheOppositeRevisitsWithTheMetricBodyMotion) {
  const RigPlaceEvaluation e = Evaluate(*with_depth_);
  std::printf(
      "front + rear, depth: %d of %d revisits, %d detections; body pose over %d metric loops: "
      "translation %.2f %% of the distance, rotation %.3f deg (medians)\n",
      e.correct, e.query_frames_with_truth, e.detections, e.metric_correct,
      e.median_translation_error_pct, e.median_rotation_error_deg);
  EXPECT_EQ(e.detections, e.correct) << "no false loop";
  EXPECT_GE(e.recall, 0.9);
  EXPECT_GE(e.metric_correct, e.correct * 9 / 10);
  EXPECT_LE(e.median_translation_error_pct, 2.0);
  EXPECT_LE(e.median_rotation_error_deg, 1.0);
  // The pose fused from both pairs' covariances is better than either pair's.
  bool rear_saw_front = false;
  for (const RigDetectedLoop& l : e.loops) {
    if (l.status != RigLoopStatus::kLoopDetected) continue;
    for (const std::string& pair : l.camera_pairs) rear_saw_front |= pair == "rear>front";
    EXPECT_EQ(std::count(l.camera_pairs.begin(), l.camera_pairs.end(), "front>front"), 0)
        << "the way back's front camera looks the other way";
  }
  EXPECT_TRUE(rear_saw_front);
}

TEST_F(RigPlaceTest, TheFrontCameraAloneFindsNoneOfThem) {
  const RigPlaceEvaluation e = Evaluate(FrontOnly(*with_depth_));
  std::printf("front camera alone: %d of %d revisits, %d detections\n", e.correct,
              e.query_frames_with_truth, e.detections);
  EXPECT_EQ(e.correct, 0);
  EXPECT_EQ(e.detections, 0);
}

TEST_F(RigPlaceTest, AMonocularRigGetsTheBodyRotation) {
  const RigPlaceEvaluation e = Evaluate(Extract(*rendered_, false));
  std::printf(
      "front + rear, no depth: %d of %d revisits, %d detections; rotation %.3f deg (median "
      "over %d)\n",
      e.correct, e.query_frames_with_truth, e.detections, e.median_rotation_error_deg,
      e.posed_correct);
  EXPECT_EQ(e.detections, e.correct);
  EXPECT_GE(e.recall, 0.9);
  EXPECT_EQ(e.metric_correct, 0);
  EXPECT_GE(e.posed_correct, e.correct * 9 / 10);
  EXPECT_LE(e.median_rotation_error_deg, 1.0);
}

// With depth the pairs' metric body rotations disagree by about twice the error; without, no one
// body motion puts both pairs' correspondences on their epipolar lines.
TEST_F(RigPlaceTest, ARearCameraCalibrated10DegreesOffFailsTheCheckAcrossCameras) {
  const double a = 10.0 * CV_PI / 180.0;
  const cv::Matx33d off(std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a));
  for (const bool depth : {true, false}) {
    RigSequenceFeatures right = depth ? *with_depth_ : Extract(*rendered_, false);
    RigSequenceFeatures wrong = right;
    wrong.cameras[1].body_R_camera = off * wrong.cameras[1].body_R_camera;
    const RigPlaceEvaluation calibrated = Evaluate(right);
    const RigPlaceEvaluation e = Evaluate(wrong);
    int refused = 0;
    for (const RigDetectedLoop& l : e.loops) {
      if (l.status != RigLoopStatus::kInconsistentCameras) continue;
      ++refused;
      bool inconsistent_pair = false;
      for (const RigCameraMatch& p : l.result.pairs) inconsistent_pair |= p.consistent_ratio < 0.9;
      if (depth) {
        EXPECT_GT(l.rotation_disagreement_deg, 15.0) << l.query;
      } else {
        EXPECT_TRUE(inconsistent_pair) << l.query;
      }
    }
    std::printf(
        "rear camera 10 deg off (%s): %d of the %d loops refused as inconsistent, %d left\n",
        depth ? "depth" : "no depth", refused, calibrated.detections, e.detections);
    EXPECT_GE(calibrated.detections, 15);
    EXPECT_GE(refused, calibrated.detections * 3 / 4);
    EXPECT_LE(e.detections, calibrated.detections / 4);
  }
}

}  // namespace
}  // namespace recog::cli
