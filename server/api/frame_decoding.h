// Decoding and validating a request's Frame (recognition/v1/common.proto) into a DecodedFrame: its
// image (encoded or raw) or the client's features, its intrinsics, its depth or stereo right
// image, its timestamp and ids. Every image is charged to the call's PixelBudget from the size its
// header declares before anything is decoded, so that a small file declaring a huge image costs
// nothing. Anything core could not use (undecodable image, zero size, wrong descriptor length, bad
// intrinsics, non-finite numbers) is INVALID_ARGUMENT naming the field, so that core only ever sees
// good data. Places prepare a decoded frame further (prepared_frame.h).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/descriptor.h"
#include "core/common/feature_set.h"
#include "core/common/status.h"
#include "core/geometry/camera_model.h"
#include "core/index/entry.h"
#include "recognition/v1/common.pb.h"
#include "server/api/image_header.h"

namespace recog::server {

namespace pb = ::recognition::v1;

// Limits on what a frame may hold (beyond gRPC's message size).
inline constexpr uint32_t kMaxImageSide = 16384;  // pixels, width or height
// 16 Mpixel (4096x4096; robots' largest cameras give 12.6): what one image costs to process grows
// with it (a 16384x4096 PNG of 65 KB took 309 MiB and 7 s of a worker at 64 Mpixel).
inline constexpr uint64_t kMaxImagePixels = 16ull << 20;
inline constexpr uint64_t kMaxCallPixels = 64ull << 20;  // all the images of one call together
// Memory to decode one image (MemoryToDecode: the image and the decoder's buffers): 128 MiB holds
// a 4096x3072 progressive 4:4:4 JPEG (84 MiB), not an 8192x8192 progressive JPEG (256 MiB in
// 4:2:0, 576 MiB in CMYK).
inline constexpr uint64_t kMaxImageDecodeBytes = 128ull << 20;
// PixelBudget's default memory for the images of one call (see there).
inline constexpr uint64_t kDefaultCallDecodeBytes = 256ull << 20;
// Scans of a JPEG: each one is a pass of the decoder over the image (a progressive JPEG has 6 to
// 18; libjpeg's default script makes 10 for colour), so that a few bytes a scan cannot buy seconds.
inline constexpr uint32_t kMaxJpegScans = 64;
inline constexpr uint32_t kMaxClientFeatures = 100000;
inline constexpr size_t kMaxFrameIdBytes = 128;  // camera_id and client_frame_id

// A frame as the algorithms want it: an 8-bit grey image, or the client's features.
struct DecodedFrame {
  cv::Mat image;        // CV_8UC1; empty when the client sent features
  FeatureSet features;  // the client's features (when image is empty)
  std::optional<CameraIntrinsics> intrinsics;
  std::optional<double> timestamp;  // seconds; none when the frame has none
  std::string camera_id;
  std::string client_frame_id;  // stored with a place frame
  double decode_ms = 0;         // time spent decoding the image (and the depth or right image)
  // The frame's 3D structure (place maps, metric loops); at most one of the two, and then
  // `intrinsics` is set without distortion. Sizes match the image (or the features' image size).
  cv::Mat depth;           // CV_16U (units of depth_scale metres) or CV_32F (metres); or empty
  double depth_scale = 0;  // metres per unit of CV_16U depth
  cv::Mat right;           // CV_8UC1, the right image of a rectified stereo pair; or empty
  double baseline_m = 0;   // > 0 with `right`
  std::vector<EntryId> excluded_frames;  // place maps: never candidates for this frame
  bool has_image() const { return !image.empty(); }
};

// The pixels and the memory one call may decode, charged before anything is decoded from the size
// an encoded image declares in its header, so that a small file declaring a huge or costly image
// costs nothing. Each image: at most kMaxImageSide pixels a side and kMaxImagePixels, a JPEG at
// most kMaxJpegScans scans, and at most kMaxImageDecodeBytes to decode. All the images of the call
// (its frames, their views, depth and right images) together: at most kMaxCallPixels, and their
// decoded images plus the decoder's buffers of the one being decoded at most `max_decode_bytes`, so
// that a call's images never take more. Calls decode on the workers, one call each: with N workers,
// the images being decoded or held take at most N x max_decode_bytes in all. One per call.
class PixelBudget {
 public:
  explicit PixelBudget(uint64_t max_decode_bytes = kDefaultCallDecodeBytes)
      : max_decode_bytes_(max_decode_bytes), decode_bytes_left_(max_decode_bytes) {}

  // Charges an encoded image of `field` decoded to `bytes_per_pixel` a pixel (1: 8-bit grey; 2: a
  // 16-bit depth PNG). INVALID_ARGUMENT naming it and the figure for a zero size or anything
  // beyond a limit (then nothing is charged).
  Status Take(const ImageHeader& header, const std::string& field, uint32_t bytes_per_pixel = 1);
  // Charges a width x height image of `bytes_per_pixel` a pixel that needs no decoder (a raw
  // image's copy, or a size checked as an image's); as above.
  Status Take(uint64_t width, uint64_t height, const std::string& field,
              uint32_t bytes_per_pixel = 1);

 private:
  // Charges `memory` to decode a `what` image of `pixels` (whose size is checked).
  Status Charge(uint64_t pixels, const DecodeMemory& memory, const std::string& what,
                const std::string& field);

  uint64_t pixels_left_ = kMaxCallPixels;
  uint64_t max_decode_bytes_;
  uint64_t decode_bytes_left_;  // what the call's decoded images leave of max_decode_bytes_
};

// Decodes and validates a frame, its images charged to `budget`. Client features must have
// `format`'s descriptor length. INVALID_ARGUMENT (naming the field) for anything unusable,
// including a frame without content, and for depth or a right image that cannot go with the frame:
// another size than the image, 8-bit depth, a missing or non-positive baseline, no intrinsics (or
// intrinsics with distortion), both depth and a right image, a right image with client features,
// more than kMaxExcludedFrames exclude_frame_ids. `camera`, when given, is the frame's intrinsics
// in place of frame.intrinsics (a rig view's, which its camera in the map's rig holds).
inline constexpr int kMaxExcludedFrames = 1000;
StatusOr<DecodedFrame> DecodeFrame(const pb::Frame& frame, const DescriptorFormat& format,
                                   PixelBudget& budget, const CameraIntrinsics* camera = nullptr);
// The part of DecodeFrame that does not look at the content: the timestamp, the ids and
// exclude_frame_ids (a rig frame's, whose content is in its views).
Status DecodeFrameHeader(const pb::Frame& frame, DecodedFrame* out);

// A lens model of the wire (CameraIntrinsics.lens); INVALID_ARGUMENT naming `field` for a number
// that names none.
StatusOr<LensModel> LensFromProto(int lens, const std::string& field);

}  // namespace recog::server
