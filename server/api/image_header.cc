#include "server/api/image_header.h"

namespace recog::server {
namespace {

constexpr std::string_view kPngSignature("\x89PNG\r\n\x1a\n", 8);

uint32_t BigEndian(std::string_view bytes, size_t at, size_t size) {
  uint32_t value = 0;
  for (size_t i = 0; i < size; ++i) value = (value << 8) | static_cast<uint8_t>(bytes[at + i]);
  return value;
}

StatusOr<ImageHeader> ReadPngHeader(std::string_view bytes, const std::string& field) {
  // The signature, then the IHDR chunk: length 13, "IHDR", width, height (big-endian 32 bits).
  if (bytes.size() < 24 || BigEndian(bytes, 8, 4) != 13 || bytes.substr(12, 4) != "IHDR") {
    return Status::InvalidArgument(field + " is a PNG without a valid IHDR header");
  }
  return ImageHeader{ImageHeader::Format::kPng, BigEndian(bytes, 16, 4), BigEndian(bytes, 20, 4)};
}

// A start-of-frame marker: SOF0..SOF15 but DHT (C4), JPG (C8) and DAC (CC).
bool IsStartOfFrame(uint8_t marker) {
  return marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
}

StatusOr<ImageHeader> ReadJpegHeader(std::string_view bytes, const std::string& field) {
  const auto malformed = [&](const std::string& why) {
    return Status::InvalidArgument(field + " is a JPEG whose header " + why);
  };
  size_t at = 2;  // after SOI
  while (true) {
    if (at >= bytes.size() || static_cast<uint8_t>(bytes[at]) != 0xFF) {
      return malformed("has no frame header (SOF) before its data");
    }
    while (at < bytes.size() && static_cast<uint8_t>(bytes[at]) == 0xFF) ++at;  // fill bytes
    if (at >= bytes.size()) return malformed("is cut short");
    const uint8_t marker = static_cast<uint8_t>(bytes[at++]);
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) continue;  // no length
    if (marker == 0xD8 || marker == 0xD9 || marker == 0xDA) {
      return malformed("has no frame header (SOF) before its data");
    }
    if (at + 2 > bytes.size()) return malformed("is cut short");
    const uint32_t length = BigEndian(bytes, at, 2);  // includes its own two bytes
    if (length < 2 || at + length > bytes.size()) return malformed("has a segment cut short");
    if (IsStartOfFrame(marker)) {
      // precision (1), height (2), width (2), components...
      if (length < 8) return malformed("has a frame header cut short");
      return ImageHeader{ImageHeader::Format::kJpeg, BigEndian(bytes, at + 5, 2),
                         BigEndian(bytes, at + 3, 2)};
    }
    at += length;
  }
}

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

}  // namespace recog::server
