// PreparedFrame and PreparedRigFrame: a request's frame made ready for a place map with the
// features the given extraction finds, a rig frame's views each with its camera's intrinsics and
// keypoints in its camera's pinhole model, and the rig requests a map refuses.
#include "server/api/prepared_frame.h"

#include <cmath>
#include <cstring>
#include <memory>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "core/index/memory_index_store.h"
#include "core/place/map_registry.h"
#include "core/vocabulary/vocabulary_io.h"

namespace recog::server {
namespace {

constexpr int kWidth = 64, kHeight = 48;
const cv::Matx33d kK(50, 0, 31.5, 0, 50, 23.5, 0, 0, 1);

std::string Png(int width = kWidth, int height = kHeight) {
  std::vector<uchar> bytes;
  EXPECT_TRUE(cv::imencode(".png", cv::Mat(height, width, CV_8UC1, cv::Scalar(90)), bytes));
  return std::string(bytes.begin(), bytes.end());
}

// A feature extraction that records what it was given and finds two keypoints: one on the
// principal point, one 10 pixels right of it and 10 below.
class FakeExtraction {
 public:
  ExtractPlaceFeatures Function() {
    return [this](const cv::Mat& image, FeatureSet* out) {
      sizes_.push_back(image.size());
      out->keypoints = {cv::KeyPoint(31.5f, 23.5f, 7), cv::KeyPoint(41.5f, 33.5f, 7)};
      out->descriptors = cv::Mat(2, 32, CV_8U, cv::Scalar(3));
      return Status::Ok();
    };
  }
  const std::vector<cv::Size>& sizes() const { return sizes_; }

