// Test support: ROS 2 bags written here, byte by byte, for the tests and benchmarks of the bag
// readers (tools/bag/, tools/evaluation/ros_bag.h). Not a product writer, and not the evidence
// that the readers read what ROS 2 writes: the acceptance bags are written by real writers
// (@mcap/core, @foxglove/rosmsg2-serialization, rosbag2's sqlite3 layout) in tools/bag/writers/,
// see tests/data/bags/README.md. This writer makes what those fixtures cannot: bags of any size
// and layout, and damaged ones.
//
//  - Messages: sensor_msgs Image, CompressedImage and CameraInfo serialized as ROS 2's CDR (little
//    or big endian; CdrSerializer) or as ROS 1 (Ros1Serializer), through WriteMessage; the
//    serializers' primitives write anything else (a count that lies, a header alone).
//  - MCAP (WriteMcapFile): Header, an Attachment if asked, Schema and Channel records, Message
//    records outside chunks or in chunks (uncompressed, zstd, or lz4 as an LZ4 frame) closed
//    after a number of messages or at a size, as rosbag2's writer does, each chunk followed by
//    its Message Index records; DataEnd; a summary (schemas, channels, Statistics, Chunk
//    Indexes) unless asked not to; Footer; CRCs unless asked not to.
//  - rosbag2 sqlite3 (WriteRosbag2Sqlite3, through libsqlite3): tables topics(id, name, type,
//    serialization_format, offered_qos_profiles) and messages(id, topic_id, timestamp, data)
//    with rosbag2's timestamp index.
//  - A rosbag2 folder (WriteRosbag2Folder): one MCAP or sqlite3 file and the metadata.yaml
//    (version 5, Humble's) naming it (Rosbag2MetadataYaml).
// A bag's topics (BagTopic) and messages (BagMessage) are described once for every storage: a
// topic's id is its MCAP channel id (and its schema's) and its sqlite3 topics row id.
//
// Users link libzstd, liblz4, libsqlite3 and zlib.
#pragma once

#include <lz4frame.h>
#include <sqlite3.h>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/common/status.h"
#include "tools/bag/mcap.h"

namespace recog::testing {

// ---------------------------------------------------------------------------------------------
// sensor_msgs serialization.

// std_msgs/Header.
struct HeaderFields {
  int32_t sec = 0;
  uint32_t nanosec = 0;
  std::string frame_id;
  uint32_t seq = 0;  // ROS 1 only
};

// ROS 1 serialization: little endian, packed.
class Ros1Serializer {
 public:
  void U8(uint8_t value) { bytes_.push_back(value); }
  void U32(uint32_t value) { Little(value, 4); }
  void F64(double value) {
    uint64_t bits = 0;
    std::memcpy(&bits, &value, sizeof(bits));
    Little(bits, 8);
  }
  void String(std::string_view text) {
    U32(uint32_t(text.size()));
    bytes_.insert(bytes_.end(), text.begin(), text.end());
  }
  void ByteSequence(std::span<const uint8_t> data) {
    U32(uint32_t(data.size()));
    bytes_.insert(bytes_.end(), data.begin(), data.end());
  }
  void Header(const HeaderFields& header) {
    U32(header.seq);
    U32(uint32_t(header.sec));
    U32(header.nanosec);
    String(header.frame_id);
  }

  const std::vector<uint8_t>& bytes() const { return bytes_; }

 private:
  void Little(uint64_t value, int size) {
    for (int i = 0; i < size; ++i) bytes_.push_back(uint8_t(value >> (8 * i)));
  }

  std::vector<uint8_t> bytes_;
};

// CDR as rmw writes it: the 4-byte encapsulation header (CDR_LE 00 01 00 00, CDR_BE 00 00 00 00),
// then each primitive aligned to its size from the end of that header; strings with their
// terminating NUL counted.
class CdrSerializer {
 public:
  explicit CdrSerializer(bool big_endian = false) : big_endian_(big_endian) {
    bytes_ = {0x00, uint8_t(big_endian ? 0x00 : 0x01), 0x00, 0x00};
  }

