// The ROS 1 bags that other projects recorded (shared data, bags/ros1; its README says where each
// comes from), read through the bag store and the sensor_msgs decoders: every image, depth and
// CameraInfo message decodes, and depth sent three ways — a raw 16UC1 image, a 16-bit PNG and
// image_transport's compressedDepth — gives the PNG's values.
#include <algorithm>
#include <map>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "tests/testing/test_data.h"
#include "tools/bag/bag_store.h"
#include "tools/bag/ros_images.h"
#include "tools/bag/ros_messages.h"

namespace recog::bag {
namespace {

std::string Ros1Bag(const std::string& name) {
  return recog::testing::SharedData("bags/ros1/" + name + ".bag");
}

std::unique_ptr<BagStore> Open(const std::string& name) {
  StatusOr<std::unique_ptr<BagStore>> store = OpenBag(Ros1Bag(name));
  EXPECT_TRUE(store.ok()) << store.status().ToString();
  return store.ok() ? std::move(*store) : nullptr;
}

const TopicSummary* Find(const BagStore& store, const std::string& topic) {
  for (const TopicSummary& t : store.summary().topics) {
    if (t.name == topic) return &t;
  }
  return nullptr;
}

// The pixels of every message of `topic` (depth for `role` kDepth, grey otherwise).
std::vector<cv::Mat> DecodeAll(BagStore& store, const std::string& topic, ImageRole role) {
  const TopicSummary* summary = Find(store, topic);
  EXPECT_NE(summary, nullptr) << topic;
  if (summary == nullptr) return {};
  const bool compressed = IsMessageType(summary->type, "sensor_msgs", "CompressedImage");
  std::vector<cv::Mat> images;
  const Status s = store.ForEachMessage(topic, [&](const StoredMessage& stored) -> Status {
    cv::Mat pixels;
    const auto decode = [&](const auto& m) -> Status {
      RECOG_ASSIGN_OR_RETURN(const ImageLayout layout, InspectImage(m, role));
      RECOG_RETURN_IF_ERROR(role == ImageRole::kDepth ? DecodeDepth(m, &pixels)
                                                      : DecodeGray(m, &pixels, nullptr));
      EXPECT_EQ(pixels.size(), layout.size) << topic;
      return Status::Ok();
    };
    if (compressed) {
      RECOG_ASSIGN_OR_RETURN(const CompressedImageMessage m,
                             DecodeCompressedImageMessage(Serialization::kRos1, stored.data));
      RECOG_RETURN_IF_ERROR(decode(m));
    } else {
      RECOG_ASSIGN_OR_RETURN(const ImageMessage m,
                             DecodeImageMessage(Serialization::kRos1, stored.data));
      RECOG_RETURN_IF_ERROR(decode(m));
    }
    images.push_back(pixels);
    return Status::Ok();
  });
  EXPECT_TRUE(s.ok()) << topic << ": " << s.ToString();
  EXPECT_EQ(images.size(), summary->messages) << topic;
  return images;
}

// The PNG inside the one message of a compressed depth topic, decoded by OpenCV.
cv::Mat PngOf(BagStore& store, const std::string& topic, size_t skip) {
  cv::Mat png;
  EXPECT_TRUE(
      store
          .ForEachMessage(topic,
                          [&](const StoredMessage& stored) -> Status {
                            RECOG_ASSIGN_OR_RETURN(
                                const CompressedImageMessage m,
                                DecodeCompressedImageMessage(Serialization::kRos1, stored.data));
                            const std::vector<uint8_t> bytes(m.data.begin() + skip, m.data.end());
                            png = cv::imdecode(bytes, cv::IMREAD_ANYDEPTH);
                            return Status::Ok();
                          })
          .ok());
  return png;
}

bool Same(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

TEST(Ros1Bags, SpotImagesDecodeInEveryEncoding) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/ros1");
  const std::map<std::string, cv::Size> sizes = {{"/spot/camera/frontleft/image", {640, 480}},
                                                 {"/spot/camera/hand_mono/image", {224, 171}},
                                                 {"/spot/camera/hand_color/image", {640, 480}}};
  for (const std::string bag : {"ctu_spot_raw", "ctu_spot_compressed"}) {
    std::unique_ptr<BagStore> store = Open(bag);
    ASSERT_NE(store, nullptr);
    EXPECT_EQ(store->summary().storage, "ros1");
    for (const auto& [topic, size] : sizes) {
      const std::string name = bag == "ctu_spot_raw" ? topic : topic + "/compressed";
      const std::vector<cv::Mat> images = DecodeAll(*store, name, ImageRole::kImage);
      ASSERT_EQ(images.size(), 1u) << name;
      EXPECT_EQ(images[0].size(), size) << name;
      EXPECT_EQ(images[0].type(), CV_8UC1) << name;
    }
  }
}

TEST(Ros1Bags, DepthSentThreeWaysHasThePngsValues) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/ros1");
  std::unique_ptr<BagStore> raw = Open("ctu_spot_raw");
  std::unique_ptr<BagStore> png = Open("ctu_spot_compressed");
  std::unique_ptr<BagStore> compressed_depth = Open("ctu_spot_compressedDepth");
  ASSERT_TRUE(raw && png && compressed_depth);

  const std::vector<cv::Mat> from_raw =
      DecodeAll(*raw, "/spot/depth/frontleft/image", ImageRole::kDepth);
  const std::vector<cv::Mat> from_png =
      DecodeAll(*png, "/spot/depth/frontleft/image/compressed", ImageRole::kDepth);
  const std::vector<cv::Mat> from_compressed_depth = DecodeAll(
      *compressed_depth, "/spot/depth/frontleft/image/compressedDepth", ImageRole::kDepth);
  ASSERT_EQ(from_raw.size(), 1u);
  ASSERT_EQ(from_png.size(), 1u);
  ASSERT_EQ(from_compressed_depth.size(), 1u);

