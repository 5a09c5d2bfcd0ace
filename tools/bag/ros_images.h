// The pixels of sensor_msgs Image and CompressedImage messages as the project's images: grey (and
// colour) images for the image topics, depth images for a depth topic — depth as ROS drivers and
// image_transport send it:
//  - Image: mono8/8UC1, rgb8, bgr8, rgba8, bgra8 for images; 16UC1 and mono16 (millimetres, REP
//    118) and 32FC1 (metres) for depth, with is_bigendian honoured;
//  - CompressedImage: a JPEG or a PNG for images (format "jpeg", "png", "bgr8; jpeg compressed
//    bgr8", ...); for depth a 16-bit grey PNG ("png", "16UC1; png compressed"), or
//    compressed_depth_image_transport's "16UC1; compressedDepth [png|rvl]" (a 12-byte header, then
//    a 16-bit PNG or RVL of millimetres) and "32FC1; compressedDepth [png|rvl]" (the same header
//    with its two quantisation parameters, then inverse depth; decoded to metres).
// Depth comes out in the message's own units, no conversion: CV_16UC1 millimetres or CV_32FC1
// metres; 0 (and NaN) = no depth. Inverse depth q is a / (q - b) metres, a and b the header's
// floats (little endian), as the transport's decoder computes it in float; q = 0, or a header
// whose a and b give no positive depth, is NaN.
//
// An image's sides are 1 to 65536 pixels; a JPEG, PNG or RVL image has at most 2^26 pixels
// (8192 x 8192), since its header alone says how much decoding it allocates. An RVL stream is
// decoded with every run checked against the pixels left.
//
// Inspect* reads a message's fields and, for a compressed one, only the header of its data, so
// that a whole topic is checked before any frame is decoded; Decode* then gives the pixels. Both
// return INVALID_ARGUMENT saying what is wrong (an encoding or format not supported for the role,
// data shorter than step × height, a header that does not match the data); the caller adds the
// file, topic and message.
#pragma once

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "tools/bag/ros_messages.h"

namespace recog::bag {

// What a topic is read for.
enum class ImageRole { kImage, kDepth };

// What a message holds, from its fields or its encoded header.
struct ImageLayout {
  cv::Size size;
  bool color = false;   // a colour image (raw or encoded); never for depth
  int depth_type = -1;  // for ImageRole::kDepth: CV_16UC1 or CV_32FC1, the type Decode* gives
};

StatusOr<ImageLayout> InspectImage(const ImageMessage& message, ImageRole role);
StatusOr<ImageLayout> InspectImage(const CompressedImageMessage& message, ImageRole role);

// An image topic's pixels: *gray (CV_8UC1, a compressed image through the decoder's own grey
// conversion) and, when `color` is not null and the message is colour, *color (CV_8UC3 BGR, with
// *gray converted from it). INVALID_ARGUMENT when the pixels do not decode to the inspected size.
Status DecodeGray(const ImageMessage& message, cv::Mat* gray, cv::Mat* color);
Status DecodeGray(const CompressedImageMessage& message, cv::Mat* gray, cv::Mat* color);

// A depth topic's pixels: CV_16UC1 millimetres or CV_32FC1 metres (ImageLayout::depth_type).
Status DecodeDepth(const ImageMessage& message, cv::Mat* depth);
Status DecodeDepth(const CompressedImageMessage& message, cv::Mat* depth);

}  // namespace recog::bag
