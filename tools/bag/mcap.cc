#include "tools/bag/mcap.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <queue>
#include <tuple>

#include "tools/bag/byte_reader.h"
#include "tools/bag/decompress.h"

namespace recog::bag::mcap {
namespace {

// An opcode byte and a uint64 length before every record's content.
constexpr uint64_t kRecordHeaderSize = 9;
// A footer's content: summary_start, summary_offset_start, summary_crc.
constexpr uint64_t kFooterContentSize = 20;
// The most bytes of one record (or of the summary section) read into memory at once.
constexpr uint64_t kMaxRecordBytes = kMaxDecompressedBytes;
// The most decompressed bytes ReadMessagesByTime holds at once: the chunks whose time ranges
// overlap the message it is at.
constexpr uint64_t kMaxHeldChunkBytes = 2 * kMaxDecompressedBytes;
// Positioned reads of a CRC'd range go through a buffer of this size.
constexpr size_t kCrcReadSize = 1 << 20;

uint64_t LittleEndian64(const uint8_t* bytes) {
  uint64_t value = 0;
  for (int i = 0; i < 8; ++i) value |= uint64_t(bytes[i]) << (8 * i);
  return value;
}

uint32_t Crc32(uint32_t crc, std::span<const uint8_t> bytes) {
  // zlib's crc32 takes a uInt length: feed it in pieces that fit.
  constexpr size_t kPiece = size_t(1) << 30;
  while (!bytes.empty()) {
    const size_t size = std::min(bytes.size(), kPiece);
    crc = uint32_t(crc32(crc, bytes.data(), uInt(size)));
    bytes = bytes.subspan(size);
  }
  return crc;
}

std::string Hex(uint32_t value) {
  char text[16];
  std::snprintf(text, sizeof(text), "0x%08x", value);
  return text;
}

// "MCAP file 'a.mcap', Chunk record at byte 28" (or "... at byte 57 of the chunk at byte 28").
std::string Describe(const std::string& path, uint8_t opcode, const RecordPosition& position) {
  std::string text = "MCAP file '" + path + "', " + OpcodeName(opcode) + " record at byte " +
                     std::to_string(position.offset);
  if (position.chunk_offset != kNotInChunk) {
    text += " of the chunk at byte " + std::to_string(position.chunk_offset);
  }
  return text;
}

// MCAP's Map<K, V>: a uint32 byte length, then key-value pairs filling exactly that many bytes.
// False when it is cut short.
template <typename Map, typename ReadPair>
bool ReadMap(ByteReader& reader, Map* map, ReadPair read_pair) {
  ByteReader pairs(reader.Prefixed32());
  while (!reader.failed() && !pairs.failed() && pairs.remaining() > 0) read_pair(pairs, map);
  return !reader.failed() && !pairs.failed();
}

bool ReadStringMap(ByteReader& reader, std::map<std::string, std::string>* map) {
  return ReadMap(reader, map, [](ByteReader& pairs, std::map<std::string, std::string>* out) {
    std::string key(pairs.PrefixedText32());
    std::string value(pairs.PrefixedText32());
    if (!pairs.failed()) (*out)[std::move(key)] = std::move(value);
  });
}

bool ReadIdMap(ByteReader& reader, std::map<uint16_t, uint64_t>* map) {
  return ReadMap(reader, map, [](ByteReader& pairs, std::map<uint16_t, uint64_t>* out) {
    const uint16_t key = pairs.U16();
    const uint64_t value = pairs.U64();
    if (!pairs.failed()) (*out)[key] = value;
  });
}

// Each parser reads the fields of one record type from its content (the bytes after them are
// skipped) and says whether they were all there.
bool Parse(ByteReader& reader, Header* record) {
  record->profile = reader.PrefixedText32();
  record->library = reader.PrefixedText32();
  return !reader.failed();
}
bool Parse(ByteReader& reader, Footer* record) {
  record->summary_start = reader.U64();
  record->summary_offset_start = reader.U64();
  record->summary_crc = reader.U32();
  return !reader.failed();
}
bool Parse(ByteReader& reader, Schema* record) {
  record->id = reader.U16();
  record->name = reader.PrefixedText32();
  record->encoding = reader.PrefixedText32();
  const std::span<const uint8_t> data = reader.Prefixed32();
  record->data.assign(data.begin(), data.end());
  return !reader.failed();
}
bool Parse(ByteReader& reader, Channel* record) {
  record->id = reader.U16();
  record->schema_id = reader.U16();
  record->topic = reader.PrefixedText32();
  record->message_encoding = reader.PrefixedText32();
  return ReadStringMap(reader, &record->metadata);
}
bool Parse(ByteReader& reader, Message* record) {
  record->channel_id = reader.U16();
  record->sequence = reader.U32();
  record->log_time = reader.U64();
  record->publish_time = reader.U64();
  record->data = reader.Bytes(reader.remaining());
  return !reader.failed();
}
bool Parse(ByteReader& reader, Chunk* record) {
  record->message_start_time = reader.U64();
  record->message_end_time = reader.U64();
  record->uncompressed_size = reader.U64();
  record->uncompressed_crc = reader.U32();
  record->compression = reader.PrefixedText32();
  record->records = reader.Bytes(reader.U64());
  return !reader.failed();
}
bool Parse(ByteReader& reader, MessageIndex* record) {
  record->channel_id = reader.U16();
  ByteReader entries(reader.Prefixed32());
  if (entries.remaining() % 16 != 0) return false;
  while (entries.remaining() > 0) {
    const uint64_t log_time = entries.U64();
    record->records.emplace_back(log_time, entries.U64());
  }
  return !reader.failed();
}
bool Parse(ByteReader& reader, ChunkIndex* record) {
  record->message_start_time = reader.U64();
  record->message_end_time = reader.U64();
  record->chunk_start_offset = reader.U64();
  record->chunk_length = reader.U64();
  const bool offsets_complete = ReadIdMap(reader, &record->message_index_offsets);
  record->message_index_length = reader.U64();
  record->compression = reader.PrefixedText32();
  record->compressed_size = reader.U64();
  record->uncompressed_size = reader.U64();
  return offsets_complete && !reader.failed();
}
bool Parse(ByteReader& reader, Attachment* record) {
  record->log_time = reader.U64();
  record->create_time = reader.U64();
  record->name = reader.PrefixedText32();
  record->media_type = reader.PrefixedText32();
  record->data = reader.Bytes(reader.U64());
  record->crc = reader.U32();
  return !reader.failed();
}
bool Parse(ByteReader& reader, AttachmentIndex* record) {
  record->offset = reader.U64();
  record->length = reader.U64();
  record->log_time = reader.U64();
  record->create_time = reader.U64();
  record->data_size = reader.U64();
  record->name = reader.PrefixedText32();
  record->media_type = reader.PrefixedText32();
  return !reader.failed();
}
bool Parse(ByteReader& reader, Statistics* record) {
  record->message_count = reader.U64();
  record->schema_count = reader.U16();
  record->channel_count = reader.U32();
  record->attachment_count = reader.U32();
  record->metadata_count = reader.U32();
  record->chunk_count = reader.U32();
  record->message_start_time = reader.U64();
  record->message_end_time = reader.U64();
  return ReadIdMap(reader, &record->channel_message_counts);
}
bool Parse(ByteReader& reader, Metadata* record) {
  record->name = reader.PrefixedText32();
  return ReadStringMap(reader, &record->metadata);
}
bool Parse(ByteReader& reader, MetadataIndex* record) {
  record->offset = reader.U64();
  record->length = reader.U64();
  record->name = reader.PrefixedText32();
  return !reader.failed();
}
bool Parse(ByteReader& reader, SummaryOffset* record) {
  record->group_opcode = reader.U8();
  record->group_start = reader.U64();
  record->group_length = reader.U64();
  return !reader.failed();
}
bool Parse(ByteReader& reader, DataEnd* record) {
  record->data_section_crc = reader.U32();
  return !reader.failed();
}

template <typename RecordType>
Status ParseAs(std::span<const uint8_t> content, const std::function<std::string()>& describe,
               std::optional<Record>* record) {
  ByteReader reader(content);
  RecordType parsed;
  if (!Parse(reader, &parsed)) {
    return Status::DataLoss(describe() + ": its " + std::to_string(content.size()) +
                            " bytes end inside its fields");
  }
  *record = std::move(parsed);
  return Status::Ok();
}

// The record `opcode` with `content`; nullopt for an opcode the specification does not define.
// `describe` names the record in errors.
Status ParseRecord(uint8_t opcode, std::span<const uint8_t> content,
                   const std::function<std::string()>& describe, std::optional<Record>* record) {
  record->reset();
  switch (Opcode(opcode)) {
    case Opcode::kHeader:
      return ParseAs<Header>(content, describe, record);
    case Opcode::kFooter:
      return ParseAs<Footer>(content, describe, record);
    case Opcode::kSchema:
      return ParseAs<Schema>(content, describe, record);
    case Opcode::kChannel:
      return ParseAs<Channel>(content, describe, record);
    case Opcode::kMessage:
      return ParseAs<Message>(content, describe, record);
    case Opcode::kChunk:
      return ParseAs<Chunk>(content, describe, record);
    case Opcode::kMessageIndex:
      return ParseAs<MessageIndex>(content, describe, record);
    case Opcode::kChunkIndex:
      return ParseAs<ChunkIndex>(content, describe, record);
    case Opcode::kAttachment:
      return ParseAs<Attachment>(content, describe, record);
    case Opcode::kAttachmentIndex:
      return ParseAs<AttachmentIndex>(content, describe, record);
    case Opcode::kStatistics:
      return ParseAs<Statistics>(content, describe, record);
    case Opcode::kMetadata:
      return ParseAs<Metadata>(content, describe, record);
    case Opcode::kMetadataIndex:
      return ParseAs<MetadataIndex>(content, describe, record);
    case Opcode::kSummaryOffset:
      return ParseAs<SummaryOffset>(content, describe, record);
    case Opcode::kDataEnd:
      return ParseAs<DataEnd>(content, describe, record);
  }
  return Status::Ok();
}

// One record of a chunk's decompressed records: its opcode and content, framed by ByteReader.
struct ChunkRecord {
  uint8_t opcode = 0;
  uint64_t offset = 0;
  std::span<const uint8_t> content;
};

// The record at byte `offset` of a chunk's `records`; DATA_LOSS when its length runs past them.
Status FrameChunkRecord(const std::string& path, uint64_t chunk_offset,
                        std::span<const uint8_t> records, uint64_t offset, ChunkRecord* record) {
  ByteReader reader(records);
  reader.Skip(offset);
  record->opcode = reader.U8();
  const uint64_t length = reader.U64();
  record->offset = offset;
  record->content = reader.Bytes(length);
  if (reader.failed()) {
    return Status::DataLoss(Describe(path, record->opcode, {chunk_offset, offset}) +
                            ": runs past the end of the chunk's " + std::to_string(records.size()) +
                            " bytes");
  }
  return Status::Ok();
}

// Visits the records of a chunk's decompressed `records` (Schema, Channel and Message; unknown
// opcodes are skipped, other records are not allowed in a chunk).
Status ForEachChunkRecord(const std::string& path, uint64_t chunk_offset,
                          std::span<const uint8_t> records,
                          const std::function<Status(const ChunkRecord&)>& visit) {
  ChunkRecord record;
  for (uint64_t offset = 0; offset < records.size();
       offset += kRecordHeaderSize + record.content.size()) {
    RECOG_RETURN_IF_ERROR(FrameChunkRecord(path, chunk_offset, records, offset, &record));
    const Opcode opcode = Opcode(record.opcode);
    if (record.opcode >= uint8_t(Opcode::kHeader) && record.opcode <= uint8_t(Opcode::kDataEnd) &&
        opcode != Opcode::kSchema && opcode != Opcode::kChannel && opcode != Opcode::kMessage) {
      return Status::DataLoss(Describe(path, record.opcode, {chunk_offset, offset}) +
                              ": not allowed inside a chunk");
    }
    RECOG_RETURN_IF_ERROR(visit(record));
  }
  return Status::Ok();
}

// A parsed record of a chunk, or an error naming it.
Status ParseChunkRecord(const std::string& path, uint64_t chunk_offset, const ChunkRecord& record,
                        std::optional<Record>* parsed) {
  return ParseRecord(
      record.opcode, record.content,
      [&] {
        return Describe(path, record.opcode, {chunk_offset, record.offset});
      },
      parsed);
}

bool MayHoldWantedChannel(const ChunkIndex& index,
                          const std::function<bool(uint16_t channel_id)>& wanted) {
  // Without message indexes the chunk index does not list its channels: any may be there.
  if (index.message_index_offsets.empty()) return true;
  return std::any_of(index.message_index_offsets.begin(), index.message_index_offsets.end(),
                     [&](const auto& entry) { return wanted(entry.first); });
}

}  // namespace

std::string OpcodeName(uint8_t opcode) {
  static constexpr const char* kNames[] = {
      "Header",     "Footer",       "Schema",        "Channel",       "Message",
      "Chunk",      "MessageIndex", "ChunkIndex",    "Attachment",    "AttachmentIndex",
      "Statistics", "Metadata",     "MetadataIndex", "SummaryOffset", "DataEnd"};
  if (opcode >= uint8_t(Opcode::kHeader) && opcode <= uint8_t(Opcode::kDataEnd)) {
    return kNames[opcode - 1];
  }
  char text[16];
  std::snprintf(text, sizeof(text), "record 0x%02x", opcode);
  return text;
}

McapReader::McapReader(std::string path, int fd, uint64_t file_size)
    : path_(std::move(path)), fd_(fd), file_size_(file_size) {}

McapReader::~McapReader() { ::close(fd_); }

StatusOr<std::unique_ptr<McapReader>> McapReader::Open(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    return Status::NotFound("MCAP file '" + path + "' cannot be opened: " + std::strerror(errno));
  }
  struct stat info {};
  if (::fstat(fd, &info) != 0 || !S_ISREG(info.st_mode)) {
    ::close(fd);
    return Status::InvalidArgument("MCAP file '" + path + "' is not a regular file");
  }
  std::unique_ptr<McapReader> reader(new McapReader(path, fd, uint64_t(info.st_size)));
  const uint64_t magic_size = kMagic.size();
  std::vector<uint8_t> bytes;
  RECOG_RETURN_IF_ERROR(reader->ReadAt(0, std::min(magic_size, reader->file_size_), &bytes));
  const std::string_view start(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  if (start != kMagic.substr(0, start.size()) || start.empty()) {
    return Status::InvalidArgument("file '" + path + "' is not MCAP: it does not start with " +
                                   "the MCAP magic");
  }
  if (start.size() < magic_size) {
    return Status::DataLoss("MCAP file '" + path + "' is cut short inside its magic");
  }
  if (reader->file_size_ < 2 * magic_size) {
    return Status::DataLoss("MCAP file '" + path +
                            "' is cut short: " + std::to_string(reader->file_size_) + " bytes");
  }
  RECOG_RETURN_IF_ERROR(reader->ReadAt(reader->file_size_ - magic_size, magic_size, &bytes));
  if (std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()) != kMagic) {
    return Status::DataLoss("MCAP file '" + path +
                            "' does not end with the MCAP magic: it is cut short or damaged");
  }
  return reader;
}

