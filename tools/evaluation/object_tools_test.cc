// The object evaluation's image transforms and the ViSP file readers.
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/index/memory_index_store.h"
#include "core/object/recognition/object_database.h"
#include "core/object/recognition/object_recognizer.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tests/testing/recognizers.h"
#include "tests/testing/test_data.h"
#include "tests/testing/vocabularies.h"
#include "tools/evaluation/object_evaluation.h"
#include "tools/evaluation/visp_files.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

// Where the transformed camera sees an object point must be where the transformed image moved
// the original pixel.
TEST(ObjectEvaluationTest, TransformedCamerasSeeThePointsWhereTheImageMovedThem) {
  const cv::Point3d x(0.1, -0.05, 0.02);
  for (ImageTransform transform :
       {ImageTransform::kHalfScale, ImageTransform::kRotate90, ImageTransform::kRotate180}) {
    cv::Mat image(480, 640, CV_8U, cv::Scalar(0));
    CameraIntrinsics camera{600, 600, 320, 240, {}};
    RigidTransform pose;
    cv::Rodrigues(cv::Vec3d(0.2, -0.1, 0.3), pose.R);
    pose.t = {0.01, 0.02, 1.0};
    cv::Point2d before, after;
    ASSERT_TRUE(ProjectPoint(camera, pose, x, &before));
    TransformView(transform, &image, &camera, &pose);
    ASSERT_TRUE(ProjectPoint(camera, pose, x, &after));
    cv::Point2d expected;
    switch (transform) {
      case ImageTransform::kHalfScale:
        EXPECT_EQ(image.size(), cv::Size(320, 240));
        expected = {(before.x + 0.5) / 2 - 0.5, (before.y + 0.5) / 2 - 0.5};
        break;
      case ImageTransform::kRotate90:
        EXPECT_EQ(image.size(), cv::Size(480, 640));
        expected = {479 - before.y, before.x};
        break;
      default:
        expected = {639 - before.x, 479 - before.y};
    }
    EXPECT_NEAR(after.x, expected.x, 1e-9) << ImageTransformName(transform);
    EXPECT_NEAR(after.y, expected.y, 1e-9) << ImageTransformName(transform);
  }
}

TEST(ObjectEvaluationTest, ImageTransformsParseByName) {
  EXPECT_EQ(ParseImageTransform("rot45").status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(*ParseImageTransform("scale0.5"), ImageTransform::kHalfScale);
}

class VispFilesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("recog_visp_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Write(const std::string& name, const std::string& text) {
    std::ofstream(dir_ / name) << text;
    return (dir_ / name).string();
  }
  fs::path dir_;
};

TEST_F(VispFilesTest, ReadsFacesFromPointsAndAPose) {
  const std::string cao = Write("square.cao",
                                "V1\n# points\n4\n0 0 0\n1 0 0 # a comment\n1 1 0\n0 1 0\n"
                                "0\n0\n1\n4 0 1 2 3\n0\n0\n");
  auto faces = ReadCaoFaces(cao);
  ASSERT_TRUE(faces.ok()) << faces.status().ToString();
  ASSERT_EQ(faces->size(), 1u);
  EXPECT_EQ((*faces)[0].corners[2], cv::Point3d(1, 1, 0));
  auto pose = ReadVispPose(Write("p.pos", "0.1 0.2 0.5\n0 0 1.5707963267948966\n"));
  ASSERT_TRUE(pose.ok());
  EXPECT_NEAR(pose->R(0, 1), -1.0, 1e-9);  // 90 degrees about z
  EXPECT_EQ(pose->t, cv::Vec3d(0.1, 0.2, 0.5));
}

TEST_F(VispFilesTest, MalformedFilesAreRejected) {
  EXPECT_EQ(ReadCaoFaces((dir_ / "missing.cao").string()).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(ReadCaoFaces(Write("a.cao", "V2\n")).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadCaoFaces(Write("b.cao", "V1\n2\n0 0 0\n1 0 0\n0\n0\n1\n3 0 1 7\n")).status().code(),
            StatusCode::kInvalidArgument);  // corner 7 does not exist
  EXPECT_EQ(ReadCaoFaces(Write("c.cao", "V1\n1\n0 0 x\n")).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadVispPose(Write("d.pos", "1 2 3\n")).status().code(), StatusCode::kInvalidArgument);
}

TEST(VispFilesSharedDataTest, ReadsTheVispCube) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/visp-cube/cube.cao");
  auto faces = ReadCaoFaces(testing::SharedData("objects/visp-cube/cube.cao"));
  ASSERT_TRUE(faces.ok()) << faces.status().ToString();
  EXPECT_EQ(faces->size(), 6u);
  auto pose = ReadVispPose(testing::SharedData("objects/visp-cube/cube.0.pos"));
  ASSERT_TRUE(pose.ok());
  EXPECT_NEAR(pose->t[2], 0.5071128378, 1e-12);
}

