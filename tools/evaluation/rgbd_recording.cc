#include "tools/evaluation/rgbd_recording.h"

#include <algorithm>
#include <filesystem>
#include <map>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/features/feature_extractor.h"
#include "tools/common/cli_support.h"
#include "tools/evaluation/frame_poses.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

// The images of `dir` by their number; INVALID_ARGUMENT for a name without one or a number twice.
StatusOr<std::map<int, std::string>> ImagesByNumber(const std::string& dir) {
  RECOG_ASSIGN_OR_RETURN(const std::vector<std::string> paths, ListImages(dir));
  std::map<int, std::string> by_number;
  for (const std::string& path : paths) {
    const std::optional<int> number = FrameNumber(path);
    if (!number) return Status::InvalidArgument("'" + path + "' has no frame number");
    if (const auto [other, added] = by_number.emplace(*number, path); !added) {
      return Status::InvalidArgument("'" + other->second + "' and '" + path + "' are both frame " +
                                     std::to_string(*number));
    }
  }
  return by_number;
}

// The depth image of a view: 16-bit, of its colour image's size.
StatusOr<cv::Mat> ReadDepth(const std::string& path, const cv::Size& size) {
  const cv::Mat depth = cv::imread(path, cv::IMREAD_ANYDEPTH);
  if (depth.empty()) return Status::InvalidArgument("cannot read depth image '" + path + "'");
  if (depth.type() != CV_16UC1 || depth.size() != size) {
    const auto described = [](int type, const cv::Size& of) {
      return cv::typeToString(type) + " of " + std::to_string(of.width) + "x" +
             std::to_string(of.height);
    };
    return Status::InvalidArgument("depth image '" + path + "' must be " +
                                   described(CV_16UC1, size) + " like its colour image, is " +
                                   described(depth.type(), depth.size()));
  }
  return depth;
}

}  // namespace

StatusOr<std::vector<RgbdRecordingFrame>> ListRgbdRecording(const std::string& dir) {
  const fs::path root(dir);
  RECOG_ASSIGN_OR_RETURN(const auto images, ImagesByNumber((root / "images").string()));
  RECOG_ASSIGN_OR_RETURN(const auto depths, ImagesByNumber((root / "depth").string()));
  std::vector<RgbdRecordingFrame> frames;
  for (const auto& [number, image] : images) {
    const auto depth = depths.find(number);
    if (depth == depths.end()) {
      return Status::NotFound("no depth image of frame " + std::to_string(number) + " ('" + image +
                              "') in '" + (root / "depth").string() + "'");
    }
    frames.push_back({number, image, depth->second});
  }
  return frames;
}

StatusOr<LearnedModel> LearnFromRgbdRecording(ModelBuilder* builder,
                                              const std::vector<RgbdRecordingFrame>& frames,
                                              const RgbdRecordingOptions& options,
                                              const LearningProgress& progress,
                                              std::vector<RgbdViewReport>* view_report) {
  if (frames.empty()) return Status::InvalidArgument("an RGB-D recording needs frames");
  if (!(options.depth_scale > 0)) return Status::InvalidArgument("depth scale must be positive");
  std::map<std::string, std::string> depth_of;  // frame name -> its depth image
  PosedImage first;
  std::vector<RecordingFrame> later;
  for (const RgbdRecordingFrame& frame : frames) {
    const std::string name = fs::path(frame.image).stem().string();
    depth_of[name] = frame.depth;
    RECOG_ASSIGN_OR_RETURN(cv::Mat image, ReadGrayImage(frame.image));
    if (first.image.empty()) {
      first = {name, std::move(image), options.camera, options.first_pose};
    } else {
      later.push_back({name, std::move(image)});
    }
  }
  std::map<std::string, RgbdView> chosen;  // by name: the views read so far
  const ModelFromViews build = [&](const std::vector<PosedImage>& views) -> StatusOr<ObjectModel> {
    std::vector<RgbdView> rgbd;
    for (const PosedImage& view : views) {
      auto known = chosen.find(view.name);
      if (known == chosen.end()) {
        RgbdView added;
        added.view = view;
        RECOG_ASSIGN_OR_RETURN(added.depth, ReadDepth(depth_of.at(view.name), view.image.size()));
        added.depth_scale = options.depth_scale;
        known = chosen.emplace(view.name, std::move(added)).first;
      }
      rgbd.push_back(known->second);
    }
    // The learner's last build is the learned model's: its report is the one left.
    return builder->FromRgbd(options.name, rgbd, options.box, view_report);
  };
  return LearnFromRecording(build, builder->vocabulary(), first, later, options.learning, progress);
}

StatusOr<std::vector<RgbdView>> PosedRgbdViews(const std::vector<RgbdRecordingFrame>& frames,
                                               const std::map<int, RigidTransform>& poses,
                                               const CameraIntrinsics& camera, double depth_scale,
                                               const std::vector<int>& numbers) {
  if (!(depth_scale > 0)) return Status::InvalidArgument("depth scale must be positive");
  std::vector<RgbdView> views;
  for (int number : numbers) {
    const auto frame = std::find_if(frames.begin(), frames.end(), [&](const RgbdRecordingFrame& f) {
      return f.number == number;
    });
    const auto pose = poses.find(number);
    if (frame == frames.end() || pose == poses.end()) {
      return Status::NotFound("frame " + std::to_string(number) + " has no " +
                              (frame == frames.end() ? "image" : "pose"));
    }
    RgbdView view;
    view.view.name = fs::path(frame->image).stem().string();
    RECOG_ASSIGN_OR_RETURN(view.view.image, ReadGrayImage(frame->image));
    view.view.camera = camera;
    view.view.camera_from_object = pose->second;
    RECOG_ASSIGN_OR_RETURN(view.depth, ReadDepth(frame->depth, view.view.image.size()));
    view.depth_scale = depth_scale;
    views.push_back(std::move(view));
  }
  return views;
}

}  // namespace recog::cli