Status McapReader::ReadAt(uint64_t offset, uint64_t size, std::vector<uint8_t>* buffer) const {
  if (offset > file_size_ || size > file_size_ - offset) {
    return Status::DataLoss("MCAP file '" + path_ + "' is cut short: " + std::to_string(size) +
                            " bytes at byte " + std::to_string(offset) + " are past its end");
  }
  buffer->resize(size_t(size));
  size_t done = 0;
  while (done < size) {
    const ssize_t read =
        ::pread(fd_, buffer->data() + done, size_t(size) - done, off_t(offset + done));
    if (read < 0 && errno == EINTR) continue;
    if (read <= 0) {
      return Status::DataLoss("MCAP file '" + path_ + "' cannot be read at byte " +
                              std::to_string(offset + done) +
                              (read < 0 ? std::string(": ") + std::strerror(errno) : ""));
    }
    done += size_t(read);
  }
  return Status::Ok();
}

Status McapReader::ReadRecordAt(uint64_t offset, uint64_t end, uint8_t* opcode,
                                std::vector<uint8_t>* buffer) const {
  if (offset > end || end - offset < kRecordHeaderSize) {
    return Status::DataLoss("MCAP file '" + path_ + "' is cut short in the record at byte " +
                            std::to_string(offset));
  }
  RECOG_RETURN_IF_ERROR(ReadAt(offset, kRecordHeaderSize, buffer));
  *opcode = (*buffer)[0];
  const uint64_t length = LittleEndian64(buffer->data() + 1);
  const RecordPosition position{kNotInChunk, offset};
  if (length > end - offset - kRecordHeaderSize) {
    return Status::DataLoss(Describe(path_, *opcode, position) + ": its length " +
                            std::to_string(length) + " runs past byte " + std::to_string(end));
  }
  if (length > kMaxRecordBytes) {
    return Status::ResourceExhausted(Describe(path_, *opcode, position) + ": its length " +
                                     std::to_string(length) + " is above the limit of " +
                                     std::to_string(kMaxRecordBytes) + " bytes");
  }
  return ReadAt(offset + kRecordHeaderSize, length, buffer);
}

