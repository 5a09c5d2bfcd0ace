// Robot recordings as a sequence of camera frames, for `recog eval place --bag`, `recog stream
// --bag` and `recog load --bag` (through FrameSource): ROS 1 bags, ROS 2 bags (a rosbag2 folder, a
// lone MCAP or sqlite3 file) — whatever tools/bag/bag_store.h opens, recognised by content. No ROS
// installation or environment is needed.
//
// A bag is opened with the topics of one camera: the image topic (required), and optionally its
// CameraInfo, a depth topic registered to it, and the right image of a rectified stereo pair with
// its CameraInfo. Opening checks everything before a frame is given out, so that nothing is
// streamed half: the file is a bag whose format checks pass (bag_store.h: a truncated file, a
// damaged chunk or an unindexed ROS 1 bag is DATA_LOSS saying so), each topic is in the bag (an
// unknown topic is NOT_FOUND listing the bag's topics with their types and counts), of a supported
// type and, message by message, of a supported encoding with a consistent size; the frames' stamps
// and their depth and right partners are then fixed. Only the pixels are decoded later, when their
// frame is read (a JPEG or PNG damaged past its header is then INVALID_ARGUMENT naming the frame).
//
// Supported messages (ROS 1 and ROS 2 alike; tools/bag/ros_images.h says every encoding):
//  - image and right topics: sensor_msgs/Image (mono8, rgb8, bgr8, ...) or CompressedImage (JPEG,
//    PNG);
//  - depth topic: sensor_msgs/Image in 16UC1 or mono16 (millimetres, REP 118) or 32FC1 (metres),
//    either byte order; or CompressedImage holding a 16-bit grey PNG or image_transport's
//    compressedDepth (PNG or RVL, millimetres or inverse depth). Frames carry depth in the
//    message's own units (no conversion): CV_16UC1 millimetres or CV_32FC1 metres; 0 (and NaN) =
//    no depth.
//  - camera info topics: sensor_msgs/CameraInfo; the first message is the calibration.
//
// Frames are the image topic's messages in the order of their header stamps (not the recording
// order), each stamp in seconds. Its depth image is the depth message of nearest stamp within
// BagReadOptions::max_depth_offset, its right image the right message of nearest stamp within
// max_right_offset (both may go with several frames); a frame without one is an error at open
// unless keep_unmatched_frames.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "core/object/model/object_model.h"
#include "tools/bag/bag_store.h"
#include "tools/evaluation/dataset_layouts.h"

namespace recog::cli {

// The topics of one camera in a bag; only `image` is required.
struct BagTopics {
  std::string image;              // sensor_msgs/Image or sensor_msgs/CompressedImage
  std::string camera_info;        // sensor_msgs/CameraInfo of the image topic
  std::string depth;              // depth registered to the image (same size)
  std::string right;              // right image of a rectified stereo pair (same size)
  std::string right_camera_info;  // sensor_msgs/CameraInfo of the right camera (its P: baseline)
};

struct BagReadOptions {
  // Largest |stamp_depth - stamp_image| (seconds) for a depth image to go with a frame. Default:
  // the TUM RGB-D reader's 0.02 s (kTumMaxDepthOffset).
  double max_depth_offset = kTumMaxDepthOffset;
  // Largest |stamp_right - stamp_left| (seconds) for a right image. Default 0: equal stamps (to
  // the nanosecond), as stereo drivers stamp the two images of a pair.
  double max_right_offset = 0;
  // Default false: a frame without a depth (or right) image within the offset is
  // INVALID_ARGUMENT at open, naming its stamp. true: the frame is kept without it.
  bool keep_unmatched_frames = false;
  // Default false: frames carry the grey image only. true: a colour message's frame also
  // carries its BGR image (BagFrame::color); the grey image is then converted from it.
  bool keep_color = false;
  // Default false: every frame's image is decoded. true: a CompressedImage's frame carries its
  // bytes as the bag holds them (BagFrame::encoded, a JPEG or a PNG) and no pixels, for a reader
  // that writes the image files (`recog bag extract`); a raw Image's frame is decoded as before.
  bool keep_encoded = false;

