// A recorded bag as its messages, whichever format holds them: the storage-independent view that
// the frame reader (tools/evaluation/ros_bag.h) and `recog bag info` read.
//
// Three storages are read, recognised by their content, never by a file's extension:
//  - ROS 1 bags (rosbag 2.0, "#ROSBAG V2.0"), through Debian's librosbag_storage (ros1_store.cc);
//  - MCAP files (the "\x89MCAP0\r\n" magic), with the project's own reader of the published
//    specification (mcap.h; a lone .mcap or the files of a rosbag2 folder);
//  - rosbag2's sqlite3 storage (the "SQLite format 3" header), through libsqlite3
//    (sqlite3_store.cc; a lone .db3 or the files of a rosbag2 folder);
// and a rosbag2 folder: its metadata.yaml (versions 1 to 8) naming its files in order, each one
// MCAP or sqlite3, whole-file or per-message zstd compressed (rosbag2_folder.cc).
//
// A store is opened once and checked as far as its format allows without reading every message
// (lengths within the file, known compressions, the serialization format of every topic); the
// messages of a topic are then visited in the order they were recorded, and any one of them can
// be read again by the id the visit gave it. Errors name the file and the record or message:
// NOT_FOUND for a missing file, DATA_LOSS for a file cut short, a CRC that does not match or a
// chunk that does not decompress to its declared size, INVALID_ARGUMENT for anything that is not
// a bag of a supported kind (an unknown compression, a serialization format that is neither
// ROS 1's nor CDR, a metadata.yaml naming files that are not there).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/common/status.h"

namespace recog::bag {

// How a topic's messages are serialized.
enum class Serialization { kRos1, kCdr };

struct TopicSummary {
  std::string name;
  // As the bag names it: "sensor_msgs/Image" (ROS 1, rosbag2 of 2018), "sensor_msgs/msg/Image".
  std::string type;
  Serialization serialization = Serialization::kCdr;
  uint64_t messages = 0;
};

struct BagSummary {
  std::string path;                // as given to OpenBag
  std::string storage;             // "ros1", "mcap", "sqlite3"
  std::vector<std::string> files;  // the files holding the messages, in order
  // How the data is compressed, as a person reads it: "none", "bz2, lz4" (ROS 1 chunks),
  // "zstd" (MCAP chunks), "zstd (file)" / "zstd (message)" (rosbag2's modes).
  std::string compression;
  uint64_t messages = 0;
  // The first and last message's log time (when it was recorded), nanoseconds since the epoch;
  // both 0 for a bag without messages.
  int64_t start_ns = 0;
  int64_t end_ns = 0;
  std::vector<TopicSummary> topics;  // sorted by name, topics without messages included
};

// One message, as a visit gives it.
struct StoredMessage {
  uint64_t id = 0;                // ReadMessage's key; stable while the store is open
  int64_t log_time_ns = 0;        // when it was recorded (not its header's stamp)
  std::span<const uint8_t> data;  // its serialized bytes, valid during the visit only
};

// A bag opened for reading. Not thread-safe; one store per thread.
class BagStore {
 public:
  virtual ~BagStore() = default;

  virtual const BagSummary& summary() const = 0;

  // Visits the messages of `topic` in the order they were recorded (log time, then file order);
  // stops at, and returns, the first error of `visit` or of the file. A topic the bag does not
  // have is NOT_FOUND.
  virtual Status ForEachMessage(const std::string& topic,
                                const std::function<Status(const StoredMessage&)>& visit) = 0;

  // The bytes of the message `id` of `topic` (an id ForEachMessage gave) into *data (its
  // capacity is reused).
  virtual Status ReadMessage(const std::string& topic, uint64_t id, std::vector<uint8_t>* data) = 0;
};

// The bag at `path` (a ROS 1 bag, an MCAP file, an sqlite3 file or a rosbag2 folder), by its
// content. The errors of the header comment; a path that is none of these is INVALID_ARGUMENT
// saying what was found.
StatusOr<std::unique_ptr<BagStore>> OpenBag(const std::string& path);

// The stores of each kind (OpenBag chooses among them); `path` is one file, or for
// OpenRosbag2Folder a folder.
StatusOr<std::unique_ptr<BagStore>> OpenRos1Bag(const std::string& path);
StatusOr<std::unique_ptr<BagStore>> OpenMcapFile(const std::string& path);
StatusOr<std::unique_ptr<BagStore>> OpenSqlite3File(const std::string& path);
StatusOr<std::unique_ptr<BagStore>> OpenRosbag2Folder(const std::string& path);

// "sensor_msgs/msg/Image" and "sensor_msgs/Image" alike: true when `type` is package/name, with
// or without ROS 2's "/msg/".
bool IsMessageType(std::string_view type, std::string_view package, std::string_view name);

}  // namespace recog::bag