StatusOr<uint32_t> McapReader::Crc32OfRange(uint64_t begin, uint64_t end) const {
  std::vector<uint8_t> buffer;
  uint32_t crc = 0;
  for (uint64_t offset = begin; offset < end;) {
    const uint64_t size = std::min<uint64_t>(kCrcReadSize, end - offset);
    RECOG_RETURN_IF_ERROR(ReadAt(offset, size, &buffer));
    crc = Crc32(crc, buffer);
    offset += size;
  }
  return crc;
}

Status McapReader::CheckSummaryCrc(const Footer& footer, uint64_t footer_offset) const {
  if (footer.summary_crc == 0) return Status::Ok();
  const uint64_t start = footer.summary_start != 0 ? footer.summary_start : footer_offset;
  // From the summary's start through the footer's summary_offset_start field.
  const uint64_t end = footer_offset + kRecordHeaderSize + 16;
  if (start > footer_offset) {
    return Status::DataLoss(
        Describe(path_, uint8_t(Opcode::kFooter), {kNotInChunk, footer_offset}) +
        ": summary_start " + std::to_string(start) + " is after the footer");
  }
  RECOG_ASSIGN_OR_RETURN(const uint32_t crc, Crc32OfRange(start, end));
  if (crc != footer.summary_crc) {
    return Status::DataLoss(
        Describe(path_, uint8_t(Opcode::kFooter), {kNotInChunk, footer_offset}) +
        ": the summary's CRC is " + Hex(crc) + ", the footer says " + Hex(footer.summary_crc));
  }
  return Status::Ok();
}