TEST(ObjectEvaluationTest, MethodsHaveNames) {
  EXPECT_EQ(*ParseObjectEvaluationMethod("independent-views"),
            ObjectEvaluationMethod::kIndependentViews);
  EXPECT_EQ(ObjectEvaluationMethodName(ObjectEvaluationMethod::kMerged), "merged");
  EXPECT_EQ(ParseObjectEvaluationMethod("views").status().code(), StatusCode::kInvalidArgument);
}

// Leave-one-view-out on two RoboEarth folders (bio: 3D, 5 views; bottle1: planar, 1 view), as is
// only, with each way of filling the database.
class ObjectEvaluationSharedDataTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!testing::HasSharedData("objects/roboearth/models/bio/meta.xml")) return;
    root_ = fs::temp_directory_path() / ("recog_eval_objects_" + std::to_string(::getpid()));
    fs::create_directories(root_);
    for (const char* name : {"bio", "bottle1"}) {
      fs::create_directory_symlink(testing::SharedData("objects/roboearth/models/") + name,
                                   root_ / name);
    }
  }
  void TearDown() override {
    if (!root_.empty()) fs::remove_all(root_);
  }
  StatusOr<ObjectEvaluation> Evaluate(ObjectEvaluationMethod method) const {
    ObjectEvaluationOptions options;
    options.roboearth_dir = root_.string();
    options.vocabulary_path = DefaultObjectVocabularyPath();
    options.method = method;
    options.transforms = {ImageTransform::kNone};
    return EvaluateObjects(options);
  }
  fs::path root_;
};

// What holds for either method: one query per view of bio (the only 3D object with 5 views), and
// counts that agree with the queries.
void ExpectConsistent(const ObjectEvaluation& e) {
  ASSERT_EQ(e.queries.size(), 5u);
  ASSERT_EQ(e.summaries.size(), 1u);
  const ObjectEvaluationSummary& s = e.summaries[0];
  EXPECT_EQ(s.queries, 5u);
  size_t detected = 0, wrong = 0;
  for (size_t i = 0; i < e.queries.size(); ++i) {
    const ObjectQuery& q = e.queries[i];
    EXPECT_EQ(q.object, "bio");
    EXPECT_EQ(q.view, int(i));
    detected += q.detected;
    wrong += q.wrong.size();
    for (const std::string& w : q.wrong) EXPECT_EQ(w, "bottle1");
    if (q.detected) {
      EXPECT_EQ(e.objects.at(q.matched), "bio");
      EXPECT_GE(q.inliers, 6u);
    } else {
      EXPECT_TRUE(q.matched.empty());
    }
  }
  EXPECT_EQ(s.detections, detected);
  EXPECT_EQ(s.wrong_detections, wrong);
  EXPECT_DOUBLE_EQ(s.detection_rate, double(detected) / 5.0);
}

TEST_F(ObjectEvaluationSharedDataTest, MergedModelsAreOnePerFolder) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/roboearth/models/bio/meta.xml");
  auto e = Evaluate(ObjectEvaluationMethod::kMerged);
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  EXPECT_EQ(e->database, (std::vector<std::string>{"bio", "bottle1"}));
  EXPECT_TRUE(e->skipped_views.empty());
  ExpectConsistent(*e);
  for (const ObjectQuery& q : e->queries) {
    if (q.detected) {
      EXPECT_EQ(q.matched, "bio");
    }
  }
}

TEST_F(ObjectEvaluationSharedDataTest,
       IndependentViewsAreOneEntryPerViewAndTheHeldOutOneIsLeftOut) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/roboearth/models/bio/meta.xml");
  auto e = Evaluate(ObjectEvaluationMethod::kIndependentViews);
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  EXPECT_EQ(e->method, ObjectEvaluationMethod::kIndependentViews);
  EXPECT_EQ(e->database,
            (std::vector<std::string>{"bio.face_000", "bio.face_001", "bio.face_002",
                                      "bio.face_003", "bio.face_004", "bottle1.face_000"}));
  EXPECT_EQ(e->objects.at("bio.face_003"), "bio");
  EXPECT_EQ(e->objects.at("bottle1.face_000"), "bottle1");
  ExpectConsistent(*e);
  size_t detected = 0;
  for (const ObjectQuery& q : e->queries) {
    if (!q.detected) continue;
    ++detected;
    char held_out[32];
    std::snprintf(held_out, sizeof(held_out), "bio.face_%03d", q.view);
    EXPECT_NE(q.matched, held_out) << "the held-out view must not be in the database";
  }
  // Neighbouring views of the pack overlap: most held-out views are found through another one.
  EXPECT_GE(detected, 3u);
}

