#include "tools/evaluation/rig_file.h"

#include <cmath>
#include <filesystem>
#include <fstream>

#include <yaml-cpp/yaml.h>

namespace recog::cli {
namespace {

YAML::Node Required(const YAML::Node& node, const std::string& key) {
  const YAML::Node value = node[key];
  if (!value) throw YAML::Exception(node.Mark(), "missing key '" + key + "'");
  return value;
}

RigCamera ParseCamera(const YAML::Node& node) {
  RigCamera c;
  c.name = Required(node, "name").as<std::string>();
  c.size = {Required(node, "width").as<int>(), Required(node, "height").as<int>()};
  c.K = {Required(node, "fx").as<double>(),
         0,
         Required(node, "cx").as<double>(),
         0,
         Required(node, "fy").as<double>(),
         Required(node, "cy").as<double>(),
         0,
         0,
         1};
  if (node["distortion"]) c.distortion = YamlNumbers(node["distortion"], 0, "distortion");
  if (node["lens"]) {
    const StatusOr<LensModel> lens = ParseLensModel(node["lens"].as<std::string>());
    if (!lens.ok()) throw YAML::Exception(node["lens"].Mark(), lens.status().message());
    c.lens = *lens;
  }
  const YAML::Node pose = Required(node, "body_from_camera");
  const std::vector<double> r = YamlNumbers(Required(pose, "rotation"), 9, "rotation");
  const std::vector<double> t = YamlNumbers(Required(pose, "translation"), 3, "translation");
  for (int i = 0; i < 9; ++i) c.body_R_camera.val[i] = r[size_t(i)];
  c.body_t_camera = {t[0], t[1], t[2]};
  return c;
}

}  // namespace

std::vector<double> YamlNumbers(const YAML::Node& node, size_t count, const std::string& key) {
  if (!node.IsSequence() || (count != 0 && node.size() != count)) {
    throw YAML::Exception(node.Mark(), key + " must be a list of " +
                                           (count ? std::to_string(count) + " " : "") + "numbers");
  }
  std::vector<double> out;
  for (const YAML::Node& v : node) out.push_back(v.as<double>());
  return out;
}

StatusOr<std::vector<RigCamera>> ReadRigFile(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    return Status::NotFound("rig file '" + path + "' does not exist");
  }
  std::vector<RigCamera> cameras;
  try {
    const YAML::Node root = YAML::LoadFile(path);
    const YAML::Node list = root["cameras"];
    if (!list || !list.IsSequence()) {
      return Status::InvalidArgument("rig file '" + path + "' needs a list 'cameras'");
    }
    for (const YAML::Node& node : list) cameras.push_back(ParseCamera(node));
  } catch (const YAML::Exception& e) {
    return Status::InvalidArgument("rig file '" + path + "': " + e.what());
  }
  if (Status s = ValidateRig(cameras); !s.ok()) return s.WithContext("rig file '" + path + "'");
  return cameras;
}

Status WriteRigFile(const std::vector<RigCamera>& cameras, const std::string& path) {
  RECOG_RETURN_IF_ERROR(ValidateRig(cameras));
  YAML::Node root;
  for (const RigCamera& camera : cameras) {
    YAML::Node node;
    node["name"] = camera.name;
    node["width"] = camera.size.width;
    node["height"] = camera.size.height;
    node["fx"] = camera.K(0, 0);
    node["fy"] = camera.K(1, 1);
    node["cx"] = camera.K(0, 2);
    node["cy"] = camera.K(1, 2);
    node["distortion"] = YAML::Node(YAML::NodeType::Sequence);
    for (double v : camera.distortion) node["distortion"].push_back(v);
    node["distortion"].SetStyle(YAML::EmitterStyle::Flow);
    if (camera.lens != LensModel::kRadialTangential) {
      node["lens"] = std::string(LensModelName(camera.lens));
    }
    YAML::Node pose;
    for (double v : camera.body_R_camera.val) pose["rotation"].push_back(v);
    for (int i = 0; i < 3; ++i) pose["translation"].push_back(camera.body_t_camera[i]);
    pose["rotation"].SetStyle(YAML::EmitterStyle::Flow);
    pose["translation"].SetStyle(YAML::EmitterStyle::Flow);
    node["body_from_camera"] = pose;
    root["cameras"].push_back(node);
  }
  YAML::Emitter yaml;
  yaml.SetDoublePrecision(17);
  yaml << root;
  std::ofstream file(path);
  file << yaml.c_str() << "\n";
  file.close();
  if (!file) return Status::Internal("cannot write '" + path + "'");
  return Status::Ok();
}

CameraPose CameraInWorld(const CameraPose& body, const RigCamera& camera) {
  return {body.world_from_camera * camera.body_R_camera,
          body.center + body.world_from_camera * camera.body_t_camera};
}

}  // namespace recog::cli