StatusOr<std::span<const uint8_t>> McapReader::DecompressChunk(
    const Chunk& chunk, uint64_t chunk_offset, std::vector<uint8_t>* decompressed) const {
  const std::string where = Describe(path_, uint8_t(Opcode::kChunk), {kNotInChunk, chunk_offset});
  if (chunk.uncompressed_size > kMaxDecompressedBytes) {
    return Status::ResourceExhausted(
        where + ": its uncompressed size " + std::to_string(chunk.uncompressed_size) +
        " is above the limit of " + std::to_string(kMaxDecompressedBytes) + " bytes");
  }
  std::span<const uint8_t> records = chunk.records;
  if (!chunk.compression.empty()) {
    RECOG_RETURN_IF_ERROR(DecompressExactly(chunk.compression, chunk.records,
                                            chunk.uncompressed_size, decompressed, where));
    records = *decompressed;
  } else if (records.size() != chunk.uncompressed_size) {
    return Status::DataLoss(where + ": holds " + std::to_string(records.size()) +
                            " uncompressed bytes, not the " +
                            std::to_string(chunk.uncompressed_size) + " it declares");
  }
  if (chunk.uncompressed_crc != 0 && !crc_checked_chunks_.contains(chunk_offset)) {
    const uint32_t crc = Crc32(0, records);
    if (crc != chunk.uncompressed_crc) {
      return Status::DataLoss(where + ": its records' CRC is " + Hex(crc) + ", the chunk says " +
                              Hex(chunk.uncompressed_crc));
    }
    crc_checked_chunks_.insert(chunk_offset);
  }
  return records;
}

