#include "tools/bag/ros_images.h"

#include <algorithm>
#include <bit>
#include <cctype>
#include <climits>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <string_view>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tools/bag/byte_reader.h"

namespace recog::bag {
namespace {

// Largest width and height of any image; largest pixel count of an encoded one (JPEG, PNG, RVL),
// whose header alone would otherwise say how much is allocated.
constexpr uint64_t kMaxSide = 1 << 16;
constexpr uint64_t kMaxEncodedPixels = uint64_t(1) << 26;  // 8192 x 8192
// compressed_depth_image_transport's ConfigHeader before the PNG or RVL: an int32 format, then
// the floats depthQuantA and depthQuantB (native byte order: little endian on every robot).
constexpr size_t kCompressedDepthHeaderSize = 12;

std::string Quoted(std::string_view text) {
  std::string quoted(1, '\'');
  quoted.append(text).push_back('\'');
  return quoted;
}

std::string RoleTopic(ImageRole role) {
  return role == ImageRole::kDepth ? "a depth topic" : "an image topic";
}

std::string SizeText(uint64_t width, uint64_t height) {
  return std::to_string(width) + " x " + std::to_string(height);
}

Status CheckDimensions(uint64_t width, uint64_t height) {
  if (width == 0 || height == 0 || width > kMaxSide || height > kMaxSide) {
    return Status::InvalidArgument("an image of " + SizeText(width, height) +
                                   " pixels (each side 1 to " + std::to_string(kMaxSide) + ")");
  }
  return Status::Ok();
}

// An encoded image's size, which says how much its decoding allocates.
Status CheckEncodedDimensions(uint64_t width, uint64_t height) {
  RECOG_RETURN_IF_ERROR(CheckDimensions(width, height));
  if (width * height > kMaxEncodedPixels) {
    return Status::InvalidArgument("an image of " + SizeText(width, height) +
                                   " pixels (an encoded image has at most " +
                                   std::to_string(kMaxEncodedPixels) + ")");
  }
  return Status::Ok();
}

// ---- Raw images ----

// A sensor_msgs/Image encoding the project reads: its role, its OpenCV type, and for an image the
// conversions of its pixels to grey and to BGR (-1: none, the pixels are already that).
struct RawEncoding {
  std::string_view name;
  ImageRole role;
  int type;
  int to_gray;
  int to_bgr;
};

constexpr RawEncoding kRawEncodings[] = {
    {"mono8", ImageRole::kImage, CV_8UC1, -1, -1},
    {"8UC1", ImageRole::kImage, CV_8UC1, -1, -1},
    {"rgb8", ImageRole::kImage, CV_8UC3, cv::COLOR_RGB2GRAY, cv::COLOR_RGB2BGR},
    {"bgr8", ImageRole::kImage, CV_8UC3, cv::COLOR_BGR2GRAY, -1},
    {"rgba8", ImageRole::kImage, CV_8UC4, cv::COLOR_RGBA2GRAY, cv::COLOR_RGBA2BGR},
    {"bgra8", ImageRole::kImage, CV_8UC4, cv::COLOR_BGRA2GRAY, cv::COLOR_BGRA2BGR},
    {"16UC1", ImageRole::kDepth, CV_16UC1, -1, -1},
    {"mono16", ImageRole::kDepth, CV_16UC1, -1, -1},
    {"32FC1", ImageRole::kDepth, CV_32FC1, -1, -1},
};

constexpr const char* kImageEncodings = "mono8, 8UC1, rgb8, bgr8, rgba8, bgra8";
constexpr const char* kDepthEncodings = "16UC1 and mono16 in millimetres, 32FC1 in metres";

StatusOr<RawEncoding> FindRawEncoding(const std::string& encoding, ImageRole role) {
  const auto found = std::find_if(std::begin(kRawEncodings), std::end(kRawEncodings),
                                  [&](const RawEncoding& e) { return e.name == encoding; });
  std::string other;
  if (found != std::end(kRawEncodings)) {
    if (found->role == role) return *found;
    other = found->role == ImageRole::kDepth ? " (a depth encoding)" : " (an image encoding)";
  }
  return Status::InvalidArgument(
      "encoding " + Quoted(encoding) + other + " is not supported for " + RoleTopic(role) + " (" +
      (role == ImageRole::kDepth ? kDepthEncodings : kImageEncodings) + ")");
}

// A raw image's encoding, checked against its size, step and data.
StatusOr<RawEncoding> CheckRaw(const ImageMessage& message, ImageRole role) {
  RECOG_ASSIGN_OR_RETURN(const RawEncoding encoding, FindRawEncoding(message.encoding, role));
  RECOG_RETURN_IF_ERROR(CheckDimensions(message.width, message.height));
  const uint64_t row = uint64_t(message.width) * CV_ELEM_SIZE(encoding.type);
  if (message.step < row) {
    return Status::InvalidArgument("a step of " + std::to_string(message.step) +
                                   " bytes is less than a row of " + std::to_string(message.width) +
                                   " " + message.encoding + " pixels (" + std::to_string(row) +
                                   " bytes)");
  }
  const uint64_t needed = uint64_t(message.step) * message.height;
  if (message.data.size() < needed) {
    return Status::InvalidArgument(
        "its data of " + std::to_string(message.data.size()) +
        " bytes is shorter than step x height = " + std::to_string(message.step) + " x " +
        std::to_string(message.height) + " = " + std::to_string(needed) + " bytes");
  }
  return encoding;
}

// An image's 8-bit pixels where they are (not copied); any step is a whole number of 8-bit
// elements, as cv::Mat requires.
cv::Mat RawImagePixels(const ImageMessage& message, const RawEncoding& encoding) {
  return cv::Mat(int(message.height), int(message.width), encoding.type,
                 const_cast<uint8_t*>(message.data.data()), message.step);
}

// ---- Encoded images: JPEG and PNG headers, RVL ----

enum class Codec { kJpeg, kPng, kRvl };

// What the header of a JPEG or PNG says; its size before CheckEncodedDimensions (a PNG's may not
// fit an int).
struct EncodedHeader {
  Codec codec = Codec::kJpeg;
  uint64_t width = 0;
  uint64_t height = 0;
  bool color = false;
  int bit_depth = 8;
};

uint32_t Be16(const uint8_t* p) { return uint32_t(p[0]) << 8 | p[1]; }
uint32_t Be32(const uint8_t* p) { return Be16(p) << 16 | Be16(p + 2); }

// The header of a PNG (its IHDR) or a JPEG (its first SOF marker); none when `data` is neither.
std::optional<EncodedHeader> ReadEncodedHeader(std::span<const uint8_t> data) {
  static constexpr uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  const uint8_t* bytes = data.data();
  const size_t size = data.size();
  EncodedHeader header;
  if (size >= 26 && std::memcmp(bytes, kPngSignature, 8) == 0 &&
      std::memcmp(bytes + 12, "IHDR", 4) == 0) {
    header.codec = Codec::kPng;
    header.width = Be32(bytes + 16);
    header.height = Be32(bytes + 20);
    header.bit_depth = bytes[24];
    header.color = bytes[25] == 2 || bytes[25] == 3 || bytes[25] == 6;  // RGB, palette, RGBA
    return header;
  }
  if (size < 4 || bytes[0] != 0xff || bytes[1] != 0xd8) return std::nullopt;
  // The JPEG's markers up to its first start of frame.
  for (size_t at = 2; at + 4 <= size;) {
    if (bytes[at] != 0xff) return std::nullopt;
    const uint8_t marker = bytes[at + 1];
    if (marker == 0xff) {  // fill byte
      ++at;
      continue;
    }
    if (marker == 0x01 || (marker >= 0xd0 && marker <= 0xd8)) {  // markers without a length
      at += 2;
      continue;
    }
    const bool start_of_frame =
        marker >= 0xc0 && marker <= 0xcf && marker != 0xc4 && marker != 0xc8 && marker != 0xcc;
    if (start_of_frame) {
      if (at + 10 > size) return std::nullopt;
      header.bit_depth = bytes[at + 4];
      header.height = Be16(bytes + at + 5);
      header.width = Be16(bytes + at + 7);
      header.color = bytes[at + 9] >= 3;  // components
      return header;
    }
    if (marker == 0xda || marker == 0xd9) return std::nullopt;  // a scan or the end before a frame
    at += 2 + Be16(bytes + at + 2);
  }
  return std::nullopt;
}

// cv::imdecode of bytes held elsewhere; empty when they do not decode (OpenCV's own limits throw).
cv::Mat Imdecode(std::span<const uint8_t> bytes, int flags) {
  if (bytes.empty() || bytes.size() > size_t(INT_MAX)) return {};
  try {
    return cv::imdecode(cv::Mat(1, int(bytes.size()), CV_8UC1, const_cast<uint8_t*>(bytes.data())),
                        flags);
  } catch (const cv::Exception&) {
    return {};
  }
}

// RVL (A. D. Wilson, "Fast Lossless Depth Image Compression", 2017) as
// compressed_depth_image_transport writes it: little-endian 32-bit words, each holding 8 nibbles
// taken from its most significant end. A value is a run of nibbles, 3 bits each, least significant
// first, a nibble's high bit saying that another follows. The pixels are pairs of runs — a count
// of zero pixels, then a count of non-zero ones, each of those the zigzag-coded difference from the
// previous non-zero pixel (0 before the first) — until the image is full.
class RvlReader {
 public:
  explicit RvlReader(std::span<const uint8_t> words) : words_(words) {}

