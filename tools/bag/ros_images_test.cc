// The pixels of Image and CompressedImage messages built here in memory: raw images of every
// encoding (big-endian depth included), JPEG and PNG, and depth as compressed_depth_image_transport
// sends it — its 12-byte header before a 16-bit PNG or an RVL stream (written here from the
// codec's description), millimetres or quantised inverse depth. Decoded depth is compared with
// cv::imdecode of the same PNG, or with the pixels that were encoded; damaged messages are refused.
#include "tools/bag/ros_images.h"

#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace recog::bag {
namespace {

ImageMessage Raw(const std::string& encoding, uint32_t width, uint32_t height, uint32_t step,
                 std::span<const uint8_t> data, bool big_endian = false) {
  ImageMessage m;
  m.encoding = encoding;
  m.width = width;
  m.height = height;
  m.step = step;
  m.data = data;
  m.is_bigendian = big_endian;
  return m;
}

CompressedImageMessage Compressed(const std::string& format, std::span<const uint8_t> data) {
  CompressedImageMessage m;
  m.format = format;
  m.data = data;
  return m;
}

std::vector<uint8_t> Encoded(const std::string& extension, const cv::Mat& pixels) {
  std::vector<uint8_t> bytes;
  EXPECT_TRUE(cv::imencode(extension, pixels, bytes));
  return bytes;
}

// compressed_depth_image_transport's ConfigHeader (format INV_DEPTH = 0, depthQuantA,
// depthQuantB) before `payload`.
std::vector<uint8_t> WithDepthHeader(const std::vector<uint8_t>& payload, float a = 0,
                                     float b = 0) {
  std::vector<uint8_t> bytes(12, 0);
  std::memcpy(bytes.data() + 4, &a, 4);
  std::memcpy(bytes.data() + 8, &b, 4);
  bytes.insert(bytes.end(), payload.begin(), payload.end());
  return bytes;
}

// An RVL stream as the codec describes it: 32-bit little-endian words of 8 nibbles, the first in
// the most significant bits; values in 3-bit groups, least significant first, bit 3 = more.
class RvlWriter {
 public:
  void Value(uint64_t value) {
    do {
      uint32_t nibble = value & 7;
      value >>= 3;
      if (value != 0) nibble |= 8;
      word_ = word_ << 4 | nibble;
      if (++nibbles_ == 8) Flush();
    } while (value != 0);
  }

  // The words, the last one's unused nibbles zero.
  std::vector<uint8_t> Finish() {
    if (nibbles_ > 0) {
      word_ <<= 4 * (8 - nibbles_);
      Flush();
    }
    return bytes_;
  }

 private:
  void Flush() {
    for (int i = 0; i < 4; ++i) bytes_.push_back(uint8_t(word_ >> (8 * i)));
    word_ = 0;
    nibbles_ = 0;
  }

