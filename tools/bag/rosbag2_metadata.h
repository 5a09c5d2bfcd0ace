// rosbag2's own description of a bag, private to the sqlite3 and folder stores.
//
// Rosbag2Metadata is what a rosbag2 metadata.yaml says (versions 1 to 8, and a later version when
// the fields it needs are there): the storage, the files in order, the compression and the topics
// with their message counts. The same document, without its `rosbag2_bagfile_information` root,
// is what version 8 writes into the `metadata` table of each .db3, so one parser reads both.
// Sqlite3Options tells OpenSqlite3File what the folder's metadata.yaml knows about a .db3's
// messages (per-message zstd compression), which the file alone may not say.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/status.h"
#include "tools/bag/bag_store.h"

namespace recog::bag {

struct Rosbag2TopicMetadata {
  std::string name;
  std::string type;
  std::string serialization_format;
  uint64_t message_count = 0;
};

// How rosbag2 compressed a bag (its `compression_mode`).
enum class Rosbag2Compression {
  kUnknown,  // the metadata does not say (version 1 to 3, or a .db3 without metadata)
  kNone,
  kFile,     // every file is one zstd frame: X.db3.zstd, X.mcap.zstd
  kMessage,  // every message's data is one zstd frame
};

struct Rosbag2Metadata {
  int version = 0;
  std::string storage_identifier;       // "sqlite3" or "mcap" (rosbag2 names no other)
  std::vector<std::string> file_paths;  // relative to the folder, in order
  Rosbag2Compression compression = Rosbag2Compression::kUnknown;
  std::vector<Rosbag2TopicMetadata> topics;  // as listed
};

// Largest metadata.yaml read (a bag with thousands of topics writes a few MiB).
inline constexpr uint64_t kMaxRosbag2MetadataBytes = uint64_t(64) << 20;

// Parses `yaml`, a metadata document with or without its `rosbag2_bagfile_information` root.
// DATA_LOSS naming `where` for text that does not parse as YAML; INVALID_ARGUMENT for a missing
// or mistyped field, an unknown compression (only zstd is rosbag2's) or storage.
StatusOr<Rosbag2Metadata> ParseRosbag2Metadata(const std::string& yaml, std::string_view where);

// The metadata.yaml at `path`: NOT_FOUND when missing, RESOURCE_EXHAUSTED above
// kMaxRosbag2MetadataBytes, then ParseRosbag2Metadata's errors.
StatusOr<Rosbag2Metadata> ReadRosbag2Metadata(const std::string& path);

struct Sqlite3Options {
  // kUnknown: the file decides. Its own `metadata` table when it has one (version 8), else the
  // first message by id: a zstd frame (magic 28 B5 2F FD) means every message is compressed. The
  // sniff cannot mistake a plain message: CDR data starts with its encapsulation header, 00 00 or
  // 00 01 then two option bytes.
  Rosbag2Compression compression = Rosbag2Compression::kUnknown;
};

// OpenSqlite3File with what the folder knows about the file.
StatusOr<std::unique_ptr<BagStore>> OpenSqlite3File(const std::string& path,
                                                    const Sqlite3Options& options);

// 'text', as the errors of the rosbag2 stores name files, topics and fields.
std::string Quoted(std::string_view text);

// True when `bytes` start with a zstd frame's magic number.
bool StartsWithZstdMagic(std::string_view bytes);

}  // namespace recog::bag