 private:
  std::vector<cv::Size> sizes_;
};

// A single-camera frame prepared for ORB maps with `extraction`, on a budget of its own.
StatusOr<PreparedFrame> Prepare(const pb::Frame& request, FakeExtraction& extraction) {
  PixelBudget budget;
  pb::Timing timing;
  return PreparedFrame::Prepare(request, DescriptorFormat::Orb(), extraction.Function(), budget,
                                &timing);
}

TEST(PreparedFrameTest, AnImageIsExtractedAndAPinholeCameraGivesItsMatrix) {
  pb::Frame request;
  request.set_encoded_image(Png());
  request.mutable_intrinsics()->set_fx(50);
  request.mutable_intrinsics()->set_fy(50);
  request.mutable_intrinsics()->set_cx(31.5);
  request.mutable_intrinsics()->set_cy(23.5);
  FakeExtraction extraction;
  auto prepared = Prepare(request, extraction);
  ASSERT_TRUE(prepared.ok()) << prepared.status().ToString();
  EXPECT_EQ(extraction.sizes(), std::vector<cv::Size>{cv::Size(kWidth, kHeight)});
  EXPECT_EQ(prepared->features().size(), 2u);
  ASSERT_NE(prepared->geometry(), nullptr);
  EXPECT_EQ(prepared->geometry()->K, kK);
  EXPECT_TRUE(prepared->geometry()->points.empty());
}

// A fisheye's keypoints move into the pinhole image of its K, where the loop geometry works: the
// one on the principal point stays, the one 10 px right and below lies at radius θd = 0.283 on
// the normalised plane (no coefficients beyond θ), so at tan(θ) = tan(0.283) there.
TEST(PreparedFrameTest, ALensMovesTheKeypointsIntoThePinholeImageOfItsMatrix) {
  pb::Frame request;
  request.set_encoded_image(Png());
  pb::CameraIntrinsics* intrinsics = request.mutable_intrinsics();
  intrinsics->set_fx(50);
  intrinsics->set_fy(50);
  intrinsics->set_cx(31.5);
  intrinsics->set_cy(23.5);
  intrinsics->set_lens(pb::LENS_MODEL_EQUIDISTANT);
  for (int i = 0; i < 4; ++i) intrinsics->add_distortion(0);
  FakeExtraction extraction;
  auto prepared = Prepare(request, extraction);
  ASSERT_TRUE(prepared.ok()) << prepared.status().ToString();
  ASSERT_NE(prepared->geometry(), nullptr);
  EXPECT_EQ(prepared->geometry()->K, kK);
  const std::vector<cv::KeyPoint>& keypoints = prepared->features().keypoints;
  EXPECT_EQ(keypoints[0].pt, cv::Point2f(31.5f, 23.5f));
  const double theta = std::hypot(10.0, 10.0) / 50.0;
  const double moved = 50.0 * std::tan(theta) / std::sqrt(2.0);  // along each axis
  EXPECT_NEAR(keypoints[1].pt.x, 31.5 + moved, 1e-3);
  EXPECT_NEAR(keypoints[1].pt.y, 23.5 + moved, 1e-3);
}

TEST(PreparedFrameTest, AnUnknownLensOrCoefficientsItDoesNotTakeAreRefused) {
  pb::Frame request;
  request.set_encoded_image(Png());
  pb::CameraIntrinsics* intrinsics = request.mutable_intrinsics();
  intrinsics->set_fx(50);
  intrinsics->set_fy(50);
  intrinsics->set_lens(pb::LensModel(7));
  FakeExtraction extraction;
  auto unknown = Prepare(request, extraction);
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(unknown.status().message().find("frame.intrinsics.lens 7"), std::string::npos)
      << unknown.status().ToString();
  intrinsics->set_lens(pb::LENS_MODEL_DOUBLE_SPHERE);
  for (int i = 0; i < 4; ++i) intrinsics->add_distortion(0.1);
  auto miscounted = Prepare(request, extraction);
  ASSERT_FALSE(miscounted.ok());
  EXPECT_NE(miscounted.status().message().find("frame.intrinsics"), std::string::npos)
      << miscounted.status().ToString();
}

TEST(PreparedFrameTest, ClientFeaturesAreNotExtractedAgainAndNoCameraGivesNoGeometry) {
  pb::Frame request;
  pb::Features* features = request.mutable_features();
  features->set_descriptor_bytes(32);
  for (const float x : {5.0f, 9.0f}) {
    features->mutable_keypoints()->add_x(x);
    features->mutable_keypoints()->add_y(4);
    features->mutable_keypoints()->add_size(7);
    features->mutable_keypoints()->add_angle(-1);
    features->mutable_keypoints()->add_response(1);
    features->mutable_keypoints()->add_octave(0);
  }
  features->set_descriptors(std::string(64, '\x05'));
  FakeExtraction extraction;
  auto prepared = Prepare(request, extraction);
  ASSERT_TRUE(prepared.ok()) << prepared.status().ToString();
  EXPECT_TRUE(extraction.sizes().empty());
  ASSERT_EQ(prepared->features().size(), 2u);
  EXPECT_EQ(prepared->features().keypoints[1].pt, cv::Point2f(9, 4));
  EXPECT_EQ(prepared->geometry(), nullptr);
}

// A rig map of two cameras: `front` a pinhole, `rear` with radial distortion.
class PreparedRigFrameTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto vocabulary =
        LoadVocabulary(std::string(RECOG_SOURCE_DIR) + "/vocabularies/place_orb_k10_l5.rvoc");
    ASSERT_TRUE(vocabulary.ok()) << vocabulary.status().ToString();
    auto registry = MapRegistry::Open(
        &store_, std::make_shared<const Vocabulary>(std::move(vocabulary).value()));
    ASSERT_TRUE(registry.ok()) << registry.status().ToString();
    registry_ = std::move(registry).value();
    RigCamera front;
    front.name = "front";
    front.size = {kWidth, kHeight};
    front.K = kK;
    RigCamera rear = front;
    rear.name = "rear";
    rear.distortion = {-0.3, 0.1, 0, 0};
    rear.body_R_camera = {-1, 0, 0, 0, 1, 0, 0, 0, -1};
    auto map = registry_->Create("rig", LoopDetectorParams{}, "", {front, rear});
    ASSERT_TRUE(map.ok()) << map.status().ToString();
    map_ = std::move(map).value();
  }

  // A request with a view of each camera named, in that order.
  static pb::Frame Request(const std::vector<std::string>& cameras) {
    pb::Frame request;
    request.set_timestamp(12.5);
    request.set_client_frame_id("kf-7");
    request.add_exclude_frame_ids(3);
    for (const std::string& camera : cameras) {
      pb::Frame* view = request.add_views();
      view->set_camera_id(camera);
      view->set_encoded_image(Png());
    }
    return request;
  }

  StatusOr<PreparedRigFrame> Prepare(const pb::Frame& request) {
    PixelBudget budget;
    return PreparedRigFrame::Prepare(request, *map_, extraction_.Function(), budget, &timing_);
  }

