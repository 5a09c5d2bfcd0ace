#include "tools/evaluation/rig_dataset.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <utility>

#include <yaml-cpp/yaml.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "tools/common/cli_support.h"
#include "tools/evaluation/camera_calibration.h"
#include "tools/evaluation/dataset_layouts.h"
#include "tools/evaluation/rig_file.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

// 'path' (GCC 12 warns, wrongly, about "'" + path.string()).
std::string QuotedPath(const fs::path& path) {
  std::string quoted = "'";
  quoted += path.string();
  quoted += "'";
  return quoted;
}

// Largest Frobenius distance from a EuRoC T_BS rotation to the nearest rotation that is still
// taken for rounding (the files print ~9 digits); anything farther is left for ValidateRig to
// refuse.
constexpr double kRoundedRotationTolerance = 1e-3;

// One camera's frames in the plain layout.
struct CameraFrames {
  std::vector<std::optional<double>> timestamps;
  std::vector<std::string> images, depths;
};

// A camera folder of the plain layout: a TUM RGB-D folder or a plain folder of images.
StatusOr<CameraFrames> ReadPlainCamera(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    return Status::NotFound("folder " + QuotedPath(dir) + " not found");
  CameraFrames frames;
  const DatasetLayout layout = DetectDatasetLayout(dir.string());
  if (layout == DatasetLayout::kTum) {
    RECOG_ASSIGN_OR_RETURN(const std::vector<DatasetFrame> tum,
                           ReadDatasetFrames(dir.string(), layout));
    for (const DatasetFrame& frame : tum) {
      frames.timestamps.push_back(frame.timestamp);
      frames.images.push_back(frame.image);
      frames.depths.push_back(frame.depth);
    }
  } else if (layout == DatasetLayout::kFolder) {
    RECOG_ASSIGN_OR_RETURN(frames.images, ListImages(dir.string()));
    frames.timestamps.assign(frames.images.size(), std::nullopt);
    frames.depths.assign(frames.images.size(), "");
  } else {
    // ListImages would mix a stereo dataset's two cameras into one.
    return Status::InvalidArgument(QuotedPath(dir) + " is a " +
                                   std::string(DatasetLayoutName(layout)) +
                                   " dataset; a rig camera's folder is a TUM RGB-D folder or a "
                                   "folder of images");
  }
  return frames;
}

StatusOr<RigDataset> ReadPlain(const fs::path& path) {
  std::error_code ec;
  const fs::path file = fs::is_directory(path, ec) ? path / "rig.yaml" : path;
  RECOG_ASSIGN_OR_RETURN(std::vector<RigCamera> cameras, ReadRigFile(file.string()));
  std::vector<CameraFrames> per_camera;
  for (const RigCamera& camera : cameras) {
    StatusOr<CameraFrames> frames = ReadPlainCamera(file.parent_path() / camera.name);
    if (!frames.ok()) return frames.status().WithContext("rig camera '" + camera.name + "'");
    const size_t count = frames->images.size(),
                 first = per_camera.empty() ? count : per_camera[0].images.size();
    if (count != first) {
      return Status::InvalidArgument("rig camera '" + camera.name + "' of " + QuotedPath(file) +
                                     " has " + std::to_string(count) + " frames, camera '" +
                                     cameras[0].name + "' has " + std::to_string(first));
    }
    per_camera.push_back(*std::move(frames));
  }
  RigDataset rig;
  rig.layout = RigLayout::kPlain;
  rig.cameras = std::move(cameras);
  rig.timestamps = per_camera[0].timestamps;
  for (size_t i = 0; i < rig.timestamps.size(); ++i) {
    rig.images.emplace_back();
    rig.depths.emplace_back();
    for (const CameraFrames& camera : per_camera) {
      rig.images.back().push_back(camera.images[i]);
      rig.depths.back().push_back(camera.depths[i]);
    }
  }
  return rig;
}

