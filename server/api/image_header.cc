#include "server/api/image_header.h"

#include <algorithm>
#include <bit>

namespace recog::server {
namespace {

constexpr std::string_view kPngSignature("\x89PNG\r\n\x1a\n", 8);

uint32_t BigEndian(std::string_view bytes, size_t at, size_t size) {
  uint32_t value = 0;
  for (size_t i = 0; i < size; ++i) value = (value << 8) | static_cast<uint8_t>(bytes[at + i]);
  return value;
}

// PNG's colour types: the samples of a pixel and the bit depths allowed (a mask of 1..16).
struct PngColourType {
  uint8_t code;
  uint32_t samples;
  uint32_t depths;
};
constexpr PngColourType kPngColourTypes[] = {{0, 1, 1 | 2 | 4 | 8 | 16},
                                             {2, 3, 8 | 16},
                                             {3, 1, 1 | 2 | 4 | 8},
                                             {4, 2, 8 | 16},
                                             {6, 4, 8 | 16}};
constexpr uint8_t kPngPalette = 3;

StatusOr<ImageHeader> ReadPngHeader(std::string_view bytes, const std::string& field) {
  // The signature, then the IHDR chunk: length 13, "IHDR", width, height (big-endian 32 bits),
  // bit depth, colour type, compression, filter and interlace methods.
  if (bytes.size() < 29 || BigEndian(bytes, 8, 4) != 13 || bytes.substr(12, 4) != "IHDR") {
    return Status::InvalidArgument(field + " is a PNG without a valid IHDR header");
  }
  ImageHeader header;
  header.width = BigEndian(bytes, 16, 4);
  header.height = BigEndian(bytes, 20, 4);
  header.bit_depth = static_cast<uint8_t>(bytes[24]);
  const uint8_t colour_type = static_cast<uint8_t>(bytes[25]);
  const auto type = std::find_if(std::begin(kPngColourTypes), std::end(kPngColourTypes),
                                 [&](const PngColourType& t) { return t.code == colour_type; });
  if (type == std::end(kPngColourTypes) || !std::has_single_bit(header.bit_depth) ||
      (type->depths & header.bit_depth) == 0) {
    return Status::InvalidArgument(
        field + " is a PNG of colour type " + std::to_string(colour_type) + " and bit depth " +
        std::to_string(header.bit_depth) + ", which PNG does not define");
  }
  header.components = type->samples;
  header.palette = colour_type == kPngPalette;
  return header;
}

Status MalformedJpeg(const std::string& field, const std::string& why) {
  return Status::InvalidArgument(field + " is a JPEG whose header " + why);
}

// A start-of-frame marker: SOF0..SOF15 but DHT (C4), JPG (C8) and DAC (CC).
bool IsStartOfFrame(uint8_t marker) {
  return marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
}

constexpr uint8_t kStartOfScan = 0xDA;

// The next marker at or after `at`, which it leaves just past the marker: bytes that are not a
// marker (entropy-coded data, where a 0xFF byte is followed by 0x00; stray bytes, which libjpeg
// skips too) and fill bytes (0xFF before a marker) are passed over. 0 when the bytes end first.
uint8_t NextMarker(std::string_view bytes, size_t& at) {
  while (true) {
    const size_t ff = bytes.find('\xFF', at);
    if (ff == std::string_view::npos) break;
    at = ff + 1;
    while (at < bytes.size() && static_cast<uint8_t>(bytes[at]) == 0xFF) ++at;
    if (at >= bytes.size()) break;
    const uint8_t marker = static_cast<uint8_t>(bytes[at++]);
    if (marker != 0x00) return marker;
  }
  at = bytes.size();
  return 0;
}

// Reads a frame header (`segment`, from its length on) of start-of-frame `marker` into `header`:
// precision (1 byte), height, width (2 each), components (1), then 3 bytes a component: its id,
// its horizontal and vertical sampling factors (4 bits each), its quantisation table.
Status ReadJpegFrame(std::string_view segment, uint8_t marker, const std::string& field,
                     ImageHeader* header) {
  if (segment.size() < 8) return MalformedJpeg(field, "has a frame header cut short");
  header->bit_depth = static_cast<uint8_t>(segment[2]);
  header->height = BigEndian(segment, 3, 2);
  header->width = BigEndian(segment, 5, 2);
  header->components = static_cast<uint8_t>(segment[7]);
  if (header->components == 0 || segment.size() != 8 + 3 * size_t(header->components)) {
    return MalformedJpeg(field, "has a frame header of " + std::to_string(segment.size()) +
                                    " bytes for " + std::to_string(header->components) +
                                    " components");
  }
  uint32_t max_h = 1, max_v = 1;
  for (uint32_t c = 0; c < header->components; ++c) {
    const uint8_t sampling = static_cast<uint8_t>(segment[9 + 3 * c]);
    const uint32_t h = sampling >> 4, v = sampling & 0x0F;
    if (h < 1 || h > 4 || v < 1 || v > 4) {
      return MalformedJpeg(field, "has a sampling factor outside 1..4");
    }
    max_h = std::max(max_h, h);
    max_v = std::max(max_v, v);
    header->blocks_per_mcu += h * v;
  }
  header->mcu_width = 8 * max_h;
  header->mcu_height = 8 * max_v;
  header->progressive = marker == 0xC2 || marker == 0xC6 || marker == 0xCA || marker == 0xCE;
  return Status::Ok();
}

StatusOr<ImageHeader> ReadJpegHeader(std::string_view bytes, const std::string& field) {
  ImageHeader header;
  header.format = ImageHeader::Format::kJpeg;
  bool has_frame = false;
  size_t at = 2;  // after SOI
  for (uint8_t marker = NextMarker(bytes, at); marker != 0; marker = NextMarker(bytes, at)) {
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) continue;  // no length
    // The end of the image, another start (which libjpeg refuses), or a scan before the frame.
    if (marker == 0xD9 || marker == 0xD8 || (marker == kStartOfScan && !has_frame)) break;
    const uint32_t length = at + 2 <= bytes.size() ? BigEndian(bytes, at, 2) : 0;  // with itself
    if (length < 2 || at + length > bytes.size()) {
      if (!has_frame) return MalformedJpeg(field, "has a segment cut short");
      break;  // libjpeg decodes what came before
    }
    if (IsStartOfFrame(marker) && !has_frame) {
      RECOG_RETURN_IF_ERROR(ReadJpegFrame(bytes.substr(at, length), marker, field, &header));
      has_frame = true;
    } else if (marker == kStartOfScan) {
      // Its length, then the number of components it codes.
      if (header.scans++ == 0 && length >= 3) {
        header.first_scan_components = static_cast<uint8_t>(bytes[at + 2]);
      }
    }
    at += length;
  }
  if (!has_frame) return MalformedJpeg(field, "has no frame header (SOF) before its data");
  return header;
}

uint64_t CeilDiv(uint64_t a, uint64_t b) { return (a + b - 1) / b; }

}  // namespace

