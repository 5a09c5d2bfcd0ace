// Looking a frame up in other maps: a fleet's shared memory of places (robot B recognising where
// robot A has been) and a robot's earlier sessions (relocalising in yesterday's map).
//
// SearchMaps runs a relocalisation query (PlaceMap::Query: every frame of the map is a candidate,
// no tau_c, no temporal consistency, nothing added) on each map of a search set and returns the
// places recognised, one match at most per map, best first. The maps are searched as if they
// were one: the frame is converted to a bag of words once, and each map's scores are normalised
// by the best score over all the maps (PlaceMap::Recognise), so a map whose best candidate is
// under alpha of the best map's is not verified (`bench_place` Relocalize_Group10x2600_vs_One26K
// measures the cost against one map of all the frames). On the corridor split between two
// robots (`recog eval place --split 40`), each of robot B's frames looked up alone in robot A's
// map finds at least as many revisits as the single map's detector, with no false one (the
// counts are in docs/places.md, "Queries across maps"). The maps must share a vocabulary (all
// maps of a MapRegistry do).
//
// Thread safety: as PlaceMap::Query, any number of searches may run at once and beside the maps'
// own Add and Detect.
#pragma once

#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/place/place_map.h"

namespace recog {

struct MapMatch {
  std::string map;          // the map the place was recognised in
  PlaceFrameResult result;  // its PlaceMap::Query answer (status kLoopDetected)
};

// Queries every map of `maps` with the frame and returns the recognised places, most RANSAC
// inliers first (then highest score, then map name). Maps without a recognised place, and maps
// deleted meanwhile, are left out. Errors are those of PlaceMap::Query (bad options or geometry, a
// failing store), naming the map.
StatusOr<std::vector<MapMatch>> SearchMaps(std::span<const std::shared_ptr<PlaceMap>> maps,
                                           const FeatureSet& features,
                                           const PlaceResultOptions& options = {},
                                           const FrameGeometry* geometry = nullptr);

// One frame of a relocalisation (Relocalize): its features, and its 3D points or intrinsics when
// it has them (metric checks, as in PlaceMap::Query).
struct RelocalizationFrame {
  const FeatureSet* features = nullptr;
  const FrameGeometry* geometry = nullptr;
};

struct Relocalization {
  std::string map;               // the map the place was recognised in
  size_t frame_index = 0;        // the frame of the request `result` is for (the map's best)
  size_t frames_recognised = 0;  // how many of the request's frames were recognised in the map
  PlaceFrameResult result;       // that frame's PlaceMap::Query answer (status kLoopDetected)
};

// Looks every frame up in every map (SearchMaps) and returns one answer per map that recognised
// any: the frame with the most inliers (then the highest score, then the earliest frame). Maps
// come by frames recognised, then as SearchMaps ranks them. Nothing is added to any map.
StatusOr<std::vector<Relocalization>> Relocalize(std::span<const std::shared_ptr<PlaceMap>> maps,
                                                 std::span<const RelocalizationFrame> frames,
                                                 const PlaceResultOptions& options = {});

}  // namespace recog
