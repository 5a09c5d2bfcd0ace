// What a recognition database stores for one entry (a place frame or an object model view).
//
// An entry is its bag of words (what the inverted index is built from), its direct-index
// feature vector (vocabulary node -> features, for fast correspondences), its keypoints and
// descriptors (for geometric verification), and metadata. Object entries also carry the 3D point
// (object frame) of every feature, for pose estimation; place frames may carry the 3D point of
// every feature (camera frame, from depth or stereo) and the camera matrix of their keypoints,
// for metric loops. Entries of a map get increasing ids
// 0, 1, 2, ... in the order they are added; a removed id is never reused.
#pragma once

#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/bow/bow_vector.h"
#include "core/bow/feature_vector.h"
#include "core/bow/scoring.h"
#include "core/common/descriptor.h"

namespace recog {

using EntryId = uint32_t;
inline constexpr EntryId kInvalidEntryId = std::numeric_limits<EntryId>::max();
using MapId = uint32_t;

// Parts of an entry, to read only what is needed (bit flags).
enum EntryPart : uint32_t {
  kEntryMetadata = 1u << 0,
  kEntryBow = 1u << 1,
  kEntryDirect = 1u << 2,
  kEntryFeatures = 1u << 3,  // keypoints, descriptors and 3D points
  kEntryAllParts = kEntryMetadata | kEntryBow | kEntryDirect | kEntryFeatures,
};

inline constexpr size_t kMaxClientIdBytes = 128;

struct EntryMetadata {
  std::optional<double> timestamp;  // seconds, as given by the client; none when it gave none
  uint32_t num_features = 0;        // keypoints of the entry; the direct index refers to them
  std::string user_data;            // opaque to the database (camera id, pose, ...), at most 64 KiB
  // The client's own id of the frame (a SLAM's keyframe id), returned with every match; at most
  // kMaxClientIdBytes, empty when the client gave none (and for entries stored before it existed).
  std::string client_id;

  friend bool operator==(const EntryMetadata&, const EntryMetadata&) = default;
};

struct EntryRecord {
  EntryId id = kInvalidEntryId;
  EntryMetadata metadata;
  BowVector bow;
  FeatureVector direct;
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;              // one row per keypoint, in the map's descriptor format
  std::vector<cv::Point3f> points;  // one per keypoint (object entries, frames with depth) or empty
  // The pinhole camera matrix of the keypoints when the frame came with one (place frames with
  // intrinsics); all zeros when unknown.
  cv::Matx33d camera = cv::Matx33d::zeros();

  bool has_camera() const { return camera(0, 0) > 0.0 && camera(1, 1) > 0.0; }
};

// Fixed when a map is created.
struct MapConfig {
  std::string name;  // 1..128 characters of [A-Za-z0-9._-]
  uint64_t vocabulary_checksum = 0;
  uint32_t vocabulary_words = 0;
  uint32_t vocabulary_nodes = 0;
  DescriptorFormat descriptor = DescriptorFormat::Orb();
  ScoringType scoring = ScoringType::kL1;
  uint32_t direct_index_levels_up = 2;  // thesis Table 4.4: direct index at level 2

  // OK when the name is valid and the vocabulary fields are set.
  Status Validate() const;
  friend bool operator==(const MapConfig&, const MapConfig&) = default;
};

struct MapInfo {
  MapId id = 0;
  MapConfig config;
  int64_t created_unix_ms = 0;
  friend bool operator==(const MapInfo&, const MapInfo&) = default;
};

}  // namespace recog
