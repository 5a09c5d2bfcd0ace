// Object models, the object database and recognition, end to end: synthetic views of a planar
// poster with known poses, and (when the shared data is there) a held-out RoboEarth view.
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Eigenvalues>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/rotation_angle.h"
#include "core/index/memory_index_store.h"
#include "core/object/builder/model_builder.h"
#include "core/object/formats/roboearth.h"
#include "core/object/recognition/object_database.h"
#include "core/object/recognition/object_recognizer.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tests/testing/option_cases.h"
#include "tests/testing/recognizers.h"
#include "tests/testing/test_data.h"
#include "tests/testing/vocabularies.h"

namespace recog {
namespace {

constexpr double kPosterWidth = 0.64, kPosterHeight = 0.48;  // metres

cv::Mat Poster(const std::string& name = "corridor/1.jpg") {
  return cv::imread(testing::ProjectTestData(name), cv::IMREAD_GRAYSCALE);
}

RigidTransform PoseAt(double yaw_deg, double pitch_deg, const cv::Vec3d& t) {
  RigidTransform pose;
  cv::Rodrigues(cv::Vec3d(pitch_deg * CV_PI / 180, yaw_deg * CV_PI / 180, 0), pose.R);
  pose.t = t;
  return pose;
}

// Renders the poster model's front face as `camera` sees it under `camera_from_object`, over
// `background` (640x480) or over a uniform grey.
cv::Mat RenderPoster(const cv::Mat& poster, const ObjectModel& model,
                     const CameraIntrinsics& camera, const RigidTransform& camera_from_object,
                     const cv::Mat& background = {}) {
  const RigidTransform camera_from_face = camera_from_object * model.faces[0].object_from_face;
  const cv::Matx33d& R = camera_from_face.R;
  const cv::Matx33d plane(R(0, 0), R(0, 1), camera_from_face.t[0], R(1, 0), R(1, 1),
                          camera_from_face.t[1], R(2, 0), R(2, 1), camera_from_face.t[2]);
  const cv::Matx33d pixels_to_face(kPosterWidth / poster.cols, 0, 0, 0, kPosterHeight / poster.rows,
                                   0, 0, 0, 1);
  cv::Mat view = background.empty() ? cv::Mat(480, 640, CV_8U, cv::Scalar(90)) : background.clone();
  cv::warpPerspective(poster, view, cv::Mat(camera.K() * plane * pixels_to_face), view.size(),
                      cv::INTER_LINEAR, cv::BORDER_TRANSPARENT);
  return view;
}

class ObjectRecognitionTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ModelBuilder builder(testing::BundledObjectVocabulary());
    auto poster = builder.FromFaceImages("poster", {{BoxSide::kFront, Poster()}}, kPosterWidth,
                                         kPosterHeight);
    ASSERT_TRUE(poster.ok()) << poster.status().ToString();
    poster_ = std::move(*poster);
    auto database = ObjectDatabase::Open(&store_, testing::BundledObjectVocabulary());
    ASSERT_TRUE(database.ok()) << database.status().ToString();
    database_ = std::move(*database);
    camera_ = {500, 500, 320, 240, {}};
  }

  MemoryIndexStore store_;
  ObjectModel poster_;
  std::shared_ptr<ObjectDatabase> database_;
  CameraIntrinsics camera_;
};

TEST_F(ObjectRecognitionTest, APlanarModelPutsEveryPointOnItsFace) {
  EXPECT_EQ(poster_.metadata.type, ObjectType::kPlanar);
  ASSERT_EQ(poster_.faces.size(), 1u);
  EXPECT_GT(poster_.num_features(), 300u);
  EXPECT_EQ(poster_.views.size(), 1u);
  EXPECT_FALSE(poster_.views[0].image_png.empty());
  for (const cv::Point3f& p : poster_.points) {
    EXPECT_NEAR(p.z, 0.0, 1e-6);  // a flat poster: depth 0, centred on the object origin
    EXPECT_LE(std::abs(p.x), kPosterWidth / 2 + 1e-6);
    EXPECT_LE(std::abs(p.y), kPosterHeight / 2 + 1e-6);
  }
}

TEST_F(ObjectRecognitionTest, RecognisesThePosterAndRecoversItsPose) {
  ASSERT_TRUE(database_->Put(poster_).ok());
  ObjectRecognizer recognizer = testing::MakeRecognizer(database_);
  for (const RigidTransform& truth : {PoseAt(0, 0, {0, 0, 0.9}), PoseAt(25, 0, {0.05, 0, 1.0}),
                                      PoseAt(-15, 20, {0, 0.05, 1.1})}) {
    const cv::Mat view = RenderPoster(Poster(), poster_, camera_, truth);
    std::vector<Detection> detections;
    RecognitionTiming timing;
    ASSERT_TRUE(recognizer.Recognize(view, camera_, &detections, &timing).ok());
    ASSERT_EQ(detections.size(), 1u);
    const Detection& d = detections[0];
    EXPECT_EQ(d.name, "poster");
    EXPECT_EQ(d.version, 1u);
    EXPECT_GE(d.inliers, 30u);
    EXPECT_LT(RotationAngleDeg(d.camera_from_object.R, truth.R), 1.5);
    EXPECT_LT(cv::norm(d.camera_from_object.t - truth.t) / cv::norm(truth.t), 0.02);
    EXPECT_LT(d.reprojection_error_px, 2.0);
    EXPECT_GE(d.outline.size(), 4u);
    EXPECT_GT(timing.total, 0.0);
    EXPECT_GE(timing.regions, 1u);
  }
}

TEST_F(ObjectRecognitionTest, SameInputGivesTheSameOutput) {
  ASSERT_TRUE(database_->Put(poster_).ok());
  const cv::Mat view = RenderPoster(Poster(), poster_, camera_, PoseAt(20, 10, {0, 0, 1.0}));
  std::vector<Detection> first, second;
  ObjectRecognizer a = testing::MakeRecognizer(database_), b = testing::MakeRecognizer(database_);
  ASSERT_TRUE(a.Recognize(view, camera_, &first).ok());
  ASSERT_TRUE(b.Recognize(view, camera_, &second).ok());
  ASSERT_EQ(first.size(), 1u);
  ASSERT_EQ(second.size(), 1u);
  EXPECT_EQ(first[0].inliers, second[0].inliers);
  EXPECT_EQ(first[0].camera_from_object.t, second[0].camera_from_object.t);
}