  const cv::Mat png_pixels = PngOf(*png, "/spot/depth/frontleft/image/compressed", 0);
  const cv::Mat compressed_depth_pixels =
      PngOf(*compressed_depth, "/spot/depth/frontleft/image/compressedDepth", 12);
  ASSERT_EQ(png_pixels.type(), CV_16UC1);
  ASSERT_EQ(compressed_depth_pixels.type(), CV_16UC1);
  EXPECT_EQ(png_pixels.size(), cv::Size(424, 240));
  EXPECT_GT(cv::countNonZero(png_pixels), 1000);
  EXPECT_TRUE(Same(from_png[0], png_pixels));
  EXPECT_TRUE(Same(from_compressed_depth[0], compressed_depth_pixels));
  // The raw image is the one the PNG holds.
  EXPECT_TRUE(Same(from_raw[0], png_pixels));
}

TEST(Ros1Bags, CameraInfosAndAJpegFromARaspberryPi) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/ros1");
  std::unique_ptr<BagStore> store = Open("fiducials_aruco_images");
  ASSERT_NE(store, nullptr);
  const std::vector<cv::Mat> images =
      DecodeAll(*store, "/raspicam_node/image/compressed", ImageRole::kImage);
  ASSERT_EQ(images.size(), 1u);
  EXPECT_EQ(images[0].size(), cv::Size(1280, 960));
  size_t infos = 0;
  ASSERT_TRUE(store
                  ->ForEachMessage("/raspicam_node/camera_info",
                                   [&](const StoredMessage& stored) -> Status {
                                     RECOG_ASSIGN_OR_RETURN(const CameraInfoMessage c,
                                                            DecodeCameraInfoMessage(
                                                                Serialization::kRos1, stored.data));
                                     EXPECT_GT(c.k[0], 0);
                                     EXPECT_GT(c.k[4], 0);
                                     EXPECT_EQ(c.width, 1280u);
                                     EXPECT_EQ(c.height, 960u);
                                     ++infos;
                                     return Status::Ok();
                                   })
                  .ok());
  EXPECT_EQ(infos, 15u);
}

TEST(Ros1Bags, Bz2AndLz4ChunksGiveTheSameMessages) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/ros1");
  std::unique_ptr<BagStore> bz2 = Open("webviz_example_bz2_noimg");
  std::unique_ptr<BagStore> lz4 = Open("webviz_example_lz4_noimg");
  ASSERT_TRUE(bz2 && lz4);
  EXPECT_EQ(bz2->summary().compression, "bz2");
  EXPECT_EQ(lz4->summary().compression, "lz4");
  EXPECT_GT(bz2->summary().messages, 8000u);
  EXPECT_EQ(bz2->summary().messages, lz4->summary().messages);
  ASSERT_EQ(bz2->summary().topics.size(), lz4->summary().topics.size());
  for (size_t i = 0; i < bz2->summary().topics.size(); ++i) {
    const TopicSummary& a = bz2->summary().topics[i];
    const TopicSummary& b = lz4->summary().topics[i];
    EXPECT_EQ(a.name, b.name);
    EXPECT_EQ(a.type, b.type);
    EXPECT_EQ(a.messages, b.messages) << a.name;
    std::vector<std::vector<uint8_t>> from_bz2;
    ASSERT_TRUE(bz2->ForEachMessage(a.name,
                                    [&](const StoredMessage& m) {
                                      from_bz2.emplace_back(m.data.begin(), m.data.end());
                                      return Status::Ok();
                                    })
                    .ok());
    size_t k = 0;
    ASSERT_TRUE(lz4->ForEachMessage(b.name,
                                    [&](const StoredMessage& m) {
                                      EXPECT_TRUE(k < from_bz2.size() &&
                                                  std::equal(m.data.begin(), m.data.end(),
                                                             from_bz2[k].begin(),
                                                             from_bz2[k].end()))
                                          << a.name << " message " << k;
                                      ++k;
                                      return Status::Ok();
                                    })
                    .ok());
    EXPECT_EQ(k, from_bz2.size());
  }
}

TEST(Ros1Bags, AMessageIsReadAgainByItsId) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/ros1");
  std::unique_ptr<BagStore> store = Open("fiducials_aruco_images");
  ASSERT_NE(store, nullptr);
  std::vector<std::pair<uint64_t, std::vector<uint8_t>>> seen;
  ASSERT_TRUE(store
                  ->ForEachMessage("/raspicam_node/camera_info",
                                   [&](const StoredMessage& m) {
                                     seen.emplace_back(
                                         m.id, std::vector<uint8_t>(m.data.begin(), m.data.end()));
                                     return Status::Ok();
                                   })
                  .ok());
  ASSERT_EQ(seen.size(), 15u);
  std::vector<uint8_t> again;
  for (auto it = seen.rbegin(); it != seen.rend(); ++it) {
    ASSERT_TRUE(store->ReadMessage("/raspicam_node/camera_info", it->first, &again).ok());
    EXPECT_EQ(again, it->second);
  }
  EXPECT_EQ(store->ReadMessage("/raspicam_node/camera_info", 15, &again).code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(
      store->ForEachMessage("/none", [](const StoredMessage&) { return Status::Ok(); }).code(),
      StatusCode::kNotFound);
}

}  // namespace
}  // namespace recog::bag
