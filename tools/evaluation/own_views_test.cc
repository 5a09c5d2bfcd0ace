// The invariant that a model recognises the views it was built from, with each view's own pose,
// on every real data set we have: the RoboEarth models (every view of every model, the eleven in
// one database, each alone), the visp-cube model learned from its recording (its five views), the
// visp-castle RGB-D model of frame 0 and the visp-rbt-cube RGB-D model of frames 0 and 33 (the
// last three with the eleven RoboEarth models as distractors).
//
// A model that misses its own view means that the builder keeps features the recogniser never
// extracts: before the query's features were spread over the image, visp-rbt-cube's model of
// frame 0 did not find the cube in frame 0 (the frame's 1000 strongest ORB corners all lay on the
// clutter around the 8.5 cm cube). Each test skips without the shared data.
//
// The pose must come back within 2 degrees and 1 cm of the view's (for RoboEarth's 3D models,
// whose units are those of their structure from motion, within 2 % of the camera's distance,
// 1 cm at 0.5 m).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "core/common/rotation_angle.h"
#include "core/index/memory_index_store.h"
#include "core/object/builder/model_builder.h"
#include "core/object/recognition/object_recognizer.h"
#include "core/object/tracking/recording_learner.h"
#include "tests/testing/recognizers.h"
#include "tests/testing/test_data.h"
#include "tests/testing/vocabularies.h"
#include "tools/evaluation/frame_poses.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/evaluation/rgbd_recording.h"
#include "tools/evaluation/visp_files.h"

namespace recog::cli {
namespace {

constexpr double kMaxRotationDeg = 2.0;
constexpr double kMaxTranslationM = 0.01;
constexpr double kMaxTranslationRatio = 0.02;  // models in structure-from-motion units
// A planar model's view shows one face; a face with fewer model points than this cannot be
// expected to give the 12 homography inliers a planar detection needs (RoboEarth's bottle caps
// hold 22 and 26, bottle1_small's side 37; the other faces 71 to 1,723). 40 is also the inliers
// a frame needs to become a view when a model is learned from a recording.
constexpr size_t kMinFacePoints = 40;

// Model points on face `face` of a planar model (whose view k shows face k).
size_t FacePoints(const ObjectModel& model, size_t face) {
  return size_t(std::count(model.face_of_point.begin(), model.face_of_point.end(), face));
}
const CameraIntrinsics kRbtCubeCamera = {
    607.178466796875, 607.2342529296875, 321.39129638671875, 241.91822814941406, {}};
const ObjectBox kRbtCubeBox{{0.085, 0.085, 0.085}, {0, 0, 0}};

// Frames `numbers` of visp-rbt-cube as RGB-D views posed by its poses.txt.
// The views of `numbers` with their poses from `pose_file` (poses.txt, refined on the depth and
// the edges; poses_fiducial.txt, the first ones from the fiducial grid).
StatusOr<std::vector<RgbdView>> RbtCubeViews(const std::vector<int>& numbers,
                                             const std::string& pose_file = "poses.txt") {
  const std::string dir = testing::SharedData("objects/visp-rbt-cube/");
  RECOG_ASSIGN_OR_RETURN(const std::vector<RgbdRecordingFrame> frames, ListRgbdRecording(dir));
  RECOG_ASSIGN_OR_RETURN(auto poses, ReadFramePoses(dir + pose_file));
  return PosedRgbdViews(frames, poses, kRbtCubeCamera, 1000, numbers);
}

class OwnViewsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto database = ObjectDatabase::Open(&store_, testing::BundledObjectVocabulary());
    ASSERT_TRUE(database.ok()) << database.status().ToString();
    database_ = std::move(*database);
  }

  // Puts the eleven RoboEarth models into the database; returns them.
  std::vector<ObjectModel> AddRoboEarthModels() {
    std::vector<ObjectModel> models;
    for (const ModelSource& source :
         FindModelSources(testing::SharedData("objects/roboearth/models"))) {
      auto model = builder_.FromRoboEarth(source.path);
      EXPECT_TRUE(model.ok()) << source.path << ": " << model.status().ToString();
      if (!model.ok()) continue;
      EXPECT_TRUE(database_->Put(*model).ok());
      models.push_back(std::move(*model));
    }
    EXPECT_EQ(models.size(), 11u);
    return models;
  }