  void U8(uint8_t value) { bytes_.push_back(value); }
  void U32(uint32_t value) { Aligned(value, 4); }
  void F64(double value) {
    uint64_t bits = 0;
    std::memcpy(&bits, &value, sizeof(bits));
    Aligned(bits, 8);
  }
  void String(std::string_view text) {
    U32(uint32_t(text.size() + 1));
    bytes_.insert(bytes_.end(), text.begin(), text.end());
    bytes_.push_back(0);
  }
  void ByteSequence(std::span<const uint8_t> data) {
    U32(uint32_t(data.size()));
    bytes_.insert(bytes_.end(), data.begin(), data.end());
  }
  // builtin_interfaces/Time (int32 sec, uint32 nanosec), then frame_id.
  void Header(const HeaderFields& header) {
    U32(uint32_t(header.sec));
    U32(header.nanosec);
    String(header.frame_id);
  }

  const std::vector<uint8_t>& bytes() const { return bytes_; }

 private:
  void Aligned(uint64_t value, int size) {
    while ((bytes_.size() - 4) % size != 0) bytes_.push_back(0);
    for (int i = 0; i < size; ++i) {
      bytes_.push_back(uint8_t(value >> (8 * (big_endian_ ? size - 1 - i : i))));
    }
  }

  bool big_endian_;
  std::vector<uint8_t> bytes_;
};

// The fields of the three messages. Their data is viewed, not owned: it must outlive the fields.
struct ImageFields {
  HeaderFields header;
  uint32_t height = 0;
  uint32_t width = 0;
  std::string encoding;
  bool is_bigendian = false;
  uint32_t step = 0;
  std::span<const uint8_t> data;
};

struct CompressedImageFields {
  HeaderFields header;
  std::string format;
  std::span<const uint8_t> data;
};

struct CameraInfoFields {
  HeaderFields header;
  uint32_t height = 0;
  uint32_t width = 0;
  std::string distortion_model;
  std::vector<double> d;
  std::array<double, 9> k{};
  std::array<double, 9> r{};
  std::array<double, 12> p{};
  uint32_t binning_x = 0;
  uint32_t binning_y = 0;
  // Written as d's element count instead of the true one (a count that lies), when set.
  std::optional<uint32_t> declared_d_count;
  // The region of interest is written as zeros (x_offset, y_offset, height, width, do_rectify).
};

template <typename Serializer>
void WriteMessage(Serializer& s, const ImageFields& m) {
  s.Header(m.header);
  s.U32(m.height);
  s.U32(m.width);
  s.String(m.encoding);
  s.U8(m.is_bigendian ? 1 : 0);
  s.U32(m.step);
  s.ByteSequence(m.data);
}

template <typename Serializer>
void WriteMessage(Serializer& s, const CompressedImageFields& m) {
  s.Header(m.header);
  s.String(m.format);
  s.ByteSequence(m.data);
}

template <typename Serializer>
void WriteMessage(Serializer& s, const CameraInfoFields& m) {
  s.Header(m.header);
  s.U32(m.height);
  s.U32(m.width);
  s.String(m.distortion_model);
  s.U32(m.declared_d_count.value_or(uint32_t(m.d.size())));
  for (const double value : m.d) s.F64(value);
  for (const double value : m.k) s.F64(value);
  for (const double value : m.r) s.F64(value);
  for (const double value : m.p) s.F64(value);
  s.U32(m.binning_x);
  s.U32(m.binning_y);
  for (int i = 0; i < 4; ++i) s.U32(0);  // roi: x_offset, y_offset, height, width
  s.U8(0);                               // roi.do_rectify
}

// `message` serialized by `serializer` (e.g. CdrSerializer(true) for big-endian CDR).
template <typename Serializer, typename Fields>
std::vector<uint8_t> Serialized(Serializer serializer, const Fields& message) {
  WriteMessage(serializer, message);
  return serializer.bytes();
}

// ---------------------------------------------------------------------------------------------
// Bags.

// A topic: its MCAP channel (with a schema of the same id) and its sqlite3 topics row.
struct BagTopic {
  uint16_t id = 0;  // from 1
  std::string name;
  std::string type;                          // "sensor_msgs/msg/Image"
  std::string serialization_format = "cdr";  // the MCAP channel's message encoding
};

struct BagMessage {
  uint16_t topic_id = 0;
  uint64_t log_time = 0;  // ns; the MCAP publish time is written as log_time + 1
  std::string data;
};

// ---------------------------------------------------------------------------------------------
// MCAP.

// The content of an MCAP record, field by field, little endian.
class McapFields {
 public:
  McapFields& U8(uint8_t value) { return Little(value, 1); }
  McapFields& U16(uint16_t value) { return Little(value, 2); }
  McapFields& U32(uint32_t value) { return Little(value, 4); }
  McapFields& U64(uint64_t value) { return Little(value, 8); }
  McapFields& Raw(std::string_view bytes) {
    bytes_ += bytes;
    return *this;
  }
  McapFields& String(std::string_view text) { return U32(uint32_t(text.size())).Raw(text); }
  McapFields& Bytes64(std::string_view bytes) { return U64(bytes.size()).Raw(bytes); }
  const std::string& bytes() const { return bytes_; }

