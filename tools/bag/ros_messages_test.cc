// sensor_msgs Image, CompressedImage and CameraInfo decoded from ROS 1 serialization and from CDR
// (little and big endian), the messages written by the test-only serializers of
// tests/testing/ros2_bag_writer.h and by hand; messages cut at every byte, huge declared counts
// and unknown encapsulations are refused.
#include "tools/bag/ros_messages.h"

#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/testing/ros2_bag_writer.h"

namespace recog::bag {
namespace {

using testing::CameraInfoFields;
using testing::CdrSerializer;
using testing::CompressedImageFields;
using testing::ImageFields;
using testing::Ros1Serializer;
using testing::WriteMessage;

const std::vector<uint8_t> kPixels = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};

const ImageFields kImage = {
    .header = {.sec = 1305031102, .nanosec = 175304000, .frame_id = "camera", .seq = 7},
    .height = 2,
    .width = 3,
    .encoding = "rgb8",
    .is_bigendian = true,
    .step = 6,
    .data = kPixels};

const CompressedImageFields kCompressedImage = {
    .header = {.sec = 12, .nanosec = 500, .frame_id = "cam", .seq = 7},
    .format = "16UC1; compressedDepth",
    .data = kPixels};

// D, K, R and P of distinct values; binning 1 x 1. `distortion_count` is written as D's count.
CameraInfoFields CameraInfo(uint32_t distortion_count) {
  CameraInfoFields m;
  m.header = {.sec = 3, .nanosec = 4, .frame_id = "optical", .seq = 7};
  m.height = 480;
  m.width = 640;
  m.distortion_model = "plumb_bob";
  m.binning_x = 1;
  m.binning_y = 1;
  m.declared_d_count = distortion_count;
  for (int i = 0; i < 5; ++i) m.d.push_back(0.1 * (i + 1));
  for (int i = 0; i < 9; ++i) m.k[i] = 100 + i;
  for (int i = 0; i < 9; ++i) m.r[i] = 200 + i;
  for (int i = 0; i < 12; ++i) m.p[i] = 300 + i;
  return m;
}

// The three serializations: ROS 1, CDR little endian, CDR big endian.
struct Format {
  const char* name;
  Serialization serialization;
  bool big_endian;
};
const Format kFormats[] = {{"ros1", Serialization::kRos1, false},
                           {"cdr_le", Serialization::kCdr, false},
                           {"cdr_be", Serialization::kCdr, true}};

class MessagesTest : public ::testing::TestWithParam<Format> {
 protected:
  template <typename Write>
  std::vector<uint8_t> Written(Write write) const {
    if (GetParam().serialization == Serialization::kRos1) {
      Ros1Serializer w;
      write(w);
      return w.bytes();
    }
    CdrSerializer w(GetParam().big_endian);
    write(w);
    return w.bytes();
  }
  Serialization serialization() const { return GetParam().serialization; }
};

TEST_P(MessagesTest, Image) {
  const std::vector<uint8_t> bytes = Written([](auto& w) { WriteMessage(w, kImage); });
  const StatusOr<ImageMessage> m = DecodeImageMessage(serialization(), bytes);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->header.stamp_ns, 1305031102175304000);
  EXPECT_EQ(m->header.frame_id, "camera");
  EXPECT_EQ(m->height, 2u);
  EXPECT_EQ(m->width, 3u);
  EXPECT_EQ(m->encoding, "rgb8");
  EXPECT_TRUE(m->is_bigendian);
  EXPECT_EQ(m->step, 6u);
  // The pixels in place, the last bytes of the message.
  EXPECT_EQ(m->data.data(), bytes.data() + bytes.size() - kPixels.size());
  EXPECT_EQ(std::vector<uint8_t>(m->data.begin(), m->data.end()), kPixels);
}

TEST_P(MessagesTest, CompressedImage) {
  const std::vector<uint8_t> bytes = Written([](auto& w) { WriteMessage(w, kCompressedImage); });
  const StatusOr<CompressedImageMessage> m = DecodeCompressedImageMessage(serialization(), bytes);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->header.stamp_ns, 12000000500);
  EXPECT_EQ(m->header.frame_id, "cam");
  EXPECT_EQ(m->format, "16UC1; compressedDepth");
  EXPECT_EQ(std::vector<uint8_t>(m->data.begin(), m->data.end()), kPixels);
}

