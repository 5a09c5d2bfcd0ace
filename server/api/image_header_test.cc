// The image header reader and the pixel budget: what the server refuses before decoding.
#include "server/api/image_header.h"

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "server/api/converters.h"

namespace recog::server {
namespace {

std::string Encoded(const char* extension, int width, int height) {
  std::vector<uchar> bytes;
  EXPECT_TRUE(cv::imencode(extension, cv::Mat(height, width, CV_8UC1, cv::Scalar(80)), bytes));
  return std::string(bytes.begin(), bytes.end());
}

// The first bytes of a PNG declaring width x height (what a decompression bomb starts with).
std::string PngHeader(uint32_t width, uint32_t height) {
  std::string bytes("\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR", 16);
  for (uint32_t v : {width, height}) {
    for (int shift = 24; shift >= 0; shift -= 8) bytes += char((v >> shift) & 0xFF);
  }
  return bytes + std::string("\x08\x00\x00\x00\x00", 5);
}

// A JPEG's start, an APP0 segment, then a baseline frame header of width x height.
std::string JpegHeader(uint32_t width, uint32_t height) {
  std::string bytes("\xFF\xD8\xFF\xE0\x00\x04\x00\x00\xFF\xFF\xC0\x00\x0B\x08", 14);
  for (uint32_t v : {height, width}) bytes += {char(v >> 8), char(v & 0xFF)};
  return bytes + std::string("\x01\x01\x11\x00", 4);
}

TEST(ImageHeaderTest, TheSizeOfARealPngAndJpegIsReadFromTheirHeaders) {
  const auto png = ReadImageHeader(Encoded(".png", 321, 123), "f");
  ASSERT_TRUE(png.ok()) << png.status().ToString();
  EXPECT_EQ(png->format, ImageHeader::Format::kPng);
  EXPECT_EQ(png->width, 321u);
  EXPECT_EQ(png->height, 123u);
  const auto jpeg = ReadImageHeader(Encoded(".jpg", 320, 240), "f");
  ASSERT_TRUE(jpeg.ok()) << jpeg.status().ToString();
  EXPECT_EQ(jpeg->format, ImageHeader::Format::kJpeg);
  EXPECT_EQ(jpeg->width, 320u);
  EXPECT_EQ(jpeg->height, 240u);
}

TEST(ImageHeaderTest, AHugeDeclaredSizeIsReadWithoutTheRestOfTheFile) {
  const auto png = ReadImageHeader(PngHeader(20000, 20000), "f");
  ASSERT_TRUE(png.ok());
  EXPECT_EQ(png->width, 20000u);
  const auto jpeg = ReadImageHeader(JpegHeader(20000, 30000), "f");
  ASSERT_TRUE(jpeg.ok()) << jpeg.status().ToString();
  EXPECT_EQ(jpeg->width, 20000u);
  EXPECT_EQ(jpeg->height, 30000u);
}

TEST(ImageHeaderTest, OtherFormatsAndBrokenHeadersAreRefusedNamingTheField) {
  for (const std::string& bytes :
       {std::string("GIF89a garbage"), Encoded(".bmp", 8, 8), std::string("\x89PNG\r\n\x1a\n", 8),
        PngHeader(1, 1).substr(0, 20), std::string("\xFF\xD8\xFF\xDA\x00\x02", 6),
        std::string("\xFF\xD8\xFF\xE0\x00\x40", 6), JpegHeader(10, 10).substr(0, 16),
        std::string("\xFF\xD8\xFF", 3)}) {
    const auto header = ReadImageHeader(bytes, "frame.encoded_image");
    ASSERT_FALSE(header.ok()) << bytes.size();
    EXPECT_EQ(header.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(header.status().message().find("frame.encoded_image"), std::string::npos);
  }
}

TEST(PixelBudgetTest, EachImageAndTheWholeCallAreBounded) {
  PixelBudget budget;
  EXPECT_EQ(budget.Take(0, 10, "a").code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(budget.Take(kMaxImageSide + 1, 1, "a").code(), StatusCode::kInvalidArgument);
  const Status huge = budget.Take(20000, 20000, "frame.encoded_image");
  EXPECT_EQ(huge.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(huge.message().find("20000x20000"), std::string::npos) << huge.message();
  // Refusals charge nothing: the whole budget is still there.
  EXPECT_TRUE(budget.Take(8192, 4096, "first").ok());   // 32 Mpixel
  EXPECT_TRUE(budget.Take(8192, 4096, "second").ok());  // 64 Mpixel in all
  const Status over = budget.Take(1, 1, "frames[2]");
  EXPECT_EQ(over.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(over.message().find("frames[2]"), std::string::npos);
}

TEST(PixelBudgetTest, AFrameWhoseImageIsBeyondTheCallsBudgetIsRefusedBeforeDecoding) {
  PixelBudget budget;
  ASSERT_TRUE(budget.Take(8192, 8192, "an earlier frame").ok());  // the whole budget
  pb::Frame frame;
  frame.set_encoded_image(Encoded(".png", 640, 480));
  const auto decoded = DecodeFrame(frame, DescriptorFormat::Orb(), budget);
  ASSERT_FALSE(decoded.ok());
  EXPECT_NE(decoded.status().message().find("together"), std::string::npos)
      << decoded.status().ToString();
  PixelBudget fresh;
  EXPECT_TRUE(DecodeFrame(frame, DescriptorFormat::Orb(), fresh).ok());
}

TEST(PixelBudgetTest, A20000By20000PngOrJpegHeaderIsRefusedNamingItsSize) {
  for (const std::string& bytes : {PngHeader(20000, 20000), JpegHeader(20000, 20000)}) {
    PixelBudget budget;
    pb::Frame frame;
    frame.set_encoded_image(bytes);
    const auto decoded = DecodeFrame(frame, DescriptorFormat::Orb(), budget);
    ASSERT_FALSE(decoded.ok());
    EXPECT_NE(decoded.status().message().find("too large (20000x20000"), std::string::npos)
        << decoded.status().ToString();
  }
}

}  // namespace
}  // namespace recog::server
