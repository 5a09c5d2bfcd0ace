#include "tools/evaluation/camera_calibration.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>

#include <yaml-cpp/yaml.h>

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

// The pairs of Kalibr's camera_model and distortion_model that are read, for messages.
constexpr char kKalibrModels[] = "pinhole with radtan, equidistant or none; ds with none";
// The CameraInfo distortion models that are read, for messages.
constexpr char kRosModels[] =
    "plumb_bob, rational_polynomial, equidistant (and the Kalibr names radtan, equi, ds), or any "
    "model with D all 0";

// "calibration file 'PATH'" (built by appending: GCC 12 warns, wrongly, about "'" + path).
std::string FileName(const std::string& path) {
  std::string name = "calibration file '";
  name += path;
  name += "'";
  return name;
}

// Where in a calibration file a value is, for messages: "calibration file 'F': cam1: ".
struct Source {
  std::string prefix;

  Source In(std::string_view key) const { return {prefix + std::string(key) + ": "}; }
  Status Fault(std::string_view what) const {
    return Status::InvalidArgument(prefix + std::string(what));
  }
};

bool AllZero(const std::vector<double>& values) {
  return std::all_of(values.begin(), values.end(), [](double v) { return v == 0; });
}

// A radial-tangential lens whose coefficients are all 0 is the pinhole camera: no coefficients.
void DropZeroRadTan(CameraIntrinsics* camera) {
  if (camera->lens == LensModel::kRadialTangential && AllZero(camera->distortion)) {
    camera->distortion.clear();
  }
}

StatusOr<YAML::Node> Required(const YAML::Node& map, const std::string& key, const Source& at) {
  const YAML::Node value = map[key];
  if (!value) return at.Fault("missing key '" + key + "'");
  return value;
}

// The text of `key`, `otherwise` when the map has none.
StatusOr<std::string> OptionalText(const YAML::Node& map, const std::string& key,
                                   const std::string& otherwise, const Source& at) {
  const YAML::Node value = map[key];
  if (!value) return otherwise;
  if (!value.IsScalar()) return at.Fault(key + " must be a name");
  return value.Scalar();
}

StatusOr<std::vector<double>> Numbers(const YAML::Node& list, const std::string& key,
                                      const Source& at) {
  if (!list.IsSequence()) return at.Fault(key + " must be a list of numbers");
  std::vector<double> numbers;
  for (const YAML::Node& item : list) {
    double v = 0;
    if (!YAML::convert<double>::decode(item, v)) {
      return at.Fault(key + " must be a list of numbers ('" +
                      (item.IsScalar() ? item.Scalar() : std::string("a list or map")) +
                      "' is not one)");
    }
    numbers.push_back(v);
  }
  return numbers;
}

// An image width or height: a whole number of pixels > 0.
bool IsPixelCount(double v) { return v >= 1 && v <= 1e6 && v == std::floor(v); }

// Kalibr's and EuRoC's `resolution: [width, height]`; 0 x 0 when there is none.
StatusOr<cv::Size> Resolution(const YAML::Node& map, const Source& at) {
  const YAML::Node value = map["resolution"];
  if (!value) return cv::Size();
  RECOG_ASSIGN_OR_RETURN(const std::vector<double> wh, Numbers(value, "resolution", at));
  if (wh.size() != 2 || !IsPixelCount(wh[0]) || !IsPixelCount(wh[1])) {
    return at.Fault("resolution must be [width, height] in whole pixels");
  }
  return cv::Size(int(wh[0]), int(wh[1]));
}

// The intrinsics and resolution of a camera that passed its lens's checks.
StatusOr<CameraCalibration> Calibrated(CameraIntrinsics camera, cv::Size size, const Source& at) {
  DropZeroRadTan(&camera);
  if (Status valid = camera.Validate(); !valid.ok()) return at.Fault(valid.message());
  return CameraCalibration{std::move(camera), size};
}