  // Recognises every training view of `model` (which is in the database) and checks that the
  // model is found there with the view's pose.
  void ExpectEveryViewRecognised(const ObjectModel& model) {
    ObjectRecognizer recognizer = testing::MakeRecognizer(database_);
    ASSERT_FALSE(model.views.empty()) << model.metadata.name;
    for (const TrainingView& view : model.views) {
      const std::string where = model.metadata.name + " view " + view.name;
      ASSERT_FALSE(view.image_png.empty()) << where << ": the model keeps no image";
      const cv::Mat image = cv::imdecode(view.image_png, cv::IMREAD_UNCHANGED);
      ASSERT_FALSE(image.empty()) << where;
      if (model.metadata.type == ObjectType::kPlanar &&
          FacePoints(model, size_t(&view - model.views.data())) < kMinFacePoints) {
        ++too_poor_;
        continue;
      }
      std::vector<Detection> detections;
      std::vector<ObjectExplanation> explanation;
      ASSERT_TRUE(
          recognizer.Recognize(image, view.camera, &detections, nullptr, {}, {}, &explanation).ok())
          << where;
      const auto found =
          std::find_if(detections.begin(), detections.end(),
                       [&](const Detection& d) { return d.name == model.metadata.name; });
      ++views_;
      if (found == detections.end()) {
        const auto why =
            std::find_if(explanation.begin(), explanation.end(),
                         [&](const ObjectExplanation& e) { return e.name == model.metadata.name; });
        ADD_FAILURE() << where << " (" << image.cols << "x" << image.rows << "): not recognised: "
                      << (why == explanation.end() ? "?" : ObjectOutcomeName(why->outcome)) << ", "
                      << (why == explanation.end() ? 0 : why->correspondences)
                      << " correspondences, " << (why == explanation.end() ? 0 : why->inliers)
                      << " inliers";
        continue;
      }
      const double rotation =
          RotationAngleDeg(found->camera_from_object.R, view.camera_from_object.R);
      const double translation = cv::norm(found->camera_from_object.t - view.camera_from_object.t);
      EXPECT_LE(rotation, kMaxRotationDeg) << where << " (" << found->inliers << " inliers)";
      if (model.metadata.units == "sfm") {
        EXPECT_LE(translation / cv::norm(view.camera_from_object.t), kMaxTranslationRatio) << where;
      } else {
        EXPECT_LE(translation, kMaxTranslationM) << where << " (" << found->inliers << " inliers)";
      }
    }
  }

  ModelBuilder builder_{testing::BundledObjectVocabulary()};
  MemoryIndexStore store_;
  std::shared_ptr<ObjectDatabase> database_;
  size_t views_ = 0;     // views checked
  size_t too_poor_ = 0;  // planar views left out: their face has under kMinFacePoints points
};

// Each model alone in the database: bottle1, bottle1_big and bottle1_medium are one product at
// three sizes with the same face images, so among the eleven a view of one is (rightly) as much a
// view of the others.
TEST_F(OwnViewsTest, EveryRoboEarthModelRecognisesEachOfItsViews) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/roboearth/models/lion/meta.xml");
  const std::vector<ObjectModel> models = AddRoboEarthModels();
  for (const ObjectModel& model : models) {
    for (const ObjectModel& other : models) {
      if (other.metadata.name != model.metadata.name) {
        ASSERT_TRUE(database_->Remove(other.metadata.name).ok());
      }
    }
    ExpectEveryViewRecognised(model);
    for (const ObjectModel& other : models) {
      if (other.metadata.name != model.metadata.name) {
        ASSERT_TRUE(database_->Put(other).ok());
      }
    }
  }
  EXPECT_GE(views_, 65u);
  EXPECT_EQ(too_poor_, 5u);  // the caps of bottle1_big and bottle1_medium, bottle1_small's side
}

TEST_F(OwnViewsTest, TheVispCubeModelLearnedFromItsRecordingRecognisesEachOfItsViews) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/visp-cube/cube.cao");
  const std::string dir = testing::SharedData("objects/visp-cube/");
  auto faces = ReadCaoFaces(dir + "cube.cao");
  ASSERT_TRUE(faces.ok()) << faces.status().ToString();
  PosedImage first;
  first.name = "image0000";
  auto image = ReadGrayImage(dir + "images/image0000.png");
  ASSERT_TRUE(image.ok()) << image.status().ToString();
  first.image = *image;
  first.camera = {547, 547, 338, 234, {}};
  auto pose = ReadVispPose(dir + "cube.0.pos");
  ASSERT_TRUE(pose.ok()) << pose.status().ToString();
  first.camera_from_object = *pose;
  std::vector<RecordingFrame> frames;
  for (int i = 1; i < 218; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "image%04d", i);
    auto frame = ReadGrayImage(dir + "images/" + name + ".png");
    ASSERT_TRUE(frame.ok()) << frame.status().ToString();
    frames.push_back({name, *frame});
  }
  const ModelFromViews build = [&](const std::vector<PosedImage>& views) {
    return builder_.FromPosedPolygons("visp-cube", *faces, views);
  };
  auto learned = LearnFromRecording(build, testing::BundledObjectVocabulary(), first, frames);
  ASSERT_TRUE(learned.ok()) << learned.status().ToString();
  ASSERT_GE(learned->model.views.size(), 3u);
  AddRoboEarthModels();
  ASSERT_TRUE(database_->Put(learned->model).ok());
  ExpectEveryViewRecognised(learned->model);
}

