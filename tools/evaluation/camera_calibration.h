// Camera calibration files: one camera's intrinsics and lens (core/geometry/camera_model.h) from
// what calibration tools write, recognised by content (docs/cli.md, "Cameras"):
//  - a Kalibr camchain (camchain.yaml; TUM-VI's too): `cam0:`, `cam1:`, … each with
//    `camera_model`, `intrinsics`, `distortion_model`, `distortion_coeffs` and `resolution`
//    [width, height]. Read: camera_model pinhole (intrinsics [fx, fy, cx, cy]) with
//    distortion_model radtan, equidistant (or equi) or none, and camera_model ds (intrinsics
//    [xi, alpha, fx, fy, cx, cy]) with none. Others (omni, eucm, pinhole-fov, …) are refused.
//  - one camera in the same terms at the top level: EuRoC's and TUM-VI's `sensor.yaml`
//    (`distortion_coefficients`, `radial-tangential`; OpenCV's "%YAML:1.0" first line is skipped).
//  - a ROS camera_calibration file (camera_info_manager's YAML): `image_width`, `image_height`,
//    `camera_matrix: {rows: 3, cols: 3, data: [9 numbers]}`, `distortion_model` and
//    `distortion_coefficients: {data: […]}`, read as a CameraInfo (RosCameraIntrinsics). OpenCV's
//    FileStorage calibration (the calibration sample's `camera_matrix` and
//    `distortion_coefficients` as !!opencv-matrix, no distortion_model) is read the same way:
//    radial-tangential.
// Coefficients that are all 0 on a radial-tangential lens give a pinhole camera (none).
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "core/geometry/camera_model.h"

namespace YAML {
class Node;
}

namespace recog::cli {

struct CameraCalibration {
  CameraIntrinsics camera;  // valid (CameraIntrinsics::Validate)
  cv::Size size;            // the calibrated image size; 0 x 0 when the file gives none
};

// The camera of the calibration file at `path`; `camera` names a camchain's camera ("cam1";
// default cam0) and must be empty for the other formats. NOT_FOUND when the file does not exist;
// INVALID_ARGUMENT naming the file (and the camera and key) for YAML that does not parse, a file
// of none of the formats, an unknown camera name (listing the file's), a missing or malformed
// key, an unsupported lens (naming it and what is read) or intrinsics that do not validate.
StatusOr<CameraCalibration> ReadCalibrationFile(const std::string& path,
                                                std::string_view camera = "");
// Its camera alone.
StatusOr<CameraIntrinsics> ReadCameraCalibration(const std::string& path,
                                                 std::string_view camera = "");

// A camera flag of the command-line tools (--camera, --depth-camera): the path of a calibration
// file, optionally with "#camN" to pick a camchain's camera, when that file exists; otherwise
// ParseCameraText's syntax (fx,fy,cx,cy[,k1,k2,p1,p2[,k3…]] or LENS:fx,fy,cx,cy,coefficients). A
// text that looks like a file (with a '/' or ending in .yaml or .yml) but names none is NOT_FOUND.
// Errors are prefixed with `flag`.
StatusOr<CameraIntrinsics> ParseCameraFlag(std::string_view flag, const std::string& text);

// ParseCameraFlag's syntax in short, for the flags' help texts.
inline constexpr char kCameraFlagSyntax[] =
    "fx,fy,cx,cy[,k1,k2,p1,p2[,k3]], LENS:fx,fy,cx,cy,coefficients (LENS equidistant or ds), or "
    "a calibration file (Kalibr camchain[#camN], EuRoC sensor.yaml, ROS camera_info YAML); "
    "docs/cli.md \"Cameras\"";

// The camera of a ROS CameraInfo (sensor_msgs/CameraInfo, camera_info_manager's YAML): `camera`'s
// fx, fy, cx, cy with its `distortion`, D, as the coefficients of the lens `distortion_model`
// names, mapped by ParseLensModel: plumb_bob and rational_polynomial are radial-tangential,
// equidistant is equidistant (D kept even when all 0: r = θ is no pinhole). A radial-tangential D
// of zeros, and a model no lens knows with D empty or all 0, are a pinhole camera; an empty model
// with coefficients is radial-tangential (older drivers); another model with coefficients is
// INVALID_ARGUMENT naming it and the models read. The camera is validated.
StatusOr<CameraIntrinsics> RosCameraIntrinsics(CameraIntrinsics camera,
                                               std::string_view distortion_model);

// The YAML document of the file at `path` as yaml-cpp reads it, after OpenCV FileStorage's
// "%YAML:1.0" first line (EuRoC's sensor.yaml files have it), a directive yaml-cpp refuses.
// NOT_FOUND when the file cannot be opened; INVALID_ARGUMENT naming it when it does not parse.
StatusOr<YAML::Node> LoadYamlFile(const std::string& path);

}  // namespace recog::cli