StatusOr<std::span<const uint8_t>> McapReader::LoadChunk(uint64_t chunk_offset,
                                                         std::vector<uint8_t>* record,
                                                         std::vector<uint8_t>* decompressed,
                                                         Chunk* chunk) const {
  uint8_t opcode = 0;
  RECOG_RETURN_IF_ERROR(ReadRecordAt(chunk_offset, file_size_ - kMagic.size(), &opcode, record));
  const RecordPosition position{kNotInChunk, chunk_offset};
  if (opcode != uint8_t(Opcode::kChunk)) {
    return Status::DataLoss(Describe(path_, opcode, position) + ": a chunk was expected there");
  }
  std::optional<Record> parsed;
  RECOG_RETURN_IF_ERROR(ParseRecord(
      opcode, *record, [&] { return Describe(path_, opcode, position); }, &parsed));
  *chunk = std::get<Chunk>(*parsed);
  return DecompressChunk(*chunk, chunk_offset, decompressed);
}

Status McapReader::ReadRecords(const RecordVisitor& visit) {
  const uint64_t end = file_size_ - kMagic.size();
  std::vector<uint8_t> content;
  std::vector<uint8_t> decompressed;
  std::optional<Record> record;
  uint32_t data_crc = Crc32(0, {reinterpret_cast<const uint8_t*>(kMagic.data()), kMagic.size()});
  bool data_ended = false;
  for (uint64_t offset = kMagic.size(); offset < end;
       offset += kRecordHeaderSize + content.size()) {
    uint8_t opcode = 0;
    RECOG_RETURN_IF_ERROR(ReadRecordAt(offset, end, &opcode, &content));
    const RecordPosition position{kNotInChunk, offset};
    const auto describe = [&] { return Describe(path_, opcode, position); };
    if (offset == kMagic.size() && opcode != uint8_t(Opcode::kHeader)) {
      return Status::DataLoss(describe() + ": the file does not start with a Header record");
    }
    RECOG_RETURN_IF_ERROR(ParseRecord(opcode, content, describe, &record));
    if (const auto* data_end = record ? std::get_if<DataEnd>(&*record) : nullptr) {
      if (!data_ended && data_end->data_section_crc != 0 &&
          data_end->data_section_crc != data_crc) {
        return Status::DataLoss(describe() + ": the data section's CRC is " + Hex(data_crc) +
                                ", the record says " + Hex(data_end->data_section_crc));
      }
      data_ended = true;
    }
    if (!data_ended) {
      uint8_t header[kRecordHeaderSize] = {opcode};
      for (int i = 0; i < 8; ++i) header[1 + i] = uint8_t(uint64_t(content.size()) >> (8 * i));
      data_crc = Crc32(Crc32(data_crc, header), content);
    }
    if (!record) continue;
    if (const auto* attachment = std::get_if<Attachment>(&*record); attachment && attachment->crc) {
      const size_t covered =
          size_t(attachment->data.data() + attachment->data.size() - content.data());
      const uint32_t crc = Crc32(0, std::span<const uint8_t>(content).first(covered));
      if (crc != attachment->crc) {
        return Status::DataLoss(describe() + ": its CRC is " + Hex(crc) + ", the record says " +
                                Hex(attachment->crc));
      }
    }
    RECOG_RETURN_IF_ERROR(visit(*record, position));
    if (const auto* chunk = std::get_if<Chunk>(&*record)) {
      RECOG_ASSIGN_OR_RETURN(const std::span<const uint8_t> records,
                             DecompressChunk(*chunk, offset, &decompressed));
      std::optional<Record> inner;
      RECOG_RETURN_IF_ERROR(
          ForEachChunkRecord(path_, offset, records, [&](const ChunkRecord& chunk_record) {
            RECOG_RETURN_IF_ERROR(ParseChunkRecord(path_, offset, chunk_record, &inner));
            return inner ? visit(*inner, {offset, chunk_record.offset}) : Status::Ok();
          }));
    }
    if (const auto* footer = std::get_if<Footer>(&*record)) {
      if (!data_ended) {
        return Status::DataLoss(describe() + ": no DataEnd record ends the data section");
      }
      if (offset + kRecordHeaderSize + content.size() != end) {
        return Status::DataLoss(describe() + ": records follow the footer");
      }
      return CheckSummaryCrc(*footer, offset);
    }
  }
  return Status::DataLoss("MCAP file '" + path_ + "' ends without a Footer record: it is cut " +
                          "short or damaged");
}