// One camera in Kalibr's terms: a camchain's camN, or EuRoC's and TUM-VI's sensor.yaml (whose
// coefficients are `distortion_coefficients`). Without camera_model: pinhole; without
// distortion_model: radtan when there are coefficients, none otherwise (as EuRoC's reader did).
StatusOr<CameraCalibration> ReadKalibrCamera(const YAML::Node& node, const Source& at) {
  if (!node.IsMap()) return at.Fault("must be a map with camera_model, intrinsics, …");
  RECOG_ASSIGN_OR_RETURN(const std::string camera_model,
                         OptionalText(node, "camera_model", "pinhole", at));
  const std::string coefficients_key =
      node["distortion_coeffs"] ? "distortion_coeffs" : "distortion_coefficients";
  std::vector<double> coefficients;
  if (node[coefficients_key]) {
    RECOG_ASSIGN_OR_RETURN(coefficients, Numbers(node[coefficients_key], coefficients_key, at));
  }
  RECOG_ASSIGN_OR_RETURN(
      const std::string distortion_model,
      OptionalText(node, "distortion_model", coefficients.empty() ? "none" : "radtan", at));
  RECOG_ASSIGN_OR_RETURN(const YAML::Node intrinsics_node, Required(node, "intrinsics", at));
  RECOG_ASSIGN_OR_RETURN(const std::vector<double> k, Numbers(intrinsics_node, "intrinsics", at));
  RECOG_ASSIGN_OR_RETURN(const cv::Size size, Resolution(node, at));

  const bool no_distortion = distortion_model == "none";
  if (no_distortion && !AllZero(coefficients)) {
    return at.Fault("distortion_model is none but " + coefficients_key + " are not all 0");
  }
  const StatusOr<LensModel> camera_lens = ParseLensModel(camera_model);
  const StatusOr<LensModel> distortion_lens = ParseLensModel(distortion_model);
  if (camera_model == "pinhole" &&
      (no_distortion || (distortion_lens.ok() && *distortion_lens != LensModel::kDoubleSphere))) {
    if (k.size() != 4) return at.Fault("intrinsics of a pinhole camera must be [fx, fy, cx, cy]");
    const LensModel lens = no_distortion ? LensModel::kRadialTangential : *distortion_lens;
    return Calibrated(
        {k[0], k[1], k[2], k[3], no_distortion ? std::vector<double>{} : coefficients, lens}, size,
        at);
  }
  if (camera_lens.ok() && *camera_lens == LensModel::kDoubleSphere && no_distortion) {
    if (k.size() != 6) {
      return at.Fault("intrinsics of a ds camera must be [xi, alpha, fx, fy, cx, cy]");
    }
    return Calibrated({k[2], k[3], k[4], k[5], {k[0], k[1]}, LensModel::kDoubleSphere}, size, at);
  }
  return at.Fault("camera_model '" + camera_model + "' with distortion_model '" + distortion_model +
                  "' is not supported (" + kKalibrModels + ")");
}

// "cam" and a number: cam0, cam1, ...
bool IsCamchainCamera(const std::string& key) {
  return key.size() > 3 && key.starts_with("cam") &&
         std::all_of(key.begin() + 3, key.end(), [](char c) { return c >= '0' && c <= '9'; });
}

bool IsCamchain(const YAML::Node& root) {
  for (const auto& entry : root) {
    if (entry.first.IsScalar() && IsCamchainCamera(entry.first.Scalar())) return true;
  }
  return false;
}

StatusOr<CameraCalibration> ReadCamchain(const YAML::Node& root, std::string_view camera,
                                         const Source& at) {
  const std::string name = camera.empty() ? "cam0" : std::string(camera);
  if (!IsCamchainCamera(name) || !root[name]) {
    std::string cameras;
    for (const auto& entry : root) {
      if (!entry.first.IsScalar() || !IsCamchainCamera(entry.first.Scalar())) continue;
      cameras += (cameras.empty() ? "" : ", ") + entry.first.Scalar();
    }
    return at.Fault("no camera '" + name + "' (the camchain has " + cameras + ")");
  }
  return ReadKalibrCamera(root[name], at.In(name));
}

// A matrix of a ROS or OpenCV calibration: a map with `data` (row-major) and, optionally, `rows`
// and `cols` (OpenCV adds `dt` and the tag !!opencv-matrix).
StatusOr<std::vector<double>> MatrixData(const YAML::Node& node, const Source& at) {
  if (!node.IsMap()) return at.Fault("must be a map with rows, cols and data");
  RECOG_ASSIGN_OR_RETURN(const YAML::Node data_node, Required(node, "data", at));
  RECOG_ASSIGN_OR_RETURN(std::vector<double> data, Numbers(data_node, "data", at));
  if (node["rows"] && node["cols"]) {
    double rows = 0, cols = 0;
    if (!YAML::convert<double>::decode(node["rows"], rows) ||
        !YAML::convert<double>::decode(node["cols"], cols) || rows * cols != double(data.size())) {
      return at.Fault("data has " + std::to_string(data.size()) +
                      " values, not rows x cols of them");
    }
  }
  return data;
}