TEST_F(OwnViewsTest, TheVispCastleRgbdModelOfFrameZeroRecognisesFrameZero) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/visp-castle/chateau.0.pos");
  const std::string dir = testing::SharedData("objects/visp-castle/");
  RgbdView view;
  view.view.name = "image_0000";
  auto image = ReadGrayImage(dir + "images/image_0000.png");
  ASSERT_TRUE(image.ok()) << image.status().ToString();
  view.view.image = *image;
  view.view.camera = {615.1674804688, 615.1675415039, 312.1889953613, 243.4373779297, {}};
  auto pose = ReadVispPose(dir + "chateau.0.pos");
  ASSERT_TRUE(pose.ok()) << pose.status().ToString();
  view.view.camera_from_object = *pose;
  view.depth = cv::imread(dir + "depth/depth_image_0000.png", cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(view.depth.empty());
  view.depth_scale = 1.0 / 0.000124986647;
  view.depth_camera = {476.0536193848, 476.0534973145, 311.4845581055, 246.2832336426, {}};
  view.depth_from_color.R = {0.9999922514,    -0.003901827615, -0.000573842437,
                             0.003898504889,  0.9999762774,    -0.005681734998,
                             0.0005959979608, 0.005679453723,  0.9999836683};
  view.depth_from_color.t = {-0.02470519207, 0.0006583171198, -0.003773850389};
  const ObjectBox box{{0.22842, 0.172, 0.2195}, {-0.03566, 0.09276, 0.00875}};
  auto model = builder_.FromRgbd("castle", {view}, box);
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  AddRoboEarthModels();
  ASSERT_TRUE(database_->Put(*model).ok());
  ExpectEveryViewRecognised(*model);
}

// Frames 0 and 33 (the two-view model). With frames 16 and 49 of the first, fiducial
// poses in the model too, their own poses did not come back (frame 16's at 2.0 degrees / 2.1 cm,
// frame 49's wrong): those poses were off (see the next test), so their points were misplaced.
TEST_F(OwnViewsTest, TheVispRbtCubeRgbdModelOfTwoFramesRecognisesEachOfThem) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/visp-rbt-cube/poses.txt");
  auto views = RbtCubeViews({0, 33});
  ASSERT_TRUE(views.ok()) << views.status().ToString();
  ASSERT_EQ(views->size(), 2u);
  auto model = builder_.FromRgbd("rbt-cube", *views, kRbtCubeBox);
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  AddRoboEarthModels();
  ASSERT_TRUE(database_->Put(*model).ok());
  ExpectEveryViewRecognised(*model);
}

// The builder's report tells views whose given pose is off: with the first, fiducial poses
// (poses_fiducial.txt), frames 16 and 49 put most of the cube's depth outside its box (their
// projected outlines lie ~15 px off the cube in the images), frames 0 and 33 do not; with the
// refined poses.txt, which replaced them in the shared data, none does.
TEST_F(OwnViewsTest, TheVispRbtCubeViewsWhoseGivenPoseIsOffAreReported) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/visp-rbt-cube/poses_fiducial.txt");
  for (const char* pose_file : {"poses_fiducial.txt", "poses.txt"}) {
    const bool fiducial = std::string(pose_file) == "poses_fiducial.txt";
    auto views = RbtCubeViews({0, 16, 33, 49}, pose_file);
    ASSERT_TRUE(views.ok()) << views.status().ToString();
    std::vector<RgbdViewReport> report;
    auto model = builder_.FromRgbd("rbt-cube", *views, kRbtCubeBox, &report);
    ASSERT_TRUE(model.ok()) << model.status().ToString();
    ASSERT_EQ(report.size(), 4u);
    for (size_t i = 0; i < report.size(); ++i) {
      EXPECT_EQ(report[i].name, (*views)[i].view.name);
      EXPECT_EQ(report[i].LooksMisposed(), fiducial && (i == 1 || i == 3))
          << pose_file << ", " << report[i].name << ": " << report[i].in_box << " of "
          << report[i].with_depth;
    }
  }
}

}  // namespace
}  // namespace recog::cli
