#include "core/place/map_search.h"

#include <algorithm>
#include <tuple>

namespace recog {

StatusOr<std::vector<MapMatch>> SearchMaps(std::span<const std::shared_ptr<PlaceMap>> maps,
                                           const FeatureSet& features,
                                           std::optional<double> timestamp,
                                           const PlaceResultOptions& options,
                                           const FrameGeometry* geometry) {
  std::vector<MapMatch> matches;
  for (const std::shared_ptr<PlaceMap>& map : maps) {
    if (map->deleted()) continue;
    StatusOr<PlaceFrameResult> found = map->Query(features, timestamp, options, geometry);
    if (!found.ok()) return found.status().WithContext("map '" + map->name() + "'");
    if (found->loop.status != LoopStatus::kLoopDetected) continue;
    matches.push_back({map->name(), std::move(found).value()});
  }
  const auto rank = [](const MapMatch& m) {
    return std::make_tuple(m.result.loop.inliers.size(), m.result.loop.score);
  };
  std::sort(matches.begin(), matches.end(), [&](const MapMatch& a, const MapMatch& b) {
    if (rank(a) != rank(b)) return rank(a) > rank(b);
    return a.map < b.map;
  });
  return matches;
}

}  // namespace recog