  // The next value; none when the stream ends before it, or it is longer than any count of an
  // image's pixels (33 bits).
  std::optional<uint64_t> Next() {
    uint64_t value = 0;
    for (int shift = 0; shift < kMaxBits; shift += 3) {
      if (nibbles_left_ == 0) {
        if (words_.size() < 4) return std::nullopt;
        word_ = uint32_t(words_[0]) | uint32_t(words_[1]) << 8 | uint32_t(words_[2]) << 16 |
                uint32_t(words_[3]) << 24;
        words_ = words_.subspan(4);
        nibbles_left_ = 8;
      }
      const uint32_t nibble = word_ >> 28;
      word_ <<= 4;
      --nibbles_left_;
      value |= uint64_t(nibble & 0x7) << shift;
      if ((nibble & 0x8) == 0) return value;
    }
    return std::nullopt;
  }

 private:
  static constexpr int kMaxBits = 33;

  std::span<const uint8_t> words_;
  uint32_t word_ = 0;
  int nibbles_left_ = 0;
};

// The RVL `stream` into `pixels` (CV_16UC1, continuous), never past its end: a stream that ends
// early, or whose runs go past the image, is INVALID_ARGUMENT.
Status DecodeRvl(std::span<const uint8_t> stream, cv::Mat* pixels) {
  RvlReader reader(stream);
  uint16_t* out = pixels->ptr<uint16_t>();
  const uint64_t total = pixels->total();
  uint64_t done = 0;
  uint16_t previous = 0;
  const auto ended = [&] {
    return Status::InvalidArgument("its RVL stream of " + std::to_string(stream.size()) +
                                   " bytes stops after " + std::to_string(done) + " of its " +
                                   std::to_string(total) +
                                   " pixels (it ends, or a value runs past 33 bits)");
  };
  const auto overflow = [&](uint64_t run) {
    return Status::InvalidArgument("its RVL stream gives a run of " + std::to_string(run) +
                                   " pixels after " + std::to_string(done) + ", past its " +
                                   std::to_string(total) + " pixels");
  };
  while (done < total) {
    const std::optional<uint64_t> zeros = reader.Next();
    if (!zeros.has_value()) return ended();
    if (*zeros > total - done) return overflow(*zeros);
    std::fill_n(out + done, *zeros, uint16_t(0));
    done += *zeros;
    const std::optional<uint64_t> nonzeros = reader.Next();
    if (!nonzeros.has_value()) return ended();
    if (*nonzeros > total - done) return overflow(*nonzeros);
    for (uint64_t i = 0; i < *nonzeros; ++i) {
      const std::optional<uint64_t> zigzag = reader.Next();
      if (!zigzag.has_value()) return ended();
      const int64_t delta = int64_t(*zigzag >> 1) ^ -int64_t(*zigzag & 1);
      previous = uint16_t(int64_t(previous) + delta);
      out[done++] = previous;
    }
  }
  return Status::Ok();
}

// ---- Compressed images ----

// compressed_depth_image_transport's word in a format, in lower case as formats are compared.
constexpr std::string_view kCompressedDepth = "compresseddepth";

std::string Lowercase(std::string_view text) {
  std::string lower(text);
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return lower;
}

std::string_view Trimmed(std::string_view text) {
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.front()))) {
    text.remove_prefix(1);
  }
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) {
    text.remove_suffix(1);
  }
  return text;
}