  std::vector<uint8_t> bytes_;
  uint32_t word_ = 0;
  int nibbles_ = 0;
};

std::vector<uint8_t> RvlSize(uint32_t width, uint32_t height) {
  std::vector<uint8_t> bytes(8);
  std::memcpy(bytes.data(), &width, 4);
  std::memcpy(bytes.data() + 4, &height, 4);
  return bytes;
}

// `pixels` (CV_16UC1) as the RVL payload: width, height, then runs of zeros and of non-zero
// pixels, each of those the zigzag code of its difference from the previous non-zero pixel.
std::vector<uint8_t> Rvl(const cv::Mat& pixels) {
  std::vector<uint16_t> values(pixels.begin<uint16_t>(), pixels.end<uint16_t>());
  RvlWriter writer;
  int previous = 0;
  for (size_t at = 0; at < values.size();) {
    size_t zeros = 0, nonzeros = 0;
    while (at + zeros < values.size() && values[at + zeros] == 0) ++zeros;
    at += zeros;
    while (at + nonzeros < values.size() && values[at + nonzeros] != 0) ++nonzeros;
    writer.Value(zeros);
    writer.Value(nonzeros);
    for (size_t i = 0; i < nonzeros; ++i) {
      const int delta = values[at + i] - previous;
      writer.Value(uint32_t(delta < 0 ? -2 * delta - 1 : 2 * delta));
      previous = values[at + i];
    }
    at += nonzeros;
  }
  std::vector<uint8_t> bytes = RvlSize(uint32_t(pixels.cols), uint32_t(pixels.rows));
  const std::vector<uint8_t> words = writer.Finish();
  bytes.insert(bytes.end(), words.begin(), words.end());
  return bytes;
}

// Millimetres with holes (runs of 0), large jumps both ways, and 65535.
cv::Mat DepthMillimetres() {
  cv::Mat depth(30, 40, CV_16UC1);
  for (int y = 0; y < depth.rows; ++y) {
    for (int x = 0; x < depth.cols; ++x) {
      depth.at<uint16_t>(y, x) = uint16_t((x / 7 + y) % 5 == 0 ? 0 : 400 + 37 * x + 101 * y);
    }
  }
  depth.at<uint16_t>(3, 3) = 65535;
  depth.at<uint16_t>(3, 4) = 1;
  depth.at<uint16_t>(29, 39) = 1234;  // the last pixel non-zero: the stream ends with values
  return depth;
}

// Metres from 0.3 to 9.5 m, with NaN holes.
cv::Mat DepthMetres() {
  cv::Mat depth(24, 32, CV_32FC1);
  for (int y = 0; y < depth.rows; ++y) {
    for (int x = 0; x < depth.cols; ++x) {
      depth.at<float>(y, x) = (x + y) % 9 == 0 ? std::numeric_limits<float>::quiet_NaN()
                                               : 0.3f + 9.2f * float(x * depth.rows + y) / 768.0f;
    }
  }
  return depth;
}

// compressed_depth_image_transport's quantisation of metres to inverse depth, with its default
// parameters (depth_quantization 100, depth_max 10 m): a = z0 (z0 + 1), b = 1 - a / max, q = a / d
// + b truncated, 0 for no depth or depth beyond max.
struct InverseDepth {
  float a = 0;
  float b = 0;
  cv::Mat q;
};
InverseDepth Quantised(const cv::Mat& metres) {
  const float z0 = 100, max = 10;
  InverseDepth inverse;
  inverse.a = z0 * (z0 + 1);
  inverse.b = 1 - inverse.a / max;
  inverse.q.create(metres.size(), CV_16UC1);
  for (int y = 0; y < metres.rows; ++y) {
    for (int x = 0; x < metres.cols; ++x) {
      const float d = metres.at<float>(y, x);
      inverse.q.at<uint16_t>(y, x) = d < max ? uint16_t(inverse.a / d + inverse.b) : 0;
    }
  }
  return inverse;
}

void ExpectEqualPixels(const cv::Mat& actual, const cv::Mat& expected) {
  ASSERT_EQ(actual.type(), expected.type());
  ASSERT_EQ(actual.size(), expected.size());
  EXPECT_EQ(cv::norm(actual, expected, cv::NORM_INF), 0);
}

// Decoded inverse depth: NaN where q is 0, else a / (q - b) as the codec's decoder computes it,
// within one quantisation step (d² / a) of the metres that were encoded.
void ExpectInverseDepth(const cv::Mat& decoded, const cv::Mat& metres,
                        const InverseDepth& inverse) {
  ASSERT_EQ(decoded.type(), CV_32FC1);
  ASSERT_EQ(decoded.size(), metres.size());
  int holes = 0;
  for (int y = 0; y < metres.rows; ++y) {
    for (int x = 0; x < metres.cols; ++x) {
      const uint16_t q = inverse.q.at<uint16_t>(y, x);
      const float got = decoded.at<float>(y, x);
      if (q == 0) {
        EXPECT_TRUE(std::isnan(got)) << y << ", " << x;
        ++holes;
        continue;
      }
      const float d = metres.at<float>(y, x);
      ASSERT_EQ(got, inverse.a / (float(q) - inverse.b)) << y << ", " << x;
      EXPECT_NEAR(got, d, 1.01 * d * d / inverse.a) << y << ", " << x;
    }
  }
  EXPECT_GT(holes, 0);
}

std::string MessageOf(const Status& status) {
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << status.ToString();
  return status.message();
}

#define EXPECT_REFUSED(status_expr, text)                       \
  do {                                                          \
    const std::string message_ = MessageOf(status_expr);        \
    EXPECT_NE(message_.find(text), std::string::npos)           \
        << "\"" << message_ << "\" lacks \"" << (text) << "\""; \
  } while (false)

// ---- Raw images ----

TEST(RawImageTest, Mono8WithRowPadding) {
  // 3 x 2 pixels, rows of 4 bytes; 8UC1 and a meaningless is_bigendian (as Spot's driver sends)
  // read alike.
  const std::vector<uint8_t> data = {1, 2, 3, 99, 4, 5, 6, 99};
  for (const char* encoding : {"mono8", "8UC1"}) {
    const ImageMessage m = Raw(encoding, 3, 2, 4, data, /*big_endian=*/true);
    const StatusOr<ImageLayout> layout = InspectImage(m, ImageRole::kImage);
    ASSERT_TRUE(layout.ok()) << layout.status().ToString();
    EXPECT_EQ(layout->size, cv::Size(3, 2));
    EXPECT_FALSE(layout->color);
    EXPECT_EQ(layout->depth_type, -1);
    cv::Mat gray, color;
    ASSERT_TRUE(DecodeGray(m, &gray, &color).ok());
    ExpectEqualPixels(gray, (cv::Mat_<uint8_t>(2, 3) << 1, 2, 3, 4, 5, 6));
    EXPECT_TRUE(color.empty());
  }
}

TEST(RawImageTest, ColourEncodingsToBgrAndGrey) {
  // One pixel of red (200), green (100), blue (50), in each encoding's channel order.
  const struct {
    const char* encoding;
    std::vector<uint8_t> data;
  } cases[] = {{"rgb8", {200, 100, 50}},
               {"bgr8", {50, 100, 200}},
               {"rgba8", {200, 100, 50, 255}},
               {"bgra8", {50, 100, 200, 255}}};
  cv::Mat expected_gray;
  cv::cvtColor(cv::Mat(1, 1, CV_8UC3, cv::Scalar(50, 100, 200)), expected_gray, cv::COLOR_BGR2GRAY);
  for (const auto& c : cases) {
    SCOPED_TRACE(c.encoding);
    const ImageMessage m = Raw(c.encoding, 1, 1, uint32_t(c.data.size()), c.data);
    const StatusOr<ImageLayout> layout = InspectImage(m, ImageRole::kImage);
    ASSERT_TRUE(layout.ok()) << layout.status().ToString();
    EXPECT_TRUE(layout->color);
    cv::Mat gray, color;
    ASSERT_TRUE(DecodeGray(m, &gray, &color).ok());
    ASSERT_EQ(color.type(), CV_8UC3);
    EXPECT_EQ(color.at<cv::Vec3b>(0, 0), cv::Vec3b(50, 100, 200));
    ExpectEqualPixels(gray, expected_gray);
    cv::Mat gray_only;
    ASSERT_TRUE(DecodeGray(m, &gray_only, nullptr).ok());
    ExpectEqualPixels(gray_only, expected_gray);
  }
}

TEST(RawImageTest, DepthInMillimetresBothByteOrders) {
  const cv::Mat expected = (cv::Mat_<uint16_t>(1, 3) << 0x0102, 0xa0b0, 65535);
  const std::vector<uint8_t> little = {0x02, 0x01, 0xb0, 0xa0, 0xff, 0xff};
  const std::vector<uint8_t> big = {0x01, 0x02, 0xa0, 0xb0, 0xff, 0xff};
  for (const char* encoding : {"16UC1", "mono16"}) {
    SCOPED_TRACE(encoding);
    const ImageMessage m = Raw(encoding, 3, 1, 6, little);
    const StatusOr<ImageLayout> layout = InspectImage(m, ImageRole::kDepth);
    ASSERT_TRUE(layout.ok()) << layout.status().ToString();
    EXPECT_EQ(layout->depth_type, CV_16UC1);
    EXPECT_FALSE(layout->color);
    cv::Mat depth;
    ASSERT_TRUE(DecodeDepth(m, &depth).ok());
    ExpectEqualPixels(depth, expected);
    ASSERT_TRUE(DecodeDepth(Raw(encoding, 3, 1, 6, big, /*big_endian=*/true), &depth).ok());
    ExpectEqualPixels(depth, expected);
  }
}

TEST(RawImageTest, DepthInMetresBothByteOrders) {
  const float values[] = {1.5f, 0.25f, 0.0f, 7.125f};
  std::vector<uint8_t> little(16), big(16);
  std::memcpy(little.data(), values, 16);
  for (size_t i = 0; i < 16; ++i) big[i] = little[(i / 4) * 4 + 3 - i % 4];
  const cv::Mat expected = (cv::Mat_<float>(2, 2) << 1.5f, 0.25f, 0.0f, 7.125f);
  cv::Mat depth;
  ASSERT_TRUE(DecodeDepth(Raw("32FC1", 2, 2, 8, little), &depth).ok());
  ExpectEqualPixels(depth, expected);
  const ImageMessage big_endian = Raw("32FC1", 2, 2, 8, big, true);
  ASSERT_EQ(InspectImage(big_endian, ImageRole::kDepth)->depth_type, CV_32FC1);
  ASSERT_TRUE(DecodeDepth(big_endian, &depth).ok());
  ExpectEqualPixels(depth, expected);
}

// Pixels at an odd address with an odd step (no whole number of 16-bit pixels) still decode.
TEST(RawImageTest, DepthAtAnyAddressAndStep) {
  const std::vector<uint8_t> data = {0xee, 0x01, 0x00, 0x02, 0x00, 0xee,
                                     0x03, 0x00, 0x04, 0x00, 0xee};
  const ImageMessage m = Raw("16UC1", 2, 2, 5, std::span(data).subspan(1));
  cv::Mat depth;
  const Status status = DecodeDepth(m, &depth);
  ASSERT_TRUE(status.ok()) << status.ToString();
  ExpectEqualPixels(depth, (cv::Mat_<uint16_t>(2, 2) << 1, 2, 3, 4));
}

TEST(RawImageTest, RefusesEncodingsOfTheOtherRoleOrUnknown) {
  const std::vector<uint8_t> data(64, 0);
  cv::Mat gray, depth;
  EXPECT_REFUSED(InspectImage(Raw("16UC1", 2, 2, 4, data), ImageRole::kImage).status(),
                 "encoding '16UC1' (a depth encoding) is not supported for an image topic");
  EXPECT_REFUSED(DecodeGray(Raw("16UC1", 2, 2, 4, data), &gray, nullptr),
                 "encoding '16UC1' (a depth encoding)");
  EXPECT_REFUSED(DecodeDepth(Raw("rgb8", 2, 2, 6, data), &depth),
                 "encoding 'rgb8' (an image encoding) is not supported for a depth topic");
  EXPECT_REFUSED(InspectImage(Raw("yuv422", 2, 2, 4, data), ImageRole::kImage).status(),
                 "encoding 'yuv422' is not supported for an image topic (mono8, 8UC1");
  EXPECT_TRUE(gray.empty());
  EXPECT_TRUE(depth.empty());
}

TEST(RawImageTest, RefusesSizesStepsAndShortData) {
  const std::vector<uint8_t> data(100, 0);
  EXPECT_REFUSED(InspectImage(Raw("mono8", 0, 2, 4, data), ImageRole::kImage).status(),
                 "an image of 0 x 2 pixels");
  EXPECT_REFUSED(InspectImage(Raw("mono8", 70000, 1, 70000, data), ImageRole::kImage).status(),
                 "an image of 70000 x 1 pixels");
  EXPECT_REFUSED(InspectImage(Raw("16UC1", 4, 2, 7, data), ImageRole::kDepth).status(),
                 "a step of 7 bytes is less than a row of 4 16UC1 pixels (8 bytes)");
  cv::Mat depth;
  EXPECT_REFUSED(DecodeDepth(Raw("32FC1", 5, 6, 20, data), &depth),
                 "its data of 100 bytes is shorter than step x height = 20 x 6 = 120 bytes");
  // A step x height beyond 32 bits.
  EXPECT_REFUSED(DecodeDepth(Raw("mono16", 65536, 65536, 4000000000u, data), &depth),
                 "shorter than step x height = 4000000000 x 65536 = 262144000000000 bytes");
}

// ---- Compressed images ----

cv::Mat Gradient(cv::Size size, bool color) {
  cv::Mat image(size, color ? CV_8UC3 : CV_8UC1);
  for (int y = 0; y < size.height; ++y) {
    for (int x = 0; x < size.width; ++x) {
      if (color) {
        image.at<cv::Vec3b>(y, x) = cv::Vec3b(uint8_t(4 * x), uint8_t(5 * y), uint8_t(x + y));
      } else {
        image.at<uint8_t>(y, x) = uint8_t(3 * x + 2 * y);
      }
    }
  }
  return image;
}

TEST(CompressedImageTest, JpegAndPngImages) {
  for (const char* extension : {".jpg", ".png"}) {
    for (const bool color : {false, true}) {
      SCOPED_TRACE(std::string(extension) + (color ? " colour" : " grey"));
      const std::vector<uint8_t> bytes = Encoded(extension, Gradient({48, 32}, color));
      const std::string format =
          extension == std::string(".jpg") ? "rgb8; jpeg compressed bgr8" : "png";
      const CompressedImageMessage m = Compressed(format, bytes);
      const StatusOr<ImageLayout> layout = InspectImage(m, ImageRole::kImage);
      ASSERT_TRUE(layout.ok()) << layout.status().ToString();
      EXPECT_EQ(layout->size, cv::Size(48, 32));
      EXPECT_EQ(layout->color, color);
      cv::Mat gray, color_pixels;
      ASSERT_TRUE(DecodeGray(m, &gray, &color_pixels).ok());
      if (color) {
        ExpectEqualPixels(color_pixels, cv::imdecode(bytes, cv::IMREAD_COLOR));
        cv::Mat expected_gray;
        cv::cvtColor(color_pixels, expected_gray, cv::COLOR_BGR2GRAY);
        ExpectEqualPixels(gray, expected_gray);
      } else {
        EXPECT_TRUE(color_pixels.empty());
        ExpectEqualPixels(gray, cv::imdecode(bytes, cv::IMREAD_GRAYSCALE));
      }
      ASSERT_TRUE(DecodeGray(m, &gray, nullptr).ok());
      ExpectEqualPixels(gray, cv::imdecode(bytes, cv::IMREAD_GRAYSCALE));
    }
  }
}

TEST(CompressedImageTest, RefusesFormatsAndDataThatAreNoImage) {
  const std::vector<uint8_t> jpeg = Encoded(".jpg", Gradient({16, 16}, false));
  const std::vector<uint8_t> png = Encoded(".png", Gradient({16, 16}, false));
  const std::vector<uint8_t> garbage(64, 7);
  cv::Mat gray;
  EXPECT_REFUSED(InspectImage(Compressed("theora", jpeg), ImageRole::kImage).status(),
                 "format 'theora' is not supported for an image topic (JPEG or PNG)");
  EXPECT_REFUSED(DecodeGray(Compressed("jpeg", garbage), &gray, nullptr),
                 "format 'jpeg', but its data is neither a JPEG nor a PNG");
  EXPECT_REFUSED(
      InspectImage(Compressed("16UC1; compressedDepth", WithDepthHeader(jpeg)), ImageRole::kImage)
          .status(),
      "(compressed_depth_image_transport's depth) is not supported for an image topic");
  // A PNG cut after its header: inspected, but it does not decode.
  const std::vector<uint8_t> cut(png.begin(), png.begin() + 40);
  ASSERT_TRUE(InspectImage(Compressed("png", cut), ImageRole::kImage).ok());
  EXPECT_REFUSED(DecodeGray(Compressed("png", cut), &gray, nullptr), "its data does not decode");
  EXPECT_TRUE(gray.empty());
}

TEST(CompressedImageTest, RefusesHeadersBeyondTheSizeLimits) {
  std::vector<uint8_t> png = Encoded(".png", Gradient({16, 16}, false));
  png[16] = 0x7f;  // IHDR width 0x7f000010
  EXPECT_REFUSED(InspectImage(Compressed("png", png), ImageRole::kImage).status(),
                 "its PNG header says: an image of 2130706448 x 16 pixels");
  png[16] = 0;
  png[18] = 0x20;  // width 8192 x 16: allowed
  png[19] = 0;
  ASSERT_TRUE(InspectImage(Compressed("png", png), ImageRole::kImage).ok());
  png[22] = 0x20;  // height 8208: more pixels than an encoded image may have
  png[23] = 0x10;
  EXPECT_REFUSED(InspectImage(Compressed("png", png), ImageRole::kImage).status(),
                 "an image of 8192 x 8208 pixels (an encoded image has at most 67108864)");
}

// ---- Compressed depth ----

TEST(CompressedDepthTest, SixteenBitPng) {
  const cv::Mat millimetres = DepthMillimetres();
  const std::vector<uint8_t> png = Encoded(".png", millimetres);
  const CompressedImageMessage m = Compressed("16UC1; png compressed ", png);
  const StatusOr<ImageLayout> layout = InspectImage(m, ImageRole::kDepth);
  ASSERT_TRUE(layout.ok()) << layout.status().ToString();
  EXPECT_EQ(layout->size, millimetres.size());
  EXPECT_EQ(layout->depth_type, CV_16UC1);
  cv::Mat depth;
  ASSERT_TRUE(DecodeDepth(m, &depth).ok());
  ExpectEqualPixels(depth, cv::imdecode(png, cv::IMREAD_ANYDEPTH));
  ExpectEqualPixels(depth, millimetres);
}

// "16UC1; compressedDepth" (Spot's bag: its header's quantisation floats are uninitialised bytes,
// unused for millimetres), "... png", and mono16.
TEST(CompressedDepthTest, CompressedDepthPngOfMillimetres) {
  const cv::Mat millimetres = DepthMillimetres();
  const std::vector<uint8_t> png = Encoded(".png", millimetres);
  const std::vector<uint8_t> data = WithDepthHeader(png, 1.9e9f, -3.5e-20f);
  for (const char* format :
       {"16UC1; compressedDepth", "16UC1; compressedDepth png", "mono16; compressedDepth png"}) {
    SCOPED_TRACE(format);
    const CompressedImageMessage m = Compressed(format, data);
    const StatusOr<ImageLayout> layout = InspectImage(m, ImageRole::kDepth);
    ASSERT_TRUE(layout.ok()) << layout.status().ToString();
    EXPECT_EQ(layout->size, millimetres.size());
    EXPECT_EQ(layout->depth_type, CV_16UC1);
    cv::Mat depth;
    ASSERT_TRUE(DecodeDepth(m, &depth).ok());
    ExpectEqualPixels(depth, cv::imdecode(png, cv::IMREAD_ANYDEPTH));
    ExpectEqualPixels(depth, millimetres);
  }
}

TEST(CompressedDepthTest, CompressedDepthRvlOfMillimetres) {
  const cv::Mat millimetres = DepthMillimetres();
  const std::vector<uint8_t> data = WithDepthHeader(Rvl(millimetres));
  const CompressedImageMessage m = Compressed("16UC1; compressedDepth rvl", data);
  const StatusOr<ImageLayout> layout = InspectImage(m, ImageRole::kDepth);
  ASSERT_TRUE(layout.ok()) << layout.status().ToString();
  EXPECT_EQ(layout->size, millimetres.size());
  EXPECT_EQ(layout->depth_type, CV_16UC1);
  cv::Mat depth;
  const Status status = DecodeDepth(m, &depth);
  ASSERT_TRUE(status.ok()) << status.ToString();
  ExpectEqualPixels(depth, millimetres);
}

TEST(CompressedDepthTest, InverseDepthPngAndRvlToMetres) {
  const cv::Mat metres = DepthMetres();
  const InverseDepth inverse = Quantised(metres);
  const struct {
    const char* format;
    std::vector<uint8_t> payload;
  } cases[] = {{"32FC1; compressedDepth", Encoded(".png", inverse.q)},
               {"32FC1; compressedDepth png", Encoded(".png", inverse.q)},
               {"32FC1; compressedDepth rvl", Rvl(inverse.q)}};
  for (const auto& c : cases) {
    SCOPED_TRACE(c.format);
    const std::vector<uint8_t> data = WithDepthHeader(c.payload, inverse.a, inverse.b);
    const CompressedImageMessage m = Compressed(c.format, data);
    const StatusOr<ImageLayout> layout = InspectImage(m, ImageRole::kDepth);
    ASSERT_TRUE(layout.ok()) << layout.status().ToString();
    EXPECT_EQ(layout->depth_type, CV_32FC1);
    EXPECT_EQ(layout->size, metres.size());
    cv::Mat depth;
    const Status status = DecodeDepth(m, &depth);
    ASSERT_TRUE(status.ok()) << status.ToString();
    ExpectInverseDepth(depth, metres, inverse);
  }
}

TEST(CompressedDepthTest, RefusesWhatIsNoSixteenBitDepth) {
  const std::vector<uint8_t> png8 = Encoded(".png", Gradient({16, 8}, false));
  const std::vector<uint8_t> png16 = Encoded(".png", DepthMillimetres());
  const std::vector<uint8_t> jpeg = Encoded(".jpg", Gradient({16, 8}, false));
  cv::Mat depth;
  EXPECT_REFUSED(DecodeDepth(Compressed("16UC1; compressedDepth", WithDepthHeader(png8)), &depth),
                 "the data after its compressedDepth header is not a 16-bit grey PNG");
  EXPECT_REFUSED(DecodeDepth(Compressed("16UC1; png compressed", png8), &depth),
                 "its data (8-bit grey PNG) is not supported for depth");
  EXPECT_REFUSED(DecodeDepth(Compressed("mono8; jpeg compressed", jpeg), &depth),
                 "its data (8-bit grey JPEG) is not supported for depth");
  EXPECT_REFUSED(InspectImage(Compressed("theora", png16), ImageRole::kDepth).status(),
                 "format 'theora' is not supported for a depth topic");
  EXPECT_REFUSED(DecodeDepth(Compressed("8UC1; compressedDepth", WithDepthHeader(png16)), &depth),
                 "compressedDepth of encoding '8UC1' is not supported (16UC1, mono16, 32FC1)");
  EXPECT_REFUSED(
      DecodeDepth(Compressed("16UC1; compressedDepth zstd", WithDepthHeader(png16)), &depth),
      "compressedDepth compression 'zstd' is not supported (png, rvl)");
  EXPECT_REFUSED(
      DecodeDepth(Compressed("16UC1; compressedDepth", std::vector<uint8_t>(12)), &depth),
      "its data of 12 bytes is no longer than the 12-byte compressedDepth header");
  EXPECT_TRUE(depth.empty());
}

TEST(CompressedDepthTest, RefusesTruncatedPng) {
  const std::vector<uint8_t> data = WithDepthHeader(Encoded(".png", DepthMillimetres()));
  const std::vector<uint8_t> cut(data.begin(), data.end() - 100);
  const CompressedImageMessage m = Compressed("16UC1; compressedDepth", cut);
  ASSERT_TRUE(InspectImage(m, ImageRole::kDepth).ok());
  cv::Mat depth;
  EXPECT_EQ(DecodeDepth(m, &depth).code(), StatusCode::kInvalidArgument);
}

TEST(CompressedDepthTest, RefusesTruncatedRvl) {
  const std::vector<uint8_t> data = WithDepthHeader(Rvl(DepthMillimetres()));
  for (const size_t cut : {size_t(4), size_t(9), data.size() - 20}) {
    SCOPED_TRACE(cut);
    const std::vector<uint8_t> shorter(data.begin(), data.end() - long(cut));
    const CompressedImageMessage m = Compressed("16UC1; compressedDepth rvl", shorter);
    ASSERT_TRUE(InspectImage(m, ImageRole::kDepth).ok());  // the header alone
    cv::Mat depth;
    EXPECT_REFUSED(DecodeDepth(m, &depth), "of its 1200 pixels (it ends");
  }
  // Cut inside the RVL size.
  const std::vector<uint8_t> no_size(data.begin(), data.begin() + 16);
  EXPECT_REFUSED(
      InspectImage(Compressed("16UC1; compressedDepth rvl", no_size), ImageRole::kDepth).status(),
      "its data ends inside the RVL image size");
}

// Runs past the image's end are refused, never written.
TEST(CompressedDepthTest, RefusesRvlRunsPastTheImage) {
  const auto rvl_of = [](const std::vector<uint64_t>& values) {
    RvlWriter writer;
    for (uint64_t value : values) writer.Value(value);
    std::vector<uint8_t> payload = RvlSize(4, 2);
    const std::vector<uint8_t> words = writer.Finish();
    payload.insert(payload.end(), words.begin(), words.end());
    return WithDepthHeader(payload);
  };
  cv::Mat depth;
  const std::vector<uint8_t> zeros = rvl_of({9, 0});
  EXPECT_REFUSED(DecodeDepth(Compressed("16UC1; compressedDepth rvl", zeros), &depth),
                 "its RVL stream gives a run of 9 pixels after 0, past its 8 pixels");
  const std::vector<uint8_t> nonzeros = rvl_of({3, 6, 2, 2, 2, 2, 2, 2});
  EXPECT_REFUSED(DecodeDepth(Compressed("16UC1; compressedDepth rvl", nonzeros), &depth),
                 "its RVL stream gives a run of 6 pixels after 3, past its 8 pixels");
  const std::vector<uint8_t> huge = rvl_of({uint64_t(1) << 32, 0});
  EXPECT_REFUSED(DecodeDepth(Compressed("16UC1; compressedDepth rvl", huge), &depth),
                 "a run of 4294967296 pixels");
  // A value that never ends (every nibble says another follows).
  std::vector<uint8_t> endless = RvlSize(4, 2);
  endless.insert(endless.end(), 16, 0xff);
  EXPECT_REFUSED(
      DecodeDepth(Compressed("16UC1; compressedDepth rvl", WithDepthHeader(endless)), &depth),
      "a value runs past 33 bits");
  // The exact image: 8 pixels, accepted.
  const std::vector<uint8_t> exact = rvl_of({3, 5, 2, 2, 2, 2, 2});
  ASSERT_TRUE(DecodeDepth(Compressed("16UC1; compressedDepth rvl", exact), &depth).ok());
  ExpectEqualPixels(depth, (cv::Mat_<uint16_t>(2, 4) << 0, 0, 0, 1, 2, 3, 4, 5));
}

// Any byte of an RVL stream set to another value: decoded to the image's size or refused.
TEST(CompressedDepthTest, CorruptRvlIsDecodedOrRefused) {
  const std::vector<uint8_t> data = WithDepthHeader(Rvl(DepthMillimetres()));
  int refused = 0;
  for (size_t at = 20; at < data.size(); ++at) {
    for (const uint8_t value : {0x00, 0x88, 0xff}) {
      std::vector<uint8_t> corrupt = data;
      corrupt[at] = value;
      cv::Mat depth;
      const Status status = DecodeDepth(Compressed("16UC1; compressedDepth rvl", corrupt), &depth);
      if (status.ok()) {
        EXPECT_EQ(depth.size(), cv::Size(40, 30));
        continue;
      }
      ++refused;
      ASSERT_EQ(status.code(), StatusCode::kInvalidArgument) << status.ToString();
    }
  }
  EXPECT_GT(refused, 0);
}

TEST(CompressedDepthTest, RefusesRvlSizesBeyondTheLimits) {
  for (const auto& [width, height, text] :
       {std::tuple<uint32_t, uint32_t, const char*>{0, 480, "an image of 0 x 480 pixels"},
        {70000, 1, "an image of 70000 x 1 pixels"},
        {65536, 65536, "an image of 65536 x 65536 pixels (an encoded image has at most"}}) {
    std::vector<uint8_t> payload = RvlSize(width, height);
    payload.resize(payload.size() + 8, 0);
    EXPECT_REFUSED(InspectImage(Compressed("16UC1; compressedDepth rvl", WithDepthHeader(payload)),
                                ImageRole::kDepth)
                       .status(),
                   std::string("its RVL header says: ") + text);
  }
}

}  // namespace
}  // namespace recog::bag
