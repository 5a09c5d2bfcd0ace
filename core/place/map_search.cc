#include "core/place/map_search.h"

#include <algorithm>
#include <tuple>

namespace recog {
namespace {

// How strongly a recognised place is supported: RANSAC inliers, then the score.
std::tuple<size_t, double> Strength(const PlaceFrameResult& found) {
  return {found.loop.inliers.size(), found.loop.score};
}

}  // namespace

StatusOr<std::vector<MapMatch>> SearchMaps(std::span<const std::shared_ptr<PlaceMap>> maps,
                                           const FeatureSet& features,
                                           std::optional<double> timestamp,
                                           const PlaceResultOptions& options,
                                           const FrameGeometry* geometry) {
  std::vector<MapMatch> matches;
  matches.reserve(maps.size());
  for (const std::shared_ptr<PlaceMap>& map : maps) {
    if (map->deleted()) continue;
    StatusOr<PlaceFrameResult> found = map->Query(features, timestamp, options, geometry);
    if (!found.ok()) return found.status().WithContext("map '" + map->name() + "'");
    if (found->loop.status != LoopStatus::kLoopDetected) continue;
    matches.push_back({map->name(), std::move(found).value()});
  }
  std::sort(matches.begin(), matches.end(), [](const MapMatch& a, const MapMatch& b) {
    if (Strength(a.result) != Strength(b.result)) return Strength(a.result) > Strength(b.result);
    return a.map < b.map;
  });
  return matches;
}

StatusOr<std::vector<Relocalization>> Relocalize(std::span<const std::shared_ptr<PlaceMap>> maps,
                                                 std::span<const RelocalizationFrame> frames,
                                                 const PlaceResultOptions& options) {
  std::vector<Relocalization> found;  // one per map, in the order maps first recognise a frame
  for (size_t i = 0; i < frames.size(); ++i) {
    RECOG_ASSIGN_OR_RETURN(
        std::vector<MapMatch> matches,
        SearchMaps(maps, *frames[i].features, frames[i].timestamp, options, frames[i].geometry));
    for (MapMatch& match : matches) {
      auto same_map = std::find_if(found.begin(), found.end(),
                                   [&](const Relocalization& r) { return r.map == match.map; });
      if (same_map == found.end()) {
        found.push_back({std::move(match.map), i, 1, std::move(match.result)});
        continue;
      }
      ++same_map->frames_recognised;
      if (Strength(match.result) > Strength(same_map->result)) {  // earlier frames win ties
        same_map->frame_index = i;
        same_map->result = std::move(match.result);
      }
    }
  }
  std::sort(found.begin(), found.end(), [](const Relocalization& a, const Relocalization& b) {
    if (a.frames_recognised != b.frames_recognised) {
      return a.frames_recognised > b.frames_recognised;
    }
    if (Strength(a.result) != Strength(b.result)) return Strength(a.result) > Strength(b.result);
    return a.map < b.map;
  });
  return found;
}

}  // namespace recog
