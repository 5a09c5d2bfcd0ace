// ReadImageHeader: the format, size and layout an encoded image declares, read from its bytes
// without decoding it, so that the server can refuse an image too costly to decode (a PNG of a few
// hundred kilobytes may declare 20000 x 20000 pixels; a 150-byte progressive JPEG may make libjpeg
// hold 576 MB of coefficients) before any decoder allocates for it. MemoryToDecode turns a header
// into what OpenCV's decoders will allocate for it.
//
// Only the formats the API accepts are recognised: PNG (the IHDR chunk that must follow the
// signature) and JPEG. A JPEG's marker segments are walked to its end as libjpeg walks them: each
// segment skipped by its length, entropy-coded data and stray bytes scanned for the next marker
// (in entropy-coded data a 0xFF byte is always followed by 0x00 or a restart marker, so 0xFF 0xDA
// there is a real start of scan). It yields the first frame header (SOF0..SOF15 but DHT, JPG and
// DAC) and the scans (SOS) of the whole file. Reading is bounded by the bytes given and costs no
// allocation.
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
  // Samples a pixel: PNG 1 (grey or palette), 2 (grey and alpha), 3 (RGB), 4 (RGBA); JPEG the
  // frame's components (1 grey, 3 YCbCr, 4 CMYK).
  uint32_t components = 0;
  uint32_t bit_depth = 0;  // bits a sample: PNG 1 to 16; JPEG its precision (8 or 12)
  bool palette = false;    // PNG: colour-indexed (the decoder expands it to RGB or RGBA)

  // JPEG only. The minimum coded unit (MCU), the pixels the decoder handles at once (8 x 8 times
  // the largest sampling factors: 16 x 16 for 4:2:0), and the 8 x 8 blocks of all the components
  // in one MCU (6 for 4:2:0 YCbCr, 3 for 4:4:4, 4 for CMYK).
  uint32_t mcu_width = 0, mcu_height = 0, blocks_per_mcu = 0;
  bool progressive = false;            // a progressive frame (SOF2, SOF6, SOF10, SOF14)
  uint32_t scans = 0;                  // start-of-scan (SOS) markers in the whole file
  uint32_t first_scan_components = 0;  // components in the first scan (0 without scans)
};

// INVALID_ARGUMENT naming `field` when `bytes` is neither a PNG nor a JPEG, or when its header is
// cut short or malformed (a PNG colour type or bit depth PNG does not define, a JPEG sampling
// factor outside 1..4: the decoders refuse those too). A JPEG cut short after its frame header is
// read as far as it goes, as libjpeg decodes it.
StatusOr<ImageHeader> ReadImageHeader(std::string_view bytes, const std::string& field);

// "8192x8192 progressive JPEG, 4 components", "16384x4096 PNG, 16-bit, 4 samples a pixel": the
// header in a message.
std::string Describe(const ImageHeader& header);

// What decoding an image takes in memory.
struct DecodeMemory {
  uint64_t image = 0;    // the decoded image, which the caller keeps
  uint64_t decoder = 0;  // the decoder's own buffers, freed when it returns
  uint64_t total() const { return image + decoder; }
};

// The memory OpenCV 4's decoders take to decode `header`'s image to `bytes_per_pixel` a pixel
// (1: 8-bit grey, IMREAD_GRAYSCALE; 2: a 16-bit grey PNG, IMREAD_UNCHANGED), measured with
// OpenCV 4.6, libpng 1.6 and libjpeg-turbo 2.1:
// - PNG: libpng decodes row by row into the image, converting each row (palette and colour to
//   grey, 16 to 8 bits): two rows (the current and the previous one, which filters refer to) at
//   the deepest a pixel gets on the way (RGBA for a palette, at least 8 bits a sample).
// - JPEG: libjpeg decodes a baseline image an MCU row at a time: two MCU rows of samples. A
//   progressive image, or one whose first scan lacks some components, it decodes scan by scan into
//   a buffer of every DCT coefficient of the image, 2 bytes each, whole MCUs (4:2:0 YCbCr: 3 bytes
//   a pixel; 4:4:4: 6; CMYK: 8), and converts that to the image at the end.
// The size must have been checked (at most 65535 a side, kMaxImageSide in practice).
DecodeMemory MemoryToDecode(const ImageHeader& header, uint32_t bytes_per_pixel);

}  // namespace recog::server
