#include "core/place/map_registry.h"

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <cstdlib>
#include <sstream>

#include "core/common/names.h"
#include "core/place/detector_settings.h"

namespace recog {
namespace {

constexpr char kSettingsPrefix[] = "place-settings/";

std::string SettingsKey(const std::string& name) { return kSettingsPrefix + name; }

}  // namespace

// One "rig_camera" line of the settings (EncodePlaceSettings).
std::string EncodeRigCamera(const RigCamera& camera) {
  std::string line = "rig_camera ";
  line += camera.name;
  char number[32];
  std::snprintf(number, sizeof(number), " %d %d", camera.size.width, camera.size.height);
  line += number;
  const auto add = [&](double value) {
    std::snprintf(number, sizeof(number), " %.17g", value);
    line += number;
  };
  for (const double v : {camera.K(0, 0), camera.K(1, 1), camera.K(0, 2), camera.K(1, 2)}) add(v);
  for (const double v : camera.body_R_camera.val) add(v);
  for (const double v : camera.body_t_camera.val) add(v);
  std::snprintf(number, sizeof(number), " %zu", camera.distortion.size());
  line += number;
  for (const double v : camera.distortion) add(v);
  // A lens other than radtan follows its coefficients (lines written before lenses have none).
  if (camera.lens != LensModel::kRadialTangential) {
    line += " lens ";
    line += LensModelName(camera.lens);
  }
  line += '\n';
  return line;
}

// The rest of a "rig_camera" line whose name `in` has read.
StatusOr<RigCamera> DecodeRigCamera(const std::string& name, std::istream& in) {
  RigCamera camera;
  camera.name = name;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  size_t distortion = 0;
  in >> camera.size.width >> camera.size.height >> fx >> fy >> cx >> cy;
  for (double& v : camera.body_R_camera.val) in >> v;
  for (double& v : camera.body_t_camera.val) in >> v;
  in >> distortion;
  if (!in || distortion > 14) {
    return Status::DataLoss("place settings: a malformed rig camera '" + name + "'");
  }
  camera.distortion.resize(distortion);
  for (double& v : camera.distortion) in >> v;
  if (!in) return Status::DataLoss("place settings: a malformed rig camera '" + name + "'");
  // The rest of the line: nothing, or the lens.
  std::string rest, word, lens;
  std::getline(in, rest);
  std::istringstream tail(rest);
  if (tail >> word) {
    StatusOr<LensModel> model = word == "lens" && (tail >> lens)
                                    ? ParseLensModel(lens)
                                    : Status::DataLoss("an unexpected '" + word + "'");
    if (!model.ok()) {
      return Status::DataLoss("place settings: a malformed rig camera '" + name +
                              "': " + model.status().message());
    }
    camera.lens = *model;
  }
  camera.K = cv::Matx33d(fx, 0, cx, 0, fy, cy, 0, 0, 1);
  return camera;
}

namespace {

// Version 4 stores the map's preset and only the kept settings whose value differs from that
// preset's: a map that never changed a setting follows its preset's value of the day, so a
// preset retuned needs neither a new version nor a migration.
constexpr int kPlaceSettingsVersion = 4;

// Versions 1 to 3 stored each kept setting with its value, the preset's own included. When a
// later version changed a preset's value, a map of that preset still holding the value of then
// follows the value of now, as a map that never changed it should (a value it changed stays;
// a map that set a value equal to the preset's of then cannot be told apart, and follows too):
// - version 2: the keyframes preset's correspondences for views metres apart (exhaustive with a
//   cross check, 45 inliers; docs/places.md, "Repeated architecture and wide baselines"). Its
//   looser correspondences with the old floor of 12 inliers would accept false loops.
// - version 3: the keyframes preset leaves out the last 3 keyframes instead of 4, so that a
//   keyframe can close a loop with the one 4 back (docs/places.md, "Keyframe streams").
// This applies to maps written before version 4 only.
constexpr int kFirstPresetRelativeVersion = 4;

struct FormerPresetValue {
  int changed_in;  // the first version whose preset has another value
  std::string_view setting, value;
};
constexpr FormerPresetValue kFormerKeyframesValues[] = {
    {2, "geometry", "direct_index"},
    {2, "min_inliers", "12"},
    {3, "recent_frames", "4"},
};

void DropFormerPresetValues(int version, std::vector<NamedSetting>* settings) {
  const bool keyframes = std::any_of(settings->begin(), settings->end(), [](const NamedSetting& s) {
    return s.first == "preset" && s.second == "keyframes";
  });
  if (!keyframes) return;
  std::erase_if(*settings, [&](const NamedSetting& s) {
    return std::any_of(std::begin(kFormerKeyframesValues), std::end(kFormerKeyframesValues),
                       [&](const FormerPresetValue& former) {
                         return version < former.changed_in && s.first == former.setting &&
                                s.second == former.value;
                       });
  });
}

// The version line's number: DATA_LOSS unless a positive number, FAILED_PRECONDITION above
// kPlaceSettingsVersion (written by a newer build).
StatusOr<int> ParseVersion(const std::string& text) {
  uint64_t version = 0;
  const char* const end = text.data() + text.size();
  const auto [stop, error] = std::from_chars(text.data(), end, version);
  const bool too_large = error == std::errc::result_out_of_range;
  if (stop != end || (error != std::errc() && !too_large) || (!too_large && version == 0)) {
    return Status::DataLoss("place settings: a malformed version '" + text + "'");
  }
  if (too_large || version > uint64_t(kPlaceSettingsVersion)) {
    return Status::FailedPrecondition("place settings of an unknown version " + text);
  }
  return int(version);
}

}  // namespace

std::string EncodePlaceSettings(const LoopDetectorParams& p, const std::string& group,
                                const std::vector<RigCamera>& rig) {
  std::string text = "version " + std::to_string(kPlaceSettingsVersion) + "\n";
  const std::vector<NamedSetting> own = MapDetectorSettings(p);
  const std::vector<NamedSetting> preset =
      MapDetectorSettings(ParseDetectorPreset(DetectorPresetName(p.preset)).value());
  for (size_t i = 0; i < own.size(); ++i) {
    // `preset` first (MapDetectorSettings), always written; the others where they differ.
    if (i == 0 || own[i].second != preset[i].second) {
      text += own[i].first + " " + own[i].second + "\n";
    }
  }
  if (!group.empty()) text += "group " + group + "\n";
  for (const RigCamera& camera : rig) text += EncodeRigCamera(camera);
  return text;
}

StatusOr<LoopDetectorParams> DecodePlaceSettings(std::string_view text, std::string* group,
                                                 std::vector<RigCamera>* rig) {
  return DecodePlaceSettings(text, ParseDetectorPreset, group, rig);
}

StatusOr<LoopDetectorParams> DecodePlaceSettings(std::string_view text,
                                                 const PresetValues& preset_values,
                                                 std::string* group, std::vector<RigCamera>* rig) {
  std::istringstream in{std::string(text)};
  std::string key, value;
  int version = 0;
  if (group != nullptr) group->clear();
  std::vector<RigCamera> cameras;
  std::vector<NamedSetting> settings;
  while (in >> key >> value) {
    if (key == "version") {
      RECOG_ASSIGN_OR_RETURN(version, ParseVersion(value));
    } else if (key == "group") {
      if (!ValidateName("group", value).ok()) {
        return Status::DataLoss("place settings: a malformed group name");
      }
      if (group != nullptr) *group = value;
    } else if (key == "rig_camera") {
      RECOG_ASSIGN_OR_RETURN(RigCamera camera, DecodeRigCamera(value, in));
      cameras.push_back(std::move(camera));
    } else if (FindDetectorSetting(key) != nullptr) {
      settings.emplace_back(key, value);
    }  // unknown keys: written by a newer minor version, ignored
  }
  if (version == 0) return Status::DataLoss("place settings without a version line");
  if (version < kFirstPresetRelativeVersion) DropFormerPresetValues(version, &settings);
  // The settings apply over their preset's values (settings written before presets were stored
  // have none and start from the default).
  const auto is_preset = [](const NamedSetting& s) { return s.first == "preset"; };
  const auto preset = std::find_if(settings.begin(), settings.end(), is_preset);
  if (preset != settings.end() && std::count_if(settings.begin(), settings.end(), is_preset) > 1) {
    return Status::DataLoss("place settings: the preset is given twice");
  }
  StatusOr<LoopDetectorParams> p =
      preset_values(preset == settings.end() ? "default" : std::string_view(preset->second));
  if (!p.ok()) return p.status().WithContext("place settings", StatusCode::kDataLoss);
  if (preset != settings.end()) settings.erase(preset);
  const Status valid = ApplyDetectorSettings(settings, &*p);
  if (!valid.ok()) return valid.WithContext("place settings", StatusCode::kDataLoss);
  if (!cameras.empty()) {
    const Status rig_valid = ValidateRig(cameras);
    if (!rig_valid.ok()) return rig_valid.WithContext("place settings", StatusCode::kDataLoss);
  }
  if (rig != nullptr) *rig = std::move(cameras);
  return p;
}

StatusOr<std::unique_ptr<MapRegistry>> MapRegistry::Open(
    IndexStore* store, std::shared_ptr<const Vocabulary> vocabulary,
    const std::function<void(size_t, size_t)>& progress) {
  std::unique_ptr<MapRegistry> registry(new MapRegistry(store, std::move(vocabulary)));
  RECOG_ASSIGN_OR_RETURN(std::vector<std::string> keys, store->ListBlobKeys(kSettingsPrefix));
  size_t done = 0;
  for (const std::string& key : keys) {
    const std::string name = key.substr(sizeof(kSettingsPrefix) - 1);
    RECOG_ASSIGN_OR_RETURN(std::string text, store->GetBlob(key));
    std::string group;
    std::vector<RigCamera> rig;
    StatusOr<LoopDetectorParams> params = DecodePlaceSettings(text, &group, &rig);
    if (!params.ok()) return params.status().WithContext("map '" + name + "'");
    StatusOr<std::shared_ptr<PlaceMap>> map =
        PlaceMap::Open(store, name, params.value(), registry->vocabulary_, std::move(rig));
    if (map.ok()) map.value()->group_ = group;
    if (map.status().code() == StatusCode::kNotFound) {
      // Settings left behind by a deletion that was interrupted: finish it.
      RECOG_RETURN_IF_ERROR(store->DeleteBlob(key));
    } else if (!map.ok()) {
      return map.status().WithContext("map '" + name + "'");
    } else {
      registry->maps_.emplace(name, std::move(map).value());
    }
    if (progress) progress(++done, keys.size());
  }
  return registry;
}

StatusOr<std::shared_ptr<PlaceMap>> MapRegistry::Create(const std::string& name,
                                                        const LoopDetectorParams& params,
                                                        const std::string& group,
                                                        const std::vector<RigCamera>& rig) {
  RECOG_RETURN_IF_ERROR(params.Validate());
  if (!group.empty()) RECOG_RETURN_IF_ERROR(ValidateName("group", group));
  if (!rig.empty()) RECOG_RETURN_IF_ERROR(ValidateRig(rig));
  std::lock_guard write(write_mutex_);
  {
    std::shared_lock read(maps_mutex_);
    if (maps_.count(name) > 0) {
      return Status::AlreadyExists("map '" + name + "' already exists");
    }
  }
  // Settings first, then the map: a crash in between leaves settings without a map, which Open
  // drops (the other order would leave a map that Open does not list but whose name is taken).
  RECOG_RETURN_IF_ERROR(
      store_->PutBlob(SettingsKey(name), EncodePlaceSettings(params, group, rig)));
  StatusOr<std::unique_ptr<Database>> created = Database::Create(store_, name, vocabulary_);
  if (!created.ok()) {
    if (created.status().code() != StatusCode::kAlreadyExists) {
      (void)store_->DeleteBlob(SettingsKey(name));  // best effort; Open would drop it too
    }
    return created.status();
  }
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<PlaceMap> map,
                         PlaceMap::Open(store_, name, params, vocabulary_, rig));
  map->group_ = group;
  std::unique_lock lock(maps_mutex_);
  maps_[name] = map;
  return map;
}

