#include "tools/evaluation/video_input.h"

#include <dlfcn.h>

#include <cstdlib>
#include <filesystem>

namespace recog::cli {

namespace {

namespace fs = std::filesystem;

// The module's two entry points (video_module.cc): an opened input, or null when it cannot be.
using OpenFileFunction = VideoInput* (*)(const char* path);
using OpenCameraFunction = VideoInput* (*)(int index);

struct VideoModule {
  OpenFileFunction open_file = nullptr;
  OpenCameraFunction open_camera = nullptr;
  Status status;  // why it could not be loaded
};

// Loaded once, on first use, and never unloaded: the inputs it makes run its code.
const VideoModule& LoadVideoModule() {
  static const VideoModule module = [] {
    VideoModule loaded;
    const std::string path = VideoModulePath();
    void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (handle != nullptr) {
      loaded.open_file = reinterpret_cast<OpenFileFunction>(dlsym(handle, "recog_video_open_file"));
      loaded.open_camera =
          reinterpret_cast<OpenCameraFunction>(dlsym(handle, "recog_video_open_camera"));
    }
    if (loaded.open_file == nullptr || loaded.open_camera == nullptr) {
      const char* error = dlerror();
      loaded.status =
          Status::FailedPrecondition("video and camera input need the video module " + path +
                                     " (installed with recog; RECOG_VIDEO_MODULE names another): " +
                                     (error != nullptr ? error : "its entry points are missing"));
    }
    return loaded;
  }();
  return module;
}

}  // namespace

std::string VideoModulePath() {
  if (const char* path = std::getenv("RECOG_VIDEO_MODULE"); path != nullptr && *path != '\0') {
    return path;
  }
  std::error_code error;
  const fs::path program = fs::read_symlink("/proc/self/exe", error);
  return (program.parent_path() / RECOG_VIDEO_MODULE_FROM_PROGRAM).lexically_normal().string();
}

StatusOr<std::unique_ptr<VideoInput>> OpenVideoFile(const std::string& path) {
  const VideoModule& module = LoadVideoModule();
  if (!module.status.ok()) return module.status;
  std::unique_ptr<VideoInput> input(module.open_file(path.c_str()));
  if (input == nullptr) return Status::InvalidArgument("'" + path + "' cannot be read as a video");
  return input;
}

StatusOr<std::unique_ptr<VideoInput>> OpenCamera(int index) {
  const VideoModule& module = LoadVideoModule();
  if (!module.status.ok()) return module.status;
  std::unique_ptr<VideoInput> input(module.open_camera(index));
  if (input == nullptr) {
    return Status::NotFound("camera " + std::to_string(index) + " (/dev/video" +
                            std::to_string(index) + ") cannot be opened: missing or busy");
  }
  return input;
}

}  // namespace recog::cli