TEST_P(MessagesTest, CameraInfo) {
  const std::vector<uint8_t> bytes = Written([](auto& w) { WriteMessage(w, CameraInfo(5)); });
  const StatusOr<CameraInfoMessage> m = DecodeCameraInfoMessage(serialization(), bytes);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->header.stamp_ns, 3000000004);
  EXPECT_EQ(m->header.frame_id, "optical");
  EXPECT_EQ(m->height, 480u);
  EXPECT_EQ(m->width, 640u);
  EXPECT_EQ(m->distortion_model, "plumb_bob");
  EXPECT_EQ(m->d, (std::vector<double>{0.1, 0.2, 0.30000000000000004, 0.4, 0.5}));
  for (int i = 0; i < 9; ++i) EXPECT_EQ(m->k[i], 100 + i);
  for (int i = 0; i < 9; ++i) EXPECT_EQ(m->r[i], 200 + i);
  for (int i = 0; i < 12; ++i) EXPECT_EQ(m->p[i], 300 + i);
}

// Every message cut at every byte is refused, naming a field, and nothing crashes.
TEST_P(MessagesTest, EveryTruncationIsRefused) {
  const std::vector<uint8_t> messages[] = {
      Written([](auto& w) { WriteMessage(w, kImage); }),
      Written([](auto& w) { WriteMessage(w, kCompressedImage); }),
      Written([](auto& w) { WriteMessage(w, CameraInfo(5)); }),
  };
  for (int type = 0; type < 3; ++type) {
    const std::vector<uint8_t>& whole = messages[type];
    for (size_t size = 0; size < whole.size(); ++size) {
      // A copy of exactly `size` bytes, so that a read past it is a read past an allocation.
      const std::vector<uint8_t> cut(whole.begin(), whole.begin() + long(size));
      const Status status = type == 0 ? DecodeImageMessage(serialization(), cut).status()
                            : type == 1
                                ? DecodeCompressedImageMessage(serialization(), cut).status()
                                : DecodeCameraInfoMessage(serialization(), cut).status();
      ASSERT_EQ(status.code(), StatusCode::kInvalidArgument)
          << "message " << type << " cut to " << size << " of " << whole.size() << " bytes";
      const bool names_something = status.message().find("field '") != std::string::npos ||
                                   status.message().find("encapsulation") != std::string::npos;
      EXPECT_TRUE(names_something) << status.message();
    }
  }
}

// A count far beyond the message is refused before anything is allocated for it.
TEST_P(MessagesTest, HugeCountsAreRefused) {
  const std::vector<uint8_t> info = Written([](auto& w) { WriteMessage(w, CameraInfo(1u << 31)); });
  const Status status = DecodeCameraInfoMessage(serialization(), info).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("field 'd' declares 2147483648 elements of 8 bytes"),
            std::string::npos)
      << status.message();

  const std::vector<uint8_t> image = Written([](auto& w) {
    w.Header({.sec = 1, .nanosec = 2, .frame_id = "camera", .seq = 7});
    w.U32(2);
    w.U32(3);
    w.String("mono8");
    w.U8(0);
    w.U32(3);
    w.U32(0xffffffff);  // data's count
    w.U8(1);
  });
  const Status image_status = DecodeImageMessage(serialization(), image).status();
  EXPECT_EQ(image_status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(image_status.message().find("field 'data' declares 4294967295 elements"),
            std::string::npos)
      << image_status.message();
}

// Any byte of a message set to another value: decoded or refused, never a crash (a count or a
// length grown past the end is the usual case).
TEST_P(MessagesTest, CorruptBytesAreDecodedOrRefused) {
  const std::vector<uint8_t> messages[] = {
      Written([](auto& w) { WriteMessage(w, kImage); }),
      Written([](auto& w) { WriteMessage(w, kCompressedImage); }),
      Written([](auto& w) { WriteMessage(w, CameraInfo(5)); }),
  };
  int refused = 0;
  for (int type = 0; type < 3; ++type) {
    for (size_t at = 0; at < messages[type].size(); ++at) {
      for (const uint8_t value : {0x00, 0x7f, 0xff}) {
        std::vector<uint8_t> corrupt = messages[type];
        corrupt[at] = value;
        const Status status = type == 0 ? DecodeImageMessage(serialization(), corrupt).status()
                              : type == 1
                                  ? DecodeCompressedImageMessage(serialization(), corrupt).status()
                                  : DecodeCameraInfoMessage(serialization(), corrupt).status();
        if (status.ok()) continue;
        ++refused;
        ASSERT_EQ(status.code(), StatusCode::kInvalidArgument) << status.ToString();
      }
    }
  }
  EXPECT_GT(refused, 0);
}

INSTANTIATE_TEST_SUITE_P(Serializations, MessagesTest, ::testing::ValuesIn(kFormats),
                         [](const ::testing::TestParamInfo<Format>& info) {
                           return std::string(info.param.name);
                         });

