// librecog_video.so: OpenCV's videoio behind VideoInput (video_input.h). OpenVideoFile and
// OpenCamera load it on first use, so that only the programs that read a video or a camera load
// videoio and the codec and camera libraries it brings. Its two entry points return an opened
// input, or null when the file or camera cannot be opened.
#include <memory>

#include <opencv2/core/utils/logger.hpp>
#include <opencv2/videoio.hpp>

#include "tools/evaluation/video_input.h"

namespace recog::cli {
namespace {

class CaptureInput final : public VideoInput {
 public:
  CaptureInput(std::unique_ptr<cv::VideoCapture> capture, bool live)
      : capture_(std::move(capture)), live_(live) {}

  bool Read(cv::Mat* frame) override { return capture_->read(*frame) && !frame->empty(); }

  size_t FrameCount() const override {
    if (live_) return 0;
    const double count = capture_->get(cv::CAP_PROP_FRAME_COUNT);
    return count > 0 ? size_t(count) : 0;
  }

 private:
  std::unique_ptr<cv::VideoCapture> capture_;
  bool live_;
};

// The capture `open` makes, or null when it is not opened or OpenCV throws.
template <typename Open>
VideoInput* Opened(Open open, bool live) {
  try {
    auto capture = open();
    if (!capture->isOpened()) return nullptr;
    return new CaptureInput(std::move(capture), live);
  } catch (const cv::Exception&) {
    return nullptr;
  }
}

}  // namespace
}  // namespace recog::cli

// FFmpeg reads video files; letting OpenCV probe every capture backend would also start camera
// libraries (FireWire, USB) that have no business with a file.
extern "C" recog::cli::VideoInput* recog_video_open_file(const char* path) {
  return recog::cli::Opened(
      [path] { return std::make_unique<cv::VideoCapture>(path, cv::CAP_FFMPEG); }, false);
}

// A missing device is reported by the caller, once, not also by OpenCV's own warning.
extern "C" recog::cli::VideoInput* recog_video_open_camera(int index) {
  const auto log_level = cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_ERROR);
  recog::cli::VideoInput* input = recog::cli::Opened(
      [index] { return std::make_unique<cv::VideoCapture>(index, cv::CAP_V4L2); }, true);
  cv::utils::logging::setLogLevel(log_level);
  return input;
}
