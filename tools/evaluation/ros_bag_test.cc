// The frame reader on ROS 1 bags that Debian's python3-rosbag writes (tests/testing/write_bag.py):
// every encoding and format it takes, frames in header-stamp order with their depth, right image
// and camera info, and each bag it must refuse, with a named error and no frame.
#include "tools/evaluation/ros_bag.h"

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tools/evaluation/place_evaluation.h"
#include "tools/evaluation/test_folder.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;
using testing::ExpectError;

constexpr int kFrames = 3;
constexpr char kTopic[] = "/camera/image_raw";

// The topics of a bag (GCC warns of designated initializers that leave fields out).
BagTopics Topics(const std::string& image, const std::string& depth = "",
                 const std::string& camera_info = "", const std::string& right = "",
                 const std::string& right_camera_info = "") {
  BagTopics topics;
  topics.image = image;
  topics.depth = depth;
  topics.camera_info = camera_info;
  topics.right = right;
  topics.right_camera_info = right_camera_info;
  return topics;
}

BagReadOptions KeepColor(bool keep) {
  BagReadOptions options;
  options.keep_color = keep;
  return options;
}

// Three 64 x 48 colour frames of noise (each its own), their 16-bit depth images (millimetres,
// 0 = none in a corner) and their right images; bags are written from them by write_bag.py.
class BagTest : public ::testing::Test {
 protected:
  void SetUp() override {
    cv::RNG rng(7);
    for (int k = 0; k < kFrames; ++k) {
      cv::Mat color(48, 64, CV_8UC3), depth(48, 64, CV_16UC1), right(48, 64, CV_8UC1);
      rng.fill(color, cv::RNG::UNIFORM, 0, 256);
      rng.fill(depth, cv::RNG::UNIFORM, 500, 4000);
      depth(cv::Rect(0, 0, 4, 4)) = 0;
      rng.fill(right, cv::RNG::UNIFORM, 0, 256);
      const std::string name = std::to_string(k + 1) + ".png";
      fs::create_directories(dir_ / "images");
      fs::create_directories(dir_ / "depth");
      fs::create_directories(dir_ / "right");
      ASSERT_TRUE(cv::imwrite(dir_ / ("images/" + name), color));
      ASSERT_TRUE(cv::imwrite(dir_ / ("depth/" + name), depth));
      ASSERT_TRUE(cv::imwrite(dir_ / ("right/" + name), right));
      fs::create_directories(dir_ / "jpeg");
      ASSERT_TRUE(cv::imwrite(dir_ / ("jpeg/" + std::to_string(k + 1) + ".jpg"), color));
      colors_.push_back(color);
      depths_.push_back(depth);
      rights_.push_back(right);
    }
  }

  // Writes bag `name` from the frames with write_bag.py's `options`; its path.
  std::string WriteBag(const std::string& name, const std::string& options,
                       const std::string& images = "images") {
    const std::string bag = dir_ / name;
    const std::string command = "/usr/bin/python3 " + std::string(RECOG_SOURCE_DIR) +
                                "/tests/testing/write_bag.py " + bag + " --images " +
                                (dir_ / images) + " --start 100 --period 0.5 " + options;
    EXPECT_EQ(std::system(command.c_str()), 0) << command;
    return bag;
  }

  // Every frame of the bag, read in order with Next.
  static std::vector<BagFrame> ReadAll(RosBagReader& reader) {
    std::vector<BagFrame> frames;
    BagFrame frame;
    for (;;) {
      StatusOr<bool> more = reader.Next(&frame);
      EXPECT_TRUE(more.ok()) << more.status().ToString();
      if (!more.ok() || !*more) break;
      frames.push_back(frame);
    }
    return frames;
  }

  static cv::Mat Gray(const cv::Mat& bgr) {
    cv::Mat gray;
    cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
    return gray;
  }

  static bool Same(const cv::Mat& a, const cv::Mat& b) {
    return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
  }

