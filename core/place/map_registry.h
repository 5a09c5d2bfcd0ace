// MapRegistry: the place maps of one store (PlaceMap, place_map.h: a map's frames and its loop
// detector).
//
// The registry opens every map of the store at start-up (rebuilding the in-memory inverted
// indexes), creates and deletes maps, and persists each map's detector parameters, group and rig
// (for a rig map) beside it in the store (a blob "place-settings/<name>"), so that a restarted
// server runs every map as before. A map group (a fleet's maps, or one robot's sessions) is a name
// given at creation that queries across maps search together (Group); all maps of a registry share
// its vocabulary. Maps other than place maps (the object map) are not touched: the registry only
// opens maps that have settings.
//
// Thread safety: every method may be called from any thread. Deleting a map while it is in use is
// safe: it waits for the frame being added to the map, and the map's holders then get NOT_FOUND
// for every write (see PlaceMap).
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/index/database.h"
#include "core/index/index_store.h"
#include "core/place/loop_detector.h"
#include "core/place/place_map.h"

namespace recog {

class MapRegistry {
 public:
  // Opens every place map of `store` with `vocabulary` (FAILED_PRECONDITION when a map was built
  // with another one). `progress`, when set, is called after each map with (done, total).
  static StatusOr<std::unique_ptr<MapRegistry>> Open(
      IndexStore* store, std::shared_ptr<const Vocabulary> vocabulary,
      const std::function<void(size_t, size_t)>& progress = {});

  // Creates an empty map in `group` (empty: none), a rig map when `rig` has cameras.
  // ALREADY_EXISTS when the name is taken (by any map of the store), INVALID_ARGUMENT for a bad
  // name, group name (the map name rule), parameters or rig (ValidateRig, naming the camera).
  StatusOr<std::shared_ptr<PlaceMap>> Create(const std::string& name,
                                             const LoopDetectorParams& params,
                                             const std::string& group = {},
                                             const std::vector<RigCamera>& rig = {});
  // NOT_FOUND for an unknown map.
  StatusOr<std::shared_ptr<PlaceMap>> Get(const std::string& name) const;
  // The maps of `group`, by name. NOT_FOUND naming the group when no map is in it.
  StatusOr<std::vector<std::shared_ptr<PlaceMap>>> Group(const std::string& group) const;
  // Every map, by name.
  std::vector<std::shared_ptr<PlaceMap>> List() const;
  // Deletes a map and its frames, and marks the map deleted for its holders; returns how many
  // frames it had. NOT_FOUND when unknown.
  StatusOr<size_t> Delete(const std::string& name);

  const Vocabulary& vocabulary() const { return *vocabulary_; }

 private:
  MapRegistry(IndexStore* store, std::shared_ptr<const Vocabulary> vocabulary)
      : store_(store), vocabulary_(std::move(vocabulary)) {}

  IndexStore* store_;
  std::shared_ptr<const Vocabulary> vocabulary_;
  std::mutex write_mutex_;                // serialises Create/Delete
  mutable std::shared_mutex maps_mutex_;  // guards maps_
  std::map<std::string, std::shared_ptr<PlaceMap>> maps_;
};

// The parameters a map's settings blob holds, as text ("key value" lines), and back: the preset
// the map started from (DetectorPreset), then only the settings a map keeps (detector_settings.h)
// whose value differs from that preset's, applied over the preset's values when read (so a
// preset retuned reaches every map that did not change that setting); the map's group (no line
// for none, as in settings written before groups); and a rig map's cameras, one "rig_camera" line
// each (name, width, height, fx, fy, cx, cy, body_R_camera row-major, body_t_camera, the number
// of distortion coefficients, then them), in rig order. The text starts with its version (4;
// versions 1 to 3 stored every kept value, and a keyframes map's preset values of then give way
// to the preset's of now, see map_registry.cc); a version above 4 is FAILED_PRECONDITION, a
// malformed one DATA_LOSS.
std::string EncodePlaceSettings(const LoopDetectorParams& params, const std::string& group = {},
                                const std::vector<RigCamera>& rig = {});
StatusOr<LoopDetectorParams> DecodePlaceSettings(std::string_view text,
                                                 std::string* group = nullptr,
                                                 std::vector<RigCamera>* rig = nullptr);
// The values of the preset named `name` (ParseDetectorPreset's, or a test's retuned presets).
using PresetValues = std::function<StatusOr<LoopDetectorParams>(std::string_view name)>;
// The same, with the presets' values from `preset_values` instead of this build's.
StatusOr<LoopDetectorParams> DecodePlaceSettings(std::string_view text,
                                                 const PresetValues& preset_values,
                                                 std::string* group = nullptr,
                                                 std::vector<RigCamera>* rig = nullptr);

}  // namespace recog