  // INVALID_ARGUMENT naming the field: offsets must be finite and >= 0.
  Status Validate(std::string_view name = "BagReadOptions") const;
};

// A CameraInfo message as the project's cameras.
struct BagCameraInfo {
  std::string topic;
  cv::Size size;  // width, height of the calibration (0 x 0 when the message has none)
  // K (fx, fy, cx, cy) with D as the coefficients of the lens distortion_model names
  // (RosCameraIntrinsics, camera_calibration.h): plumb_bob and rational_polynomial are
  // radial-tangential (OpenCV's order k1 k2 p1 p2 [k3 ...]), equidistant is equidistant; no
  // distortion when a radial-tangential D is empty or all zeros.
  CameraIntrinsics camera;
  // P's fx, fy, cx, cy: the camera of the rectified images, without distortion.
  CameraIntrinsics rectified;
  // P's Tx (P[3]) = -fx' * baseline for the right camera of a stereo pair; 0 for a left or
  // monocular camera.
  double projection_tx = 0;
  std::string distortion_model;
};

// A topic of a bag, for listings and messages.
struct BagTopicInfo {
  std::string topic;
  std::string type;  // "sensor_msgs/Image"
  uint64_t messages = 0;
};

struct BagFrame {
  double stamp = 0;      // header.stamp of the image message, seconds
  int64_t stamp_ns = 0;  // the same in nanoseconds since the epoch, exactly
  cv::Mat gray;          // CV_8UC1
  cv::Mat color;         // CV_8UC3 BGR, with keep_color for a colour message; else empty
  cv::Mat depth;         // CV_16UC1 millimetres or CV_32FC1 metres; empty without a depth image
  cv::Mat right;         // CV_8UC1; empty without a right image
  std::vector<uint8_t> encoded;  // with keep_encoded, a compressed image's bytes (gray empty)
  uint64_t index = 0;            // in stamp order, from 0
};

// "1305031102.175304000": a stamp (nanoseconds since the epoch) in seconds, exactly, as the
// messages and rgb.txt show it.
std::string BagStampText(int64_t ns);

// A bag opened for reading frames. Not thread-safe (one reader per thread); movable only.
class RosBagReader {
 public:
  // Opens `path` and checks it (header comment). NOT_FOUND for a missing file or topic;
  // DATA_LOSS for a truncated, unindexed or damaged bag; INVALID_ARGUMENT for anything else that
  // is not a bag of a supported kind, a topic of another type, an encoding or format
  // that is not supported, a message whose size disagrees with its data or its partner's, a
  // camera info without calibration (K zero), an image topic without messages, two frames with
  // the same stamp, a frame without a depth or right image (unless keep_unmatched_frames), or
  // bad options.
  static StatusOr<RosBagReader> Open(const std::string& path, const BagTopics& topics,
                                     const BagReadOptions& options = {});
  RosBagReader(RosBagReader&&) noexcept;
  RosBagReader& operator=(RosBagReader&&) noexcept;
  ~RosBagReader();

  // The topics of the bag at `path` (sorted by name); the errors of Open's file checks.
  static StatusOr<std::vector<BagTopicInfo>> ListTopics(const std::string& path);

  const std::string& path() const;
  const BagTopics& topics() const;
  // The bag as a whole: its storage, files, compression, duration and topics.
  const bag::BagSummary& summary() const;
  size_t size() const;  // frames
  // Each frame's stamp in seconds, in order.
  const std::vector<double>& stamps() const;
  // The image topic's camera, with BagTopics::camera_info; the right camera's with
  // right_camera_info.
  const std::optional<BagCameraInfo>& camera() const;
  const std::optional<BagCameraInfo>& right_camera() const;
  // The camera of the frames' images, with camera_info: the left camera's P (rectified, without
  // distortion) when the bag is read with a right topic, else its K with its distortion.
  std::optional<CameraIntrinsics> FrameCamera() const;
  // The stereo baseline in metres from the right camera's P (-Tx / fx'); none without
  // right_camera_info, INVALID_ARGUMENT when it is not positive (not a rectified right camera).
  StatusOr<std::optional<double>> StereoBaseline() const;

  // Frame i (< size()) in stamp order. INVALID_ARGUMENT for a compressed image that cannot be
  // decoded (naming the frame's stamp), DATA_LOSS when the bag cannot be read there.
  StatusOr<BagFrame> Read(size_t i);
  // The frame after the one Next returned last (the first at the start); false at the end.
  StatusOr<bool> Next(BagFrame* frame);

 private:
  struct Impl;
  explicit RosBagReader(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
  size_t next_ = 0;
};

}  // namespace recog::cli
