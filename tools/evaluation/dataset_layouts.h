// Readers of public RGB-D and stereo dataset layouts, for `recog eval place --images DIR`: each
// turns a dataset folder into its frames in order, with their timestamps (seconds) and image
// paths.
//  - TUM RGB-D: DIR/rgb.txt and DIR/depth.txt, lines "timestamp path" (seconds; paths relative to
//    DIR), "#" comments. Each colour image gets the depth image of nearest timestamp when it is
//    within kTumMaxDepthOffset (else none); depth.txt is optional.
//  - EuRoC MAV: DIR/mav0/cam0/data.csv (or DIR/cam0/data.csv), lines "timestamp [ns],filename"
//    with the images in cam0/data/, "#" comments (the header). The right image is cam1's row of
//    the same timestamp (none when cam1/data.csv is missing or has no such row).
//  - KITTI odometry: DIR/times.txt, one time in seconds per line, frame i being
//    DIR/image_0/%06d.png (left) and DIR/image_1/%06d.png (right, when it exists).
// Every listed image must exist (NOT_FOUND naming it); a malformed line (INVALID_ARGUMENT naming
// the file and line), a negative or non-finite time, timestamps that do not strictly increase, or
// a list without frames are INVALID_ARGUMENT; a missing list file is NOT_FOUND.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/common/status.h"

namespace recog::cli {

// kFolder: a plain folder of images (natural order of names), without timestamps.
enum class DatasetLayout { kFolder, kTum, kEuroc, kKitti };
std::string_view DatasetLayoutName(DatasetLayout layout);  // "folder", "tum", "euroc", "kitti"
// INVALID_ARGUMENT for another name.
StatusOr<DatasetLayout> ParseDatasetLayout(std::string_view name);

// The layout of folder `dir` by its files: kTum with rgb.txt, kEuroc with mav0/cam0/data.csv or
// cam0/data.csv, kKitti with times.txt and image_0/, kFolder otherwise.
DatasetLayout DetectDatasetLayout(const std::string& dir);

// Largest |t_depth - t_rgb| (seconds) for a TUM depth image to go with a colour image.
inline constexpr double kTumMaxDepthOffset = 0.02;

struct DatasetFrame {
  double timestamp = 0;  // seconds
  std::string image;     // colour (TUM) or left (EuRoC cam0, KITTI image_0) image
  std::string depth;     // TUM: the associated depth image; empty when none
  std::string right;     // EuRoC cam1 / KITTI image_1: the right image; empty when none
};

// The frames of the dataset in `dir`, in order. kFolder is INVALID_ARGUMENT (no timestamps:
// list its images with ListImages).
StatusOr<std::vector<DatasetFrame>> ReadDatasetFrames(const std::string& dir, DatasetLayout layout);

// The list parsers behind ReadDatasetFrames, shared with the rig readers (rig_dataset.h); the
// checks above apply, but a list without frames is not an error here.
// An EuRoC camera folder's data.csv (images in camera_dir/data/): (timestamp [ns], image path)
// per line, in order.
StatusOr<std::vector<std::pair<int64_t, std::string>>> ReadEurocCameraList(
    const std::string& camera_dir);
// A KITTI odometry folder's times.txt: each frame's time in seconds, in order.
StatusOr<std::vector<double>> ReadKittiTimes(const std::string& dir);

}  // namespace recog::cli