// camera_info_manager's YAML (and OpenCV's FileStorage calibration, without distortion_model).
StatusOr<CameraCalibration> ReadRosCalibration(const YAML::Node& root, const Source& at) {
  RECOG_ASSIGN_OR_RETURN(const std::vector<double> K,
                         MatrixData(root["camera_matrix"], at.In("camera_matrix")));
  if (K.size() != 9 || K[1] != 0 || K[3] != 0 || K[6] != 0 || K[7] != 0 || K[8] != 1) {
    return at.Fault("camera_matrix must be 3 x 3 [fx, 0, cx, 0, fy, cy, 0, 0, 1]");
  }
  std::vector<double> d;
  if (root["distortion_coefficients"]) {
    RECOG_ASSIGN_OR_RETURN(
        d, MatrixData(root["distortion_coefficients"], at.In("distortion_coefficients")));
  }
  RECOG_ASSIGN_OR_RETURN(const std::string model, OptionalText(root, "distortion_model", "", at));
  cv::Size size;
  if (root["image_width"] || root["image_height"]) {
    double width = 0, height = 0;
    if (!YAML::convert<double>::decode(root["image_width"], width) ||
        !YAML::convert<double>::decode(root["image_height"], height) || !IsPixelCount(width) ||
        !IsPixelCount(height)) {
      return at.Fault("image_width and image_height must be whole numbers of pixels");
    }
    size = cv::Size(int(width), int(height));
  }
  StatusOr<CameraIntrinsics> camera = RosCameraIntrinsics({K[0], K[4], K[2], K[5], d}, model);
  if (!camera.ok()) return at.Fault(camera.status().message());
  return CameraCalibration{*std::move(camera), size};
}

// A text that names a file rather than numbers: a path, or a YAML file name.
bool LooksLikeFile(const std::string& text) {
  std::string lower = text;
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return lower.find('/') != std::string::npos || lower.ends_with(".yaml") ||
         lower.ends_with(".yml");
}

}  // namespace

StatusOr<YAML::Node> LoadYamlFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Status::NotFound("cannot open " + FileName(path));
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (text.starts_with("%YAML")) {
    const size_t end = text.find('\n');
    text.erase(0, end == std::string::npos ? text.size() : end + 1);
  }
  try {
    return YAML::Load(text);
  } catch (const YAML::Exception& e) {
    return Status::InvalidArgument(FileName(path) + ": " + e.what());
  }
}

StatusOr<CameraCalibration> ReadCalibrationFile(const std::string& path, std::string_view camera) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return Status::NotFound(FileName(path) + " does not exist");
  RECOG_ASSIGN_OR_RETURN(const YAML::Node root, LoadYamlFile(path));
  const Source at{FileName(path) + ": "};
  if (!root.IsMap()) return at.Fault("is not a map of keys");
  if (IsCamchain(root)) return ReadCamchain(root, camera, at);
  if (!camera.empty()) {
    return at.Fault("holds one camera: '#" + std::string(camera) +
                    "' picks a camera of a Kalibr camchain only");
  }
  if (root["camera_matrix"]) return ReadRosCalibration(root, at);
  if (root["intrinsics"] || root["camera_model"]) return ReadKalibrCamera(root, at);
  return at.Fault(
      "is not a calibration file: expected a Kalibr camchain (cam0: …), a EuRoC or TUM-VI "
      "sensor.yaml (camera_model, intrinsics) or a ROS or OpenCV calibration (camera_matrix)");
}

StatusOr<CameraIntrinsics> ReadCameraCalibration(const std::string& path, std::string_view camera) {
  RECOG_ASSIGN_OR_RETURN(CameraCalibration calibration, ReadCalibrationFile(path, camera));
  return std::move(calibration.camera);
}

StatusOr<CameraIntrinsics> ParseCameraFlag(std::string_view flag, const std::string& text) {
  std::error_code ec;
  std::string path = text, camera;
  const size_t hash = text.rfind('#');
  if (hash != std::string::npos && !fs::exists(text, ec)) {
    path = text.substr(0, hash);
    camera = text.substr(hash + 1);
  }
  if (fs::is_regular_file(path, ec)) {
    StatusOr<CameraIntrinsics> read = ReadCameraCalibration(path, camera);
    if (!read.ok()) return read.status().WithContext(flag);
    return read;
  }
  if (LooksLikeFile(path)) {
    return Status::NotFound(std::string(flag) + ": " + FileName(path) + " does not exist");
  }
  return ParseCameraText(flag, text);
}

StatusOr<CameraIntrinsics> RosCameraIntrinsics(CameraIntrinsics camera,
                                               std::string_view distortion_model) {
  camera.lens = LensModel::kRadialTangential;
  if (!distortion_model.empty()) {
    const StatusOr<LensModel> lens = ParseLensModel(distortion_model);
    if (lens.ok()) {
      camera.lens = *lens;
    } else if (AllZero(camera.distortion)) {
      camera.distortion.clear();
    } else {
      return Status::InvalidArgument("distortion model '" + std::string(distortion_model) +
                                     "' is not supported (read: " + kRosModels + ")");
    }
  }
  DropZeroRadTan(&camera);
  RECOG_RETURN_IF_ERROR(camera.Validate());
  return camera;
}

}  // namespace recog::cli
