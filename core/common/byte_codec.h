// ByteWriter and ByteReader: the little-endian binary encoding of the project's own records
// (object model files, model repository versions).
//
// ByteWriter appends trivially copyable values and length-prefixed strings (u32 length + bytes)
// to a string. ByteReader reads them back and never reads past the end: failure is sticky — once
// a read does not fit, it and every later read yield zeros / empty values and ok() turns false —
// so a parser can run to its end, allocating nothing the bytes do not justify, and check once.
// (This machine and every target are little-endian; values are copied as they are in memory.)
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <type_traits>

namespace recog {

class ByteWriter {
 public:
  template <class T>
  void Put(T value) {
    static_assert(std::is_trivially_copyable_v<T>);
    char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    out_.append(bytes, sizeof(T));
  }
  void PutBytes(const void* data, size_t size) {
    out_.append(static_cast<const char*>(data), size);
  }
  void PutString(std::string_view s) {
    Put<uint32_t>(uint32_t(s.size()));
    out_.append(s);
  }
  std::string& bytes() { return out_; }

 private:
  std::string out_;
};

class ByteReader {
 public:
  explicit ByteReader(std::string_view bytes) : bytes_(bytes) {}

  bool ok() const { return ok_; }
  size_t left() const { return bytes_.size() - pos_; }

  template <class T>
  T Get() {
    static_assert(std::is_trivially_copyable_v<T>);
    T value{};
    if (const char* p = Take(sizeof(T))) std::memcpy(&value, p, sizeof(T));
    return value;
  }
  // Points at the next n bytes (nullptr, and the reader fails, when fewer are left).
  const char* Take(uint64_t n) {
    if (!ok_ || left() < n) {
      ok_ = false;
      return nullptr;
    }
    const char* p = bytes_.data() + pos_;
    pos_ += n;
    return p;
  }
  std::string_view GetBytes(uint64_t n) {
    const char* p = Take(n);
    return p == nullptr ? std::string_view() : std::string_view(p, n);
  }
  std::string GetString() { return std::string(GetBytes(Get<uint32_t>())); }
  // A u32 count of items of at least item_bytes each; fails (returning 0) when that many items
  // cannot fit in what is left.
  uint32_t GetCount(size_t item_bytes) {
    const uint32_t count = Get<uint32_t>();
    if (count > left() / item_bytes) {
      ok_ = false;
      return 0;
    }
    return count;
  }

 private:
  std::string_view bytes_;
  size_t pos_ = 0;
  bool ok_ = true;
};

}  // namespace recog
