// CdrReader: the fields of a ROS 2 message in CDR (OMG's Common Data Representation, as
// rmw/Fast-CDR write it), read from a byte span with every length checked against what is left.
//
// A message starts with a 4-byte encapsulation header (big-endian id 0x0000 CDR_BE, 0x0001
// CDR_LE, then two option bytes); every primitive is then aligned to its own size (1, 2, 4, 8)
// counted from the end of that header, in the header's byte order. As ByteReader does, a read past
// the end does not throw: it sets failed() and returns zeros and empty values. Strings and
// sequences (a uint32 count, then the elements) are read by the caller from U32, Align and Bytes,
// checking the count against remaining() first. Private to recog_bag (ros_messages.cc).
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <span>
#include <string>

#include "core/common/status.h"

namespace recog::bag {

class CdrReader {
 public:
  static constexpr size_t kEncapsulationSize = 4;

  // A reader after `message`'s encapsulation header: INVALID_ARGUMENT for a message shorter than
  // the header, or whose encapsulation is not plain CDR (parameter lists, XCDR2), naming it.
  static StatusOr<CdrReader> Open(std::span<const uint8_t> message) {
    if (message.size() < kEncapsulationSize) {
      return Status::InvalidArgument("a CDR message of " + std::to_string(message.size()) +
                                     " bytes is shorter than its 4-byte encapsulation header");
    }
    const unsigned encapsulation = unsigned(message[0]) << 8 | message[1];
    if (encapsulation > 1) {
      static constexpr const char* kParameterLists[] = {" (PL_CDR_BE)", " (PL_CDR_LE)"};
      char id[8];
      std::snprintf(id, sizeof(id), "0x%04x", encapsulation);
      return Status::InvalidArgument(
          "CDR encapsulation " + std::string(id) +
          (encapsulation <= 3 ? kParameterLists[encapsulation - 2] : "") +
          " is not supported (plain CDR, 0x0000 CDR_BE or 0x0001 CDR_LE, as ROS 2 writes)");
    }
    return CdrReader(message.subspan(kEncapsulationSize), /*big_endian=*/encapsulation == 0);
  }

  bool failed() const { return failed_; }
  // Position and size counted from the end of the encapsulation header.
  size_t position() const { return position_; }
  size_t remaining() const { return failed_ ? 0 : bytes_.size() - position_; }

  uint8_t U8() { return uint8_t(Aligned(1)); }
  uint32_t U32() { return uint32_t(Aligned(4)); }
  int32_t I32() { return int32_t(U32()); }
  uint64_t U64() { return Aligned(8); }
  double F64() {
    const uint64_t bits = U64();
    double value = 0;
    std::memcpy(&value, &bits, sizeof(value));
    return value;
  }

  // Skips the padding before a field of `size` bytes (1, 2, 4 or 8).
  void Align(size_t size) { Bytes((size - position_ % size) % size); }

  // The next `size` bytes, unaligned (a string's or a sequence<uint8>'s); empty, and failed(),
  // when fewer are left.
  std::span<const uint8_t> Bytes(uint64_t size) {
    if (failed_ || size > bytes_.size() - position_) {
      failed_ = true;
      return {};
    }
    const std::span<const uint8_t> taken = bytes_.subspan(position_, size_t(size));
    position_ += size_t(size);
    return taken;
  }

 private:
  CdrReader(std::span<const uint8_t> bytes, bool big_endian)
      : bytes_(bytes), big_endian_(big_endian) {}

  uint64_t Aligned(size_t size) {
    Align(size);
    const std::span<const uint8_t> taken = Bytes(size);
    uint64_t value = 0;
    for (size_t i = 0; i < taken.size(); ++i) {
      const size_t shift = big_endian_ ? taken.size() - 1 - i : i;
      value |= uint64_t(taken[i]) << (8 * shift);
    }
    return value;
  }

  std::span<const uint8_t> bytes_;
  bool big_endian_ = false;
  size_t position_ = 0;
  bool failed_ = false;
};

}  // namespace recog::bag
