// LayoutBuffer: the memory that holds a vocabulary's layout, either on the heap (vocabularies
// built in memory) or as a private mapping of a vocabulary file (loading = one mmap, no copy).
//
// Both kinds are 64-byte aligned. A file mapping is read-only (a writable private mapping would
// make MAP_POPULATE copy every page); only heap buffers can be written. Move-only; releases the
// memory or the mapping on destruction.
#pragma once

#include <cassert>
#include <cstddef>
#include <cstdint>
#include <string>

#include "core/common/status.h"

namespace recog {

class LayoutBuffer {
 public:
  LayoutBuffer() = default;
  ~LayoutBuffer();
  LayoutBuffer(LayoutBuffer&& other) noexcept;
  LayoutBuffer& operator=(LayoutBuffer&& other) noexcept;
  LayoutBuffer(const LayoutBuffer&) = delete;
  LayoutBuffer& operator=(const LayoutBuffer&) = delete;

  // `bytes` of heap memory, zero-filled. Throws std::bad_alloc when memory is exhausted.
  static LayoutBuffer Allocate(size_t bytes);
  // Maps `bytes` bytes of the file at `offset` (a multiple of 64) and reads them in ahead
  // (MAP_POPULATE). The caller has checked that the file is large enough.
  static StatusOr<LayoutBuffer> MapFile(const std::string& path, size_t offset, size_t bytes);

  const uint8_t* data() const { return data_; }
  size_t size() const { return size_; }
  bool is_mapped() const { return map_base_ != nullptr; }
  // Writable view of a heap buffer (never call it on a file mapping).
  uint8_t* mutable_data() {
    assert(!is_mapped());
    return data_;
  }

 private:
  void Release();

  uint8_t* data_ = nullptr;
  size_t size_ = 0;
  void* map_base_ = nullptr;  // non-null for a file mapping
  size_t map_length_ = 0;
};

}  // namespace recog