TEST_F(ObjectRecognitionTest, DetectionsCarryTheirModelsMetadata) {
  poster_.metadata.object_class = "poster-class";
  poster_.metadata.units = "cm";
  ASSERT_TRUE(database_->Put(poster_).ok());
  ObjectRecognizer recognizer = testing::MakeRecognizer(database_);
  std::vector<Detection> detections;
  const cv::Mat view = RenderPoster(Poster(), poster_, camera_, PoseAt(10, 0, {0, 0, 1.0}));
  ASSERT_TRUE(recognizer.Recognize(view, camera_, &detections).ok());
  ASSERT_EQ(detections.size(), 1u);
  EXPECT_EQ(detections[0].name, "poster");
  EXPECT_EQ(detections[0].object_class, "poster-class");
  EXPECT_EQ(detections[0].units, "cm");
  EXPECT_EQ(detections[0].type, ObjectType::kPlanar);
}

TEST_F(ObjectRecognitionTest, AFilterDropsCandidatesBeforeVerification) {
  poster_.metadata.object_class = "print";
  ASSERT_TRUE(database_->Put(poster_).ok());
  ObjectRecognizer recognizer = testing::MakeRecognizer(database_);
  const cv::Mat view = RenderPoster(Poster(), poster_, camera_, PoseAt(10, 0, {0, 0, 1.0}));
  std::vector<Detection> detections;
  RecognitionTiming timing;

  ASSERT_TRUE(recognizer.Recognize(view, camera_, &detections, &timing).ok());  // no filter
  ASSERT_EQ(detections.size(), 1u);
  EXPECT_GE(timing.verified, 1u);

  // A filter naming another object: the poster is a candidate but is never verified.
  const ObjectFilter other{{"lion"}, {"toy"}};
  ASSERT_TRUE(recognizer.Recognize(view, camera_, &detections, &timing, other).ok());
  EXPECT_TRUE(detections.empty());
  EXPECT_EQ(timing.verified, 0u);
  EXPECT_GE(timing.regions, 1u);  // the image was still searched

  // The poster's class, or its name, lets it through.
  for (const ObjectFilter& filter : {ObjectFilter{{}, {"print"}}, ObjectFilter{{"poster"}, {}},
                                     ObjectFilter{{"lion"}, {"print"}}}) {
    ASSERT_TRUE(recognizer.Recognize(view, camera_, &detections, &timing, filter).ok());
    ASSERT_EQ(detections.size(), 1u);
    EXPECT_EQ(detections[0].name, "poster");
    EXPECT_GE(timing.verified, 1u);
  }
}

TEST_F(ObjectRecognitionTest, AnExplanationSaysWhereEachObjectDroppedOut) {
  ASSERT_TRUE(database_->Put(poster_).ok());
  ModelBuilder builder(testing::BundledObjectVocabulary());
  auto other = builder.FromFaceImages("other", {{BoxSide::kFront, Poster("corridor/60.jpg")}},
                                      kPosterWidth, kPosterHeight);
  ASSERT_TRUE(other.ok()) << other.status().ToString();
  ASSERT_TRUE(database_->Put(*other).ok());
  ObjectRecognizer recognizer = testing::MakeRecognizer(database_);
  const cv::Mat view = RenderPoster(Poster(), poster_, camera_, PoseAt(10, 0, {0, 0, 1.0}));
  std::vector<Detection> detections;
  std::vector<ObjectExplanation> explanation;
  ASSERT_TRUE(recognizer.Recognize(view, camera_, &detections, nullptr, {}, {}, &explanation).ok());
  ASSERT_EQ(detections.size(), 1u);
  ASSERT_EQ(explanation.size(), 2u);  // every object of the database, by name
  EXPECT_EQ(explanation[0].name, "other");
  EXPECT_EQ(explanation[1].name, "poster");
  const ObjectExplanation& found = explanation[1];
  EXPECT_EQ(found.outcome, ObjectOutcome::kDetected);
  EXPECT_GE(found.regions, 1u);
  EXPECT_GT(found.best_score, 0.0);
  EXPECT_GE(found.correspondences, found.inliers);
  EXPECT_GE(found.inliers, found.min_inliers);
  EXPECT_EQ(found.min_inliers, RecognitionOptions().min_planar_inliers);
  EXPECT_NE(explanation[0].outcome, ObjectOutcome::kDetected);

  // A flat image proposes nothing: every object is not_proposed.
  const cv::Mat flat(480, 640, CV_8U, cv::Scalar(128));
  ASSERT_TRUE(recognizer.Recognize(flat, camera_, &detections, nullptr, {}, {}, &explanation).ok());
  ASSERT_EQ(explanation.size(), 2u);
  for (const ObjectExplanation& e : explanation) {
    EXPECT_EQ(e.outcome, ObjectOutcome::kNotProposed) << e.name;
    EXPECT_EQ(e.regions, 0u);
  }
  EXPECT_EQ(ObjectOutcomeName(ObjectOutcome::kNotProposed), "not_proposed");
  EXPECT_EQ(ObjectOutcomeName(ObjectOutcome::kFewInliers), "few_inliers");

  // The filter's objects only; without the argument, nothing is explained.
  ASSERT_TRUE(recognizer
                  .Recognize(view, camera_, &detections, nullptr, ObjectFilter{{"other"}, {}}, {},
                             &explanation)
                  .ok());
  ASSERT_EQ(explanation.size(), 1u);
  EXPECT_EQ(explanation[0].name, "other");
  ASSERT_TRUE(recognizer.Recognize(view, camera_, &detections).ok());
  EXPECT_EQ(detections.size(), 1u);
}

TEST_F(ObjectRecognitionTest, RefinementFindsMoreInliersNearThePose) {
  ASSERT_TRUE(database_->Put(poster_).ok());
  RecognitionOptions plain;
  plain.refinement.enabled = false;
  ObjectRecognizer without = testing::MakeRecognizer(database_, plain),
                   with = testing::MakeRecognizer(database_);
  const RigidTransform truth = PoseAt(20, -10, {0.05, 0, 1.6});
  const cv::Mat view = RenderPoster(Poster(), poster_, camera_, truth);
  std::vector<Detection> first, refined;
  RecognitionTiming timing;
  ASSERT_TRUE(without.Recognize(view, camera_, &first).ok());
  ASSERT_TRUE(with.Recognize(view, camera_, &refined, &timing).ok());
  ASSERT_EQ(first.size(), 1u);
  ASSERT_EQ(refined.size(), 1u);
  EXPECT_GE(refined[0].inliers, 2 * first[0].inliers);
  EXPECT_GT(timing.refinement, 0.0);
  // Twice the inliers, and a pose closer to the truth (a poster seen nearly face-on: its tilt is
  // what the inliers constrain least).
  const auto errors = [&](const Detection& d) {
    return std::pair(RotationAngleDeg(d.camera_from_object.R, truth.R),
                     cv::norm(d.camera_from_object.t - truth.t) / cv::norm(truth.t));
  };
  EXPECT_LT(errors(refined[0]).first, errors(first[0]).first);
  EXPECT_LT(errors(refined[0]).second, errors(first[0]).second);
  EXPECT_LT(errors(refined[0]).first, 1.5);
  EXPECT_LT(errors(refined[0]).second, 0.005);
  EXPECT_EQ(refined[0].score, first[0].score);  // the region's score is kept
}

