// Descriptor formats and the distance kernels every hot loop uses.
//
// A vocabulary, a feature set and a database all agree on one DescriptorFormat: binary strings
// compared with the Hamming distance (ORB, BRIEF: 32 bytes), or float vectors compared with the
// squared Euclidean distance (SIFT: 128 floats). Descriptors always sit in contiguous rows
// (a cv::Mat of CV_8U or CV_32F, or a flat byte buffer), so the kernels below take raw pointers.
//
// Binary descriptors are compared 64 bits at a time with hardware popcount; the 32-byte case is
// fully unrolled because it is by far the most common one.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>

#include <opencv2/core/mat.hpp>

#include "core/common/status.h"

namespace recog {

enum class DescriptorType : uint8_t {
  kBinary = 1,  // bit strings, Hamming distance, k-medians (majority bit) centroids
  kFloat = 2,   // float32 vectors, squared L2 distance, k-means (mean) centroids
};

struct DescriptorFormat {
  DescriptorType type = DescriptorType::kBinary;
  uint32_t size_bytes = 32;  // bytes per descriptor (a multiple of 8 for binary, of 4 for float)

  static DescriptorFormat Orb() { return {DescriptorType::kBinary, 32}; }
  static DescriptorFormat Brief256() { return {DescriptorType::kBinary, 32}; }
  static DescriptorFormat Sift() { return {DescriptorType::kFloat, 128 * sizeof(float)}; }

  // Number of elements of a row: bytes for binary, floats for float descriptors.
  int cols() const {
    return type == DescriptorType::kBinary ? int(size_bytes) : int(size_bytes / 4);
  }
  // OpenCV element type of a descriptor matrix in this format (CV_8U or CV_32F).
  int cv_type() const;
  // "binary-256" or "float-128".
  std::string ToString() const;
  // OK when the format is usable: binary sizes are multiples of 8 bytes, float sizes of 4 bytes,
  // and neither is empty or larger than 4096 bytes.
  Status Validate() const;

  friend bool operator==(const DescriptorFormat&, const DescriptorFormat&) = default;
};

// OK when `descriptors` is a matrix of this format: continuous, the right type and row length.
// An empty matrix (0 rows) is accepted. The message names what is wrong, e.g.
// "descriptors have 64 columns of type CV_8U; the vocabulary expects binary-256 (32 columns)".
Status CheckDescriptorMatrix(const cv::Mat& descriptors, const DescriptorFormat& format);

inline uint64_t LoadU64(const uint8_t* p) {
  uint64_t v;
  std::memcpy(&v, p, sizeof(v));
  return v;
}

// Hamming distance of two 256-bit descriptors.
inline uint32_t Hamming256(const uint8_t* a, const uint8_t* b) {
  return uint32_t(__builtin_popcountll(LoadU64(a) ^ LoadU64(b)) +
                  __builtin_popcountll(LoadU64(a + 8) ^ LoadU64(b + 8)) +
                  __builtin_popcountll(LoadU64(a + 16) ^ LoadU64(b + 16)) +
                  __builtin_popcountll(LoadU64(a + 24) ^ LoadU64(b + 24)));
}

// Hamming distance of two binary descriptors of `bytes` bytes (a multiple of 8).
inline uint32_t HammingDistance(const uint8_t* a, const uint8_t* b, size_t bytes) {
  uint32_t d = 0;
  for (size_t i = 0; i < bytes; i += 8)
    d += uint32_t(__builtin_popcountll(LoadU64(a + i) ^ LoadU64(b + i)));
  return d;
}

// Squared Euclidean distance of two float vectors of `dims` elements.
inline float SquaredL2(const float* a, const float* b, size_t dims) {
  float d = 0.f;
  for (size_t i = 0; i < dims; ++i) {
    const float diff = a[i] - b[i];
    d += diff * diff;
  }
  return d;
}

// Distance under a format: Hamming for binary, squared L2 for float. For code off the hot path
// (tests, tools); hot loops call the kernels above directly.
inline double DescriptorDistance(const DescriptorFormat& f, const uint8_t* a, const uint8_t* b) {
  if (f.type == DescriptorType::kBinary) {
    return f.size_bytes == 32 ? Hamming256(a, b) : HammingDistance(a, b, f.size_bytes);
  }
  return SquaredL2(reinterpret_cast<const float*>(a), reinterpret_cast<const float*>(b),
                   f.size_bytes / sizeof(float));
}

}  // namespace recog