  static void ExpectRefused(const StatusOr<PreparedRigFrame>& prepared, const std::string& needle) {
    ASSERT_FALSE(prepared.ok());
    EXPECT_EQ(prepared.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(prepared.status().message().find(needle), std::string::npos)
        << "no '" << needle << "' in: " << prepared.status().ToString();
  }

  MemoryIndexStore store_;
  std::unique_ptr<MapRegistry> registry_;
  std::shared_ptr<PlaceMap> map_;
  FakeExtraction extraction_;
  pb::Timing timing_;
};

TEST_F(PreparedRigFrameTest, ViewsGoToTheirCamerasInRigOrderWithTheFramesIds) {
  auto prepared = Prepare(Request({"rear", "front"}));
  ASSERT_TRUE(prepared.ok()) << prepared.status().ToString();
  const RigFrame& frame = prepared->frame();
  ASSERT_EQ(frame.cameras.size(), 2u);
  EXPECT_EQ(extraction_.sizes().size(), 2u);
  EXPECT_EQ(prepared->features(), 4u);
  EXPECT_EQ(frame.timestamp, 12.5);
  EXPECT_EQ(frame.client_id, "kf-7");
  EXPECT_EQ(prepared->excluded(), std::vector<uint64_t>{3});
  // The pinhole camera's keypoints as found; the distorted camera's moved into its pinhole model
  // (but for the one on the principal point, which distortion does not move).
  EXPECT_EQ(frame.cameras[0].keypoints[1].pt, cv::Point2f(41.5f, 33.5f));
  EXPECT_EQ(frame.cameras[1].keypoints[0].pt, cv::Point2f(31.5f, 23.5f));
  EXPECT_GT(cv::norm(frame.cameras[1].keypoints[1].pt - cv::Point2f(41.5f, 33.5f)), 0.01);
}

// A view's depth becomes 3D points with its camera's matrix: the keypoint 10 pixels right of the
// principal point at 2 m, with fx = 50, is 0.4 m to the right.
TEST_F(PreparedRigFrameTest, AViewsDepthGivesPointsWithItsCamerasMatrix) {
  pb::Frame request = Request({"front", "rear"});
  pb::RawDepth* depth = request.mutable_views(0)->mutable_depth()->mutable_raw();
  depth->set_width(kWidth);
  depth->set_height(kHeight);
  depth->set_format(pb::DEPTH_FORMAT_F32);
  const cv::Mat metres(kHeight, kWidth, CV_32F, cv::Scalar(2.0f));
  depth->set_data(std::string(reinterpret_cast<const char*>(metres.data), metres.total() * 4));
  auto prepared = Prepare(request);
  ASSERT_TRUE(prepared.ok()) << prepared.status().ToString();
  const RigFrame& frame = prepared->frame();
  ASSERT_EQ(frame.points.size(), 2u);
  ASSERT_EQ(frame.points[0].size(), 2u);
  EXPECT_NEAR(frame.points[0][1].x, 0.4, 1e-6);
  EXPECT_NEAR(frame.points[0][1].y, 0.4, 1e-6);
  EXPECT_NEAR(frame.points[0][1].z, 2.0, 1e-6);
  EXPECT_TRUE(frame.points[1].empty());
}

TEST_F(PreparedRigFrameTest, RequestsThatDoNotFitTheRigAreRefusedNamingWhy) {
  ExpectRefused(Prepare(Request({"front", "side"})), "camera 'side', which the rig");
  ExpectRefused(Prepare(Request({"front", "front"})), "camera 'front' has two views");
  ExpectRefused(Prepare(Request({"rear"})), "no view for camera 'front'");
  pb::Frame own_image = Request({"front", "rear"});
  own_image.set_encoded_image(Png());
  ExpectRefused(Prepare(own_image), "is a rig map");
  pb::Frame view_intrinsics = Request({"front", "rear"});
  view_intrinsics.mutable_views(1)->mutable_intrinsics()->set_fx(50);
  ExpectRefused(Prepare(view_intrinsics), "intrinsics to the map's rig");
  pb::Frame small = Request({"front", "rear"});
  small.mutable_views(1)->set_encoded_image(Png(32, 24));
  ExpectRefused(Prepare(small), "rig camera 'rear'");
  ExpectRefused(Prepare(small), "its image is 32x24; the camera's are 64x48");
}

}  // namespace
}  // namespace recog::server