// The numbers of `map`'s list `key` of `count` numbers (`what` names it in messages).
std::vector<double> Numbers(const YAML::Node& map, const std::string& key, size_t count,
                            const std::string& what) {
  const YAML::Node node = map[key];
  if (!node) throw YAML::Exception(map.Mark(), what + " is missing");
  return YamlNumbers(node, count, what);
}

// The nearest rotation to R (U Vᵀ of its SVD), when R is one up to rounding; else R.
cv::Matx33d NearestRotation(const cv::Matx33d& R) {
  cv::Matx31d w;
  cv::Matx33d u, vt;
  cv::SVD::compute(R, w, u, vt);
  const cv::Matx33d nearest = u * vt;
  return cv::norm(R - nearest) <= kRoundedRotationTolerance ? nearest : R;
}

// A EuRoC camera's sensor.yaml, as the rig camera `name`: its camera and resolution as a
// calibration file (camera_calibration.h), and T_BS.
StatusOr<RigCamera> ReadEurocSensor(const fs::path& file, const std::string& name) {
  RECOG_ASSIGN_OR_RETURN(const CameraCalibration calibration, ReadCalibrationFile(file.string()));
  if (calibration.size.empty()) {
    return Status::InvalidArgument(QuotedPath(file) +
                                   ": resolution must be a list [width, height]");
  }
  RECOG_ASSIGN_OR_RETURN(const YAML::Node root, LoadYamlFile(file.string()));
  RigCamera camera;
  camera.name = name;
  camera.size = calibration.size;
  camera.K = calibration.camera.K();
  camera.distortion = calibration.camera.distortion;
  camera.lens = calibration.camera.lens;
  try {
    const YAML::Node pose = root["T_BS"];
    if (!pose || !pose.IsMap()) {
      return Status::InvalidArgument(QuotedPath(file) +
                                     ": needs T_BS, a 4x4 matrix with its 'data'");
    }
    const std::vector<double> T = Numbers(pose, "data", 16, "T_BS data");
    if (T[12] != 0 || T[13] != 0 || T[14] != 0 || T[15] != 1) {
      return Status::InvalidArgument(QuotedPath(file) +
                                     ": the last row of T_BS must be [0, 0, 0, 1]");
    }
    // X_body = R X_camera + t with R the top-left 3x3 and t the last column. The rotations are
    // printed to ~9 digits and orthonormal to 1e-7..1e-9 only, too close to ValidateRig's 1e-6
    // (and a rig file written from this rig would carry the error on): the nearest rotation.
    cv::Matx33d R;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) R(r, c) = T[size_t(4 * r + c)];
    }
    camera.body_R_camera = NearestRotation(R);
    camera.body_t_camera = {T[3], T[7], T[11]};
  } catch (const YAML::Exception& e) {
    return Status::InvalidArgument(QuotedPath(file) + ": " + e.what());
  }
  if (Status s = ValidateRig({&camera, 1}); !s.ok()) return s.WithContext(QuotedPath(file));
  return camera;
}

// The EuRoC root (PATH/mav0 or PATH): the folder holding cam0/sensor.yaml.
fs::path EurocRoot(const fs::path& path) {
  std::error_code ec;
  return fs::exists(path / "mav0" / "cam0" / "sensor.yaml", ec) ? path / "mav0" : path;
}

StatusOr<RigDataset> ReadEurocRig(const fs::path& path) {
  const fs::path root = EurocRoot(path);
  RigDataset rig;
  rig.layout = RigLayout::kEuroc;
  std::vector<std::map<int64_t, std::string>> lists;
  std::error_code ec;
  for (int n = 0; fs::exists(root / ("cam" + std::to_string(n)) / "sensor.yaml", ec); ++n) {
    const std::string name = "cam" + std::to_string(n);
    RECOG_ASSIGN_OR_RETURN(RigCamera camera, ReadEurocSensor(root / name / "sensor.yaml", name));
    auto list = ReadEurocCameraList((root / name).string());
    if (!list.ok()) return list.status().WithContext("EuRoC camera '" + name + "'");
    rig.cameras.push_back(std::move(camera));
    lists.emplace_back(list->begin(), list->end());
  }
  if (rig.cameras.empty()) {
    return Status::NotFound(QuotedPath(root / "cam0" / "sensor.yaml") + " does not exist");
  }
  // The cameras are triggered together but drop frames on their own: a rig frame is a timestamp
  // every camera has.
  for (const auto& [ns, image] : lists[0]) {
    std::vector<std::string> images{image};
    for (size_t c = 1; c < lists.size(); ++c) {
      const auto it = lists[c].find(ns);
      if (it == lists[c].end()) break;
      images.push_back(it->second);
    }
    if (images.size() != rig.cameras.size()) continue;
    rig.timestamps.push_back(double(ns) * 1e-9);
    rig.images.push_back(std::move(images));
    rig.depths.emplace_back(rig.cameras.size(), "");
  }
  if (rig.images.empty()) {
    return Status::InvalidArgument("the EuRoC cameras in " + QuotedPath(root) +
                                   " have no timestamp in common (data.csv)");
  }
  return rig;
}