TEST(ObjectFilterTest, EmptyPassesEverythingOtherwiseNameOrClass) {
  ObjectMetadata lion;
  lion.name = "lion";
  lion.object_class = "toy";
  EXPECT_TRUE(ObjectFilter{}.Passes(lion));
  EXPECT_TRUE((ObjectFilter{{"lion"}, {}}.Passes(lion)));
  EXPECT_TRUE((ObjectFilter{{}, {"toy"}}.Passes(lion)));
  EXPECT_FALSE((ObjectFilter{{"poster"}, {}}.Passes(lion)));
  EXPECT_FALSE((ObjectFilter{{}, {"box"}}.Passes(lion)));
  EXPECT_FALSE((ObjectFilter{{"toy"}, {"lion"}}.Passes(lion)));  // names and classes are apart
}

TEST_F(ObjectRecognitionTest, AnUnrelatedImageRecognisesNothing) {
  ASSERT_TRUE(database_->Put(poster_).ok());
  ObjectRecognizer recognizer = testing::MakeRecognizer(database_);
  std::vector<Detection> detections;
  // Another corridor frame looks alike but is not the poster.
  ASSERT_TRUE(recognizer.Recognize(Poster("corridor/60.jpg"), camera_, &detections).ok());
  EXPECT_TRUE(detections.empty());
  cv::Mat flat(480, 640, CV_8U, cv::Scalar(128));
  ASSERT_TRUE(recognizer.Recognize(flat, camera_, &detections).ok());
  EXPECT_TRUE(detections.empty());
}

TEST_F(ObjectRecognitionTest, BadInputIsRejected) {
  ObjectRecognizer recognizer = testing::MakeRecognizer(database_);
  std::vector<Detection> detections;
  EXPECT_EQ(recognizer.Recognize(cv::Mat(), camera_, &detections).code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(recognizer.Recognize(Poster(), {0, 500, 320, 240, {}}, &detections).code(),
            StatusCode::kInvalidArgument);
  FeatureSet wrong_width;
  wrong_width.keypoints.resize(2);
  wrong_width.descriptors = cv::Mat(2, 16, CV_8U, cv::Scalar(0));
  EXPECT_EQ(recognizer.RecognizeFeatures(wrong_width, camera_, &detections).code(),
            StatusCode::kInvalidArgument);
}

TEST_F(ObjectRecognitionTest, CreateRefusesOptionsOutOfRangeAndAMissingDatabase) {
  RecognitionOptions bad;
  bad.match.ratio = std::numeric_limits<double>::quiet_NaN();
  const StatusOr<ObjectRecognizer> refused = ObjectRecognizer::Create(database_, bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(refused.status().message(), "RecognitionOptions.match.ratio = nan: must be in (0, 1]");
  EXPECT_EQ(ObjectRecognizer::Create(nullptr).status().code(), StatusCode::kInvalidArgument);
  const StatusOr<ObjectRecognizer> created = ObjectRecognizer::Create(database_);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  EXPECT_EQ(created->options().min_inliers, RecognitionOptions().min_inliers);
}

TEST(RecognitionOptionsTest, TheDefaultsAreValid) {
  EXPECT_TRUE(RecognitionOptions().Validate().ok()) << RecognitionOptions().Validate().ToString();
  EXPECT_TRUE(SecondPassOptions().Validate().ok());
  EXPECT_TRUE(RefinementOptions().Validate().ok());
  EXPECT_TRUE(GuidedMatchOptions().Validate().ok());
  // The ends of the ranges are in them.
  RecognitionOptions edges;
  edges.beta = 0;
  edges.runner_up_score_ratio = 1;
  edges.match.ratio = 1;
  edges.roi.bandwidth_px = 0;
  edges.second_pass.margin = 0;
  edges.second_pass.enlarge_to_px = 0;
  edges.second_pass.max_enlarge = 1;
  edges.refinement.matching.region_margin_px = 0;
  EXPECT_TRUE(edges.Validate().ok()) << edges.Validate().ToString();
}

// One field out of its range at a time, NaN and infinity among the values; the message names the
// field by its path (the members' fields included), its value and its range.
TEST(RecognitionOptionsTest, EachFieldOutOfRangeIsRefusedWithItsNameAndValue) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  using O = RecognitionOptions;
  const std::vector<testing::BadOption<O>> cases = {
      {"RecognitionOptions.orb.levels", [](O& o) { o.orb.levels = 0; }},
      {"RecognitionOptions.roi.seeds = 0: must be in [1, 2048]", [](O& o) { o.roi.seeds = 0; }},
      {"RecognitionOptions.roi.bandwidth_px = nan", [&](O& o) { o.roi.bandwidth_px = nan; }},
      {"RecognitionOptions.beta = inf: must be in [0, 1]", [&](O& o) { o.beta = inf; }},
      {"RecognitionOptions.beta = 1.5", [](O& o) { o.beta = 1.5; }},
      {"RecognitionOptions.candidates_per_roi = 0", [](O& o) { o.candidates_per_roi = 0; }},
      {"RecognitionOptions.runner_up_score_ratio = nan",
       [&](O& o) { o.runner_up_score_ratio = nan; }},
      {"RecognitionOptions.match.ratio = 0", [](O& o) { o.match.ratio = 0; }},
      {"RecognitionOptions.ransac_iterations = 0", [](O& o) { o.ransac_iterations = 0; }},
      {"RecognitionOptions.reprojection_px = inf: must be finite and > 0",
       [&](O& o) { o.reprojection_px = inf; }},
      {"RecognitionOptions.reprojection_px = 0", [](O& o) { o.reprojection_px = 0; }},
      {"RecognitionOptions.min_inliers = 0: must be >= 1", [](O& o) { o.min_inliers = 0; }},
      {"RecognitionOptions.min_planar_inliers = 0", [](O& o) { o.min_planar_inliers = 0; }},
      {"RecognitionOptions.second_pass.margin = nan", [&](O& o) { o.second_pass.margin = nan; }},
      {"RecognitionOptions.second_pass.max_enlarge = inf",
       [&](O& o) { o.second_pass.max_enlarge = inf; }},
      {"RecognitionOptions.refinement.matching.window_px = nan",
       [&](O& o) { o.refinement.matching.window_px = nan; }},
  };
  testing::ExpectEachRefusedStartingWith(cases);
}

TEST(RecognitionOptionsTest, SecondPassOptionsOutOfRangeAreRefused) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  using O = SecondPassOptions;
  const std::vector<testing::BadOption<O>> cases = {
      {"margin = inf", [&](O& o) { o.margin = inf; }},
      {"margin = -0.1", [](O& o) { o.margin = -0.1; }},
      {"min_margin_px = -1", [](O& o) { o.min_margin_px = -1; }},
      {"enlarge_to_px = 5000", [](O& o) { o.enlarge_to_px = 5000; }},
      {"enlarge_to_px = -1", [](O& o) { o.enlarge_to_px = -1; }},
      {"max_enlarge = nan", [&](O& o) { o.max_enlarge = nan; }},
      {"max_enlarge = 0.5", [](O& o) { o.max_enlarge = 0.5; }},
      {"candidates = 0", [](O& o) { o.candidates = 0; }},
  };
  testing::ExpectEachRefused("SecondPassOptions", cases);
  SecondPassOptions orb;
  orb.orb.max_features = 0;
  EXPECT_NE(orb.Validate().message().find("SecondPassOptions.orb.max_features"), std::string::npos)
      << orb.Validate().message();
}