  testing::TestFolder dir_{"ros_bag"};
  std::vector<cv::Mat> colors_, depths_, rights_;
};

TEST_F(BagTest, Mono8FramesComeWithTheirStampsAndTheDecodersGrey) {
  const std::string bag = WriteBag("mono8.bag", "--encoding mono8");
  auto reader = RosBagReader::Open(bag, Topics(kTopic));
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  EXPECT_EQ(reader->size(), size_t(kFrames));
  EXPECT_EQ(reader->stamps(), (std::vector<double>{100.0, 100.5, 101.0}));
  EXPECT_FALSE(reader->camera().has_value());
  const std::vector<BagFrame> frames = ReadAll(*reader);
  ASSERT_EQ(frames.size(), size_t(kFrames));
  for (int k = 0; k < kFrames; ++k) {
    EXPECT_EQ(frames[k].index, uint64_t(k));
    EXPECT_DOUBLE_EQ(frames[k].stamp, 100.0 + 0.5 * k);
    EXPECT_TRUE(Same(frames[k].gray, cv::imread(dir_ / ("images/" + std::to_string(k + 1) + ".png"),
                                                cv::IMREAD_GRAYSCALE)));
    EXPECT_TRUE(frames[k].color.empty());
    EXPECT_TRUE(frames[k].depth.empty());
    EXPECT_TRUE(frames[k].right.empty());
  }
  // Random access gives the same frame.
  auto second = reader->Read(1);
  ASSERT_TRUE(second.ok()) << second.status().ToString();
  EXPECT_TRUE(Same(second->gray, frames[1].gray));
  ExpectError(reader->Read(3), StatusCode::kInvalidArgument, "frame 3 of a bag of 3 frames");
}

TEST_F(BagTest, ColourEncodingsGiveGreyAndOnRequestTheBgrImage) {
  for (const char* encoding : {"rgb8", "bgr8", "rgba8", "bgra8"}) {
    SCOPED_TRACE(encoding);
    const std::string bag =
        WriteBag(std::string(encoding) + ".bag", "--encoding " + std::string(encoding));
    for (const bool keep_color : {false, true}) {
      auto reader = RosBagReader::Open(bag, Topics(kTopic), KeepColor(keep_color));
      ASSERT_TRUE(reader.ok()) << reader.status().ToString();
      const std::vector<BagFrame> frames = ReadAll(*reader);
      ASSERT_EQ(frames.size(), size_t(kFrames));
      for (int k = 0; k < kFrames; ++k) {
        EXPECT_TRUE(Same(frames[k].gray, Gray(colors_[k])));
        if (keep_color) {
          EXPECT_TRUE(Same(frames[k].color, colors_[k]));
        } else {
          EXPECT_TRUE(frames[k].color.empty());
        }
      }
    }
  }
}

TEST_F(BagTest, CompressedImagesDecodeAsTheirFilesDo) {
  // A JPEG goes as its bytes: the grey image is exactly the file's, as recog reads it.
  const std::string jpeg = WriteBag("jpeg.bag", "--encoding jpeg", "jpeg");
  auto reader = RosBagReader::Open(jpeg, Topics(kTopic));
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  std::vector<BagFrame> frames = ReadAll(*reader);
  ASSERT_EQ(frames.size(), size_t(kFrames));
  for (int k = 0; k < kFrames; ++k) {
    auto file = ReadGrayImage(dir_ / ("jpeg/" + std::to_string(k + 1) + ".jpg"));
    ASSERT_TRUE(file.ok());
    EXPECT_TRUE(Same(frames[k].gray, *file));
  }
  // With keep_color, the colour JPEG's BGR image, and its grey from it.
  reader = RosBagReader::Open(jpeg, Topics(kTopic), KeepColor(true));
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  frames = ReadAll(*reader);
  ASSERT_EQ(frames.size(), size_t(kFrames));
  const cv::Mat decoded = cv::imread(dir_ / "jpeg/1.jpg", cv::IMREAD_COLOR);
  EXPECT_TRUE(Same(frames[0].color, decoded));
  EXPECT_TRUE(Same(frames[0].gray, Gray(decoded)));
  // A PNG, lossless: the pixels.
  reader = RosBagReader::Open(WriteBag("png.bag", "--encoding png"), Topics(kTopic));
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  frames = ReadAll(*reader);
  ASSERT_EQ(frames.size(), size_t(kFrames));
  EXPECT_TRUE(Same(frames[2].gray, cv::imread(dir_ / "images/3.png", cv::IMREAD_GRAYSCALE)));
}

