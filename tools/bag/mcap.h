// A reader of MCAP files, written from the published specification (https://mcap.dev/spec):
// the magic "\x89MCAP0\r\n", then records (an opcode byte, a uint64 length, the content), then the
// magic again. The structs below are the specification's records, field for field; Record holds
// any one of them.
//
// McapReader reads a file through positioned reads (never the whole file at once) in two ways:
//  - ReadRecords, the streamed reading: every record in file order, each chunk's records in its
//    place after the Chunk record itself, with the CRCs the file gives checked;
//  - ReadSummary and ReadMessagesByTime, the indexed reading: the footer and the summary section
//    (schemas, channels, statistics, chunk indexes...), then only the chunks whose index lists a
//    wanted channel, their messages merged in log time order (ties in file order).
// ReadMessageAt reads one message again from the position a reading gave it, keeping the last
// chunk it decompressed. Every length is checked against what is left of the file or the record
// before anything is allocated, and no chunk decompresses to more than kMaxDecompressedBytes.
// Errors name the file and the record: DATA_LOSS for a file cut short, a CRC that does not match
// or a damaged record, INVALID_ARGUMENT for a file that is not MCAP or an unknown compression,
// RESOURCE_EXHAUSTED for a record beyond the reader's limits.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <unordered_set>
#include <utility>
#include <variant>
#include <vector>

#include "core/common/status.h"

namespace recog::bag::mcap {

inline constexpr std::string_view kMagic{"\x89MCAP0\r\n", 8};

enum class Opcode : uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kAttachment = 0x09,
  kAttachmentIndex = 0x0A,
  kStatistics = 0x0B,
  kMetadata = 0x0C,
  kMetadataIndex = 0x0D,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
};

// The record's name in the specification ("Chunk"), or "record 0x42" for an unknown opcode.
std::string OpcodeName(uint8_t opcode);

// Byte fields that can be large (message data, attachments, a chunk's records) are spans into the
// reader's buffers, valid during the visit that gives them only.
struct Header {
  std::string profile;
  std::string library;
};
struct Footer {
  uint64_t summary_start = 0;
  uint64_t summary_offset_start = 0;
  uint32_t summary_crc = 0;
};
struct Schema {
  uint16_t id = 0;
  std::string name;
  std::string encoding;
  std::vector<uint8_t> data;
};
struct Channel {
  uint16_t id = 0;
  uint16_t schema_id = 0;
  std::string topic;
  std::string message_encoding;
  std::map<std::string, std::string> metadata;
};
struct Message {
  uint16_t channel_id = 0;
  uint32_t sequence = 0;
  uint64_t log_time = 0;
  uint64_t publish_time = 0;
  std::span<const uint8_t> data;
};
struct Chunk {
  uint64_t message_start_time = 0;
  uint64_t message_end_time = 0;
  uint64_t uncompressed_size = 0;
  uint32_t uncompressed_crc = 0;
  std::string compression;
  std::span<const uint8_t> records;  // compressed
};
struct MessageIndex {
  uint16_t channel_id = 0;
  std::vector<std::pair<uint64_t, uint64_t>> records;  // (log_time, offset in the chunk)
};
struct ChunkIndex {
  uint64_t message_start_time = 0;
  uint64_t message_end_time = 0;
  uint64_t chunk_start_offset = 0;
  uint64_t chunk_length = 0;
  std::map<uint16_t, uint64_t> message_index_offsets;
  uint64_t message_index_length = 0;
  std::string compression;
  uint64_t compressed_size = 0;
  uint64_t uncompressed_size = 0;
};
struct Attachment {
  uint64_t log_time = 0;
  uint64_t create_time = 0;
  std::string name;
  std::string media_type;
  std::span<const uint8_t> data;
  uint32_t crc = 0;
};
struct AttachmentIndex {
  uint64_t offset = 0;
  uint64_t length = 0;
  uint64_t log_time = 0;
  uint64_t create_time = 0;
  uint64_t data_size = 0;
  std::string name;
  std::string media_type;
};
struct Statistics {
  uint64_t message_count = 0;
  uint16_t schema_count = 0;
  uint32_t channel_count = 0;
  uint32_t attachment_count = 0;
  uint32_t metadata_count = 0;
  uint32_t chunk_count = 0;
  uint64_t message_start_time = 0;
  uint64_t message_end_time = 0;
  std::map<uint16_t, uint64_t> channel_message_counts;
};
struct Metadata {
  std::string name;
  std::map<std::string, std::string> metadata;
};
struct MetadataIndex {
  uint64_t offset = 0;
  uint64_t length = 0;
  std::string name;
};
struct SummaryOffset {
  uint8_t group_opcode = 0;
  uint64_t group_start = 0;
  uint64_t group_length = 0;
};
struct DataEnd {
  uint32_t data_section_crc = 0;
};

// The alternatives are in opcode order: a record's opcode is its index() + 1 (OpcodeOf).
using Record = std::variant<Header, Footer, Schema, Channel, Message, Chunk, MessageIndex,
                            ChunkIndex, Attachment, AttachmentIndex, Statistics, Metadata,
                            MetadataIndex, SummaryOffset, DataEnd>;