// A KITTI calib.txt: the projection matrix of each camera N with a "PN:" line (other lines,
// such as "Tr:", are skipped).
StatusOr<std::map<int, cv::Matx34d>> ReadKittiCalib(const fs::path& file) {
  std::ifstream in(file);
  if (!in) return Status::NotFound("cannot open " + QuotedPath(file));
  std::map<int, cv::Matx34d> projections;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const size_t colon = line.find(':');
    const std::string key = line.substr(0, colon);
    if (colon == std::string::npos || key.size() < 2 || key.size() > 3 || key[0] != 'P' ||
        key.find_first_not_of("0123456789", 1) != std::string::npos) {
      continue;
    }
    std::istringstream fields(line.substr(colon + 1));
    cv::Matx34d P;
    bool ok = true;
    for (double& v : P.val) ok = ok && (fields >> v) && std::isfinite(v);
    std::string extra;
    const int camera = std::stoi(key.substr(1));
    if (!ok || (fields >> extra) || !projections.emplace(camera, P).second) {
      return Status::InvalidArgument(QuotedPath(file) + " line " + std::to_string(number) +
                                     ": expected one line 'P" + std::to_string(camera) +
                                     ": 12 numbers'");
    }
  }
  return projections;
}

// KITTI camera N's image of frame i.
fs::path KittiImage(const fs::path& dir, const std::string& camera, size_t frame) {
  char name[32];
  std::snprintf(name, sizeof(name), "%06zu.png", frame);
  return dir / camera / name;
}