StatusOr<ImageHeader> ReadImageHeader(std::string_view bytes, const std::string& field) {
  if (bytes.starts_with(kPngSignature)) return ReadPngHeader(bytes, field);
  if (bytes.size() >= 2 && static_cast<uint8_t>(bytes[0]) == 0xFF &&
      static_cast<uint8_t>(bytes[1]) == 0xD8) {
    return ReadJpegHeader(bytes, field);
  }
  return Status::InvalidArgument(field + " is not a JPEG or PNG image (" +
                                 std::to_string(bytes.size()) + " bytes)");
}

std::string Describe(const ImageHeader& header) {
  const std::string size = std::to_string(header.width) + "x" + std::to_string(header.height);
  if (header.format == ImageHeader::Format::kJpeg) {
    return size + (header.progressive ? " progressive" : "") + " JPEG, " +
           std::to_string(header.components) +
           (header.components == 1 ? " component" : " components");
  }
  static constexpr const char* kSamples[] = {"", "grey", "grey and alpha", "RGB", "RGBA"};
  return size + " PNG, " + std::to_string(header.bit_depth) + "-bit " +
         (header.palette ? "palette" : kSamples[std::min<uint32_t>(header.components, 4)]);
}

DecodeMemory MemoryToDecode(const ImageHeader& header, uint32_t bytes_per_pixel) {
  DecodeMemory memory;
  memory.image = uint64_t(header.width) * header.height * bytes_per_pixel;
  if (header.format == ImageHeader::Format::kPng) {
    const uint64_t bits_per_pixel =
        header.palette ? 32 : uint64_t(header.components) * std::max<uint32_t>(header.bit_depth, 8);
    memory.decoder = 2 * (CeilDiv(header.width * bits_per_pixel, 8) + 1);  // + a filter byte
    return memory;
  }
  const uint64_t mcu_row_samples =
      CeilDiv(header.width, header.mcu_width) * uint64_t(header.blocks_per_mcu) * 64;
  memory.decoder = 2 * mcu_row_samples;
  if (header.progressive || header.first_scan_components < header.components) {
    memory.decoder += 2 * mcu_row_samples * CeilDiv(header.height, header.mcu_height);
  }
  return memory;
}

}  // namespace recog::server