TEST_F(BagTest, FramesFollowTheHeaderStampsNotTheRecordingOrder) {
  // Written last frame first, with increasing record times.
  for (const char* compression : {"none", "bz2", "lz4"}) {
    SCOPED_TRACE(compression);
    const std::string bag = WriteBag(std::string("reverse_") + compression + ".bag",
                                     "--reverse --compression " + std::string(compression));
    auto reader = RosBagReader::Open(bag, Topics(kTopic));
    ASSERT_TRUE(reader.ok()) << reader.status().ToString();
    EXPECT_EQ(reader->stamps(), (std::vector<double>{100.0, 100.5, 101.0}));
    const std::vector<BagFrame> frames = ReadAll(*reader);
    ASSERT_EQ(frames.size(), size_t(kFrames));
    EXPECT_TRUE(Same(frames[0].gray, cv::imread(dir_ / "images/1.png", cv::IMREAD_GRAYSCALE)));
  }
}

TEST_F(BagTest, CameraInfoGivesTheIntrinsicsAndTheRightCameraTheBaseline) {
  const std::string bag =
      WriteBag("stereo.bag",
               "--camera-info-topic /camera/camera_info --camera 50,51,31.5,23.5,0.1,-0.2,0,0,0.01 "
               "--right-images " +
                   (dir_ / "right") +
                   " --right-topic /right/image_rect --right-camera-info-topic /right/camera_info "
                   "--baseline 0.12");
  auto reader = RosBagReader::Open(
      bag, Topics(kTopic, "", "/camera/camera_info", "/right/image_rect", "/right/camera_info"));
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  ASSERT_TRUE(reader->camera().has_value());
  const BagCameraInfo& camera = *reader->camera();
  EXPECT_EQ(camera.size, cv::Size(64, 48));
  EXPECT_EQ(camera.camera, (CameraIntrinsics{50, 51, 31.5, 23.5, {0.1, -0.2, 0, 0, 0.01}}));
  EXPECT_EQ(camera.rectified, (CameraIntrinsics{50, 51, 31.5, 23.5, {}}));
  EXPECT_EQ(camera.distortion_model, "plumb_bob");
  EXPECT_EQ(camera.projection_tx, 0);
  auto baseline = reader->StereoBaseline();
  ASSERT_TRUE(baseline.ok()) << baseline.status().ToString();
  ASSERT_TRUE(baseline->has_value());
  EXPECT_NEAR(**baseline, 0.12, 1e-12);
  const std::vector<BagFrame> frames = ReadAll(*reader);
  ASSERT_EQ(frames.size(), size_t(kFrames));
  for (int k = 0; k < kFrames; ++k) EXPECT_TRUE(Same(frames[k].right, rights_[k]));
  // The left camera's P gives no baseline: not a right camera.
  reader =
      RosBagReader::Open(bag, Topics(kTopic, "", "", "/right/image_rect", "/camera/camera_info"));
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  ExpectError(reader->StereoBaseline(), StatusCode::kInvalidArgument,
              "is not a rectified right camera");
}

