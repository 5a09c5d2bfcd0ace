// ReadImageHeader: the format and size an encoded image declares, read from its first bytes
// without decoding it, so that the server can refuse an image too large to decode (a PNG of a few
// hundred kilobytes may declare 20000 x 20000 pixels) before any decoder allocates for it.
//
// Only the formats the API accepts are recognised: PNG (the IHDR chunk that must follow the
// signature) and JPEG (the first frame header, SOF0..SOF15 but DHT, JPG and DAC, found by walking
// the marker segments before it). Reading is bounded by the bytes given and costs no allocation.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "core/common/status.h"

namespace recog::server {

struct ImageHeader {
  enum class Format { kPng, kJpeg };
  Format format = Format::kPng;
  uint32_t width = 0, height = 0;  // as declared (0 is possible: the caller decides)
};

// INVALID_ARGUMENT naming `field` when `bytes` is neither a PNG nor a JPEG, or when its header is
// cut short or malformed.
StatusOr<ImageHeader> ReadImageHeader(std::string_view bytes, const std::string& field);

}  // namespace recog::server
