// ByteReader: little-endian fields read from a byte span with every length checked against what
// is left, for the binary formats of bags (MCAP records, ROS 1 message serialization). A read
// past the end does not throw: it sets the reader's failed() flag and returns zeros and empty
// values, so that a parser reads a whole record and checks once.
#pragma once

#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <string_view>

namespace recog::bag {

class ByteReader {
 public:
  explicit ByteReader(std::span<const uint8_t> bytes) : bytes_(bytes) {}

  bool failed() const { return failed_; }
  size_t position() const { return position_; }
  size_t remaining() const { return failed_ ? 0 : bytes_.size() - position_; }

  uint8_t U8() { return uint8_t(Little(1)); }
  uint16_t U16() { return uint16_t(Little(2)); }
  uint32_t U32() { return uint32_t(Little(4)); }
  uint64_t U64() { return Little(8); }
  int32_t I32() { return int32_t(U32()); }
  double F64() {
    const uint64_t bits = U64();
    double value = 0;
    std::memcpy(&value, &bits, sizeof(value));
    return value;
  }

  // The next `size` bytes (empty, and failed(), when fewer are left).
  std::span<const uint8_t> Bytes(uint64_t size) {
    if (failed_ || size > bytes_.size() - position_) {
      failed_ = true;
      return {};
    }
    const std::span<const uint8_t> taken = bytes_.subspan(position_, size_t(size));
    position_ += size_t(size);
    return taken;
  }
  // `size` bytes as text.
  std::string_view Text(uint64_t size) {
    const std::span<const uint8_t> taken = Bytes(size);
    return {reinterpret_cast<const char*>(taken.data()), taken.size()};
  }
  // A uint32 length, then that many bytes (the strings and byte arrays of MCAP and ROS 1).
  std::span<const uint8_t> Prefixed32() { return Bytes(U32()); }
  std::string_view PrefixedText32() { return Text(U32()); }

  void Skip(uint64_t size) { Bytes(size); }

 private:
  uint64_t Little(size_t size) {
    const std::span<const uint8_t> taken = Bytes(size);
    uint64_t value = 0;
    for (size_t i = 0; i < taken.size(); ++i) value |= uint64_t(taken[i]) << (8 * i);
    return value;
  }

  std::span<const uint8_t> bytes_;
  size_t position_ = 0;
  bool failed_ = false;
};

}  // namespace recog::bag
