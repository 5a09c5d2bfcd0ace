// Rig sequences on disk, for `recog eval place --rig PATH`: the cameras of a multi-camera rig
// (core/geometry/camera_rig.h) and, per rig frame, one image per camera (and its depth image,
// when the camera has one). Three layouts:
//  - plain: a rig file (rig_file.h) and, beside it, one folder per camera named after it, each a
//    dataset of its own: a TUM RGB-D folder (rgb.txt, optional depth.txt) or a plain folder of
//    images (natural order of names). PATH is the rig file, or the folder holding `rig.yaml`.
//    What `recog seqgen rig` writes.
//  - EuRoC MAV: PATH/mav0/camN or PATH/camN (N = 0, 1, ... while camN/sensor.yaml exists), each
//    with its sensor.yaml (T_BS: the camera's pose in the body frame, a 4x4 row-major `data`;
//    resolution [w, h]; intrinsics [fu, fv, cu, cv]; distortion_model radial-tangential
//    [k1, k2, p1, p2] or equidistant [k1, k2, k3, k4] in distortion_coefficients: read as a
//    calibration file, camera_calibration.h) and data.csv ("timestamp [ns],filename", images in
//    camN/data/). A rig frame is a timestamp every camera has an image at; others are skipped.
//  - KITTI odometry: PATH/calib.txt (lines "PN: 12 numbers", the rectified 3x4 projection matrix
//    of camera N), PATH/times.txt (seconds per frame) and PATH/image_N/%06d.png. Every camera
//    with a PN line and an image_N folder is used; its K is the left 3x3 of PN, no distortion
//    (rectified), and its pose in the body frame (camera 0's frame) is a translation by
//    -K^-1 * (column 4 of PN). Image sizes are read from each camera's first image.
// Errors: NOT_FOUND for a missing path, camera folder, list or image (naming it);
// INVALID_ARGUMENT naming the file (and camera) for a malformed file, a rig that does not
// validate, cameras with different frame counts (plain, KITTI) or no common frame (EuRoC).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/geometry/camera_rig.h"

namespace recog::cli {

enum class RigLayout { kPlain, kEuroc, kKitti };
std::string_view RigLayoutName(RigLayout layout);  // "plain", "euroc", "kitti"

struct RigDataset {
  RigLayout layout = RigLayout::kPlain;
  std::vector<RigCamera> cameras;
  // Per rig frame, seconds: from the first camera's list (TUM, EuRoC, KITTI); none when the
  // cameras are plain folders of images.
  std::vector<std::optional<double>> timestamps;
  std::vector<std::vector<std::string>> images;  // images[frame][camera]: paths
  std::vector<std::vector<std::string>> depths;  // depths[frame][camera]: path, "" when none
};

// The layout of PATH: kPlain for a file, or a folder with rig.yaml; else the EuRoC or KITTI layout
// DetectDatasetLayout (dataset_layouts.h) finds in the folder. INVALID_ARGUMENT (naming the three)
// for anything else, a TUM folder included; NOT_FOUND when PATH does not exist.
StatusOr<RigLayout> DetectRigLayout(const std::string& path);

// Reads the rig sequence at PATH in the layout DetectRigLayout finds.
StatusOr<RigDataset> ReadRigDataset(const std::string& path);

}  // namespace recog::cli