StatusOr<Summary> McapReader::ReadSummary() {
  const uint64_t end = file_size_ - kMagic.size();
  const uint64_t footer_size = kRecordHeaderSize + kFooterContentSize;
  if (end < kMagic.size() + footer_size) {
    return Status::DataLoss("MCAP file '" + path_ + "' is too short to hold a footer: " +
                            std::to_string(file_size_) + " bytes");
  }
  const uint64_t footer_offset = end - footer_size;
  const RecordPosition footer_position{kNotInChunk, footer_offset};
  std::vector<uint8_t> bytes;
  RECOG_RETURN_IF_ERROR(ReadAt(footer_offset, footer_size, &bytes));
  if (bytes[0] != uint8_t(Opcode::kFooter) ||
      LittleEndian64(bytes.data() + 1) != kFooterContentSize) {
    return Status::DataLoss("MCAP file '" + path_ + "' has no Footer record before its closing " +
                            "magic: it is damaged");
  }
  Summary summary;
  ByteReader footer_reader(std::span<const uint8_t>(bytes).subspan(kRecordHeaderSize));
  Parse(footer_reader, &summary.footer);
  const Footer& footer = summary.footer;
  RECOG_RETURN_IF_ERROR(CheckSummaryCrc(footer, footer_offset));
  if (footer.summary_start == 0) return summary;
  const std::string footer_name = Describe(path_, uint8_t(Opcode::kFooter), footer_position);
  if (footer.summary_start < kMagic.size() || footer.summary_start > footer_offset ||
      (footer.summary_offset_start != 0 && (footer.summary_offset_start < footer.summary_start ||
                                            footer.summary_offset_start > footer_offset))) {
    return Status::DataLoss(footer_name + ": summary_start " +
                            std::to_string(footer.summary_start) + " or summary_offset_start " +
                            std::to_string(footer.summary_offset_start) +
                            " is outside the file's records");
  }
  if (footer_offset - footer.summary_start > kMaxRecordBytes) {
    return Status::ResourceExhausted(footer_name + ": the summary section's " +
                                     std::to_string(footer_offset - footer.summary_start) +
                                     " bytes are above the limit of " +
                                     std::to_string(kMaxRecordBytes));
  }
  std::vector<uint8_t> section;
  RECOG_RETURN_IF_ERROR(
      ReadAt(footer.summary_start, footer_offset - footer.summary_start, &section));
  std::optional<Record> record;
  ChunkRecord framed;
  for (uint64_t offset = 0; offset < section.size();
       offset += kRecordHeaderSize + framed.content.size()) {
    const uint64_t file_offset = footer.summary_start + offset;
    ByteReader reader(section);
    reader.Skip(offset);
    framed.opcode = reader.U8();
    framed.content = reader.Bytes(reader.U64());
    const auto describe = [&] {
      return Describe(path_, framed.opcode, {kNotInChunk, file_offset});
    };
    if (reader.failed()) {
      return Status::DataLoss(describe() + ": runs past the summary section, into the footer");
    }
    RECOG_RETURN_IF_ERROR(ParseRecord(framed.opcode, framed.content, describe, &record));
    if (!record) continue;
    if (auto* schema = std::get_if<Schema>(&*record)) {
      summary.schemas[schema->id] = std::move(*schema);
    } else if (auto* channel = std::get_if<Channel>(&*record)) {
      summary.channels[channel->id] = std::move(*channel);
    } else if (auto* statistics = std::get_if<Statistics>(&*record)) {
      summary.statistics = std::move(*statistics);
    } else if (auto* chunk_index = std::get_if<ChunkIndex>(&*record)) {
      summary.chunk_indexes.push_back(std::move(*chunk_index));
    } else if (auto* attachment_index = std::get_if<AttachmentIndex>(&*record)) {
      summary.attachment_indexes.push_back(std::move(*attachment_index));
    } else if (auto* metadata_index = std::get_if<MetadataIndex>(&*record)) {
      summary.metadata_indexes.push_back(std::move(*metadata_index));
    } else if (auto* summary_offset = std::get_if<SummaryOffset>(&*record)) {
      summary.summary_offsets.push_back(*summary_offset);
    }
  }
  return summary;
}

