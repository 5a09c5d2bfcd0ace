// ModelBuilder on synthetic RGB-D scenes: a textured 0.4 x 0.3 m plane 1 m in front of the camera
// (the object frame at its centre) over an untextured background 2 m away.
#include <cmath>
#include <memory>

#include <gtest/gtest.h>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/object/builder/model_builder.h"
#include "tests/testing/test_data.h"
#include "tests/testing/vocabularies.h"

namespace recog {
namespace {

constexpr double kWidth = 0.4, kHeight = 0.3, kBackground = 2.0;
const CameraIntrinsics kCamera{500, 500, 320, 240, {}};

// A view of the plane from a camera at `t` (T_camera<-object = [I | t]), its registered depth
// (CV_32F metres) and the exact mask of the plane.
RgbdView PlaneView(const std::string& name, const cv::Vec3d& t) {
  const cv::Mat poster =
      cv::imread(testing::ProjectTestData("corridor/1.jpg"), cv::IMREAD_GRAYSCALE);
  const cv::Matx33d object_from_pixels(kWidth / poster.cols, 0, t[0] - kWidth / 2, 0,
                                       kHeight / poster.rows, t[1] - kHeight / 2, 0, 0, t[2]);
  const cv::Mat warp(kCamera.K() * object_from_pixels);
  RgbdView view;
  view.view.name = name;
  view.view.camera = kCamera;
  view.view.camera_from_object.t = t;
  cv::warpPerspective(poster, view.view.image, warp, cv::Size(640, 480), cv::INTER_LINEAR,
                      cv::BORDER_CONSTANT, 90);
  cv::warpPerspective(cv::Mat(poster.size(), CV_8U, cv::Scalar(255)), view.mask, warp,
                      cv::Size(640, 480), cv::INTER_NEAREST, cv::BORDER_CONSTANT, 0);
  view.depth = cv::Mat(480, 640, CV_32F, cv::Scalar(kBackground));
  view.depth.setTo(float(t[2]), view.mask);
  return view;
}

ModelBuildOptions NoImages() {
  ModelBuildOptions options;
  options.keep_images = false;
  return options;
}

// Points on the plane (object z = 0) and within it.
int PointsOffThePlane(const ObjectModel& model) {
  int off = 0;
  for (const cv::Point3f& p : model.points) {
    off += std::abs(p.z) > 2e-3 || std::abs(p.x) > kWidth / 2 + 5e-3 ||
           std::abs(p.y) > kHeight / 2 + 5e-3;
  }
  return off;
}

TEST(RgbdModelBuilderTest, MaskedFeaturesLieOnTheObjectAndGiveItsDimensions) {
  ModelBuilder builder(testing::BundledObjectVocabulary(), NoImages());
  auto model = builder.FromRgbd("plane", {PlaneView("front", {0, 0, 1})});
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  EXPECT_GT(model->points.size(), 300u);
  EXPECT_EQ(PointsOffThePlane(*model), 0);
  EXPECT_NEAR(model->metadata.dimensions[0], kWidth, 0.1 * kWidth);
  EXPECT_NEAR(model->metadata.dimensions[1], kHeight, 0.1 * kHeight);
  EXPECT_LT(model->metadata.dimensions[2], 0.005);
}

// An object covering 4 % of the frame (the plane at 1.56 m): the model holds at least as many
// points as ORB finds on the object when the mask is given to its detector (2000 features, 8
// levels, the builder's own ORB settings) -- and far more than whole-frame detection would leave.
TEST(RgbdModelBuilderTest, ASmallObjectsModelHoldsWhatAMaskedDetectorFindsOnIt) {
  const RgbdView view = PlaneView("far", {0, 0, 1.56});
  const double coverage = cv::countNonZero(view.mask) / double(view.mask.total());
  ASSERT_NEAR(coverage, 0.04, 0.005);
  const OrbOptions orb = ModelBuildOptions::DefaultModelOrb();
  std::vector<cv::KeyPoint> masked;
  cv::ORB::create(orb.max_features, orb.scale_factor, orb.levels)
      ->detect(view.view.image, masked, view.mask);
  ModelBuilder builder(testing::BundledObjectVocabulary(), NoImages());
  auto model = builder.FromRgbd("plane", {view});
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  std::printf("object at %.1f %% of the frame: masked ORB %zu keypoints, model %zu points\n",
              100 * coverage, masked.size(), model->points.size());
  EXPECT_GE(model->points.size(), masked.size());
  EXPECT_EQ(PointsOffThePlane(*model), 0);
}

TEST(RgbdModelBuilderTest, PointsAtDepthDiscontinuitiesAreRejected) {
  // Depth and mask 2 px out of step (as a sensor's depth edges are): keypoints along the plane's
  // border see the background's depth. With the robust extent switched off, only the
  // discontinuity test keeps them out.
  RgbdView view = PlaneView("loose", {0, 0, 1});
  cv::Mat plane_depth;
  cv::erode(view.mask, plane_depth, cv::Mat::ones(5, 5, CV_8U));
  view.depth.setTo(kBackground);
  view.depth.setTo(1.0, plane_depth);
  ModelBuildOptions options = NoImages();
  options.outlier_mads = 0;
  auto model = ModelBuilder(testing::BundledObjectVocabulary(), options).FromRgbd("plane", {view});
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  EXPECT_EQ(PointsOffThePlane(*model), 0);
  options.discontinuity_ratio = 1e9;  // the control: without the test, edge points get in
  auto loose = ModelBuilder(testing::BundledObjectVocabulary(), options).FromRgbd("plane", {view});
  ASSERT_TRUE(loose.ok()) << loose.status().ToString();
  EXPECT_GT(PointsOffThePlane(*loose), 0);
}

TEST(RgbdModelBuilderTest, PointsSeenInSeveralViewsAreMerged) {
  ModelBuilder builder(testing::BundledObjectVocabulary(), NoImages());
  const RgbdView a = PlaneView("a", {0, 0, 1}), b = PlaneView("b", {0.03, -0.02, 1.05});
  auto only_a = builder.FromRgbd("plane", {a});
  auto only_b = builder.FromRgbd("plane", {b});
  auto both = builder.FromRgbd("plane", {a, b});
  ASSERT_TRUE(only_a.ok() && only_b.ok() && both.ok()) << both.status().ToString();
  const size_t sum = only_a->points.size() + only_b->points.size();
  EXPECT_LT(both->points.size(), sum * 8 / 10);
  EXPECT_GT(both->points.size(), std::max(only_a->points.size(), only_b->points.size()));
  EXPECT_LT(both->num_features(), only_a->num_features() + only_b->num_features());
  EXPECT_GT(both->num_features(), both->points.size());  // merged points keep several words
  EXPECT_EQ(PointsOffThePlane(*both), 0);
  EXPECT_EQ(both->views.size(), 2u);
}

TEST(RgbdModelBuilderTest, AViewOrAModelWithoutPointsIsRefused) {
  ModelBuilder builder(testing::BundledObjectVocabulary(), NoImages());
  RgbdView black = PlaneView("blackview", {0, 0, 1});
  black.mask.setTo(0);
  auto model = builder.FromRgbd("plane", {PlaneView("good", {0, 0, 1}), black});
  ASSERT_EQ(model.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(model.status().message().find("'blackview'"), std::string::npos)
      << model.status().ToString();
  RgbdView no_depth = PlaneView("nodepth", {0, 0, 1});
  no_depth.depth.setTo(0);
  EXPECT_EQ(builder.FromRgbd("plane", {no_depth}).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(builder.FromRgbd("plane", {PlaneView("front", {0, 0, 1})}, ObjectBox{{0, 0.3, 0.1}})
                .status()
                .code(),
            StatusCode::kInvalidArgument);
}

TEST(RgbdModelBuilderTest, ABoxInsteadOfMasksKeepsThePointsInside) {
  ModelBuilder builder(testing::BundledObjectVocabulary(), NoImages());
  RgbdView view = PlaneView("front", {0, 0, 1});
  const size_t masked = builder.FromRgbd("plane", {view})->points.size();
  view.mask.release();
  ObjectBox box;
  box.size = {kWidth, kHeight, 0.02};
  auto model = builder.FromRgbd("plane", {view}, box);
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  EXPECT_GT(model->points.size(), masked * 8 / 10);
  EXPECT_EQ(PointsOffThePlane(*model), 0);
  // The box placed beside the plane: nothing of the plane is in it.
  box.centre = {1.0, 0, 0};
  EXPECT_EQ(builder.FromRgbd("plane", {view}, box).status().code(), StatusCode::kInvalidArgument);
}

TEST(RgbdModelBuilderTest, DepthFromItsOwnCameraIsRegisteredToTheColourImage) {
  // The depth camera sits 2.5 cm to the colour camera's left (X_depth = X_colour + 0.025 x)
  // with other intrinsics and a smaller image.
  const RgbdView registered = PlaneView("front", {0, 0, 1});
  RgbdView own = registered;
  own.depth_camera = {400, 410, 200, 150, {}};
  own.depth_from_color.t = {0.025, 0, 0};
  own.depth = cv::Mat(300, 400, CV_16U);
  own.depth_scale = 1000;
  for (int v = 0; v < own.depth.rows; ++v) {
    for (int u = 0; u < own.depth.cols; ++u) {
      // Where this depth ray meets the plane z = 1 m, in the colour (= object) frame.
      const double x = (u - 200) / 400.0 - 0.025, y = (v - 150) / 410.0;
      const bool on_plane = std::abs(x) <= kWidth / 2 && std::abs(y) <= kHeight / 2;
      own.depth.at<uint16_t>(v, u) = uint16_t(on_plane ? 1000 : 1000 * kBackground);
    }
  }
  ModelBuilder builder(testing::BundledObjectVocabulary(), NoImages());
  auto reference = builder.FromRgbd("plane", {registered});
  auto model = builder.FromRgbd("plane", {own});
  ASSERT_TRUE(reference.ok() && model.ok()) << model.status().ToString();
  EXPECT_EQ(PointsOffThePlane(*model), 0);
  EXPECT_NEAR(double(model->points.size()), double(reference->points.size()),
              0.05 * double(reference->points.size()));
  // Without the extrinsic the same depth lands 2.5 cm (about 12 px) off the plane's edges.
  own.depth_from_color.t = {0, 0, 0};
  ModelBuildOptions options = NoImages();
  options.outlier_mads = 0;
  options.discontinuity_ratio = 1e9;
  auto shifted = ModelBuilder(testing::BundledObjectVocabulary(), options).FromRgbd("plane", {own});
  ASSERT_TRUE(shifted.ok()) << shifted.status().ToString();
  EXPECT_GT(PointsOffThePlane(*shifted), 0);
}

}  // namespace
}  // namespace recog