// CameraInfo's distortion_model names the lens of D: a fisheye's equidistant D is kept (even all
// 0: r = θ is no pinhole), zeros of plumb_bob or of a model no lens knows are a pinhole, and a
// model that is not read, with coefficients, is refused naming it and the models read.
TEST_F(BagTest, CameraInfoDistortionModelsGiveTheLens) {
  const std::string info = " --camera-info-topic /camera/camera_info --camera 50,51,31.5,23.5";
  struct Case {
    std::string options;
    CameraIntrinsics camera;
  };
  const std::vector<Case> cases = {
      {",0.01,-0.002,0.0003,-0.00004 --distortion-model equidistant",
       {50, 51, 31.5, 23.5, {0.01, -0.002, 0.0003, -0.00004}, LensModel::kEquidistant}},
      {",0,0,0,0 --distortion-model equidistant",
       {50, 51, 31.5, 23.5, {0, 0, 0, 0}, LensModel::kEquidistant}},
      {",0.1,-0.2,0,0,0.01,0.001,0.002,0.003 --distortion-model rational_polynomial",
       {50, 51, 31.5, 23.5, {0.1, -0.2, 0, 0, 0.01, 0.001, 0.002, 0.003}}},
      {"", {50, 51, 31.5, 23.5, {}}},  // plumb_bob's five zeros
      {",0 --distortion-model fov", {50, 51, 31.5, 23.5, {}}},
  };
  for (size_t i = 0; i < cases.size(); ++i) {
    SCOPED_TRACE(cases[i].options);
    const std::string bag = WriteBag("lens" + std::to_string(i) + ".bag", info + cases[i].options);
    auto reader = RosBagReader::Open(bag, Topics(kTopic, "", "/camera/camera_info"));
    ASSERT_TRUE(reader.ok()) << reader.status().ToString();
    EXPECT_EQ(reader->camera()->camera, cases[i].camera);
    EXPECT_EQ(reader->FrameCamera(), cases[i].camera);
  }
  const std::string fov = WriteBag("fov.bag", info + ",0.9 --distortion-model fov");
  const auto refused = RosBagReader::Open(fov, Topics(kTopic, "", "/camera/camera_info"));
  ExpectError(refused, StatusCode::kInvalidArgument, "topic /camera/camera_info of bag");
  ExpectError(refused, StatusCode::kInvalidArgument,
              "distortion model 'fov' is not supported (read: plumb_bob, rational_polynomial, "
              "equidistant");
  // Coefficients the lens does not take.
  const std::string three =
      WriteBag("equidistant3.bag", info + ",0.1,0.01,0.001 --distortion-model equidistant");
  ExpectError(RosBagReader::Open(three, Topics(kTopic, "", "/camera/camera_info")),
              StatusCode::kInvalidArgument, "equidistant camera distortion needs 4 coefficients");
}

TEST_F(BagTest, DepthInEveryEncodingIsMatchedByNearestStamp) {
  for (const char* encoding : {"16UC1", "32FC1", "png", "compressedDepth"}) {
    SCOPED_TRACE(encoding);
    const std::string bag = WriteBag(std::string("depth_") + encoding + ".bag",
                                     "--depth-images " + (dir_ / "depth") + " --depth-encoding " +
                                         encoding + " --depth-offset 0.015");
    auto reader = RosBagReader::Open(bag, Topics(kTopic, "/camera/depth/image_raw"));
    ASSERT_TRUE(reader.ok()) << reader.status().ToString();
    const std::vector<BagFrame> frames = ReadAll(*reader);
    ASSERT_EQ(frames.size(), size_t(kFrames));
    for (int k = 0; k < kFrames; ++k) {
      if (std::string(encoding) == "32FC1") {
        ASSERT_EQ(frames[k].depth.type(), CV_32FC1);
        cv::Mat millimetres;
        frames[k].depth.convertTo(millimetres, CV_64F, 1000.0);
        cv::Mat expected;
        depths_[k].convertTo(expected, CV_64F);
        EXPECT_TRUE(std::isnan(frames[k].depth.at<float>(0, 0)));  // no depth
        EXPECT_LT(cv::norm(millimetres(cv::Rect(4, 4, 60, 44)), expected(cv::Rect(4, 4, 60, 44)),
                           cv::NORM_INF),
                  1e-3);
      } else {
        EXPECT_TRUE(Same(frames[k].depth, depths_[k]));
      }
    }
  }
}