Status McapReader::ReadMessagesByTime(const Summary& summary,
                                      const std::function<bool(uint16_t channel_id)>& wanted,
                                      const RecordVisitor& visit) {
  std::vector<const ChunkIndex*> chunks;
  for (const ChunkIndex& index : summary.chunk_indexes) {
    if (MayHoldWantedChannel(index, wanted)) chunks.push_back(&index);
  }
  std::stable_sort(chunks.begin(), chunks.end(), [](const ChunkIndex* a, const ChunkIndex* b) {
    return std::tie(a->message_start_time, a->chunk_start_offset) <
           std::tie(b->message_start_time, b->chunk_start_offset);
  });

  // The chunks read and not yet visited in full; a slot's buffers are reused once it is free.
  struct LoadedChunk {
    uint64_t offset = 0;
    std::vector<uint8_t> record;
    std::vector<uint8_t> decompressed;
    std::span<const uint8_t> records;
    size_t pending_messages = 0;
  };
  std::vector<LoadedChunk> slots;
  std::vector<size_t> free_slots;
  uint64_t held_bytes = 0;
  const auto release = [&](size_t slot) {
    held_bytes -= slots[slot].record.size() + slots[slot].decompressed.size();
    free_slots.push_back(slot);
  };

  // A message waiting to be visited: the queue gives the earliest log time, then file order.
  struct Pending {
    uint64_t log_time;
    uint64_t chunk_offset;
    uint64_t offset;
    size_t slot;
    bool operator>(const Pending& other) const {
      return std::tie(log_time, chunk_offset, offset) >
             std::tie(other.log_time, other.chunk_offset, other.offset);
    }
  };
  std::priority_queue<Pending, std::vector<Pending>, std::greater<Pending>> queue;

  const auto load = [&](const ChunkIndex& index) -> Status {
    if (free_slots.empty()) {
      free_slots.push_back(slots.size());
      slots.emplace_back();
    }
    const size_t slot = free_slots.back();
    free_slots.pop_back();
    LoadedChunk& loaded = slots[slot];
    loaded.offset = index.chunk_start_offset;
    loaded.pending_messages = 0;
    Chunk chunk;
    StatusOr<std::span<const uint8_t>> records =
        LoadChunk(loaded.offset, &loaded.record, &loaded.decompressed, &chunk);
    if (chunk.compression.empty()) loaded.decompressed.clear();
    held_bytes += loaded.record.size() + loaded.decompressed.size();
    if (!records.ok()) return records.status();
    if (held_bytes > kMaxHeldChunkBytes) {
      return Status::ResourceExhausted(
          Describe(path_, uint8_t(Opcode::kChunk), {kNotInChunk, loaded.offset}) +
          ": the chunks overlapping it in time hold more than " +
          std::to_string(kMaxHeldChunkBytes) + " bytes");
    }
    loaded.records = *records;
    std::optional<Record> parsed;
    RECOG_RETURN_IF_ERROR(ForEachChunkRecord(
        path_, loaded.offset, loaded.records, [&](const ChunkRecord& chunk_record) -> Status {
          const Opcode opcode = Opcode(chunk_record.opcode);
          if (opcode != Opcode::kSchema && opcode != Opcode::kChannel &&
              opcode != Opcode::kMessage) {
            return Status::Ok();
          }
          RECOG_RETURN_IF_ERROR(ParseChunkRecord(path_, loaded.offset, chunk_record, &parsed));
          const RecordPosition position{loaded.offset, chunk_record.offset};
          const auto* message = std::get_if<Message>(&*parsed);
          if (message == nullptr) return visit(*parsed, position);
          if (!wanted(message->channel_id)) return Status::Ok();
          if (message->log_time < index.message_start_time ||
              message->log_time > index.message_end_time) {
            return Status::DataLoss(Describe(path_, chunk_record.opcode, position) +
                                    ": its log time " + std::to_string(message->log_time) +
                                    " is outside its chunk index's range");
          }
          queue.push({message->log_time, loaded.offset, chunk_record.offset, slot});
          ++loaded.pending_messages;
          return Status::Ok();
        }));
    if (loaded.pending_messages == 0) release(slot);
    return Status::Ok();
  };

  size_t next_chunk = 0;
  std::optional<Record> parsed;
  for (;;) {
    // Read every chunk that may hold a message as early as the earliest one waiting.
    while (next_chunk < chunks.size() &&
           (queue.empty() || chunks[next_chunk]->message_start_time <= queue.top().log_time)) {
      RECOG_RETURN_IF_ERROR(load(*chunks[next_chunk++]));
    }
    if (queue.empty()) return Status::Ok();
    const Pending pending = queue.top();
    queue.pop();
    LoadedChunk& loaded = slots[pending.slot];
    ChunkRecord chunk_record;
    RECOG_RETURN_IF_ERROR(
        FrameChunkRecord(path_, loaded.offset, loaded.records, pending.offset, &chunk_record));
    RECOG_RETURN_IF_ERROR(ParseChunkRecord(path_, loaded.offset, chunk_record, &parsed));
    RECOG_RETURN_IF_ERROR(visit(*parsed, {pending.chunk_offset, pending.offset}));
    if (--loaded.pending_messages == 0) release(pending.slot);
  }
}

