// The three sensor_msgs messages a camera is recorded with — Image, CompressedImage and
// CameraInfo — decoded from their serialized bytes, in either serialization a bag holds: ROS 1's
// (little endian, packed) or ROS 2's CDR (the 4-byte encapsulation header, little or big endian,
// fields aligned to their size from the end of that header).
//
// A decoded image points into the bytes it was decoded from (its pixels are not copied), so those
// bytes must outlive it. Every length is checked against the bytes: a message cut short, a
// length past its end or an unknown CDR encapsulation is INVALID_ARGUMENT saying which field;
// the caller adds the file, topic and message. Nothing is allocated for a count before it is
// checked against the bytes left. Bytes after the last field (CDR's padding) are ignored; a CDR
// stamp of negative seconds is a time before the epoch (a negative stamp_ns).
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "tools/bag/bag_store.h"

namespace recog::bag {

// std_msgs/Header without its ROS 1 seq.
struct MessageHeader {
  int64_t stamp_ns = 0;  // header.stamp, nanoseconds since the epoch
  std::string frame_id;
};

struct ImageMessage {
  MessageHeader header;
  uint32_t height = 0;
  uint32_t width = 0;
  std::string encoding;  // "mono8", "rgb8", "16UC1", ... (sensor_msgs/image_encodings)
  bool is_bigendian = false;
  uint32_t step = 0;              // bytes per row
  std::span<const uint8_t> data;  // into the decoded bytes
};

struct CompressedImageMessage {
  MessageHeader header;
  // "jpeg", "png", or image_transport's "bgr8; jpeg compressed bgr8",
  // "16UC1; compressedDepth png", ...
  std::string format;
  std::span<const uint8_t> data;  // into the decoded bytes
};

struct CameraInfoMessage {
  MessageHeader header;
  uint32_t height = 0;
  uint32_t width = 0;
  std::string distortion_model;  // "plumb_bob", "rational_polynomial", "equidistant", ...
  std::vector<double> d;
  std::array<double, 9> k{};
  std::array<double, 9> r{};
  std::array<double, 12> p{};
};

StatusOr<ImageMessage> DecodeImageMessage(Serialization serialization,
                                          std::span<const uint8_t> bytes);
StatusOr<CompressedImageMessage> DecodeCompressedImageMessage(Serialization serialization,
                                                              std::span<const uint8_t> bytes);
StatusOr<CameraInfoMessage> DecodeCameraInfoMessage(Serialization serialization,
                                                    std::span<const uint8_t> bytes);

}  // namespace recog::bag