 private:
  McapFields& Little(uint64_t value, int size) {
    for (int i = 0; i < size; ++i) bytes_.push_back(char(value >> (8 * i)));
    return *this;
  }
  std::string bytes_;
};

// A record: its opcode, its content's length, its content.
inline std::string McapRecord(bag::mcap::Opcode opcode, const McapFields& fields) {
  return McapFields().U8(uint8_t(opcode)).U64(fields.bytes().size()).Raw(fields.bytes()).bytes();
}

inline uint32_t Crc32(std::string_view bytes) {
  return uint32_t(crc32(0, reinterpret_cast<const Bytef*>(bytes.data()), uInt(bytes.size())));
}

// `data` compressed as an MCAP chunk names it: "zstd" (level 3), "lz4" (an LZ4 frame), anything
// else (e.g. "", or an unknown name for a test) as it is.
inline std::string CompressChunk(const std::string& compression, std::string_view data) {
  std::string out;
  if (compression == "zstd") {
    out.resize(ZSTD_compressBound(data.size()));
    out.resize(ZSTD_compress(out.data(), out.size(), data.data(), data.size(), 3));
  } else if (compression == "lz4") {
    out.resize(LZ4F_compressFrameBound(data.size(), nullptr));
    out.resize(LZ4F_compressFrame(out.data(), out.size(), data.data(), data.size(), nullptr));
  } else {
    out = data;
  }
  return out;
}

// The default chunk size of rosbag2's MCAP storage: mcap::McapWriterOptions' chunkSize,
// mcap::DefaultChunkSize = 768 KiB, which rosbag2_storage_mcap leaves as it is.
inline constexpr uint64_t kRosbag2McapChunkBytes = 768 * 1024;

// How WriteMcapFile lays a file out.
struct McapOptions {
  // Chunks of `messages_per_chunk` messages each.
  McapOptions& Chunked(size_t messages_per_chunk, std::string with_compression = "") {
    chunk_messages = messages_per_chunk;
    compression = std::move(with_compression);
    return *this;
  }
  // Chunks closed once their uncompressed records reach `bytes`, as the MCAP library's writer
  // does with its chunkSize (rosbag2's: kRosbag2McapChunkBytes).
  McapOptions& ChunkedBySize(uint64_t bytes, std::string with_compression = "") {
    chunk_bytes = bytes;
    compression = std::move(with_compression);
    return *this;
  }
  McapOptions& WithoutSummary() {
    summary = false;
    return *this;
  }
  McapOptions& WithoutCrcs() {
    crcs = false;
    return *this;
  }
  McapOptions& DeclaringUncompressedSize(uint64_t size) {
    declared_uncompressed_size = size;
    return *this;
  }
  McapOptions& WithAttachment(std::string data) {
    attachment = std::move(data);
    return *this;
  }

  bool chunked() const { return chunk_messages > 0 || chunk_bytes > 0; }