StatusOr<Message> McapReader::ReadMessageAt(const RecordPosition& position) {
  uint8_t opcode = 0;
  std::span<const uint8_t> content;
  if (position.chunk_offset == kNotInChunk) {
    RECOG_RETURN_IF_ERROR(
        ReadRecordAt(position.offset, file_size_ - kMagic.size(), &opcode, &message_record_));
    content = message_record_;
  } else {
    if (cached_chunk_offset_ != position.chunk_offset) {
      cached_chunk_offset_ = kNotInChunk;
      Chunk chunk;
      RECOG_ASSIGN_OR_RETURN(cached_chunk_records_,
                             LoadChunk(position.chunk_offset, &cached_chunk_record_,
                                       &cached_chunk_decompressed_, &chunk));
      cached_chunk_offset_ = position.chunk_offset;
    }
    ChunkRecord chunk_record;
    RECOG_RETURN_IF_ERROR(FrameChunkRecord(path_, position.chunk_offset, cached_chunk_records_,
                                           position.offset, &chunk_record));
    opcode = chunk_record.opcode;
    content = chunk_record.content;
  }
  if (opcode != uint8_t(Opcode::kMessage)) {
    return Status::InvalidArgument(Describe(path_, opcode, position) + ": not a Message record");
  }
  std::optional<Record> parsed;
  RECOG_RETURN_IF_ERROR(ParseRecord(
      opcode, content, [&] { return Describe(path_, opcode, position); }, &parsed));
  return std::get<Message>(*parsed);
}

}  // namespace recog::bag::mcap
