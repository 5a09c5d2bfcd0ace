#include "core/place/map_registry.h"

#include <cstdio>
#include <cstdlib>
#include <sstream>

#include "core/common/names.h"

namespace recog {
namespace {

constexpr char kSettingsPrefix[] = "place-settings/";

std::string SettingsKey(const std::string& name) { return kSettingsPrefix + name; }

}  // namespace

std::string EncodePlaceSettings(const LoopDetectorParams& p, const std::string& group) {
  char buffer[512];
  std::snprintf(buffer, sizeof(buffer),
                "version 1\npreset %s\nalpha %.17g\ntemporal_matches %u\nmin_inliers "
                "%zu\nrecent_seconds %.17g\nrecent_frames %u\ngeometry %s\n",
                std::string(DetectorPresetName(p.preset)).c_str(), p.alpha, p.temporal_matches,
                p.epipolar.min_inliers, p.recent_seconds, p.recent_frames,
                std::string(GeometryCheckName(p.geometry)).c_str());
  return group.empty() ? std::string(buffer) : buffer + ("group " + group + "\n");
}

StatusOr<LoopDetectorParams> DecodePlaceSettings(std::string_view text, std::string* group) {
  // The preset line comes first: the other keys apply over its values. Settings written before
  // presets were stored have none and start from the default.
  LoopDetectorParams p;
  std::istringstream in{std::string(text)};
  std::string key, value;
  bool versioned = false;
  if (group != nullptr) group->clear();
  while (in >> key >> value) {
    char* end = nullptr;
    const double number = std::strtod(value.c_str(), &end);
    const bool numeric = end != value.c_str() && *end == '\0';
    if (key == "version") {
      if (!numeric || number != 1) {
        return Status::FailedPrecondition("place settings of an unknown version " + value);
      }
      versioned = true;
    } else if (key == "preset") {
      StatusOr<LoopDetectorParams> preset = ParseLoopDetectorMode(value);
      if (!preset.ok()) return preset.status().WithContext("place settings", StatusCode::kDataLoss);
      p = preset.value();
    } else if (key == "group") {
      if (!ValidateName("group", value).ok()) {
        return Status::DataLoss("place settings: a malformed group name");
      }
      if (group != nullptr) *group = value;
    } else if (key == "geometry") {
      StatusOr<GeometryCheck> geometry = ParseGeometryCheck(value);
      if (!geometry.ok()) {
        return geometry.status().WithContext("place settings", StatusCode::kDataLoss);
      }
      p.geometry = geometry.value();
    } else if (!numeric) {
      return Status::DataLoss("place settings: '" + key + "' has a non-numeric value");
    } else if (key == "alpha") {
      p.alpha = number;
    } else if (key == "temporal_matches") {
      p.temporal_matches = uint32_t(number);
    } else if (key == "min_inliers") {
      p.epipolar.min_inliers = size_t(number);
    } else if (key == "recent_seconds") {
      p.recent_seconds = number;
    } else if (key == "recent_frames") {
      p.recent_frames = uint32_t(number);
    }  // unknown keys: written by a newer minor version, ignored
  }
  if (!versioned) return Status::DataLoss("place settings without a version line");
  const Status valid = p.Validate();
  if (!valid.ok()) return valid.WithContext("place settings", StatusCode::kDataLoss);
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
    StatusOr<LoopDetectorParams> params = DecodePlaceSettings(text, &group);
    if (!params.ok()) return params.status().WithContext("map '" + name + "'");
    StatusOr<std::shared_ptr<PlaceMap>> map =
        PlaceMap::Open(store, name, params.value(), registry->vocabulary_);
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
                                                        const std::string& group) {
  RECOG_RETURN_IF_ERROR(params.Validate());
  if (!group.empty()) RECOG_RETURN_IF_ERROR(ValidateName("group", group));
  std::lock_guard write(write_mutex_);
  {
    std::shared_lock read(maps_mutex_);
    if (maps_.count(name) > 0) {
      return Status::AlreadyExists("map '" + name + "' already exists");
    }
  }
  // Settings first, then the map: a crash in between leaves settings without a map, which Open
  // drops (the other order would leave a map that Open does not list but whose name is taken).
  RECOG_RETURN_IF_ERROR(store_->PutBlob(SettingsKey(name), EncodePlaceSettings(params, group)));
  StatusOr<std::unique_ptr<Database>> created = Database::Create(store_, name, vocabulary_);
  if (!created.ok()) {
    if (created.status().code() != StatusCode::kAlreadyExists) {
      (void)store_->DeleteBlob(SettingsKey(name));  // best effort; Open would drop it too
    }
    return created.status();
  }
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<PlaceMap> map,
                         PlaceMap::Open(store_, name, params, vocabulary_));
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