TEST(RecognitionOptionsTest, GuidedMatchAndRefinementOptionsOutOfRangeAreRefused) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  using O = GuidedMatchOptions;
  const std::vector<testing::BadOption<O>> cases = {
      {"region_margin_px = nan", [&](O& o) { o.region_margin_px = nan; }},
      {"region_margin_px = -1", [](O& o) { o.region_margin_px = -1; }},
      {"window_px = inf", [&](O& o) { o.window_px = inf; }},
      {"window_px = 0", [](O& o) { o.window_px = 0; }},
      {"ratio = nan", [&](O& o) { o.ratio = nan; }},
      {"ratio = 1.1", [](O& o) { o.ratio = 1.1; }},
      {"ransac_iterations = 0", [](O& o) { o.ransac_iterations = 0; }},
      {"reprojection_px = -inf", [&](O& o) { o.reprojection_px = -inf; }},
      {"min_inliers = 0", [](O& o) { o.min_inliers = 0; }},
  };
  testing::ExpectEachRefused("GuidedMatchOptions", cases);
  GuidedMatchOptions orb;
  orb.orb.scale_factor = 1.f;
  EXPECT_NE(orb.Validate().message().find("GuidedMatchOptions.orb.scale_factor"), std::string::npos)
      << orb.Validate().message();
  RefinementOptions refinement;
  refinement.matching.reprojection_px = nan;
  EXPECT_EQ(refinement.Validate().message(),
            "RefinementOptions.matching.reprojection_px = nan: must be finite and > 0");
}

TEST_F(ObjectRecognitionTest, DatabaseAddsReplacesListsAndRemovesModels) {
  auto first = database_->Put(poster_);
  ASSERT_TRUE(first.ok());
  EXPECT_EQ(first->version, 1u);
  auto replaced = database_->Put(poster_);
  ASSERT_TRUE(replaced.ok());
  EXPECT_EQ(replaced->version, 2u);
  EXPECT_EQ(database_->size(), 1u);
  EXPECT_EQ(database_->index().size(), 1u);  // the old entry left the index

  ModelBuilder builder(testing::BundledObjectVocabulary());
  auto other =
      builder.FromFaceImages("other", {{BoxSide::kFront, Poster("corridor/41.jpg")}}, 0.3, 0.2);
  ASSERT_TRUE(other.ok());
  ASSERT_TRUE(database_->Put(*other).ok());
  const std::vector<ObjectMetadata> list = database_->List();
  ASSERT_EQ(list.size(), 2u);
  EXPECT_EQ(list[0].name, "other");
  EXPECT_EQ(list[1].name, "poster");

  auto stored = database_->Get("poster");
  ASSERT_TRUE(stored.ok());
  EXPECT_EQ(stored->num_features(), poster_.num_features());
  EXPECT_EQ(stored->faces.size(), 1u);
  EXPECT_TRUE(stored->Validate().ok());

  EXPECT_TRUE(database_->Remove("poster").ok());
  EXPECT_EQ(database_->Remove("poster").code(), StatusCode::kNotFound);
  EXPECT_EQ(database_->Get("poster").status().code(), StatusCode::kNotFound);
  EXPECT_EQ(database_->size(), 1u);
}

TEST_F(ObjectRecognitionTest, DatabaseReloadsItsObjectsFromTheStore) {
  ASSERT_TRUE(database_->Put(poster_).ok());
  ASSERT_TRUE(database_->Put(poster_).ok());  // version 2
  database_.reset();
  auto reopened = ObjectDatabase::Open(&store_, testing::BundledObjectVocabulary());
  ASSERT_TRUE(reopened.ok()) << reopened.status().ToString();
  std::shared_ptr<ObjectDatabase> database = std::move(*reopened);
  ASSERT_EQ(database->size(), 1u);
  EXPECT_EQ(database->List()[0].version, 2u);
  ObjectRecognizer recognizer = testing::MakeRecognizer(database);
  std::vector<Detection> detections;
  const RigidTransform truth = PoseAt(10, 0, {0, 0, 1.0});
  ASSERT_TRUE(
      recognizer.Recognize(RenderPoster(Poster(), poster_, camera_, truth), camera_, &detections)
          .ok());
  ASSERT_EQ(detections.size(), 1u);
  EXPECT_LT(RotationAngleDeg(detections[0].camera_from_object.R, truth.R), 1.5);
}