inline uint8_t OpcodeOf(const Record& record) { return uint8_t(record.index() + 1); }

// Where a record is: at byte `offset` of the file (chunk_offset == kNotInChunk), or at byte
// `offset` of the decompressed records of the chunk whose record starts at byte `chunk_offset`.
inline constexpr uint64_t kNotInChunk = ~uint64_t(0);
struct RecordPosition {
  uint64_t chunk_offset = kNotInChunk;
  uint64_t offset = 0;
};

using RecordVisitor = std::function<Status(const Record&, const RecordPosition&)>;

// The footer and the records of the summary section.
struct Summary {
  Footer footer;
  std::map<uint16_t, Schema> schemas;
  std::map<uint16_t, Channel> channels;
  std::optional<Statistics> statistics;
  std::vector<ChunkIndex> chunk_indexes;  // in the summary's order
  std::vector<AttachmentIndex> attachment_indexes;
  std::vector<MetadataIndex> metadata_indexes;
  std::vector<SummaryOffset> summary_offsets;
};

class McapReader {
 public:
  // Opens `path` and checks its magic at both ends: NOT_FOUND when it cannot be opened,
  // INVALID_ARGUMENT when it is not MCAP, DATA_LOSS when it is cut short.
  static StatusOr<std::unique_ptr<McapReader>> Open(const std::string& path);
  ~McapReader();
  McapReader(const McapReader&) = delete;
  McapReader& operator=(const McapReader&) = delete;

  const std::string& path() const { return path_; }
  uint64_t file_size() const { return file_size_; }

  // The streamed reading: visits every record from the Header to the Footer in file order, a
  // Chunk record followed by the records it holds; unknown opcodes and the bytes after a
  // record's known fields are skipped. The file must start with a Header and end its data section
  // with a DataEnd record. Checks the Chunk, Attachment, DataEnd and Footer CRCs that are not
  // zero. Stops at, and returns, the first error of `visit`.
  Status ReadRecords(const RecordVisitor& visit);

  // The footer and the summary section (empty when the footer's summary_start is 0), with the
  // summary CRC checked when not zero.
  StatusOr<Summary> ReadSummary();

  // The indexed reading, over the chunks `summary` indexes: visits the Schema and Channel records
  // of every chunk it reads when it reads it, and the messages of the channels `wanted` accepts
  // in log time order (ties in file order). A chunk whose index lists its channels and none that
  // `wanted` accepts is not read. Messages outside chunks are not seen: call it for files whose
  // messages are all in indexed chunks, and ReadRecords for the others.
  Status ReadMessagesByTime(const Summary& summary,
                            const std::function<bool(uint16_t channel_id)>& wanted,
                            const RecordVisitor& visit);

  // The message at `position` (one a reading gave), its data valid until the next call.
  StatusOr<Message> ReadMessageAt(const RecordPosition& position);

 private:
  McapReader(std::string path, int fd, uint64_t file_size);

  // The `size` bytes at `offset` into *buffer; DATA_LOSS when the file is shorter.
  Status ReadAt(uint64_t offset, uint64_t size, std::vector<uint8_t>* buffer) const;
  // The record at `offset` of the file, which must end by `end`: its opcode, and its content in
  // *buffer.
  Status ReadRecordAt(uint64_t offset, uint64_t end, uint8_t* opcode,
                      std::vector<uint8_t>* buffer) const;
  // The CRC-32 of the file's bytes [begin, end).
  StatusOr<uint32_t> Crc32OfRange(uint64_t begin, uint64_t end) const;
  // Checks the footer's summary CRC (when not zero) against the bytes it covers.
  Status CheckSummaryCrc(const Footer& footer, uint64_t footer_offset) const;
  // `chunk` (whose record is at `chunk_offset`) decompressed into *decompressed, or its own
  // bytes when uncompressed; its uncompressed CRC checked the first time the chunk is read.
  StatusOr<std::span<const uint8_t>> DecompressChunk(const Chunk& chunk, uint64_t chunk_offset,
                                                     std::vector<uint8_t>* decompressed) const;
  // The Chunk record at `chunk_offset` read into *record and decompressed as DecompressChunk does.
  StatusOr<std::span<const uint8_t>> LoadChunk(uint64_t chunk_offset, std::vector<uint8_t>* record,
                                               std::vector<uint8_t>* decompressed,
                                               Chunk* chunk) const;

  std::string path_;
  int fd_ = -1;
  uint64_t file_size_ = 0;
  // The last chunk ReadMessageAt decompressed (kNotInChunk: none), and the buffers it uses.
  uint64_t cached_chunk_offset_ = kNotInChunk;
  std::vector<uint8_t> cached_chunk_record_;
  std::vector<uint8_t> cached_chunk_decompressed_;
  std::span<const uint8_t> cached_chunk_records_;
  std::vector<uint8_t> message_record_;
  // The chunks whose CRC matched: a frame reader reads each chunk's messages again after its
  // reading checked them (a raw 640 x 480 colour frame is a chunk of its own; its CRC costs
  // 0.17 ms, bench_bag).
  mutable std::unordered_set<uint64_t> crc_checked_chunks_;
};

}  // namespace recog::bag::mcap