// What a CompressedImage holds, from its format and the header of its data.
struct CompressedLayout {
  ImageLayout layout;
  Codec codec = Codec::kJpeg;
  std::span<const uint8_t> payload;  // the JPEG, PNG or RVL stream (after compressedDepth's header)
  // compressedDepth of 32FC1: quantised inverse depth q, depth = quant_a / (q - quant_b) metres.
  bool inverse_depth = false;
  float quant_a = 0;
  float quant_b = 0;
};

// compressed_depth_image_transport's data: "<encoding>; compressedDepth [png|rvl]", the 12-byte
// header, then a 16-bit grey PNG or an RVL stream (uint32 width, uint32 height, the words).
StatusOr<CompressedLayout> InspectCompressedDepth(const CompressedImageMessage& message,
                                                  const std::string& lower_format) {
  const std::string_view encoding =
      Trimmed(std::string_view(message.format).substr(0, message.format.find(';')));
  const std::string lower_encoding = Lowercase(encoding);
  CompressedLayout c;
  if (lower_encoding == "16uc1" || lower_encoding == "mono16") {
    c.layout.depth_type = CV_16UC1;
  } else if (lower_encoding == "32fc1") {
    c.layout.depth_type = CV_32FC1;
    c.inverse_depth = true;
  } else {
    return Status::InvalidArgument("format " + Quoted(message.format) +
                                   ": compressedDepth of encoding " + Quoted(encoding) +
                                   " is not supported (16UC1, mono16, 32FC1)");
  }
  const std::string_view compression =
      Trimmed(std::string_view(lower_format)
                  .substr(lower_format.find(kCompressedDepth) + kCompressedDepth.size()));
  if (compression.empty() || compression == "png") {
    c.codec = Codec::kPng;
  } else if (compression == "rvl") {
    c.codec = Codec::kRvl;
  } else {
    return Status::InvalidArgument("format " + Quoted(message.format) +
                                   ": compressedDepth compression " + Quoted(compression) +
                                   " is not supported (png, rvl)");
  }
  if (message.data.size() <= kCompressedDepthHeaderSize) {
    return Status::InvalidArgument("format " + Quoted(message.format) + ", but its data of " +
                                   std::to_string(message.data.size()) +
                                   " bytes is no longer than the 12-byte compressedDepth header");
  }
  std::memcpy(&c.quant_a, message.data.data() + 4, sizeof(float));
  std::memcpy(&c.quant_b, message.data.data() + 8, sizeof(float));
  c.payload = message.data.subspan(kCompressedDepthHeaderSize);
  if (c.codec == Codec::kRvl) {
    ByteReader reader(c.payload);
    const uint32_t width = reader.U32();
    const uint32_t height = reader.U32();
    if (reader.failed()) {
      return Status::InvalidArgument("format " + Quoted(message.format) +
                                     ", but its data ends inside the RVL image size");
    }
    RECOG_RETURN_IF_ERROR(CheckEncodedDimensions(width, height).WithContext("its RVL header says"));
    c.layout.size = cv::Size(int(width), int(height));
    return c;
  }
  const std::optional<EncodedHeader> png = ReadEncodedHeader(c.payload);
  if (!png.has_value() || png->codec != Codec::kPng || png->bit_depth != 16 || png->color) {
    return Status::InvalidArgument("format " + Quoted(message.format) +
                                   ", but the data after its compressedDepth header is not a "
                                   "16-bit grey PNG");
  }
  RECOG_RETURN_IF_ERROR(
      CheckEncodedDimensions(png->width, png->height).WithContext("its PNG header says"));
  c.layout.size = cv::Size(int(png->width), int(png->height));
  return c;
}

