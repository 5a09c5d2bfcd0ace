// Tests of the frame helpers: client-side ORB features equal to the server's (core's extractor
// with PlaceFeatureOptions()), feature frames, encoded files and raw pixels.
#include <cstring>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "client/cpp/frames.h"
#include "core/features/feature_extractor.h"
#include "tests/testing/data_paths.h"

namespace recog::client {
namespace {

const std::string kCorridor1 = recog::testing::ProjectTestData("corridor/1.jpg");

// What the server extracts from `image` for a place map.
FeatureSet ServerFeatures(const cv::Mat& image) {
  auto extractor = CreateFeatureExtractor(PlaceFeatureOptions());
  EXPECT_TRUE(extractor.ok());
  FeatureSet features;
  EXPECT_TRUE(extractor.value()->Extract(image, &features).ok());
  return features;
}

void ExpectSameFeatures(const OrbFeatures& client, const FeatureSet& server) {
  ASSERT_EQ(client.keypoints.size(), server.keypoints.size());
  for (size_t i = 0; i < client.keypoints.size(); ++i) {
    const cv::KeyPoint& a = client.keypoints[i];
    const cv::KeyPoint& b = server.keypoints[i];
    ASSERT_TRUE(a.pt == b.pt && a.size == b.size && a.angle == b.angle &&
                a.response == b.response && a.octave == b.octave)
        << "keypoint " << i;
  }
  ASSERT_EQ(client.descriptors.type(), server.descriptors.type());
  ASSERT_EQ(client.descriptors.size(), server.descriptors.size());
  EXPECT_EQ(
      std::memcmp(client.descriptors.data, server.descriptors.data, client.descriptors.total()), 0);
}

TEST(FramesTest, ClientOrbFeaturesEqualTheServersOnACorridorImage) {
  const cv::Mat grey = cv::imread(kCorridor1, cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(grey.empty());
  Result<OrbFeatures> features = ExtractOrbFeatures(grey);
  ASSERT_TRUE(features.ok()) << features.status().error_message();
  EXPECT_GT(features->keypoints.size(), 300u);
  EXPECT_LE(features->keypoints.size(), 1000u);
  ExpectSameFeatures(*features, ServerFeatures(grey));

  // Colour images are converted to grey as the server converts raw BGR frames.
  const cv::Mat colour = cv::imread(kCorridor1, cv::IMREAD_COLOR);
  Result<OrbFeatures> from_colour = ExtractOrbFeatures(colour);
  ASSERT_TRUE(from_colour.ok());
  ExpectSameFeatures(*from_colour, ServerFeatures(colour));
}

TEST(FramesTest, ClientOrbFeaturesEqualTheServersOnASmallFrameEnlargedBeforeOrb) {
  const cv::Mat grey = cv::imread(kCorridor1, cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(grey.empty());
  cv::Mat small;
  cv::resize(grey, small, cv::Size(160, 120), 0, 0, cv::INTER_AREA);
  Result<OrbFeatures> features = ExtractOrbFeatures(small);
  ASSERT_TRUE(features.ok()) << features.status().error_message();
  EXPECT_GT(features->keypoints.size(), 200u) << "the enlarged frame has corners";
  for (const cv::KeyPoint& kp : features->keypoints) {
    ASSERT_TRUE(kp.pt.x >= 0 && kp.pt.x <= 159 && kp.pt.y >= 0 && kp.pt.y <= 119)
        << "keypoints are in the frame's own pixels: " << kp.pt;
  }
  ExpectSameFeatures(*features, ServerFeatures(small));
}

TEST(FramesTest, AnImageTooSmallForFeaturesHasNoneAndABadImageIsRefused) {
  Result<OrbFeatures> none = ExtractOrbFeatures(cv::Mat(12, 12, CV_8UC1, cv::Scalar(7)));
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(none->keypoints.empty());
  EXPECT_EQ(none->descriptors.cols, 32);
  EXPECT_EQ(ExtractOrbFeatures(cv::Mat()).status().error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(ExtractOrbFeatures(cv::Mat(64, 64, CV_32FC1)).status().error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
}

TEST(FramesTest, AFeaturesFrameCarriesEveryKeypointAndDescriptorInOrder) {
  const cv::Mat grey = cv::imread(kCorridor1, cv::IMREAD_GRAYSCALE);
  Result<OrbFeatures> features = ExtractOrbFeatures(grey);
  ASSERT_TRUE(features.ok());
  Result<pb::Frame> frame =
      FrameFromFeatures(features->keypoints, features->descriptors, grey.size());
  ASSERT_TRUE(frame.ok()) << frame.status().error_message();
  const pb::Features& sent = frame->features();
  const pb::Keypoints& k = sent.keypoints();
  const size_t n = features->keypoints.size();
  for (int size : {k.x_size(), k.y_size(), k.size_size(), k.angle_size(), k.response_size(),
                   k.octave_size()}) {
    ASSERT_EQ(size_t(size), n);
  }
  EXPECT_EQ(sent.descriptor_bytes(), 32u);
  EXPECT_EQ(sent.image_width(), uint32_t(grey.cols));
  EXPECT_EQ(sent.image_height(), uint32_t(grey.rows));
  const cv::KeyPoint& last = features->keypoints.back();
  const int i = int(n) - 1;
  EXPECT_EQ(k.x(i), last.pt.x);
  EXPECT_EQ(k.y(i), last.pt.y);
  EXPECT_EQ(k.size(i), last.size);
  EXPECT_EQ(k.angle(i), last.angle);
  EXPECT_EQ(k.response(i), last.response);
  EXPECT_EQ(k.octave(i), last.octave);
  ASSERT_EQ(sent.descriptors().size(), features->keypoints.size() * 32);
  EXPECT_EQ(
      std::memcmp(sent.descriptors().data(), features->descriptors.data, sent.descriptors().size()),
      0);

  std::vector<cv::KeyPoint> one_less(features->keypoints.begin() + 1, features->keypoints.end());
  EXPECT_EQ(FrameFromFeatures(one_less, features->descriptors).status().error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  cv::Mat floats;
  features->descriptors.convertTo(floats, CV_32F);
  EXPECT_EQ(FrameFromFeatures(features->keypoints, floats).status().error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
}

TEST(FramesTest, EncodedFilesAreSentAsTheyAreAndOtherFilesAreRefused) {
  Result<pb::Frame> frame = FrameFromEncodedFile(kCorridor1);
  ASSERT_TRUE(frame.ok()) << frame.status().error_message();
  std::ifstream in(kCorridor1, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(frame->encoded_image(), bytes);

  EXPECT_EQ(FrameFromEncodedFile(kCorridor1 + ".missing").status().error_code(),
            grpc::StatusCode::NOT_FOUND);
  const std::string text =
      (std::filesystem::temp_directory_path() / "recog_client_not_an_image.txt").string();
  std::ofstream(text) << "hello";
  EXPECT_EQ(FrameFromEncodedFile(text).status().error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  std::filesystem::remove(text);
}

TEST(FramesTest, RawImagesAreSentRowByRowWithoutPadding) {
  const cv::Mat colour = cv::imread(kCorridor1, cv::IMREAD_COLOR);
  const cv::Mat window = colour(cv::Rect(10, 20, 100, 50));  // not continuous
  ASSERT_FALSE(window.isContinuous());
  Result<pb::Frame> frame = FrameFromImage(window);
  ASSERT_TRUE(frame.ok());
  const pb::RawImage& raw = frame->raw_image();
  EXPECT_EQ(raw.format(), pb::PIXEL_FORMAT_BGR8);
  EXPECT_EQ(raw.width(), 100u);
  EXPECT_EQ(raw.height(), 50u);
  const cv::Mat packed = window.clone();
  ASSERT_EQ(raw.pixels().size(), packed.total() * 3);
  EXPECT_EQ(std::memcmp(raw.pixels().data(), packed.data, raw.pixels().size()), 0);

  Result<pb::Frame> grey = FrameFromImage(cv::Mat(4, 6, CV_8UC1, cv::Scalar(9)));
  ASSERT_TRUE(grey.ok());
  EXPECT_EQ(grey->raw_image().format(), pb::PIXEL_FORMAT_GRAY8);
  EXPECT_EQ(grey->raw_image().pixels(), std::string(24, '\x09'));
  EXPECT_EQ(FrameFromImage(cv::Mat(4, 6, CV_16UC1)).status().error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(FrameFromImage(cv::Mat()).status().error_code(), grpc::StatusCode::INVALID_ARGUMENT);
}

TEST(FramesTest, DepthAndRightImagesAreAttachedRawAndBadOnesAreRefused) {
  pb::Frame frame = FrameFromImage(cv::Mat(2, 3, CV_8UC1, cv::Scalar(9))).value();
  cv::Mat depth_mm(2, 3, CV_16UC1);
  for (int i = 0; i < 6; ++i) depth_mm.at<uint16_t>(i / 3, i % 3) = uint16_t(1000 + i);
  ASSERT_TRUE(AttachDepth(depth_mm(cv::Rect(0, 0, 2, 2)), 5000, &frame).ok());  // a strided view
  ASSERT_EQ(frame.depth().raw().format(), pb::DEPTH_FORMAT_U16);
  EXPECT_EQ(frame.depth().raw().width(), 2u);
  EXPECT_EQ(frame.depth().raw().height(), 2u);
  EXPECT_EQ(frame.depth().scale(), 5000.0);
  const std::string& bytes = frame.depth().raw().data();
  ASSERT_EQ(bytes.size(), 8u);
  uint16_t values[4];
  std::memcpy(values, bytes.data(), 8);
  EXPECT_EQ(values[0], 1000);
  EXPECT_EQ(values[1], 1001);
  EXPECT_EQ(values[2], 1003);  // the second row, without the view's padding
  EXPECT_EQ(values[3], 1004);

  const cv::Mat metres(2, 3, CV_32FC1, cv::Scalar(1.5f));
  ASSERT_TRUE(AttachDepth(metres, 1000, &frame).ok());
  EXPECT_EQ(frame.depth().raw().format(), pb::DEPTH_FORMAT_F32);
  EXPECT_EQ(frame.depth().raw().data().size(), 24u);
  EXPECT_EQ(frame.depth().scale(), 0.0);  // floats are metres

  ASSERT_TRUE(AttachStereoRight(cv::Mat(2, 3, CV_8UC1, cv::Scalar(7)), 0.12, &frame).ok());
  EXPECT_FALSE(frame.has_depth());  // one or the other
  EXPECT_EQ(frame.right().baseline_m(), 0.12);
  EXPECT_EQ(frame.right().raw_image().pixels(), std::string(6, '\x07'));

  EXPECT_EQ(AttachDepth(cv::Mat(2, 3, CV_8UC1), 1000, &frame).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);  // 8-bit depth
  EXPECT_EQ(AttachDepth(depth_mm, 0, &frame).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(AttachDepth(cv::Mat(), 1000, &frame).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(AttachStereoRight(cv::Mat(2, 3, CV_8UC1), 0, &frame).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(AttachStereoRight(cv::Mat(2, 3, CV_16UC1), 0.1, &frame).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(frame.has_right());  // a refused attachment leaves the frame as it was
}

}  // namespace
}  // namespace recog::client

namespace recog::client {
namespace {

TEST(FramesTest, RigViewsAreNamedAfterTheirCameraAndBadOnesAreRefused) {
  const cv::Mat image(48, 64, CV_8UC1, cv::Scalar(90));
  pb::Frame rig;
  rig.set_timestamp(12.5);
  ASSERT_TRUE(AddRigView("front", FrameFromImage(image).value(), &rig).ok());
  pb::Frame rear = FrameFromImage(image).value();
  ASSERT_TRUE(AttachDepth(cv::Mat(48, 64, CV_16UC1, cv::Scalar(1500)), 1000, &rear).ok());
  ASSERT_TRUE(AddRigView("rear", rear, &rig).ok());
  ASSERT_EQ(rig.views_size(), 2);
  EXPECT_EQ(rig.views(0).camera_id(), "front");
  EXPECT_EQ(rig.views(1).camera_id(), "rear");
  EXPECT_TRUE(rig.views(1).has_depth());
  EXPECT_EQ(rig.views(0).raw_image().width(), 64u);

  const auto refused = [&](const std::string& camera, const pb::Frame& view,
                           const std::string& words) {
    const grpc::Status status = AddRigView(camera, view, &rig);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << words;
    EXPECT_NE(status.error_message().find(words), std::string::npos) << status.error_message();
  };
  refused("front", FrameFromImage(image).value(), "has a view already");
  refused("", FrameFromImage(image).value(), "camera's name");
  refused("left", pb::Frame(), "no image");
  pb::Frame stamped = FrameFromImage(image).value();
  stamped.set_timestamp(1);
  refused("left", stamped, "'left' carries more");
  pb::Frame calibrated = FrameFromImage(image).value();
  calibrated.mutable_intrinsics()->set_fx(500);
  refused("left", calibrated, "intrinsics");
  EXPECT_EQ(rig.views_size(), 2) << "nothing added by a refused view";
}

TEST(FramesTest, ARigCameraCarriesItsSizeIntrinsicsAndBodyPose) {
  const cv::Matx33d K(500, 0, 320, 0, 510, 240, 0, 0, 1);
  const cv::Matx33d R(-1, 0, 0, 0, 1, 0, 0, 0, -1);
  const pb::RigCameraSettings camera =
      MakeRigCamera("rear", {640, 480}, K, {0.1, -0.2, 0, 0}, R, {0, 0, -0.4});
  EXPECT_EQ(camera.name(), "rear");
  EXPECT_EQ(camera.width(), 640u);
  EXPECT_EQ(camera.height(), 480u);
  EXPECT_EQ(camera.intrinsics().fy(), 510);
  EXPECT_EQ(camera.intrinsics().cx(), 320);
  ASSERT_EQ(camera.intrinsics().distortion_size(), 4);
  EXPECT_EQ(camera.intrinsics().distortion(1), -0.2);
  ASSERT_EQ(camera.body_pose().rotation_size(), 9);
  EXPECT_EQ(camera.body_pose().rotation(8), -1);
  ASSERT_EQ(camera.body_pose().translation_size(), 3);
  EXPECT_EQ(camera.body_pose().translation(2), -0.4);
}

}  // namespace
}  // namespace recog::client