  // Messages per chunk, or the size at which a chunk closes; both 0: no chunks.
  size_t chunk_messages = 0;
  uint64_t chunk_bytes = 0;
  std::string compression;  // "", "zstd", "lz4"
  bool summary = true;      // schemas, channels, statistics and chunk indexes after DataEnd
  bool crcs = true;         // chunks', the data section's and the summary's
  // Written as each chunk's uncompressed size instead of the true one (when not 0).
  uint64_t declared_uncompressed_size = 0;
  // An Attachment record after the Header holding these bytes (when not empty).
  std::string attachment;
  std::string profile = "ros2";
  std::string library = "recog tests";  // the Header's
};

// An MCAP file holding `messages` of `topics`, laid out as `options` says. Each topic is a
// channel with a schema of its own (encoding ros2msg), both of the topic's id. Messages keep
// their order, each with its index in the file as its sequence; chunked, the first chunk also
// holds the schemas and channels (and without messages there is no chunk: they are then in the
// summary only), and each chunk is followed by a Message Index per channel it holds.
inline std::string WriteMcapFile(const std::vector<BagTopic>& topics,
                                 const std::vector<BagMessage>& messages,
                                 const McapOptions& options) {
  using bag::mcap::Opcode;
  std::string file(bag::mcap::kMagic);
  file += McapRecord(Opcode::kHeader, McapFields().String(options.profile).String(options.library));
  if (!options.attachment.empty()) {
    const std::string fields = McapFields()
                                   .U64(1)
                                   .U64(2)
                                   .String("calibration.yaml")
                                   .String("text/yaml")
                                   .Bytes64(options.attachment)
                                   .bytes();
    file += McapRecord(Opcode::kAttachment, McapFields().Raw(fields).U32(Crc32(fields)));
  }
  std::string definitions;
  for (const BagTopic& topic : topics) {
    definitions += McapRecord(
        Opcode::kSchema,
        McapFields().U16(topic.id).String(topic.type).String("ros2msg").String("definition"));
  }
  for (const BagTopic& topic : topics) {
    definitions += McapRecord(Opcode::kChannel, McapFields()
                                                    .U16(topic.id)
                                                    .U16(topic.id)
                                                    .String(topic.name)
                                                    .String(topic.serialization_format)
                                                    .U32(0));  // no metadata
  }
  const auto message_record = [&](size_t i) {
    const BagMessage& message = messages[i];
    return McapRecord(Opcode::kMessage, McapFields()
                                            .U16(message.topic_id)
                                            .U32(uint32_t(i))
                                            .U64(message.log_time)
                                            .U64(message.log_time + 1)
                                            .Raw(message.data));
  };

  std::vector<std::string> chunk_indexes;
  if (!options.chunked()) {
    file += definitions;
    for (size_t i = 0; i < messages.size(); ++i) file += message_record(i);
  }
  for (size_t first = 0; options.chunked() && first < messages.size();) {
    std::string records = first == 0 ? definitions : "";
    std::map<uint16_t, std::vector<std::pair<uint64_t, uint64_t>>> index;
    uint64_t start = ~uint64_t(0);
    uint64_t end = 0;
    size_t i = first;
    // At least one message, then more while the chunk is below its count and size.
    while (i < messages.size() &&
           (i == first || ((options.chunk_messages == 0 || i < first + options.chunk_messages) &&
                           (options.chunk_bytes == 0 || records.size() < options.chunk_bytes)))) {
      index[messages[i].topic_id].emplace_back(messages[i].log_time, records.size());
      start = std::min(start, messages[i].log_time);
      end = std::max(end, messages[i].log_time);
      records += message_record(i++);
    }
    first = i;
    const std::string compressed = CompressChunk(options.compression, records);
    const uint64_t chunk_offset = file.size();
    file += McapRecord(Opcode::kChunk, McapFields()
                                           .U64(start)
                                           .U64(end)
                                           .U64(options.declared_uncompressed_size != 0
                                                    ? options.declared_uncompressed_size
                                                    : records.size())
                                           .U32(options.crcs ? Crc32(records) : 0)
                                           .String(options.compression)
                                           .Bytes64(compressed));
    const uint64_t chunk_length = file.size() - chunk_offset;
    McapFields offsets;
    for (const auto& [channel_id, entries] : index) {
      McapFields entry_bytes;
      for (const auto& [log_time, offset] : entries) entry_bytes.U64(log_time).U64(offset);
      offsets.U16(channel_id).U64(file.size());
      file += McapRecord(Opcode::kMessageIndex, McapFields()
                                                    .U16(channel_id)
                                                    .U32(uint32_t(entry_bytes.bytes().size()))
                                                    .Raw(entry_bytes.bytes()));
    }
    chunk_indexes.push_back(
        McapRecord(Opcode::kChunkIndex, McapFields()
                                            .U64(start)
                                            .U64(end)
                                            .U64(chunk_offset)
                                            .U64(chunk_length)
                                            .U32(uint32_t(offsets.bytes().size()))
                                            .Raw(offsets.bytes())
                                            .U64(file.size() - chunk_offset - chunk_length)
                                            .String(options.compression)
                                            .U64(compressed.size())
                                            .U64(records.size())));
  }
  file += McapRecord(Opcode::kDataEnd, McapFields().U32(options.crcs ? Crc32(file) : 0));

  const uint64_t summary_start = options.summary ? file.size() : 0;
  if (options.summary) {
    file += definitions;
    std::map<uint16_t, uint64_t> counts;
    for (const BagMessage& message : messages) ++counts[message.topic_id];
    McapFields channel_counts;
    for (const auto& [channel_id, count] : counts) channel_counts.U16(channel_id).U64(count);
    uint64_t start = ~uint64_t(0);
    uint64_t end = 0;
    for (const BagMessage& message : messages) {
      start = std::min(start, message.log_time);
      end = std::max(end, message.log_time);
    }
    file += McapRecord(Opcode::kStatistics, McapFields()
                                                .U64(messages.size())
                                                .U16(uint16_t(topics.size()))
                                                .U32(uint32_t(topics.size()))
                                                .U32(options.attachment.empty() ? 0 : 1)
                                                .U32(0)  // metadata
                                                .U32(uint32_t(chunk_indexes.size()))
                                                .U64(messages.empty() ? 0 : start)
                                                .U64(end)
                                                .U32(uint32_t(channel_counts.bytes().size()))
                                                .Raw(channel_counts.bytes()));
    for (const std::string& chunk_index : chunk_indexes) file += chunk_index;
  }
  // The footer's CRC covers the summary (when there is one) and the footer up to the CRC.
  const std::string footer_start = McapFields().U8(uint8_t(Opcode::kFooter)).U64(20).bytes();
  const std::string footer_fields = McapFields().U64(summary_start).U64(0).bytes();
  const std::string covered =
      file.substr(summary_start != 0 ? summary_start : file.size()) + footer_start + footer_fields;
  file +=
      footer_start + footer_fields + McapFields().U32(options.crcs ? Crc32(covered) : 0).bytes();
  return file + std::string(bag::mcap::kMagic);
}

// ---------------------------------------------------------------------------------------------
// rosbag2.

// MCAP as rosbag2's MCAP storage writes it by default: chunks of kRosbag2McapChunkBytes,
// compressed with zstd (its level aside), with every index, the summary and CRCs.
inline McapOptions Rosbag2McapOptions() {
  return McapOptions().ChunkedBySize(kRosbag2McapChunkBytes, "zstd");
}

// rosbag2's sqlite3 storage at `path` (replaced if there): `topics` and `messages` (row ids from
// 1 in the order given, timestamp = log time), in one transaction.
inline Status WriteRosbag2Sqlite3(const std::string& path, const std::vector<BagTopic>& topics,
                                  const std::vector<BagMessage>& messages) {
  std::filesystem::remove(path);
  sqlite3* raw = nullptr;
  const int opened =
      sqlite3_open_v2(path.c_str(), &raw, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, nullptr);
  const std::unique_ptr<sqlite3, int (*)(sqlite3*)> db(raw, sqlite3_close_v2);
  const auto error = [&](std::string_view doing) {
    return Status::Internal("writing sqlite3 bag '" + path + "': " + std::string(doing) + ": " +
                            (db ? sqlite3_errmsg(db.get()) : sqlite3_errstr(opened)));
  };
  if (opened != SQLITE_OK) return error("opening");
  const char* const kSchema =
      "BEGIN;"
      "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, "
      "serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);"
      "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, "
      "timestamp INTEGER NOT NULL, data BLOB NOT NULL);"
      "CREATE INDEX timestamp_idx ON messages (timestamp ASC);";
  if (sqlite3_exec(db.get(), kSchema, nullptr, nullptr, nullptr) != SQLITE_OK) {
    return error("creating its tables");
  }
  using Statement = std::unique_ptr<sqlite3_stmt, int (*)(sqlite3_stmt*)>;
  const auto prepare = [&](const char* sql) {
    sqlite3_stmt* statement = nullptr;
    sqlite3_prepare_v2(db.get(), sql, -1, &statement, nullptr);
    return Statement(statement, sqlite3_finalize);
  };
  const Statement topic_row = prepare("INSERT INTO topics VALUES (?, ?, ?, ?, '')");
  const Statement message_row = prepare("INSERT INTO messages VALUES (?, ?, ?, ?)");
  if (!topic_row || !message_row) return error("preparing its inserts");
  for (const BagTopic& topic : topics) {
    sqlite3_bind_int64(topic_row.get(), 1, topic.id);
    sqlite3_bind_text(topic_row.get(), 2, topic.name.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(topic_row.get(), 3, topic.type.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(topic_row.get(), 4, topic.serialization_format.c_str(), -1, SQLITE_TRANSIENT);
    if (sqlite3_step(topic_row.get()) != SQLITE_DONE) return error("inserting a topic");
    sqlite3_reset(topic_row.get());
  }
  for (size_t i = 0; i < messages.size(); ++i) {
    const BagMessage& message = messages[i];
    sqlite3_bind_int64(message_row.get(), 1, int64_t(i + 1));
    sqlite3_bind_int64(message_row.get(), 2, message.topic_id);
    sqlite3_bind_int64(message_row.get(), 3, int64_t(message.log_time));
    sqlite3_bind_blob(message_row.get(), 4, message.data.data(), int(message.data.size()),
                      SQLITE_STATIC);
    if (sqlite3_step(message_row.get()) != SQLITE_DONE) return error("inserting a message");
    sqlite3_reset(message_row.get());
  }
  if (sqlite3_exec(db.get(), "COMMIT", nullptr, nullptr, nullptr) != SQLITE_OK) {
    return error("committing");
  }
  return Status::Ok();
}

// A rosbag2 metadata.yaml of version 5 (as Humble writes it, uncompressed) for the bag whose
// storage is `storage_identifier` ("mcap", "sqlite3") and whose one file is `file` (relative to
// the folder), holding `messages` of `topics`.
inline std::string Rosbag2MetadataYaml(const std::string& storage_identifier,
                                       const std::string& file, const std::vector<BagTopic>& topics,
                                       const std::vector<BagMessage>& messages) {
  std::map<uint16_t, uint64_t> counts;
  uint64_t start = messages.empty() ? 0 : ~uint64_t(0);
  uint64_t end = 0;
  for (const BagMessage& message : messages) {
    ++counts[message.topic_id];
    start = std::min(start, message.log_time);
    end = std::max(end, message.log_time);
  }
  const std::string duration = std::to_string(end - start);
  const std::string count = std::to_string(messages.size());
  std::string yaml =
      "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: " + storage_identifier +
      "\n  duration:\n    nanoseconds: " + duration +
      "\n  starting_time:\n    nanoseconds_since_epoch: " + std::to_string(start) +
      "\n  message_count: " + count + "\n  topics_with_message_count:\n";
  for (const BagTopic& topic : topics) {
    yaml += "    - topic_metadata:\n        name: " + topic.name + "\n        type: " + topic.type +
            "\n        serialization_format: " + topic.serialization_format +
            "\n        offered_qos_profiles: \"\"\n      message_count: " +
            std::to_string(counts[topic.id]) + "\n";
  }
  yaml += "  compression_format: \"\"\n  compression_mode: \"\"\n  relative_file_paths:\n    - " +
          file + "\n  files:\n    - path: " + file +
          "\n      starting_time:\n        nanoseconds_since_epoch: " + std::to_string(start) +
          "\n      duration:\n        nanoseconds: " + duration +
          "\n      message_count: " + count + "\n";
  return yaml;
}

// A rosbag2 folder at `folder` (replaced if there), as `ros2 bag record -s <storage>` leaves it:
// <name>_0.mcap (written as `mcap` says: by default as rosbag2 does) or <name>_0.db3, and
// metadata.yaml, where <name> is the folder's name. `storage` is "mcap" or "sqlite3".
inline Status WriteRosbag2Folder(
    const std::string& folder, const std::string& storage, const std::vector<BagTopic>& topics,
    const std::vector<BagMessage>& messages,
    const McapOptions& mcap = McapOptions().ChunkedBySize(kRosbag2McapChunkBytes, "zstd")) {
  namespace fs = std::filesystem;
  fs::remove_all(folder);
  fs::create_directories(folder);
  const std::string file =
      fs::path(folder).filename().string() + (storage == "mcap" ? "_0.mcap" : "_0.db3");
  const std::string path = (fs::path(folder) / file).string();
  if (storage == "mcap") {
    const std::string bytes = WriteMcapFile(topics, messages, mcap);
    if (!std::ofstream(path, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()))) {
      return Status::Internal("writing '" + path + "' failed");
    }
  } else if (storage == "sqlite3") {
    RECOG_RETURN_IF_ERROR(WriteRosbag2Sqlite3(path, topics, messages));
  } else {
    return Status::InvalidArgument("storage '" + storage + "': mcap or sqlite3");
  }
  const std::string yaml = Rosbag2MetadataYaml(storage, file, topics, messages);
  const std::string metadata = (fs::path(folder) / "metadata.yaml").string();
  if (!std::ofstream(metadata, std::ios::binary).write(yaml.data(), std::streamsize(yaml.size()))) {
    return Status::Internal("writing '" + metadata + "' failed");
  }
  return Status::Ok();
}

}  // namespace recog::testing