StatusOr<CompressedLayout> InspectCompressed(const CompressedImageMessage& message,
                                             ImageRole role) {
  const std::string format = Lowercase(message.format);
  if (format.find(kCompressedDepth) != std::string::npos) {
    if (role != ImageRole::kDepth) {
      return Status::InvalidArgument("format " + Quoted(message.format) +
                                     " (compressed_depth_image_transport's depth) is not "
                                     "supported for an image topic");
    }
    return InspectCompressedDepth(message, format);
  }
  const bool named = format.find("jpeg") != std::string::npos ||
                     format.find("jpg") != std::string::npos ||
                     format.find("png") != std::string::npos;
  const char* supported = role == ImageRole::kDepth
                              ? "a 16-bit grey PNG, or compressedDepth's PNG or RVL"
                              : "JPEG or PNG";
  if (!named) {
    return Status::InvalidArgument("format " + Quoted(message.format) + " is not supported for " +
                                   RoleTopic(role) + " (" + supported + ")");
  }
  const std::optional<EncodedHeader> header = ReadEncodedHeader(message.data);
  if (!header.has_value()) {
    return Status::InvalidArgument("format " + Quoted(message.format) +
                                   ", but its data is neither a JPEG nor a PNG");
  }
  const EncodedHeader& encoded = *header;
  CompressedLayout c;
  c.codec = encoded.codec;
  c.payload = message.data;
  if (role == ImageRole::kDepth) {
    if (encoded.codec != Codec::kPng || encoded.bit_depth != 16 || encoded.color) {
      return Status::InvalidArgument("format " + Quoted(message.format) + ": its data (" +
                                     std::to_string(encoded.bit_depth) + "-bit " +
                                     (encoded.color ? "colour " : "grey ") +
                                     (encoded.codec == Codec::kPng ? "PNG" : "JPEG") +
                                     ") is not supported for depth (" + supported + ")");
    }
    c.layout.depth_type = CV_16UC1;
  } else {
    c.layout.color = encoded.color;
  }
  RECOG_RETURN_IF_ERROR(CheckEncodedDimensions(encoded.width, encoded.height)
                            .WithContext(std::string("its ") +
                                         (encoded.codec == Codec::kPng ? "PNG" : "JPEG") +
                                         " header says"));
  c.layout.size = cv::Size(int(encoded.width), int(encoded.height));
  return c;
}

