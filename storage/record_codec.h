// Record codec: the keys and the binary values that RocksDbIndexStore keeps in RocksDB.
//
// Kept apart from the store so that it can be tested on its own (round trips, every truncation,
// random garbage) and so that the store itself is only RocksDB plumbing. Nothing here includes
// RocksDB: keys and values are plain byte strings.
//
// Keys. An entry record is keyed by `map id | entry id`, both 4-byte big-endian, so that the
// byte order RocksDB sorts by is the numeric order (entries of a map are contiguous and in
// increasing id order). Catalog records (column family `maps`) are keyed by a one-byte tag:
//   "S"                    the store record: format version and the next map id
//   "M" + name             a map's MapInfo
//   "N" + map id (4, BE)   a map's next entry id
//
// Values. Every value starts with a format byte (kRecordFormat) so that a later version can
// change an encoding and still read the old one; numbers are little-endian, floats are stored
// bit for bit.
//   store      : format | next_map_id u32
//   map info   : format | id u32 | created_unix_ms i64 | vocabulary_checksum u64 |
//                vocabulary_words u32 | vocabulary_nodes u32 | descriptor type u8 |
//                descriptor size_bytes u32 | scoring u8 | direct_index_levels_up u32
//   next id    : format | next_entry_id u32
//   metadata   : format kMetadataFormat | flags u8 (bit 0: a timestamp follows) | timestamp f64
//                when flagged | num_features u32 | user_data length u32 | bytes | client_id
//                length u32 | bytes. Read too, as written before timestamps were optional (a
//                timestamp of 0 then meant none, and is read as none): format kRecordFormat |
//                timestamp f64 | num_features u32 | user_data length u32 | bytes, and format
//                kMetadataWithClientIdFormat: the same | client_id length u32 | bytes.
//   bow        : format | count u32 | count x (word u32, value f32), words strictly increasing
//   direct     : format | nodes n u32 | features m u32 | n x node u32 (strictly increasing) |
//                (n + 1) x offset u32 (0 ... m, non-decreasing) | m x feature index u32
//                (increasing under each node)
//   features   : format | keypoints k u32 | k x (x, y, size, angle, response f32, octave i32) |
//                descriptor rows u32 | cols u32 | OpenCV type i32 | rows x cols x element bytes |
//                and, for entries with 3D points and no camera matrix (object entries, and
//                frames older versions stored with depth; format byte kFeaturesWithPointsFormat), |
//                points k u32 | k x (x, y, z f32); for entries with a camera matrix (place frames
//                with intrinsics; format byte kFeaturesWithCameraFormat), | camera 9 x f64
//                (row-major) | points n u32 (0 or k) | n x (x, y, z f32)
//
// Every decoder checks every length against what is left before reading or allocating, and
// returns DATA_LOSS naming the record ("bow of map 3 entry 17: ...") on anything malformed: a
// corrupt value can never make the store read out of bounds or allocate gigabytes.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "core/index/entry.h"

namespace recog::storage {

inline constexpr uint8_t kRecordFormat = 1;
// Features records of object entries (with 3D points) start with this byte instead.
inline constexpr uint8_t kFeaturesWithPointsFormat = 2;
// Features records of entries with a camera matrix (and 3D points or not) start with this byte.
inline constexpr uint8_t kFeaturesWithCameraFormat = 3;
// Metadata records written before timestamps were optional, with a client id (read only).
inline constexpr uint8_t kMetadataWithClientIdFormat = 2;
// Metadata records as written now: the timestamp is optional (0.0 is a time).
inline constexpr uint8_t kMetadataFormat = 3;

// Which record a value belongs to, for error messages.
struct RecordContext {
  MapId map = 0;
  EntryId entry = kInvalidEntryId;  // kInvalidEntryId for catalog records
  // "map 3 entry 17" or "map 3".
  std::string Describe() const;
};

// --- Keys ---
inline constexpr size_t kEntryKeySize = 8;
std::string EntryKey(MapId map, EntryId id);
// The first key of a map's entries and a key greater than all of them (exclusive upper bound).
std::string MapEntriesBegin(MapId map);
std::string MapEntriesEnd(MapId map);
// False when `key` is not an 8-byte entry key.
bool DecodeEntryKey(std::string_view key, MapId* map, EntryId* id);

inline constexpr char kStoreRecordKey[] = "S";
inline constexpr char kMapInfoTag = 'M';
inline constexpr char kNextEntryIdTag = 'N';
std::string MapInfoKey(const std::string& name);
std::string NextEntryIdKey(MapId map);
// False when `key` is not a next-entry-id key.
bool DecodeNextEntryIdKey(std::string_view key, MapId* map);

// --- Catalog values ---
struct StoreRecord {
  MapId next_map_id = 1;
};
std::string EncodeStoreRecord(const StoreRecord& record);
Status DecodeStoreRecord(std::string_view bytes, StoreRecord* out);

// The name is the key's, so it is not repeated in the value: DecodeMapInfo takes it.
std::string EncodeMapInfo(const MapInfo& info);
Status DecodeMapInfo(std::string_view name, std::string_view bytes, MapInfo* out);

std::string EncodeNextEntryId(EntryId next);
Status DecodeNextEntryId(std::string_view bytes, const RecordContext& context, EntryId* out);

// --- Entry parts ---

// INVALID_ARGUMENT when `entry` breaks an invariant that the decoders check (bow words or
// direct-index nodes not strictly increasing, the features of a node not increasing, a descriptor
// matrix the features encoding cannot hold): the store never writes what it could not read back.
Status CheckStorable(const EntryRecord& entry);

std::string EncodeMetadata(const EntryMetadata& metadata);
Status DecodeMetadata(std::string_view bytes, const RecordContext& context, EntryMetadata* out);

std::string EncodeBow(const BowVector& bow);
Status DecodeBow(std::string_view bytes, const RecordContext& context, BowVector* out);

std::string EncodeDirect(const FeatureVector& direct);
Status DecodeDirect(std::string_view bytes, const RecordContext& context, FeatureVector* out);

// INVALID_ARGUMENT when the descriptor matrix has more than two dimensions or four channels, or
// when `points` is neither empty nor one per keypoint. A `camera` of all zeros is no camera (the
// record then has the layout it had before cameras were stored); a decoded record without one
// gives all zeros.
StatusOr<std::string> EncodeFeatures(const std::vector<cv::KeyPoint>& keypoints,
                                     const cv::Mat& descriptors,
                                     const std::vector<cv::Point3f>& points,
                                     const cv::Matx33d& camera = cv::Matx33d::zeros());
Status DecodeFeatures(std::string_view bytes, const RecordContext& context,
                      std::vector<cv::KeyPoint>* keypoints, cv::Mat* descriptors,
                      std::vector<cv::Point3f>* points, cv::Matx33d* camera);

}  // namespace recog::storage