// Written by hand from the CDR rules, not by the serializer of ros2_bag_writer.h: the padding after
// a string, and a count-prefixed sequence<uint8> without any.
TEST(CdrTest, AlignsFieldsFromTheEndOfTheEncapsulationHeader) {
  const std::vector<uint8_t> bytes = {
      0x00, 0x01, 0x00, 0x00,                          // CDR_LE
      0x01, 0x00, 0x00, 0x00, 0x02, 0x00, 0x00, 0x00,  // stamp 1 s 2 ns
      0x02, 0x00, 0x00, 0x00, 'a',  0x00,              // frame_id "a"
      0xee, 0xee,                                      // padding before format's length
      0x04, 0x00, 0x00, 0x00, 'p',  'n',  'g',  0x00,  // format "png"
      0x03, 0x00, 0x00, 0x00, 0x0a, 0x0b, 0x0c,        // data
  };
  const StatusOr<CompressedImageMessage> m =
      DecodeCompressedImageMessage(Serialization::kCdr, bytes);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->header.stamp_ns, 1000000002);
  EXPECT_EQ(m->header.frame_id, "a");
  EXPECT_EQ(m->format, "png");
  EXPECT_EQ(std::vector<uint8_t>(m->data.begin(), m->data.end()),
            (std::vector<uint8_t>{0x0a, 0x0b, 0x0c}));
}

TEST(CdrTest, BigEndianImageByHand) {
  const std::vector<uint8_t> bytes = {
      0x00, 0x00, 0x00, 0x00,                                     // CDR_BE
      0x00, 0x00, 0x00, 0x05, 0x00, 0x00, 0x00, 0x06,             // stamp 5 s 6 ns
      0x00, 0x00, 0x00, 0x00,                                     // frame_id: length 0, empty
      0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00, 0x02,             // height 1, width 2
      0x00, 0x00, 0x00, 0x06, '1',  '6',  'U',  'C',  '1', 0x00,  // encoding
      0x01,                                                       // is_bigendian
      0x00,                                                       // padding before step
      0x00, 0x00, 0x00, 0x04,                                     // step
      0x00, 0x00, 0x00, 0x04, 0x12, 0x34, 0x56, 0x78,             // data
  };
  const StatusOr<ImageMessage> m = DecodeImageMessage(Serialization::kCdr, bytes);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->header.stamp_ns, 5000000006);
  EXPECT_EQ(m->header.frame_id, "");
  EXPECT_EQ(m->height, 1u);
  EXPECT_EQ(m->width, 2u);
  EXPECT_EQ(m->encoding, "16UC1");
  EXPECT_TRUE(m->is_bigendian);
  EXPECT_EQ(m->step, 4u);
  EXPECT_EQ(m->data.size(), 4u);
}

// A negative builtin_interfaces/Time sec is a stamp before the epoch.
TEST(CdrTest, NegativeSecondsAreBeforeTheEpoch) {
  CdrSerializer w(false);
  w.Header({.sec = -2, .nanosec = 500000000, .frame_id = "", .seq = 0});
  w.String("png");
  w.ByteSequence({});
  const StatusOr<CompressedImageMessage> m =
      DecodeCompressedImageMessage(Serialization::kCdr, w.bytes());
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->header.stamp_ns, -1500000000);
  EXPECT_TRUE(m->data.empty());
}

TEST(CdrTest, RefusesOtherEncapsulations) {
  CdrSerializer w(false);
  WriteMessage(w, kImage);
  std::vector<uint8_t> bytes = w.bytes();
  bytes[1] = 0x03;  // PL_CDR_LE
  Status status = DecodeImageMessage(Serialization::kCdr, bytes).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("encapsulation 0x0003 (PL_CDR_LE) is not supported"),
            std::string::npos)
      << status.message();
  bytes[0] = 0x01;
  bytes[1] = 0x00;
  status = DecodeImageMessage(Serialization::kCdr, bytes).status();
  EXPECT_NE(status.message().find("encapsulation 0x0100 is not supported"), std::string::npos)
      << status.message();
  status = DecodeImageMessage(Serialization::kCdr, std::vector<uint8_t>{0x00, 0x01}).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("shorter than its 4-byte encapsulation header"),
            std::string::npos)
      << status.message();
}

// The error names the message, its serialization and the field it ends in.
TEST(Ros1Test, NamesTheFieldAMessageEndsIn) {
  Ros1Serializer w;
  WriteMessage(w, CameraInfo(5));
  const std::vector<uint8_t> cut(w.bytes().begin(), w.bytes().end() - 30);  // in p
  const Status status = DecodeCameraInfoMessage(Serialization::kRos1, cut).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("sensor_msgs/CameraInfo (ROS 1, " + std::to_string(cut.size()) +
                                  " bytes) is cut short: it ends in field 'p'"),
            std::string::npos)
      << status.message();
}

}  // namespace
}  // namespace recog::bag