TEST_F(ObjectRecognitionTest, DatabaseRejectsBadModels) {
  ObjectModel nameless = poster_;
  nameless.metadata.name = "no spaces allowed";
  EXPECT_EQ(database_->Put(nameless).status().code(), StatusCode::kInvalidArgument);
  ObjectModel empty = poster_;
  empty.descriptors = cv::Mat();
  empty.point_of_feature.clear();
  EXPECT_EQ(database_->Put(empty).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(database_->size(), 0u);
}

TEST(ModelBuilderTest, BoxFacesLandOnTheirSidesOfTheBox) {
  ModelBuilder builder(testing::BundledObjectVocabulary());
  const double w = 0.3, h = 0.2, d = 0.1;
  auto box = builder.FromFaceImages("box",
                                    {{BoxSide::kFront, Poster()},
                                     {BoxSide::kTop, Poster("corridor/41.jpg")},
                                     {BoxSide::kRight, Poster("corridor/60.jpg")}},
                                    w, h, d);
  ASSERT_TRUE(box.ok()) << box.status().ToString();
  ASSERT_EQ(box->faces.size(), 3u);
  for (size_t i = 0; i < box->points.size(); ++i) {
    const cv::Point3f& p = box->points[i];
    switch (box->face_of_point[i]) {
      case 0:
        EXPECT_NEAR(p.z, -d / 2, 1e-6);
        break;  // front: towards the viewer
      case 1:
        EXPECT_NEAR(p.y, -h / 2, 1e-6);
        break;  // top
      case 2:
        EXPECT_NEAR(p.x, w / 2, 1e-6);
        break;  // right
      default:
        ADD_FAILURE() << "unexpected face";
    }
  }
  EXPECT_EQ(builder
                .FromFaceImages("box", {{BoxSide::kFront, Poster()}, {BoxSide::kFront, Poster()}},
                                w, h, d)
                .status()
                .code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(builder.FromFaceImages("box", {{BoxSide::kFront, Poster()}}, -1, h).status().code(),
            StatusCode::kInvalidArgument);
}

TEST(ModelBuilderTest, RgbdViewsBackProjectFeaturesWithDepth) {
  // A fronto-parallel wall 1.5 m away, seen by a camera at the object origin; the left half has
  // no depth.
  RgbdView view;
  view.view.name = "wall";
  view.view.image = Poster();
  view.view.camera = {500, 500, 320, 240, {}};
  const cv::Size size = view.view.image.size();
  view.view.camera = {500, 500, size.width / 2.0, size.height / 2.0, {}};
  view.depth = cv::Mat(size, CV_16U, cv::Scalar(1500));
  view.depth.colRange(0, size.width / 2).setTo(0);
  ModelBuilder builder(testing::BundledObjectVocabulary());
  auto model = builder.FromRgbd("wall", {view});
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  ASSERT_GT(model->points.size(), 50u);
  for (const cv::Point3f& p : model->points) {
    EXPECT_NEAR(p.z, 1.5, 1e-6);
    EXPECT_GE(p.x, -0.01);  // only the right half had depth
  }
  view.depth = cv::Mat(10, 10, CV_16U);
  EXPECT_EQ(builder.FromRgbd("wall", {view}).status().code(), StatusCode::kInvalidArgument);
}

// A view whose pose is off puts its depth outside the box: the report says so, view by view,
// and the build goes on with the views that agree.
TEST(ModelBuilderTest, TheRgbdReportFlagsAViewWhoseDepthMissesTheBox) {
  // A wall 1.5 m in front of the camera, the object a 2 cm thick slab of it (camera frame =
  // object frame for the well-posed view).
  RgbdView posed;
  posed.view.name = "posed";
  posed.view.image = Poster();
  const cv::Size size = posed.view.image.size();
  posed.view.camera = {500, 500, size.width / 2.0, size.height / 2.0, {}};
  posed.depth = cv::Mat(size, CV_16U, cv::Scalar(1500));
  // Its depth puts the right half of the image 10 cm behind the slab, as a pose off by a few
  // centimetres puts part of a small object's outline on the background.
  RgbdView misposed = posed;
  misposed.view.name = "misposed";
  misposed.depth = posed.depth.clone();
  misposed.depth.colRange(size.width / 2, size.width).setTo(1600);
  const ObjectBox slab{{2.0, 2.0, 0.02}, {0, 0, 1.5}};
  ModelBuilder builder(testing::BundledObjectVocabulary());
  std::vector<RgbdViewReport> report;
  auto model = builder.FromRgbd("wall", {posed, misposed}, slab, &report);
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  ASSERT_EQ(report.size(), 2u);
  EXPECT_EQ(report[0].name, "posed");
  EXPECT_GT(report[0].with_depth, RgbdViewReport::kMinWithDepth);
  EXPECT_LE(report[0].with_depth, report[0].features);
  EXPECT_EQ(report[0].in_box, report[0].with_depth);
  EXPECT_FALSE(report[0].LooksMisposed());
  EXPECT_EQ(report[1].name, "misposed");
  EXPECT_GT(report[1].with_depth, RgbdViewReport::kMinWithDepth);
  EXPECT_GT(report[1].in_box, 0u);
  EXPECT_TRUE(report[1].LooksMisposed());
  for (const cv::Point3f& p : model->points) EXPECT_NEAR(p.z, 1.5, 1e-6);  // none from behind

  // A view all of whose depth misses the box gives no point: an error, and the report up to it.
  misposed.depth.setTo(1600);
  EXPECT_EQ(builder.FromRgbd("wall", {posed, misposed}, slab, &report).status().code(),
            StatusCode::kInvalidArgument);
  ASSERT_EQ(report.size(), 2u);
  EXPECT_FALSE(report[0].LooksMisposed());
  EXPECT_EQ(report[1].in_box, 0u);
  EXPECT_TRUE(report[1].LooksMisposed());
}

TEST(ModelBuilderTest, PosedPolygonsIntersectKeypointsWithTheVisibleFace) {
  // One 1 x 0.75 m face at z = 2 m in front of the camera; keypoints outside it are dropped.
  PosedImage view{"frame", Poster(), {500, 500, 320, 240, {}}, {}};
  FacePolygon face{{{-0.5, -0.375, 2}, {0.5, -0.375, 2}, {0.5, 0.375, 2}, {-0.5, 0.375, 2}}};
  ModelBuilder builder(testing::BundledObjectVocabulary());
  auto model = builder.FromPosedPolygons("face", {face}, {view});
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  ASSERT_GT(model->points.size(), 50u);
  for (const cv::Point3f& p : model->points) {
    EXPECT_NEAR(p.z, 2.0, 1e-5);
    EXPECT_LE(std::abs(p.x), 0.5 + 1e-6);
    EXPECT_LE(std::abs(p.y), 0.375 + 1e-6);
  }
}

TEST(ModelBuilderTest, RoboEarthLionHeldOutViewIsRecognisedWithItsPose) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/roboearth/models/lion");
  const std::string dir = testing::SharedData("objects/roboearth/models/lion");
  ModelBuildOptions options;
  options.keep_images = false;
  options.exclude_views = {13};
  ModelBuilder builder(testing::BundledObjectVocabulary(), options);
  auto model = builder.FromRoboEarth(dir);
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  EXPECT_EQ(model->metadata.name, "lion");
  EXPECT_EQ(model->metadata.object_class, "lion");
  EXPECT_EQ(model->views.size(), 19u);
  EXPECT_GT(model->points.size(), 1000u);

  MemoryIndexStore store;
  auto database = ObjectDatabase::Open(&store, testing::BundledObjectVocabulary());
  ASSERT_TRUE(database.ok());
  ASSERT_TRUE((*database)->Put(*model).ok());
  auto camera_file = ReadBundleCamera(dir + "/face_013.txt");
  ASSERT_TRUE(camera_file.ok());
  const CameraIntrinsics camera{camera_file->focal, camera_file->focal, 320, 240, {}};
  ObjectRecognizer recognizer =
      testing::MakeRecognizer(std::shared_ptr<const ObjectDatabase>(std::move(*database)));
  std::vector<Detection> detections;
  ASSERT_TRUE(
      recognizer
          .Recognize(cv::imread(dir + "/face_013.png", cv::IMREAD_GRAYSCALE), camera, &detections)
          .ok());
  ASSERT_EQ(detections.size(), 1u);
  const RigidTransform& truth = camera_file->camera_from_object;
  EXPECT_LT(RotationAngleDeg(detections[0].camera_from_object.R, truth.R), 3.0);
  EXPECT_LT(cv::norm(detections[0].camera_from_object.t - truth.t) / cv::norm(truth.t), 0.03);
}

}  // namespace
}  // namespace recog