Status NotInspectedSize(const cv::Mat& decoded, cv::Size size) {
  return Status::InvalidArgument(
      decoded.empty()
          ? "its data does not decode"
          : "its data decodes to " + SizeText(decoded.cols, decoded.rows) + " pixels, not the " +
                SizeText(size.width, size.height) + " of its header");
}

// Each element's bytes reversed: big-endian pixels to the host's order.
void SwapBytes(cv::Mat* pixels) {
  const size_t size = pixels->elemSize();
  for (int y = 0; y < pixels->rows; ++y) {
    uint8_t* row = pixels->ptr(y);
    for (int x = 0; x < pixels->cols; ++x) std::reverse(row + x * size, row + (x + 1) * size);
  }
}

}  // namespace

StatusOr<ImageLayout> InspectImage(const ImageMessage& message, ImageRole role) {
  RECOG_ASSIGN_OR_RETURN(const RawEncoding encoding, CheckRaw(message, role));
  ImageLayout layout;
  layout.size = cv::Size(int(message.width), int(message.height));
  layout.color = encoding.to_gray != -1;
  if (role == ImageRole::kDepth) layout.depth_type = encoding.type;
  return layout;
}

StatusOr<ImageLayout> InspectImage(const CompressedImageMessage& message, ImageRole role) {
  RECOG_ASSIGN_OR_RETURN(const CompressedLayout compressed, InspectCompressed(message, role));
  return compressed.layout;
}

