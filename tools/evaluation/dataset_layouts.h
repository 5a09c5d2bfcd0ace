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
//    DIR/image_0/%06d.png (left) and DIR/image_1/%06d.png (right, when it exists). (The rig reader,
//    rig_dataset.h, reads every camera folder image_N/ with its calib.txt.)
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

// The layout of folder `dir` by its files, for the single-camera readers here and the rig readers
// (DetectRigLayout) alike: kTum with rgb.txt; kEuroc with mav0/cam0/data.csv or cam0/data.csv;
// kKitti with times.txt beside a camera folder image_N/ (N < kKittiCameras); kFolder otherwise.
// The KITTI rule is what every KITTI sequence a reader can use has: its times and its images.
// calib.txt is no part of it (only the rig reader needs it, and names it when it is missing), nor
// is image_0/ (KITTI's colour sequences are image_2/ and image_3/, which a rig reads; the
// single-camera reader names the image_0/000000.png it lacks).
DatasetLayout DetectDatasetLayout(const std::string& dir);

// KITTI odometry's cameras: image_0/ and image_1/ grey, image_2/ and image_3/ colour.
inline constexpr int kKittiCameras = 4;

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