namespace recog {
namespace {

TEST(RgbdViewListTest, ReadsViewsAndRejectsMalformedLists) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("recog_rgbd_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  cv::imwrite((dir / "rgb.png").string(), Poster());
  cv::imwrite((dir / "depth.png").string(), cv::Mat(Poster().size(), CV_16U, cv::Scalar(1200)));
  const auto list = [&dir](const std::string& text) {
    std::ofstream((dir / "views.txt").string()) << text;
    return (dir / "views.txt").string();
  };
  const std::string identity = " 1 0 0 0 1 0 0 0 1 0 0 0";
  auto views =
      ReadRgbdViews(list("# rgb depth fx fy cx cy scale R t\nrgb.png depth.png 500 500 "
                         "256 192 1000" +
                         identity + "\n"));
  ASSERT_TRUE(views.ok()) << views.status().ToString();
  ASSERT_EQ(views->size(), 1u);
  EXPECT_EQ((*views)[0].view.name, "rgb");
  EXPECT_EQ((*views)[0].depth.type(), CV_16U);

  EXPECT_EQ(ReadRgbdViews((dir / "none.txt").string()).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(ReadRgbdViews(list("# nothing\n")).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadRgbdViews(list("rgb.png depth.png 500 500 256\n")).status().code(),
            StatusCode::kInvalidArgument);  // too few fields
  EXPECT_EQ(ReadRgbdViews(list("rgb.png depth.png 500 500 256 192 1000 2 0 0 0 1 0 0 0 1 0 0 0\n"))
                .status()
                .code(),
            StatusCode::kInvalidArgument);  // not a rotation
  EXPECT_EQ(ReadRgbdViews(list("rgb.png depth.png -5 500 256 192 1000" + identity + "\n"))
                .status()
                .code(),
            StatusCode::kInvalidArgument);  // negative focal length
  EXPECT_EQ(ReadRgbdViews(list("rgb.png missing.png 500 500 256 192 1000" + identity + "\n"))
                .status()
                .code(),
            StatusCode::kInvalidArgument);  // unreadable depth
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace recog

namespace recog {
namespace {

// The poster twice in one image (left and right halves, 1.2 m away): reported once per image by
// default, once per region where it is found with report_duplicates.
TEST_F(ObjectRecognitionTest, ReportDuplicatesGivesOneDetectionPerRegion) {
  ASSERT_TRUE(database_->Put(poster_).ok());
  const cv::Mat left = RenderPoster(Poster(), poster_, camera_, PoseAt(0, 0, {-0.38, 0, 1.2}));
  const cv::Mat right = RenderPoster(Poster(), poster_, camera_, PoseAt(0, 0, {0.38, 0, 1.2}));
  cv::Mat twice = left.clone();
  right.colRange(320, 640).copyTo(twice.colRange(320, 640));
  const auto centre_x = [](const Detection& d) {
    double x = 0;
    for (const cv::Point2f& p : d.outline) x += p.x;
    return d.outline.empty() ? -1.0 : x / double(d.outline.size());
  };

  std::vector<Detection> once;
  ASSERT_TRUE(testing::MakeRecognizer(database_).Recognize(twice, camera_, &once).ok());
  ASSERT_EQ(once.size(), 1u);
  EXPECT_EQ(once[0].name, "poster");

  RecognitionOptions options;
  options.report_duplicates = true;
  std::vector<Detection> every;
  ASSERT_TRUE(testing::MakeRecognizer(database_, options).Recognize(twice, camera_, &every).ok());
  ASSERT_GE(every.size(), 2u);
  std::vector<int> regions;
  bool seen_left = false, seen_right = false;
  for (const Detection& d : every) {
    EXPECT_EQ(d.name, "poster");
    EXPECT_EQ(std::count(regions.begin(), regions.end(), d.region), 0)
        << "region " << d.region << " reported twice";
    regions.push_back(d.region);
    seen_left |= centre_x(d) >= 0 && centre_x(d) < 320;
    seen_right |= centre_x(d) >= 320;
  }
  EXPECT_TRUE(seen_left && seen_right) << "both copies of the poster are reported";
}

// What a SLAM inserts (thesis §5.6): the inlier 2D-3D correspondences and the pose covariance,
// only when asked.
TEST_F(ObjectRecognitionTest, DetectionsCarryInliersAndCovarianceWhenAsked) {
  ASSERT_TRUE(database_->Put(poster_).ok());
  ObjectRecognizer recognizer = testing::MakeRecognizer(database_);
  const cv::Mat view = RenderPoster(Poster(), poster_, camera_, PoseAt(20, 10, {0, 0, 1.0}));
  std::vector<Detection> plain, full;
  ASSERT_TRUE(recognizer.Recognize(view, camera_, &plain).ok());
  ASSERT_EQ(plain.size(), 1u);
  EXPECT_TRUE(plain[0].inliers_2d3d.empty());
  EXPECT_TRUE(plain[0].covariance.empty());

  ASSERT_TRUE(
      recognizer.Recognize(view, camera_, &full, nullptr, {}, {.include_inliers = true}).ok());
  ASSERT_EQ(full.size(), 1u);
  EXPECT_EQ(full[0].inliers_2d3d.size(), full[0].inliers);
  EXPECT_TRUE(full[0].covariance.empty()) << "only the inliers were asked for";

  ASSERT_TRUE(recognizer
                  .Recognize(view, camera_, &full, nullptr, {},
                             {.include_inliers = true, .include_covariance = true})
                  .ok());
  ASSERT_EQ(full.size(), 1u);
  const Detection& d = full[0];
  EXPECT_EQ(d.camera_from_object.t, plain[0].camera_from_object.t);  // the same detection
  ASSERT_EQ(d.inliers_2d3d.size(), d.inliers);
  const double bound = recognizer.options().reprojection_px;
  for (const InlierCorrespondence& c : d.inliers_2d3d) {
    ASSERT_LT(c.point_id, poster_.num_features());
    const cv::Point3f& model_point = poster_.points[poster_.point_of_feature[c.point_id]];
    EXPECT_EQ(c.point, model_point);
    cv::Point2d projected;
    ASSERT_TRUE(ProjectPoint(camera_, d.camera_from_object, cv::Point3d(c.point), &projected));
    EXPECT_LE(cv::norm(projected - cv::Point2d(c.pixel)), bound) << c.point_id;
  }

  ASSERT_EQ(d.covariance.size(), 36u);
  const Eigen::Matrix<double, 6, 6, Eigen::RowMajor> covariance(d.covariance.data());
  EXPECT_LT((covariance - covariance.transpose()).norm(), 1e-12 * covariance.norm());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eigen(covariance);
  EXPECT_GT(eigen.eigenvalues().minCoeff(), 0.0);
  // Metres at 1 m: the translation is known to well under a centimetre, not exactly.
  for (int i = 3; i < 6; ++i) {
    EXPECT_GT(covariance(i, i), 0.0);
    EXPECT_LT(std::sqrt(covariance(i, i)), 0.01);
  }

  // The same computation on a quarter of the inliers: a larger uncertainty.
  std::vector<cv::Point3f> points;
  std::vector<cv::Point2f> pixels;
  for (size_t i = 0; i < d.inliers_2d3d.size(); i += 4) {
    points.push_back(d.inliers_2d3d[i].point);
    pixels.push_back(d.inliers_2d3d[i].pixel);
  }
  PoseCovariance6 subset;
  ASSERT_TRUE(ComputePoseCovariance(camera_.K(), d.camera_from_object.R, d.camera_from_object.t,
                                    points, pixels, 0.5, &subset));
  EXPECT_GT(subset[0] + subset[7] + subset[14] + subset[21] + subset[28] + subset[35],
            covariance.trace());
}

}  // namespace
}  // namespace recog

namespace recog {
namespace {

// A cluttered 640x480 frame of textures unlike the poster (a corridor photo): seeded random
// rectangles, circles, lines and text in random greys.
cv::Mat Clutter() {
  cv::RNG rng(0xc1077e5);
  cv::Mat frame(480, 640, CV_8U, cv::Scalar(128));
  const auto grey = [&rng] { return cv::Scalar(rng.uniform(0, 256)); };
  const auto point = [&rng] { return cv::Point(rng.uniform(-40, 680), rng.uniform(-40, 520)); };
  for (int i = 0; i < 120; ++i) {
    switch (i % 3) {
      case 0:
        cv::rectangle(frame, cv::Rect(point(), cv::Size(rng.uniform(8, 90), rng.uniform(8, 90))),
                      grey(), cv::FILLED);
        break;
      case 1:
        cv::circle(frame, point(), rng.uniform(4, 40), grey(), cv::FILLED, cv::LINE_AA);
        break;
      default:
        cv::line(frame, point(), point(), grey(), rng.uniform(1, 4), cv::LINE_AA);
    }
  }
  for (int i = 0; i < 40; ++i) {
    std::string word;
    for (int k = rng.uniform(3, 9); k > 0; --k) word += char('A' + rng.uniform(0, 26));
    cv::putText(frame, word, point(), cv::FONT_HERSHEY_SIMPLEX, rng.uniform(0.4, 1.5), grey(),
                rng.uniform(1, 3), cv::LINE_AA);
  }
  return frame;
}

// A poster of another corridor photo, 0.64 m wide at 2.6 m: 123 x 92 px of a 640 x 480 frame
// (3.7 %), among clutter.
constexpr char kSmallPoster[] = "corridor/20.jpg";
const RigidTransform kSmallPosterPose = PoseAt(10, 0, {-0.4, -0.2, 2.6});

// A sparse first pass (1000 features ranked over the whole frame, no grid, no refinement): the
// small poster's region is proposed but cannot be verified; the second pass, on the enlarged
// crop, can, when it looks at every region whose candidate failed (min_partial_inliers 0: the
// poster's region has fewer than 4 correspondences, no pose). With the defaults this clutter
// defeats both passes: its drawn shapes and letters are what a small object loses its features to.
RecognitionOptions SparseFirstPass() {
  RecognitionOptions options;
  options.orb.max_features = 1000;
  options.orb.grid_rows = options.orb.grid_cols = 0;
  options.refinement.enabled = false;
  options.second_pass.min_partial_inliers = 0;
  return options;
}

TEST_F(ObjectRecognitionTest, TheSecondPassFindsASmallObjectInClutter) {
  ModelBuilder builder(testing::BundledObjectVocabulary());
  auto poster = builder.FromFaceImages("poster", {{BoxSide::kFront, Poster(kSmallPoster)}},
                                       kPosterWidth, kPosterHeight);
  ASSERT_TRUE(poster.ok()) << poster.status().ToString();
  ASSERT_TRUE(database_->Put(*poster).ok());
  const RigidTransform& truth = kSmallPosterPose;
  const cv::Mat frame = RenderPoster(Poster(kSmallPoster), *poster, camera_, truth, Clutter());

  RecognitionOptions one_pass = SparseFirstPass();
  one_pass.second_pass.enabled = false;
  std::vector<Detection> first;
  RecognitionTiming timing;
  ASSERT_TRUE(
      testing::MakeRecognizer(database_, one_pass).Recognize(frame, camera_, &first, &timing).ok());
  EXPECT_TRUE(first.empty()) << "the first pass alone finds it: the test shows nothing";
  EXPECT_EQ(timing.second_pass_regions, 0u);
  EXPECT_EQ(timing.second_pass, 0.0);

  ObjectRecognizer recognizer = testing::MakeRecognizer(database_, SparseFirstPass());
  std::vector<Detection> found, again;
  ASSERT_TRUE(recognizer.Recognize(frame, camera_, &found, &timing).ok());
  ASSERT_EQ(found.size(), 1u);
  EXPECT_EQ(found[0].name, "poster");
  EXPECT_GE(timing.second_pass_regions, 1u);
  EXPECT_GT(timing.second_pass, 0.0);
  EXPECT_LE(timing.orb + timing.clustering + timing.conversion + timing.query +
                timing.correspondences + timing.ransac + timing.second_pass,
            timing.total);
  EXPECT_LT(RotationAngleDeg(found[0].camera_from_object.R, truth.R), 5.0);
  EXPECT_LT(cv::norm(found[0].camera_from_object.t - truth.t) / cv::norm(truth.t), 0.05);
  // Its inliers are image pixels on the poster (mapped back from the crop).
  cv::Point2d corner[2];
  ASSERT_TRUE(ProjectPoint(camera_, truth, {-kPosterWidth / 2, -kPosterHeight / 2, 0}, &corner[0]));
  ASSERT_TRUE(ProjectPoint(camera_, truth, {kPosterWidth / 2, kPosterHeight / 2, 0}, &corner[1]));
  const cv::Rect2d poster_box(corner[0], corner[1]);
  for (const cv::Point2f& p : found[0].inlier_pixels) {
    EXPECT_TRUE((poster_box + cv::Size2d(8, 8) - cv::Point2d(4, 4)).contains(p)) << p;
  }

  // With the default rule only regions where RANSAC came close to a pose are searched again; the
  // poster's (fewer than 4 correspondences) is not, nor are most of the others.
  RecognitionOptions near_misses_only = SparseFirstPass();
  near_misses_only.second_pass.min_partial_inliers = SecondPassOptions().min_partial_inliers;
  ASSERT_GE(near_misses_only.second_pass.min_partial_inliers, 5u);
  const size_t every_failed_region = timing.second_pass_regions;
  std::vector<Detection> near_miss_detections;
  ASSERT_TRUE(testing::MakeRecognizer(database_, near_misses_only)
                  .Recognize(frame, camera_, &near_miss_detections, &timing)
                  .ok());
  EXPECT_TRUE(near_miss_detections.empty());
  EXPECT_LT(timing.second_pass_regions, every_failed_region);

  // Deterministic: a second run, and a second recogniser, give the same detection.
  ObjectRecognizer fresh = testing::MakeRecognizer(database_, SparseFirstPass());
  for (ObjectRecognizer* other : {&recognizer, &fresh}) {
    ASSERT_TRUE(other->Recognize(frame, camera_, &again).ok());
    ASSERT_EQ(again.size(), 1u);
    EXPECT_EQ(again[0].inliers, found[0].inliers);
    EXPECT_EQ(again[0].camera_from_object.R, found[0].camera_from_object.R);
    EXPECT_EQ(again[0].camera_from_object.t, found[0].camera_from_object.t);
    EXPECT_EQ(again[0].inlier_pixels, found[0].inlier_pixels);
  }

  // The same clutter without the poster: nothing, although regions are searched twice.
  ASSERT_TRUE(recognizer.Recognize(Clutter(), camera_, &found, &timing).ok());
  EXPECT_TRUE(found.empty());
}

// RecognizeFeatures has no image to crop: no second pass.
TEST_F(ObjectRecognitionTest, RecognizeFeaturesHasNoSecondPass) {
  ModelBuilder builder(testing::BundledObjectVocabulary());
  auto poster = builder.FromFaceImages("poster", {{BoxSide::kFront, Poster(kSmallPoster)}},
                                       kPosterWidth, kPosterHeight);
  ASSERT_TRUE(poster.ok()) << poster.status().ToString();
  ASSERT_TRUE(database_->Put(*poster).ok());
  const cv::Mat frame =
      RenderPoster(Poster(kSmallPoster), *poster, camera_, kSmallPosterPose, Clutter());
  FeatureOptions feature_options;
  feature_options.orb = RecognitionOptions::DefaultQueryOrb();
  auto extractor = CreateFeatureExtractor(feature_options);
  ASSERT_TRUE(extractor.ok());
  FeatureSet features;
  ASSERT_TRUE((*extractor)->Extract(frame, &features).ok());
  ObjectRecognizer recognizer = testing::MakeRecognizer(database_);
  std::vector<Detection> detections;
  RecognitionTiming timing;
  ASSERT_TRUE(recognizer.RecognizeFeatures(features, camera_, &detections, &timing).ok());
  EXPECT_TRUE(detections.empty());
  EXPECT_EQ(timing.second_pass_regions, 0u);
}

}  // namespace
}  // namespace recog

namespace recog {
namespace {

// A second model made of the right half of the poster (like a label printed on two products): on
// a view of the whole poster, the half's detection lies inside the poster's outline with fewer
// inliers and is dropped.
TEST_F(ObjectRecognitionTest, ADetectionInsideAStrongerOneOfAnotherObjectIsDropped) {
  ASSERT_TRUE(database_->Put(poster_).ok());
  const cv::Mat poster = Poster();
  ModelBuilder builder(testing::BundledObjectVocabulary());
  auto half = builder.FromFaceImages(
      "half", {{BoxSide::kFront, poster.colRange(poster.cols / 2, poster.cols).clone()}},
      kPosterWidth / 2, kPosterHeight);
  ASSERT_TRUE(half.ok()) << half.status().ToString();
  ASSERT_TRUE(database_->Put(*half).ok());
  RecognitionOptions options;
  options.report_duplicates = true;   // every region's detection, before the suppression
  options.candidates_per_roi = 2;     // both models verified in every region
  options.runner_up_score_ratio = 0;  // however far the runner-up's score is below the best's
  options.beta = 0;                   // whatever their BC scores
  ObjectRecognizer recognizer = testing::MakeRecognizer(database_, options);
  const cv::Mat view = RenderPoster(poster, poster_, camera_, PoseAt(10, 0, {0, 0, 1.0}));
  std::vector<Detection> detections;
  ASSERT_TRUE(recognizer.Recognize(view, camera_, &detections).ok());
  ASSERT_FALSE(detections.empty());
  EXPECT_EQ(detections[0].name, "poster");
  for (const Detection& d : detections) EXPECT_EQ(d.name, "poster");
}

// The runner-up of a region is verified only when its chi-square score is close enough to the
// best's: with a ratio of 1 only the best (no two models tie here), with 0 both models.
TEST_F(ObjectRecognitionTest, ARunnerUpIsVerifiedOnlyWhenItsScoreIsCloseToTheBest) {
  ASSERT_TRUE(database_->Put(poster_).ok());
  const cv::Mat poster = Poster();
  ModelBuilder builder(testing::BundledObjectVocabulary());
  auto half = builder.FromFaceImages(
      "half", {{BoxSide::kFront, poster.colRange(0, poster.cols / 2).clone()}}, kPosterWidth / 2,
      kPosterHeight);
  ASSERT_TRUE(half.ok()) << half.status().ToString();
  ASSERT_TRUE(database_->Put(*half).ok());
  const cv::Mat view = RenderPoster(poster, poster_, camera_, PoseAt(10, 0, {0, 0, 1.0}));
  auto verified_with_ratio = [&](double ratio, RecognitionTiming* timing) {
    RecognitionOptions options;
    options.candidates_per_roi = 2;
    options.runner_up_score_ratio = ratio;
    options.report_duplicates = true;  // a model found in one region is verified in the others
    options.second_pass.enabled = false;
    options.beta = 0;  // both models are candidates of every region sharing words with them
    ObjectRecognizer recognizer = testing::MakeRecognizer(database_, options);
    std::vector<Detection> detections;
    ASSERT_TRUE(recognizer.Recognize(view, camera_, &detections, timing).ok());
  };
  RecognitionTiming only_best, both;
  verified_with_ratio(1.0, &only_best);
  verified_with_ratio(0.0, &both);
  ASSERT_GT(only_best.regions, 0u);
  EXPECT_EQ(only_best.verified, only_best.regions);
  EXPECT_EQ(both.regions, only_best.regions);
  EXPECT_EQ(both.verified, 2 * both.regions);
}

}  // namespace
}  // namespace recog