Status DecodeGray(const ImageMessage& message, cv::Mat* gray, cv::Mat* color) {
  *gray = cv::Mat();
  if (color != nullptr) *color = cv::Mat();
  RECOG_ASSIGN_OR_RETURN(const RawEncoding encoding, CheckRaw(message, ImageRole::kImage));
  const cv::Mat pixels = RawImagePixels(message, encoding);
  if (encoding.to_gray == -1) {
    *gray = pixels.clone();
    return Status::Ok();
  }
  cv::cvtColor(pixels, *gray, encoding.to_gray);
  if (color != nullptr) {
    if (encoding.to_bgr == -1) {
      *color = pixels.clone();
    } else {
      cv::cvtColor(pixels, *color, encoding.to_bgr);
    }
  }
  return Status::Ok();
}

Status DecodeGray(const CompressedImageMessage& message, cv::Mat* gray, cv::Mat* color) {
  *gray = cv::Mat();
  if (color != nullptr) *color = cv::Mat();
  RECOG_ASSIGN_OR_RETURN(const CompressedLayout c, InspectCompressed(message, ImageRole::kImage));
  if (c.layout.color && color != nullptr) {
    *color = Imdecode(c.payload, cv::IMREAD_COLOR);
    if (color->size() != c.layout.size) return NotInspectedSize(*color, c.layout.size);
    cv::cvtColor(*color, *gray, cv::COLOR_BGR2GRAY);
    return Status::Ok();
  }
  // As an image file is read: the decoder's own grey.
  *gray = Imdecode(c.payload, cv::IMREAD_GRAYSCALE);
  if (gray->size() != c.layout.size) return NotInspectedSize(*gray, c.layout.size);
  return Status::Ok();
}

Status DecodeDepth(const ImageMessage& message, cv::Mat* depth) {
  *depth = cv::Mat();
  RECOG_ASSIGN_OR_RETURN(const RawEncoding encoding, CheckRaw(message, ImageRole::kDepth));
  // The pixels may sit at any address and their step be any number of bytes: copied row by row
  // before they are read as numbers.
  depth->create(int(message.height), int(message.width), encoding.type);
  const size_t row = depth->cols * depth->elemSize();
  for (int y = 0; y < depth->rows; ++y) {
    std::memcpy(depth->ptr(y), message.data.data() + size_t(y) * message.step, row);
  }
  if (message.is_bigendian != (std::endian::native == std::endian::big)) SwapBytes(depth);
  return Status::Ok();
}

Status DecodeDepth(const CompressedImageMessage& message, cv::Mat* depth) {
  *depth = cv::Mat();
  RECOG_ASSIGN_OR_RETURN(const CompressedLayout c, InspectCompressed(message, ImageRole::kDepth));
  cv::Mat millimetres_or_q;  // millimetres, or for inverse depth its quantised values
  if (c.codec == Codec::kRvl) {
    millimetres_or_q.create(c.layout.size, CV_16UC1);
    RECOG_RETURN_IF_ERROR(DecodeRvl(c.payload.subspan(8), &millimetres_or_q));
  } else {
    millimetres_or_q = Imdecode(c.payload, cv::IMREAD_ANYDEPTH);
    if (millimetres_or_q.type() != CV_16UC1 || millimetres_or_q.size() != c.layout.size) {
      return NotInspectedSize(millimetres_or_q, c.layout.size);
    }
  }
  if (!c.inverse_depth) {
    *depth = std::move(millimetres_or_q);
    return Status::Ok();
  }
  // compressed_depth_image_transport's quantisation, inverted as its decoder does (in float):
  // q = 0 is no depth; so is a depth that is not a positive number (a damaged header).
  depth->create(c.layout.size, CV_32FC1);
  for (int y = 0; y < depth->rows; ++y) {
    const uint16_t* q = millimetres_or_q.ptr<uint16_t>(y);
    float* metres = depth->ptr<float>(y);
    for (int x = 0; x < depth->cols; ++x) {
      const float value = c.quant_a / (float(q[x]) - c.quant_b);
      metres[x] = q[x] != 0 && std::isfinite(value) && value > 0
                      ? value
                      : std::numeric_limits<float>::quiet_NaN();
    }
  }
  return Status::Ok();
}

}  // namespace recog::bag
