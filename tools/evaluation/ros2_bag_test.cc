// The frame reader on ROS 2 bags written by real writers (tests/data/bags, its README: @mcap/core
// with @foxglove/rosmsg2-serialization, and the same CDR bytes in rosbag2's sqlite3 layout): every
// storage variant gives the same frames, whose pixels, depth and camera are the README's formulas,
// and each image and depth topic's encoding gives them alike.
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "tests/testing/data_paths.h"
#include "tools/evaluation/ros_bag.h"

namespace recog::cli {
namespace {

constexpr int kFrames = 6;
constexpr int kWidth = 64, kHeight = 48;

std::string Fixture(const std::string& name) {
  return recog::testing::ProjectTestData("bags/" + name);
}

BagTopics Topics(const std::string& image, const std::string& depth,
                 const std::string& camera_info = "/camera/camera_info") {
  BagTopics topics;
  topics.image = image;
  topics.depth = depth;
  topics.camera_info = camera_info;
  return topics;
}

// The README's frame K: grey pixel (x, y) = (3x + 5y + 40K) mod 256.
cv::Mat ExpectedGray(int k) {
  cv::Mat gray(kHeight, kWidth, CV_8UC1);
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x)
      gray.at<uint8_t>(y, x) = uint8_t((3 * x + 5 * y + 40 * k) % 256);
  }
  return gray;
}

// Its depth: 1000 + 10x + y + 100K millimetres, none at (0, 0).
cv::Mat ExpectedDepth(int k) {
  cv::Mat depth(kHeight, kWidth, CV_16UC1);
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x)
      depth.at<uint16_t>(y, x) = uint16_t(1000 + 10 * x + y + 100 * k);
  }
  depth.at<uint16_t>(0, 0) = 0;
  return depth;
}

bool Same(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

class Ros2BagTest : public ::testing::TestWithParam<std::string> {};

TEST_P(Ros2BagTest, EveryEncodingGivesTheReadmesFrames) {
  for (const char* image : {"/camera/image_raw", "/camera/image_raw/compressed"}) {
    for (const char* depth :
         {"/camera/depth/image_raw", "/camera/depth/image_raw/compressedDepth"}) {
      SCOPED_TRACE(std::string(image) + " with " + depth);
      StatusOr<RosBagReader> reader = RosBagReader::Open(Fixture(GetParam()), Topics(image, depth));
      ASSERT_TRUE(reader.ok()) << reader.status().ToString();
      ASSERT_EQ(reader->size(), size_t(kFrames));
      ASSERT_TRUE(reader->FrameCamera().has_value());
      EXPECT_EQ(reader->FrameCamera()->fx, 50);
      EXPECT_EQ(reader->FrameCamera()->cx, 31.5);
      EXPECT_EQ(reader->FrameCamera()->cy, 23.5);
      EXPECT_TRUE(reader->FrameCamera()->distortion.empty());
      for (int k = 0; k < kFrames; ++k) {
        StatusOr<BagFrame> frame = reader->Read(size_t(k));
        ASSERT_TRUE(frame.ok()) << frame.status().ToString();
        EXPECT_DOUBLE_EQ(frame->stamp, 1700000000.0 + 0.1 * k);
        EXPECT_EQ(frame->stamp_ns, 1700000000000000000 + int64_t(k) * 100000000);
        EXPECT_TRUE(Same(frame->gray, ExpectedGray(k))) << "frame " << k;
        EXPECT_TRUE(Same(frame->depth, ExpectedDepth(k))) << "frame " << k;
      }
    }
  }
}

TEST_P(Ros2BagTest, TheSummaryListsTheFiveTopics) {
  StatusOr<std::vector<BagTopicInfo>> topics = RosBagReader::ListTopics(Fixture(GetParam()));
  ASSERT_TRUE(topics.ok()) << topics.status().ToString();
  ASSERT_EQ(topics->size(), 5u);
  for (const BagTopicInfo& t : *topics) {
    EXPECT_EQ(t.messages, uint64_t(kFrames)) << t.topic;
    EXPECT_EQ(t.type.rfind("sensor_msgs/msg/", 0), 0u) << t.type;
  }
  EXPECT_EQ((*topics)[0].topic, "/camera/camera_info");
}

INSTANTIATE_TEST_SUITE_P(Storages, Ros2BagTest,
                         ::testing::Values("fixture.mcap", "fixture_lz4.mcap",
                                           "fixture_noindex.mcap", "fixture_nochunk.mcap",
                                           "fixture_cdr_be.mcap", "fixture_sqlite3"),
                         [](const ::testing::TestParamInfo<std::string>& info) {
                           std::string name = info.param;
                           for (char& c : name)
                             c = std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
                           return name;
                         });

TEST(Ros2Bag, ALoneSqliteFileAndItsFolderAreOneBag) {
  const std::string folder = Fixture("fixture_sqlite3");
  StatusOr<RosBagReader> from_folder =
      RosBagReader::Open(folder, Topics("/camera/image_raw", "", ""));
  StatusOr<RosBagReader> from_file =
      RosBagReader::Open(folder + "/fixture_0.db3", Topics("/camera/image_raw", "", ""));
  ASSERT_TRUE(from_folder.ok()) << from_folder.status().ToString();
  ASSERT_TRUE(from_file.ok()) << from_file.status().ToString();
  EXPECT_EQ(from_folder->stamps(), from_file->stamps());
  EXPECT_EQ(from_folder->summary().storage, "sqlite3");
  EXPECT_EQ(from_file->summary().storage, "sqlite3");
}

TEST(Ros2Bag, KeptBytesAreTheBagsPng) {
  BagReadOptions options;
  options.keep_encoded = true;
  StatusOr<RosBagReader> reader = RosBagReader::Open(
      Fixture("fixture.mcap"), Topics("/camera/image_raw/compressed", "", ""), options);
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  StatusOr<BagFrame> frame = reader->Read(2);
  ASSERT_TRUE(frame.ok()) << frame.status().ToString();
  EXPECT_TRUE(frame->gray.empty());
  ASSERT_GT(frame->encoded.size(), 8u);
  EXPECT_EQ(frame->encoded[1], 'P');
  EXPECT_TRUE(Same(cv::imdecode(frame->encoded, cv::IMREAD_GRAYSCALE), ExpectedGray(2)));
}

}  // namespace
}  // namespace recog::cli