TEST_F(BagTest, AFrameWithoutDepthWithinTheOffsetIsANamedError) {
  const std::string bag =
      WriteBag("late_depth.bag", "--depth-images " + (dir_ / "depth") + " --depth-offset 0.05");
  const BagTopics topics = Topics(kTopic, "/camera/depth/image_raw");
  ExpectError(RosBagReader::Open(bag, topics), StatusCode::kInvalidArgument,
              "frame 1 (stamp 100.000000000) of /camera/image_raw has no depth image on "
              "/camera/depth/image_raw within 0.02 s (the nearest is 0.05 s away)");
  // Wider offset: matched; or the frames kept without depth.
  BagReadOptions options;
  options.max_depth_offset = 0.06;
  auto wider = RosBagReader::Open(bag, topics, options);
  ASSERT_TRUE(wider.ok()) << wider.status().ToString();
  EXPECT_FALSE(wider->Read(0)->depth.empty());
  options = BagReadOptions();
  options.keep_unmatched_frames = true;
  auto kept = RosBagReader::Open(bag, topics, options);
  ASSERT_TRUE(kept.ok()) << kept.status().ToString();
  EXPECT_EQ(kept->size(), size_t(kFrames));
  EXPECT_TRUE(kept->Read(0)->depth.empty());
}

TEST_F(BagTest, BrokenFilesAreNamedErrors) {
  ExpectError(RosBagReader::Open(dir_ / "none.bag", Topics(kTopic)), StatusCode::kNotFound,
              "does not exist");
  dir_.Text("text.bag", "not a bag\n");
  ExpectError(RosBagReader::Open(dir_ / "text.bag", Topics(kTopic)), StatusCode::kInvalidArgument,
              "is not a bag: it starts with 6e 6f 74");
  dir_.Text("ros2/metadata.yaml", "rosbag2_bagfile_information:\n");
  ExpectError(RosBagReader::Open(dir_ / "ros2", Topics(kTopic)), StatusCode::kInvalidArgument,
              "metadata.yaml': not rosbag2 metadata");

  const std::string good = WriteBag("good.bag", "");
  const std::string truncated = dir_ / "truncated.bag";
  fs::copy_file(good, truncated);
  fs::resize_file(truncated, fs::file_size(good) / 2);
  ExpectError(RosBagReader::Open(truncated, Topics(kTopic)), StatusCode::kDataLoss,
              "is truncated: it ends at byte");
  fs::resize_file(truncated, 20);
  ExpectError(RosBagReader::Open(truncated, Topics(kTopic)), StatusCode::kDataLoss, "is truncated");

  const std::string unindexed = WriteBag("unindexed.bag", "--unindexed");
  ExpectError(RosBagReader::Open(unindexed, Topics(kTopic)), StatusCode::kDataLoss,
              "is unindexed: its recording was not closed");
  ExpectError(RosBagReader::Open(unindexed, Topics(kTopic)), StatusCode::kDataLoss,
              "run `rosbag reindex " + unindexed + "`");
}

