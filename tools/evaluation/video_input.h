// Video files and cameras as frame sources, read by OpenCV's videoio in a module of their own
// (librecog_video.so) that is loaded the first time a video or a camera is opened. videoio brings
// ffmpeg and GStreamer with it, about a hundred shared libraries: every other run of `recog`
// (and every test binary that reads no video) starts without loading them, a third faster.
#pragma once

#include <memory>
#include <string>

#include <opencv2/core.hpp>

#include "core/common/status.h"

namespace recog::cli {

// An opened video file or camera: frames in order until the end (a camera has none).
class VideoInput {
 public:
  virtual ~VideoInput() = default;
  // The next frame as OpenCV decoded it (BGR or grey); false at the end or on a read error.
  virtual bool Read(cv::Mat* frame) = 0;
  // The container's frame count; 0 when unknown, and for a camera.
  virtual size_t FrameCount() const = 0;
};

// A video file read by FFmpeg. INVALID_ARGUMENT when FFmpeg cannot open it; FAILED_PRECONDITION
// when the video module cannot be loaded (VideoModulePath).
StatusOr<std::unique_ptr<VideoInput>> OpenVideoFile(const std::string& path);
// The Video4Linux camera /dev/video<index>. NOT_FOUND when it is missing or busy;
// FAILED_PRECONDITION when the video module cannot be loaded.
StatusOr<std::unique_ptr<VideoInput>> OpenCamera(int index);

// Where the video module is looked for: $RECOG_VIDEO_MODULE when set, else next to the running
// program's folder as installed and as built (<program dir>/../<libdir>/recog/librecog_video.so).
std::string VideoModulePath();

}  // namespace recog::cli