StatusOr<std::shared_ptr<PlaceMap>> MapRegistry::Get(const std::string& name) const {
  std::shared_lock lock(maps_mutex_);
  const auto it = maps_.find(name);
  if (it == maps_.end()) return Status::NotFound("no map named '" + name + "'");
  return it->second;
}

StatusOr<std::vector<std::shared_ptr<PlaceMap>>> MapRegistry::Group(
    const std::string& group) const {
  std::vector<std::shared_ptr<PlaceMap>> members;
  std::shared_lock lock(maps_mutex_);
  for (const auto& [name, map] : maps_) {
    if (!group.empty() && map->group() == group) members.push_back(map);
  }
  if (members.empty()) return Status::NotFound("no map in group '" + group + "'");
  return members;
}

std::vector<std::shared_ptr<PlaceMap>> MapRegistry::List() const {
  std::shared_lock lock(maps_mutex_);
  std::vector<std::shared_ptr<PlaceMap>> out;
  out.reserve(maps_.size());
  for (const auto& [name, map] : maps_) out.push_back(map);
  return out;
}

StatusOr<size_t> MapRegistry::Delete(const std::string& name) {
  std::lock_guard write(write_mutex_);
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<PlaceMap> map, Get(name));
  RECOG_ASSIGN_OR_RETURN(const size_t frames, map->DeleteFrames());
  {
    std::unique_lock lock(maps_mutex_);
    maps_.erase(name);
  }
  RECOG_RETURN_IF_ERROR(store_->DeleteBlob(SettingsKey(name)));
  return frames;
}

}  // namespace recog