TEST_F(BagTest, TopicsTypesAndEncodingsAreCheckedAtOpen) {
  const std::string bag =
      WriteBag("info.bag", "--camera-info-topic /camera/camera_info --camera 50,50,32,24");
  auto listed = RosBagReader::ListTopics(bag);
  ASSERT_TRUE(listed.ok()) << listed.status().ToString();
  ASSERT_EQ(listed->size(), 2u);
  EXPECT_EQ((*listed)[0].topic, "/camera/camera_info");
  EXPECT_EQ((*listed)[0].type, "sensor_msgs/CameraInfo");
  EXPECT_EQ((*listed)[1].messages, uint64_t(kFrames));
  // An unknown topic lists the bag's.
  ExpectError(RosBagReader::Open(bag, Topics("/cam")), StatusCode::kNotFound,
              "has no topic /cam (the image topic); its topics: /camera/camera_info "
              "(sensor_msgs/CameraInfo, 3 messages), /camera/image_raw (sensor_msgs/Image, 3 "
              "messages)");
  ExpectError(RosBagReader::Open(bag, Topics(kTopic, "/depth")), StatusCode::kNotFound,
              "has no topic /depth (the depth topic)");
  // A topic of another type.
  ExpectError(RosBagReader::Open(bag, Topics("/camera/camera_info")), StatusCode::kInvalidArgument,
              "topic /camera/camera_info (the image topic) of bag '" + bag +
                  "' is sensor_msgs/CameraInfo; expected sensor_msgs/Image or "
                  "sensor_msgs/CompressedImage");
  ExpectError(RosBagReader::Open(bag, Topics(kTopic, "", kTopic)), StatusCode::kInvalidArgument,
              "expected sensor_msgs/CameraInfo");
  // Encodings.
  ExpectError(RosBagReader::Open(WriteBag("yuv.bag", "--encoding yuv422"), Topics(kTopic)),
              StatusCode::kInvalidArgument,
              "topic /camera/image_raw, message 1 at stamp 100.000000000 of bag");
  ExpectError(RosBagReader::Open(dir_ / "yuv.bag", Topics(kTopic)), StatusCode::kInvalidArgument,
              "encoding 'yuv422' is not supported for an image topic");
  // A grey image is no depth image.
  ExpectError(RosBagReader::Open(bag, Topics(kTopic, kTopic)), StatusCode::kInvalidArgument,
              "encoding 'mono8' (an image encoding) is not supported for a depth topic (16UC1 and "
              "mono16 in millimetres, 32FC1 in metres)");
  // Options.
  BagReadOptions negative;
  negative.max_depth_offset = -1;
  ExpectError(RosBagReader::Open(bag, Topics(kTopic), negative), StatusCode::kInvalidArgument,
              "BagReadOptions.max_depth_offset = -1");
  ExpectError(RosBagReader::Open(bag, Topics("")), StatusCode::kInvalidArgument, "an image topic");
}

TEST_F(BagTest, FrameSourceReadsABagWithItsDepth) {
  const std::string bag =
      WriteBag("source.bag", "--depth-images " + (dir_ / "depth") + " --encoding jpeg");
  auto source = FrameSource::OpenBag(bag, Topics(kTopic, "/camera/depth/image_raw"));
  ASSERT_TRUE(source.ok()) << source.status().ToString();
  EXPECT_TRUE(source->is_bag());
  EXPECT_FALSE(source->is_video());
  EXPECT_EQ(source->size(), size_t(kFrames));
  ASSERT_NE(source->bag(), nullptr);
  cv::Mat gray;
  std::string name;
  std::vector<std::string> names;
  for (;;) {
    auto more = source->Next(&gray, &name);
    ASSERT_TRUE(more.ok()) << more.status().ToString();
    if (!*more) break;
    names.push_back(name);
    EXPECT_EQ(source->timestamp(), 100.0 + 0.5 * double(names.size() - 1));
    auto depth = source->depth();
    ASSERT_TRUE(depth.ok()) << depth.status().ToString();
    EXPECT_TRUE(Same(*depth, depths_[names.size() - 1]));
    auto right = source->right();
    ASSERT_TRUE(right.ok());
    EXPECT_TRUE(right->empty());
  }
  EXPECT_EQ(names, (std::vector<std::string>{"source.bag#1", "source.bag#2", "source.bag#3"}));
}

}  // namespace
}  // namespace recog::cli
