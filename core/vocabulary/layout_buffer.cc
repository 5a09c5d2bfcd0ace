#include "core/vocabulary/layout_buffer.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <new>
#include <utility>

namespace recog {

LayoutBuffer::~LayoutBuffer() { Release(); }

LayoutBuffer::LayoutBuffer(LayoutBuffer&& other) noexcept { *this = std::move(other); }

LayoutBuffer& LayoutBuffer::operator=(LayoutBuffer&& other) noexcept {
  if (this != &other) {
    Release();
    data_ = std::exchange(other.data_, nullptr);
    size_ = std::exchange(other.size_, 0);
    map_base_ = std::exchange(other.map_base_, nullptr);
    map_length_ = std::exchange(other.map_length_, 0);
  }
  return *this;
}

void LayoutBuffer::Release() {
  if (map_base_ != nullptr) {
    munmap(map_base_, map_length_);
  } else {
    std::free(data_);
  }
  data_ = nullptr;
  size_ = 0;
  map_base_ = nullptr;
  map_length_ = 0;
}

LayoutBuffer LayoutBuffer::Allocate(size_t bytes) {
  constexpr size_t kAlignment = 64;
  const size_t rounded = std::max(kAlignment, (bytes + kAlignment - 1) / kAlignment * kAlignment);
  auto* p = static_cast<uint8_t*>(std::aligned_alloc(kAlignment, rounded));
  if (p == nullptr) throw std::bad_alloc();
  std::memset(p, 0, rounded);
  LayoutBuffer buffer;
  buffer.data_ = p;
  buffer.size_ = bytes;
  return buffer;
}

StatusOr<LayoutBuffer> LayoutBuffer::MapFile(const std::string& path, size_t offset, size_t bytes) {
  if (offset % 64 != 0) return Status::Internal("mapping offset must be a multiple of 64");
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return Status::NotFound("cannot open '" + path + "': " + std::strerror(errno));
  const size_t length = offset + bytes;
  void* base = ::mmap(nullptr, length, PROT_READ, MAP_PRIVATE | MAP_POPULATE, fd, 0);
  const int map_errno = errno;
  ::close(fd);
  if (base == MAP_FAILED) {
    return Status::ResourceExhausted("cannot map '" + path + "': " + std::strerror(map_errno));
  }
  LayoutBuffer buffer;
  buffer.map_base_ = base;
  buffer.map_length_ = length;
  buffer.data_ = static_cast<uint8_t*>(base) + offset;
  buffer.size_ = bytes;
  return buffer;
}

}  // namespace recog
