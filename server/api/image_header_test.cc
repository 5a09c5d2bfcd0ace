// The image header reader and the pixel budget: what the server refuses before decoding, among it
// the decompression bombs under the pixel cap (a progressive CMYK JPEG, a JPEG of hundreds of
// empty scans, a PNG declaring 16-bit RGBA), built here byte by byte, and every format robots send,
// which must still be decoded.
#include "server/api/image_header.h"

#include <chrono>
#include <fstream>
#include <functional>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "server/api/frame_decoding.h"

namespace recog::server {
namespace {

constexpr uint64_t kMiB = 1 << 20;

std::string Encoded(const char* extension, const cv::Mat& image,
                    const std::vector<int>& params = {}) {
  std::vector<uchar> bytes;
  EXPECT_TRUE(cv::imencode(extension, image, bytes, params));
  return std::string(bytes.begin(), bytes.end());
}

std::string Encoded(const char* extension, int width, int height) {
  return Encoded(extension, cv::Mat(height, width, CV_8UC1, cv::Scalar(80)));
}

// A width x height image of `type` (8 or 16 bits, 1 to 4 channels) with a gradient in every
// channel: compresses like a photo, quickly.
cv::Mat Gradient(int width, int height, int type) {
  cv::Mat row(1, width, CV_MAKETYPE(CV_MAT_DEPTH(type), 1));
  const double scale = CV_MAT_DEPTH(type) == CV_16U ? 257 : 1;
  for (int x = 0; x < width; ++x) row.col(x).setTo(cv::Scalar((x % 256) * scale));
  cv::Mat plane, image;
  cv::repeat(row, height, 1, plane);
  cv::merge(std::vector<cv::Mat>(size_t(CV_MAT_CN(type)), plane), image);
  return image;
}

void AppendBigEndian(std::string* out, uint32_t value, int bytes = 4) {
  for (int shift = 8 * (bytes - 1); shift >= 0; shift -= 8) out->push_back(char(value >> shift));
}

uint32_t Crc32(std::string_view bytes) {
  uint32_t crc = 0xFFFFFFFF;
  for (const char c : bytes) {
    crc ^= uint8_t(c);
    for (int bit = 0; bit < 8; ++bit) crc = (crc >> 1) ^ (0xEDB88320 & (0 - (crc & 1)));
  }
  return ~crc;
}

void AppendPngChunk(std::string* png, const char* type, const std::string& data) {
  AppendBigEndian(png, uint32_t(data.size()));
  const std::string typed = std::string(type, 4) + data;
  *png += typed;
  AppendBigEndian(png, Crc32(typed));
}

// `data` as a zlib stream of stored (uncompressed) deflate blocks.
std::string StoredZlib(const std::string& data) {
  std::string out("\x78\x01", 2);
  size_t at = 0;
  do {
    const size_t size = std::min<size_t>(data.size() - at, 65535);
    out += char(at + size == data.size() ? 1 : 0);  // the final block?
    for (const uint32_t v : {uint32_t(size), uint32_t(~size & 0xFFFF)}) {
      out += {char(v & 0xFF), char(v >> 8)};  // little-endian
    }
    out += data.substr(at, size);
    at += size;
  } while (at < data.size());
  uint32_t a = 1, b = 0;  // Adler-32
  for (const char c : data) {
    a = (a + uint8_t(c)) % 65521;
    b = (b + a) % 65521;
  }
  AppendBigEndian(&out, (b << 16) | a);
  return out;
}

// A PNG of width x height, `bit_depth` and `colour_type`, whose image data is `pixels` (the
// filtered rows) in a zlib stream: a palette image, or a bomb when `pixels` is far too short.
std::string Png(uint32_t width, uint32_t height, uint8_t bit_depth, uint8_t colour_type,
                const std::string& pixels, const std::string& palette = "") {
  std::string png("\x89PNG\r\n\x1a\n", 8);
  std::string header;
  AppendBigEndian(&header, width);
  AppendBigEndian(&header, height);
  header += {char(bit_depth), char(colour_type), 0, 0, 0};
  AppendPngChunk(&png, "IHDR", header);
  if (!palette.empty()) AppendPngChunk(&png, "PLTE", palette);
  AppendPngChunk(&png, "IDAT", StoredZlib(pixels));
  AppendPngChunk(&png, "IEND", "");
  return png;
}

// The bytes of a JPEG from its start to its scans: a quantisation table, a frame header of marker
// `sof` (0xC0 baseline, 0xC2 progressive) declaring width x height and one component a sampling
// factor (0x11: 1 x 1; 0x22 for the first and 0x11 for two more: YCbCr 4:2:0), and a DC Huffman
// table; then `scans` scans of all the components without data, then the end.
std::string Jpeg(uint8_t sof, uint16_t width, uint16_t height, const std::vector<uint8_t>& sampling,
                 int scans) {
  std::string jpeg("\xFF\xD8\xFF\xDB\x00\x43\x00", 7);
  jpeg += std::string(64, '\x01');
  jpeg += {'\xFF', char(sof)};
  AppendBigEndian(&jpeg, uint32_t(8 + 3 * sampling.size()), 2);
  jpeg += char(8);
  AppendBigEndian(&jpeg, height, 2);
  AppendBigEndian(&jpeg, width, 2);
  jpeg += char(sampling.size());
  for (size_t c = 0; c < sampling.size(); ++c) jpeg += {char(c + 1), char(sampling[c]), 0};
  // One DC code: a single 1-bit code for the difference category 0.
  jpeg += std::string("\xFF\xC4\x00\x14\x00\x01", 6) + std::string(16, '\0');
  for (int s = 0; s < scans; ++s) {
    jpeg += "\xFF\xDA";
    AppendBigEndian(&jpeg, uint32_t(6 + 2 * sampling.size()), 2);
    jpeg += char(sampling.size());
    for (size_t c = 0; c < sampling.size(); ++c) jpeg += {char(c + 1), 0};
    jpeg += std::string(3, '\0');  // the DC coefficient, first pass
  }
  return jpeg + "\xFF\xD9";
}

// The bombs the server took in before it charged decoding memory.
// A 150-byte progressive CMYK JPEG: libjpeg holds every coefficient, 128 MiB at 4096x4096 (the
// probe's was 8192x8192, 512 MiB, which the pixel cap now refuses first).
std::string ProgressiveCmykBomb() { return Jpeg(0xC2, 4096, 4096, {0x11, 0x11, 0x11, 0x11}, 1); }
// 300 empty scans in 5 KB: each one a pass of the decoder over the whole image (7 s in all).
std::string ManyScansBomb() { return Jpeg(0xC2, 4096, 4096, {0x11, 0x11, 0x11, 0x11}, 300); }
// A 16384x4096 16-bit RGBA PNG whose data is a few bytes: decoded whole at full depth (as depth
// is), 512 MiB.
std::string DeepPngBomb() { return Png(16384, 4096, 16, 6, std::string(16, '\0')); }

StatusOr<ImageHeader> HeaderOf(const std::string& bytes) { return ReadImageHeader(bytes, "f"); }

// A kB figure of /proc/self/status ("VmRSS:", "VmHWM:").
int64_t ProcessStatusKiB(const std::string& key) {
  std::ifstream status("/proc/self/status");
  for (std::string line; std::getline(status, line);) {
    if (line.starts_with(key)) return std::stoll(line.substr(key.size()));
  }
  return -1;
}

// How much `run` raised the process's resident memory, in MiB: its peak (VmHWM, reset first
// through /proc/self/clear_refs) when the kernel lets it be reset, else what stays resident.
double ResidentGrowthMiB(const std::function<void()>& run) {
  std::ofstream("/proc/self/clear_refs") << "5";
  const int64_t before = ProcessStatusKiB("VmRSS:");
  const bool peak_reset = ProcessStatusKiB("VmHWM:") <= before + 1024;
  run();
  return double(ProcessStatusKiB(peak_reset ? "VmHWM:" : "VmRSS:") - before) / 1024;
}

// The first bytes of a PNG declaring width x height (what a decompression bomb starts with).
std::string PngHeader(uint32_t width, uint32_t height) {
  std::string bytes("\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR", 16);
  AppendBigEndian(&bytes, width);
  AppendBigEndian(&bytes, height);
  return bytes + std::string("\x08\x00\x00\x00\x00", 5);
}

// A JPEG's start, an APP0 segment, then a baseline frame header of width x height.
std::string JpegHeader(uint32_t width, uint32_t height) {
  std::string bytes("\xFF\xD8\xFF\xE0\x00\x04\x00\x00\xFF\xFF\xC0\x00\x0B\x08", 14);
  AppendBigEndian(&bytes, height, 2);
  AppendBigEndian(&bytes, width, 2);
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
  EXPECT_EQ(budget.Take(8192, 4096, "frame.encoded_image").code(), StatusCode::kInvalidArgument);
  for (const char* view : {"first", "second", "third", "fourth"}) {
    EXPECT_TRUE(budget.Take(4096, 4096, view).ok()) << view;  // 16 Mpixel each, 64 in all
  }
  const Status over = budget.Take(1, 1, "frames[2]");
  EXPECT_EQ(over.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(over.message().find("frames[2]"), std::string::npos);
}

TEST(PixelBudgetTest, AFrameWhoseImageIsBeyondTheCallsBudgetIsRefusedBeforeDecoding) {
  PixelBudget budget;
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(budget.Take(4096, 4096, "an earlier frame").ok());
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

TEST(ImageHeaderTest, TheLayoutOfRealImagesIsReadFromTheirHeaders) {
  for (const int type : {CV_8UC1, CV_16UC1, CV_8UC3, CV_16UC3, CV_8UC4, CV_16UC4}) {
    const auto png = HeaderOf(Encoded(".png", Gradient(64, 48, type)));
    ASSERT_TRUE(png.ok()) << png.status().ToString();
    EXPECT_EQ(png->components, uint32_t(CV_MAT_CN(type)));
    EXPECT_EQ(png->bit_depth, CV_ELEM_SIZE1(type) * 8u);
    EXPECT_FALSE(png->palette);
  }
  const auto palette = HeaderOf(Png(4, 1, 8, 3, std::string(5, '\0'), std::string(6, '\x40')));
  ASSERT_TRUE(palette.ok()) << palette.status().ToString();
  EXPECT_TRUE(palette->palette);
  EXPECT_EQ(palette->components, 1u);

  const auto baseline = HeaderOf(Encoded(".jpg", Gradient(64, 48, CV_8UC3)));
  ASSERT_TRUE(baseline.ok()) << baseline.status().ToString();
  EXPECT_EQ(baseline->components, 3u);
  EXPECT_FALSE(baseline->progressive);
  EXPECT_EQ(baseline->scans, 1u);
  EXPECT_EQ(baseline->first_scan_components, 3u);
  for (const int type : {CV_8UC1, CV_8UC3}) {
    const std::string bytes =
        Encoded(".jpg", Gradient(64, 48, type), {cv::IMWRITE_JPEG_PROGRESSIVE, 1});
    const auto progressive = HeaderOf(bytes);
    ASSERT_TRUE(progressive.ok()) << progressive.status().ToString();
    EXPECT_EQ(progressive->components, uint32_t(CV_MAT_CN(type)));
    EXPECT_TRUE(progressive->progressive);
    // Every start of scan, each a marker a byte search finds too.
    size_t markers = 0;
    for (size_t at = bytes.find("\xFF\xDA"); at != std::string::npos;
         at = bytes.find("\xFF\xDA", at + 1)) {
      ++markers;
    }
    EXPECT_EQ(progressive->scans, markers);
    EXPECT_GT(progressive->scans, 1u);
    EXPECT_LE(progressive->scans, kMaxJpegScans);
  }
}

TEST(ImageHeaderTest, AJpegsMinimumCodedUnitFollowsItsSamplingFactors) {
  const auto yuv420 = HeaderOf(Jpeg(0xC0, 100, 50, {0x22, 0x11, 0x11}, 1));
  ASSERT_TRUE(yuv420.ok()) << yuv420.status().ToString();
  EXPECT_EQ(yuv420->mcu_width, 16u);
  EXPECT_EQ(yuv420->mcu_height, 16u);
  EXPECT_EQ(yuv420->blocks_per_mcu, 6u);
  const auto yuv422 = HeaderOf(Jpeg(0xC2, 100, 50, {0x21, 0x11, 0x11}, 1));
  ASSERT_TRUE(yuv422.ok());
  EXPECT_EQ(yuv422->mcu_width, 16u);
  EXPECT_EQ(yuv422->mcu_height, 8u);
  EXPECT_EQ(yuv422->blocks_per_mcu, 4u);
  EXPECT_TRUE(yuv422->progressive);
  EXPECT_FALSE(HeaderOf(Jpeg(0xC0, 100, 50, {0x51}, 1)).ok());  // sampling factors are 1..4
  EXPECT_FALSE(HeaderOf(Png(4, 4, 16, 3, "")).ok());            // no 16-bit palette in PNG
}

TEST(ImageHeaderTest, ScansAreCountedOverTheWholeFileAsLibjpegReadsThem) {
  std::string jpeg = Jpeg(0xC0, 64, 48, {0x11}, 0);
  jpeg.resize(jpeg.size() - 2);  // no end yet
  // An EXIF segment holding a thumbnail's scan: skipped by its length.
  jpeg.insert(2, std::string("\xFF\xE1\x00\x08\xFF\xDA\x00\x08", 8));
  const std::string scan("\xFF\xDA\x00\x08\x01\x01\x00\x00\x3F\x00", 10);
  jpeg += scan;
  jpeg += std::string("\x12\xFF\x00\x34\xFF\xD0\x56", 7);  // data: a 0xFF byte, a restart
  jpeg += std::string("\x78\x9A", 2) + "\xFF\xFF" + scan;  // stray bytes, fill, a scan
  jpeg += std::string("\xFF\xD9", 2) + scan;               // the end, then what is not read
  const auto header = HeaderOf(jpeg);
  ASSERT_TRUE(header.ok()) << header.status().ToString();
  EXPECT_EQ(header->scans, 2u);
  EXPECT_EQ(header->first_scan_components, 1u);
  // Cut short after the frame header: what came before counts, as libjpeg decodes it.
  const auto cut = HeaderOf(jpeg.substr(0, jpeg.find(scan) + 4));
  ASSERT_TRUE(cut.ok()) << cut.status().ToString();
  EXPECT_EQ(cut->scans, 0u);
}

TEST(ImageHeaderTest, DecodingMemoryIsTheImageAndTheDecodersBuffers) {
  // A baseline JPEG and a PNG are decoded a few rows at a time, into the image.
  for (const std::string& bytes :
       {Jpeg(0xC0, 4096, 3072, {0x22, 0x11, 0x11}, 1), Png(4096, 3072, 16, 6, "")}) {
    const DecodeMemory memory = MemoryToDecode(*HeaderOf(bytes), 1);
    EXPECT_EQ(memory.image, 4096u * 3072u);
    EXPECT_GT(memory.decoder, 0u);
    EXPECT_LT(memory.decoder, kMiB);
  }
  EXPECT_EQ(MemoryToDecode(*HeaderOf(Png(640, 480, 16, 0, "")), 2).image, 640u * 480u * 2u);
  // A progressive JPEG, or a sequential one in several scans, is held as coefficients: 2 bytes
  // a sample, the chroma of 4:2:0 a quarter of the luma's.
  const uint64_t pixels = 4096u * 3072u;
  for (const auto& [bytes, samples] : std::vector<std::pair<std::string, double>>{
           {Jpeg(0xC2, 4096, 3072, {0x22, 0x11, 0x11}, 1), 1.5},
           {Jpeg(0xC2, 4096, 3072, {0x11, 0x11, 0x11}, 1), 3},
           {Jpeg(0xC2, 4096, 3072, {0x11, 0x11, 0x11, 0x11}, 1), 4}}) {
    const DecodeMemory memory = MemoryToDecode(*HeaderOf(bytes), 1);
    EXPECT_GE(memory.decoder, uint64_t(2 * samples * double(pixels)));
    EXPECT_LT(memory.decoder, uint64_t(2 * samples * double(pixels)) + kMiB);
  }
  std::string two_scans = Jpeg(0xC0, 4096, 3072, {0x11, 0x11}, 2);
  two_scans[two_scans.find("\xFF\xDA") + 4] = 1;  // its first scan codes 1 of 2 components
  EXPECT_GE(MemoryToDecode(*HeaderOf(two_scans), 1).decoder, 2 * 2 * pixels);
}

TEST(PixelBudgetTest, TheLargestImagesRobotsSendFitOneImagesDecodingMemory) {
  for (const std::string& bytes : {Jpeg(0xC2, 4096, 3072, {0x11, 0x11, 0x11}, 10),
                                   Jpeg(0xC0, 4096, 3072, {0x11, 0x11, 0x11}, 1),
                                   Png(4096, 3072, 16, 6, ""), Png(4096, 3072, 8, 3, "")}) {
    const auto header = HeaderOf(bytes);
    ASSERT_TRUE(header.ok()) << header.status().ToString();
    const Status taken = PixelBudget().Take(*header, "frame.encoded_image");
    EXPECT_TRUE(taken.ok()) << taken.ToString();
  }
  const auto depth = HeaderOf(Png(4096, 3072, 16, 0, ""));
  EXPECT_TRUE(PixelBudget().Take(*depth, "frame.depth.encoded", 2).ok());
}

std::string MiBText(uint64_t bytes) { return std::to_string((bytes + kMiB - 1) / kMiB) + " MiB"; }

TEST(PixelBudgetTest, ACallsMemoryHoldsItsDecodedImagesAndOneDecoderAtATime) {
  const auto header = HeaderOf(Jpeg(0xC2, 4096, 3072, {0x11, 0x11, 0x11}, 10));
  ASSERT_TRUE(header.ok());
  const DecodeMemory memory = MemoryToDecode(*header, 1);  // 72 MiB of coefficients, 12 of image
  PixelBudget budget(memory.total() + memory.image);       // room for one image and the next decode
  ASSERT_TRUE(budget.Take(*header, "frames[0]").ok());
  ASSERT_TRUE(budget.Take(*header, "frames[1]").ok());  // frames[0]'s coefficients are gone
  const Status third = budget.Take(*header, "frames[2]");
  EXPECT_EQ(third.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(third.message().find("frames[2] (4096x3072 progressive JPEG, 3 components, " +
                                 MiBText(memory.total()) + " to decode) takes the call's " +
                                 "images beyond " + MiBText(memory.total() + memory.image) +
                                 " of memory together (" + MiBText(2 * memory.image) +
                                 " decoded already)"),
            std::string::npos)
      << third.message();
  // What is left still takes smaller images, and raw ones as the copy they make.
  EXPECT_TRUE(budget.Take(640, 480, "frames[3]").ok());
  EXPECT_FALSE(budget.Take(4096, 3072, "frames[4]", 8).ok());
}

// DecodeFrame of `frame` on a budget of its own, and how long it took in seconds.
std::pair<StatusOr<DecodedFrame>, double> TimedDecode(const pb::Frame& frame) {
  PixelBudget budget;
  const auto start = std::chrono::steady_clock::now();
  StatusOr<DecodedFrame> decoded = DecodeFrame(frame, DescriptorFormat::Orb(), budget);
  return {std::move(decoded),
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count()};
}

// A frame of a 64 x 48 image, pinhole intrinsics and `depth` as its encoded depth.
pb::Frame FrameWithDepth(const std::string& depth) {
  pb::Frame frame;
  frame.set_encoded_image(Encoded(".png", 64, 48));
  frame.mutable_intrinsics()->set_fx(50);
  frame.mutable_intrinsics()->set_fy(50);
  frame.mutable_intrinsics()->set_cx(32);
  frame.mutable_intrinsics()->set_cy(24);
  frame.mutable_depth()->set_encoded(depth);
  return frame;
}

TEST(ImageBombTest, AProgressiveCmykJpegIsRefusedForTheCoefficientsItWouldTake) {
  const std::string bomb = ProgressiveCmykBomb();
  EXPECT_LT(bomb.size(), 200u);
  const auto header = HeaderOf(bomb);
  ASSERT_TRUE(header.ok()) << header.status().ToString();
  const DecodeMemory memory = MemoryToDecode(*header, 1);
  EXPECT_GE(memory.decoder, 4096u * 4096u * 4u * 2u);  // 4 components, 2 bytes a coefficient
  pb::Frame frame;
  frame.set_encoded_image(bomb);
  const auto [decoded, seconds] = TimedDecode(frame);
  ASSERT_FALSE(decoded.ok());
  EXPECT_EQ(decoded.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(decoded.status().message().find(
                "frame.encoded_image (4096x4096 progressive JPEG, 4 components) needs " +
                MiBText(memory.total()) + " to decode; at most " + MiBText(kMaxImageDecodeBytes) +
                " an image"),
            std::string::npos)
      << decoded.status().message();
  EXPECT_LT(seconds, 0.5);
  // The same image in baseline, at the largest size allowed, is decoded a row at a time: it costs
  // its pixels.
  const auto baseline = HeaderOf(Jpeg(0xC0, 4096, 4096, {0x11, 0x11, 0x11, 0x11}, 1));
  EXPECT_EQ(PixelBudget()
                .Take(*HeaderOf(Jpeg(0xC2, 8192, 8192, {0x11, 0x11, 0x11, 0x11}, 1)),
                      "frame.encoded_image")
                .code(),
            StatusCode::kInvalidArgument);  // the probe's own: beyond the pixel cap
  EXPECT_TRUE(PixelBudget().Take(*baseline, "frame.encoded_image").ok());
}

TEST(ImageBombTest, AJpegOfHundredsOfScansIsRefusedNamingItsScans) {
  EXPECT_LT(ManyScansBomb().size(), 5000u);
  // One that would fit the memory too.
  for (const std::string& bomb :
       {ManyScansBomb(), Jpeg(0xC2, 4096, 3072, {0x22, 0x11, 0x11}, 300)}) {
    pb::Frame frame;
    frame.set_encoded_image(bomb);
    const auto [decoded, seconds] = TimedDecode(frame);
    ASSERT_FALSE(decoded.ok());
    EXPECT_EQ(decoded.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(
        decoded.status().message().find("frame.encoded_image is a JPEG of 300 scans; at most " +
                                        std::to_string(kMaxJpegScans)),
        std::string::npos)
        << decoded.status().message();
    EXPECT_LT(seconds, 0.5);
  }
  const auto most = HeaderOf(Jpeg(0xC2, 4096, 3072, {0x22, 0x11, 0x11}, kMaxJpegScans));
  EXPECT_TRUE(PixelBudget().Take(*most, "frame.encoded_image").ok());
}

TEST(ImageBombTest, ADeepPngIsRefusedAsDepthFromItsHeaderAndDecodesAsGreyRowByRow) {
  const std::string bomb = DeepPngBomb();
  EXPECT_LT(bomb.size(), 200u);
  // As depth it would be decoded as it is, 8 bytes a pixel: refused from its header.
  const auto [as_depth, depth_seconds] = TimedDecode(FrameWithDepth(bomb));
  ASSERT_FALSE(as_depth.ok());
  EXPECT_EQ(as_depth.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(as_depth.status().message().find("frame.depth.encoded must be a 16-bit single-channel "
                                             "PNG (its header declares 16384x4096 PNG, 16-bit "
                                             "RGBA)"),
            std::string::npos)
      << as_depth.status().message();
  EXPECT_LT(depth_seconds, 0.5);
  // As the image it would be decoded to 8-bit grey a row at a time (its 64 Mpixel and two rows),
  // but the pixel cap refuses 64 Mpixel from the header.
  const DecodeMemory memory = MemoryToDecode(*HeaderOf(bomb), 1);
  EXPECT_EQ(memory.image, 16384u * 4096u);
  EXPECT_LT(memory.decoder, kMiB);
  pb::Frame frame;
  frame.set_encoded_image(bomb);
  const auto [decoded, seconds] = TimedDecode(frame);
  ASSERT_FALSE(decoded.ok());
  EXPECT_EQ(decoded.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(decoded.status().message().find("frame.encoded_image is too large (16384x4096"),
            std::string::npos)
      << decoded.status().message();
  EXPECT_LT(seconds, 0.5);
}

TEST(ImageBombTest, NoBombRaisesTheProcesssMemory) {
  pb::Frame cmyk, scans, deep;
  cmyk.set_encoded_image(ProgressiveCmykBomb());
  scans.set_encoded_image(ManyScansBomb());
  deep.set_encoded_image(DeepPngBomb());
  for (const auto& [name, frame] : std::vector<std::pair<std::string, pb::Frame>>{
           {"progressive_cmyk", cmyk},
           {"many_scans", scans},
           {"deep_png", deep},
           {"deep_png_depth", FrameWithDepth(DeepPngBomb())}}) {
    const double growth = ResidentGrowthMiB([&] { (void)TimedDecode(frame); });
    EXPECT_LT(growth, 50) << name;
    RecordProperty(name + "_rss_growth_kib", int(growth * 1024));
  }
}

TEST(ImageBombTest, EveryFormatRobotsSendIsStillDecoded) {
  std::vector<std::pair<std::string, std::string>> images = {
      {"baseline colour JPEG", Encoded(".jpg", Gradient(640, 480, CV_8UC3))},
      {"largest baseline colour JPEG", Encoded(".jpg", Gradient(4096, 3072, CV_8UC3))},
      {"largest progressive colour JPEG",
       Encoded(".jpg", Gradient(4096, 3072, CV_8UC3), {cv::IMWRITE_JPEG_PROGRESSIVE, 1})},
      {"progressive grey JPEG",
       Encoded(".jpg", Gradient(640, 480, CV_8UC1), {cv::IMWRITE_JPEG_PROGRESSIVE, 1})}};
  for (const int type : {CV_8UC1, CV_16UC1, CV_8UC3, CV_16UC3, CV_8UC4, CV_16UC4}) {
    images.emplace_back("PNG of type " + std::to_string(type),
                        Encoded(".png", Gradient(640, 480, type)));
  }
  std::string rows;  // filter byte 0, then 640 palette indices
  for (int y = 0; y < 480; ++y) {
    rows += '\0';
    for (int x = 0; x < 640; ++x) rows += char(x % 4);
  }
  images.emplace_back("palette PNG",
                      Png(640, 480, 8, 3, rows,
                          std::string("\x00\x00\x00\x50\x50\x50\xA0\xA0\xA0\xF0\xF0\xF0", 12)));
  for (const auto& [name, bytes] : images) {
    pb::Frame frame;
    frame.set_encoded_image(bytes);
    const auto [decoded, seconds] = TimedDecode(frame);
    ASSERT_TRUE(decoded.ok()) << name << ": " << decoded.status().ToString();
    const auto header = HeaderOf(bytes);
    EXPECT_EQ(decoded->image.size(), cv::Size(int(header->width), int(header->height))) << name;
    EXPECT_EQ(decoded->image.type(), CV_8UC1) << name;
  }
  const auto [with_depth, seconds] =
      TimedDecode(FrameWithDepth(Encoded(".png", Gradient(64, 48, CV_16UC1))));
  ASSERT_TRUE(with_depth.ok()) << with_depth.status().ToString();
  EXPECT_EQ(with_depth->depth.type(), CV_16UC1);
}

}  // namespace
}  // namespace recog::server