StatusOr<RigDataset> ReadKittiRig(const fs::path& dir) {
  const fs::path calib = dir / "calib.txt";
  RECOG_ASSIGN_OR_RETURN(const auto projections, ReadKittiCalib(calib));
  RECOG_ASSIGN_OR_RETURN(const std::vector<double> times, ReadKittiTimes(dir.string()));
  if (times.empty())
    return Status::InvalidArgument(QuotedPath(dir / "times.txt") + " lists no frames");
  RigDataset rig;
  rig.layout = RigLayout::kKitti;
  std::vector<size_t> counts;
  std::error_code ec;
  for (const auto& [n, P] : projections) {
    RigCamera camera;
    camera.name = "image_" + std::to_string(n);
    if (!fs::is_directory(dir / camera.name, ec)) continue;
    // Its frames: 000000.png, 000001.png, ... up to the first missing one, one per time at most.
    size_t count = 0;
    while (count < times.size() && fs::is_regular_file(KittiImage(dir, camera.name, count), ec)) {
      ++count;
    }
    const cv::Mat first =
        count == 0 ? cv::Mat() : cv::imread(KittiImage(dir, camera.name, 0), cv::IMREAD_UNCHANGED);
    if (count > 0 && first.empty()) {
      return Status::InvalidArgument("cannot read image " +
                                     QuotedPath(KittiImage(dir, camera.name, 0)));
    }
    camera.size = first.size();
    camera.K = P.get_minor<3, 3>(0, 0);
    // Rectified: a pinhole without skew, no distortion, every camera turned as camera 0 and
    // shifted by -K^-1 * (column 4 of P) (P = K [I | -t] in camera 0's frame).
    if (camera.K(0, 1) != 0 || camera.K(1, 0) != 0 || camera.K(2, 0) != 0 || camera.K(2, 1) != 0 ||
        camera.K(2, 2) != 1) {
      return Status::InvalidArgument(QuotedPath(calib) + ": the left 3x3 of P" + std::to_string(n) +
                                     " is not a pinhole [fx 0 cx; 0 fy cy; 0 0 1]");
    }
    camera.body_t_camera = -(camera.K.inv() * cv::Vec3d(P(0, 3), P(1, 3), P(2, 3)));
    // A camera without images has no size yet; the frame counts below report it.
    if (count > 0) {
      if (Status s = ValidateRig({&camera, 1}); !s.ok()) return s.WithContext(QuotedPath(calib));
    }
    rig.cameras.push_back(std::move(camera));
    counts.push_back(count);
  }
  if (rig.cameras.empty()) {
    return Status::InvalidArgument(QuotedPath(calib) +
                                   " has no line PN with a folder image_N beside it");
  }
  for (size_t c = 0; c < rig.cameras.size(); ++c) {
    if (counts[c] == counts[0]) continue;
    const size_t shorter = counts[c] < counts[0] ? c : 0;
    return Status::InvalidArgument(
        "KITTI camera '" + rig.cameras[shorter].name + "' has " + std::to_string(counts[shorter]) +
        " frames (no " + QuotedPath(KittiImage(dir, rig.cameras[shorter].name, counts[shorter])) +
        "), camera '" + rig.cameras[c == shorter ? 0 : c].name + "' has " +
        std::to_string(std::max(counts[c], counts[0])));
  }
  if (counts[0] < times.size()) {
    return Status::NotFound(QuotedPath(KittiImage(dir, rig.cameras[0].name, counts[0])) +
                            ", frame " + std::to_string(counts[0]) + " of " +
                            QuotedPath(dir / "times.txt") + ", does not exist");
  }
  for (size_t i = 0; i < times.size(); ++i) {
    rig.timestamps.push_back(times[i]);
    rig.images.emplace_back();
    for (const RigCamera& camera : rig.cameras) {
      rig.images.back().push_back(KittiImage(dir, camera.name, i).string());
    }
    rig.depths.emplace_back(rig.cameras.size(), "");
  }
  return rig;
}

}  // namespace

std::string_view RigLayoutName(RigLayout layout) {
  switch (layout) {
    case RigLayout::kPlain:
      return "plain";
    case RigLayout::kEuroc:
      return "euroc";
    case RigLayout::kKitti:
      return "kitti";
  }
  return "?";
}

StatusOr<RigLayout> DetectRigLayout(const std::string& path) {
  const fs::path root(path);
  std::error_code ec;
  if (!fs::exists(root, ec))
    return Status::NotFound("rig sequence " + QuotedPath(root) + " not found");
  if (fs::is_regular_file(root, ec) || fs::exists(root / "rig.yaml", ec)) return RigLayout::kPlain;
  switch (DetectDatasetLayout(path)) {
    case DatasetLayout::kEuroc:
      return RigLayout::kEuroc;
    case DatasetLayout::kKitti:
      return RigLayout::kKitti;
    case DatasetLayout::kTum:
    case DatasetLayout::kFolder:
      break;
  }
  return Status::InvalidArgument(QuotedPath(root) +
                                 " is not a rig sequence: expected a rig file or a folder with "
                                 "rig.yaml (plain), mav0/cam0/data.csv or cam0/data.csv (EuRoC), "
                                 "or times.txt and image_N/ (KITTI)");
}

StatusOr<RigDataset> ReadRigDataset(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(const RigLayout layout, DetectRigLayout(path));
  switch (layout) {
    case RigLayout::kPlain:
      return ReadPlain(path);
    case RigLayout::kEuroc:
      return ReadEurocRig(path);
    case RigLayout::kKitti:
      return ReadKittiRig(path);
  }
  return Status::Internal("unknown rig layout");
}

}  // namespace recog::cli