// The CAD builder detects inside the projected faces (cropped, enlarged): far more points on the
// cube than the 598 a whole-frame detection left on it.
TEST(VispFilesSharedDataTest, TheVispCubeModelHoldsManyPoints) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/visp-cube/cube.cao");
  auto faces = ReadCaoFaces(testing::SharedData("objects/visp-cube/cube.cao"));
  auto pose = ReadVispPose(testing::SharedData("objects/visp-cube/cube.0.pos"));
  ASSERT_TRUE(faces.ok() && pose.ok());
  auto image = ReadGrayImage(testing::SharedData("objects/visp-cube/images/image0000.png"));
  ASSERT_TRUE(image.ok()) << image.status().ToString();
  ModelBuildOptions options;
  options.keep_images = false;
  auto model = ModelBuilder(testing::BundledObjectVocabulary(), options)
                   .FromPosedPolygons("visp-cube", *faces,
                                      {{"image0000", *image, {547, 547, 338, 234, {}}, *pose}});
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  EXPECT_GT(model->points.size(), 900u);  // 1,016 when written
}

// A real RGB-D recording (SR300, depth from its own camera): a model from frame 0 with the box of
// the CAD model holds the castle, has its size, and recognises it in the other frames.
TEST(VispFilesSharedDataTest, AnRgbdModelOfTheVispCastleRecognisesIt) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("objects/visp-castle/chateau.0.pos");
  const std::string dir = testing::SharedData("objects/visp-castle");
  // The CAD model's extent (its parts, metres) is the object's box.
  cv::Vec3d low(1e9, 1e9, 1e9), high(-1e9, -1e9, -1e9);
  for (const char* part : {"floor", "tower", "front_door", "slope"}) {
    auto faces = ReadCaoFaces(dir + "/chateau_parts/chateau_" + part + ".cao");
    ASSERT_TRUE(faces.ok()) << faces.status().ToString();
    for (const FacePolygon& face : *faces) {
      for (const cv::Point3d& c : face.corners) {
        low = {std::min(low[0], c.x), std::min(low[1], c.y), std::min(low[2], c.z)};
        high = {std::max(high[0], c.x), std::max(high[1], c.y), std::max(high[2], c.z)};
      }
    }
  }
  const ObjectBox box{high - low, (high + low) / 2};
  // camera.txt
  const CameraIntrinsics color{615.1674804688, 615.1675415039, 312.1889953613, 243.4373779297, {}};
  RgbdView view;
  view.view.name = "image_0000";
  view.view.camera = color;
  auto pose = ReadVispPose(dir + "/chateau.0.pos");
  auto image = ReadGrayImage(dir + "/images/image_0000.png");
  ASSERT_TRUE(pose.ok() && image.ok());
  view.view.camera_from_object = *pose;
  view.view.image = *image;
  view.depth = cv::imread(dir + "/depth/depth_image_0000.png", cv::IMREAD_ANYDEPTH);
  ASSERT_EQ(view.depth.type(), CV_16U);
  view.depth_scale = 1 / 0.000124986647;
  view.depth_camera = {476.0536193848, 476.0534973145, 311.4845581055, 246.2832336426, {}};
  view.depth_from_color.R = {0.9999922514,    -0.003901827615, -0.000573842437,
                             0.003898504889,  0.9999762774,    -0.005681734998,
                             0.0005959979608, 0.005679453723,  0.9999836683};
  view.depth_from_color.t = {-0.02470519207, 0.0006583171198, -0.003773850389};
  ModelBuildOptions options;
  options.keep_images = false;
  auto model =
      ModelBuilder(testing::BundledObjectVocabulary(), options).FromRgbd("castle", {view}, box);
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  EXPECT_GT(model->points.size(), 500u);  // 686 when written
  // Frame 0 sees the front and the top: the depth behind is partly hidden (0.173 of 0.2195 m).
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(model->metadata.dimensions[k], box.size[k], 0.25 * box.size[k]) << "axis " << k;
  }

  MemoryIndexStore store;
  auto database = ObjectDatabase::Open(&store, testing::BundledObjectVocabulary());
  ASSERT_TRUE(database.ok());
  ASSERT_TRUE((*database)->Put(*model).ok());
  ObjectRecognizer recognizer =
      testing::MakeRecognizer(std::shared_ptr<const ObjectDatabase>(std::move(*database)));
  int found = 0;
  for (int frame = 1; frame < 30; ++frame) {
    char name[64];
    std::snprintf(name, sizeof(name), "/images/image_%04d.png", frame);
    auto query = ReadGrayImage(dir + name);
    ASSERT_TRUE(query.ok());
    std::vector<Detection> detections;
    ASSERT_TRUE(recognizer.Recognize(*query, color, &detections).ok());
    found += !detections.empty() && detections[0].name == "castle";
  }
  EXPECT_GE(found, 26) << found;  // 29 of 29 when written
}

}  // namespace
}  // namespace recog::cli
