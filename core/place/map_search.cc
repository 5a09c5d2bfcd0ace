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
                                           const PlaceResultOptions& options,
                                           const FrameGeometry* geometry) {
  RECOG_RETURN_IF_ERROR(options.Validate().WithContext(
      maps.empty() ? "search" : "map '" + maps.front()->name() + "'"));
  // The frame's bag of words once (again only for a map that converts otherwise), then each
  // map's shortlist, and the best score over all of them as the reference of every map's eta.
  struct Searched {
    const PlaceMap* map;
    const LoopDetector::ConvertedFrame* frame;
    LoopDetector::Shortlist shortlist;
  };
  std::vector<Searched> searched;
  searched.reserve(maps.size());
  std::vector<std::pair<const PlaceMap*, LoopDetector::ConvertedFrame>> conversions;
  conversions.reserve(maps.size());  // the pointers kept in `searched` stay valid
  double reference = 0;
  for (const std::shared_ptr<PlaceMap>& map : maps) {
    if (map->deleted()) continue;
    const auto named = [&](const Status& s) { return s.WithContext("map '" + map->name() + "'"); };
    auto converted = std::find_if(conversions.begin(), conversions.end(),
                                  [&](const auto& c) { return c.first->ConvertsLike(*map); });
    if (converted == conversions.end()) {
      LoopDetector::ConvertedFrame frame;
      RECOG_RETURN_IF_ERROR(named(map->ConvertForQuery(features, &frame)));
      converted = conversions.insert(conversions.end(), {map.get(), std::move(frame)});
    }
    StatusOr<LoopDetector::Shortlist> shortlist = map->Shortlist(converted->second);
    if (!shortlist.ok()) return named(shortlist.status());
    reference = std::max(reference, shortlist->best_score);
    searched.push_back({map.get(), &converted->second, std::move(shortlist).value()});
  }
  std::vector<MapMatch> matches;
  for (const Searched& s : searched) {
    StatusOr<PlaceFrameResult> found =
        s.map->Recognise(features, *s.frame, s.shortlist, reference, options, geometry);
    if (found.status().code() == StatusCode::kNotFound && s.map->deleted()) continue;  // meanwhile
    if (!found.ok()) return found.status().WithContext("map '" + s.map->name() + "'");
    if (found->loop.status != LoopStatus::kLoopDetected) continue;
    matches.push_back({s.map->name(), std::move(found).value()});
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
    RECOG_ASSIGN_OR_RETURN(std::vector<MapMatch> matches,
                           SearchMaps(maps, *frames[i].features, options, frames[i].geometry));
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
