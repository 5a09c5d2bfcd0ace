// OpenMcapFile: a BagStore over one MCAP file as rosbag2 writes it (mcap.h reads it). A topic is
// a channel, its type the channel's schema name; the summary section gives the topics, counts
// and chunk indexes when it holds them all, and a streamed pass over the file finds them
// otherwise.
#include <algorithm>
#include <map>
#include <set>
#include <unordered_map>

#include "tools/bag/bag_store.h"
#include "tools/bag/mcap.h"

namespace recog::bag {
namespace {

// A message id is the message's file offset, or for a message in a chunk this bit, the chunk's
// number (in the order the store first met the chunks) in bits 32 to 62 and the message's offset
// in the chunk's decompressed records (below kMaxDecompressedBytes) in bits 0 to 31.
constexpr uint64_t kInChunkIdBit = uint64_t(1) << 63;
constexpr uint64_t kMaxChunkNumber = (uint64_t(1) << 31) - 1;

StatusOr<Serialization> SerializationOf(const std::string& path, const mcap::Channel& channel) {
  if (channel.message_encoding == "cdr") return Serialization::kCdr;
  if (channel.message_encoding == "ros1") return Serialization::kRos1;
  return Status::InvalidArgument("MCAP file '" + path + "': topic '" + channel.topic +
                                 "' has message encoding '" + channel.message_encoding +
                                 "', neither ROS 1's ('ros1') nor CDR ('cdr')");
}

// What a store knows of the file before reading a topic's messages.
struct Contents {
  std::map<uint16_t, mcap::Channel> channels;
  std::map<uint16_t, std::string> schema_names;
  std::map<uint16_t, uint64_t> channel_messages;
  uint64_t messages = 0;
  uint64_t start_time = 0;
  uint64_t end_time = 0;
  std::vector<std::string> compressions;  // as the chunks name them, each once
  bool indexed = false;                   // every message is in a chunk the summary indexes
};

void AddCompression(const std::string& compression, Contents* contents) {
  if (std::find(contents->compressions.begin(), contents->compressions.end(), compression) ==
      contents->compressions.end()) {
    contents->compressions.push_back(compression);
  }
}

// The contents from the summary section alone, when it holds them all: statistics, every
// channel with its schema, and an index of every chunk.
std::optional<Contents> ContentsFromSummary(const mcap::Summary& summary) {
  if (!summary.statistics) return std::nullopt;
  const mcap::Statistics& statistics = *summary.statistics;
  if (summary.channels.size() != statistics.channel_count ||
      summary.chunk_indexes.size() != statistics.chunk_count) {
    return std::nullopt;
  }
  Contents contents;
  for (const auto& [id, channel] : summary.channels) {
    if (channel.schema_id != 0) {
      const auto schema = summary.schemas.find(channel.schema_id);
      if (schema == summary.schemas.end()) return std::nullopt;
      contents.schema_names[channel.schema_id] = schema->second.name;
    }
    contents.channels[id] = channel;
  }
  for (const auto& [id, count] : statistics.channel_message_counts) {
    if (!contents.channels.contains(id)) return std::nullopt;
    contents.channel_messages[id] = count;
  }
  contents.messages = statistics.message_count;
  contents.start_time = statistics.message_start_time;
  contents.end_time = statistics.message_end_time;
  for (const mcap::ChunkIndex& index : summary.chunk_indexes) {
    AddCompression(index.compression, &contents);
  }
  contents.indexed = statistics.chunk_count > 0;
  return contents;
}

// The contents from a streamed pass over the whole file.
StatusOr<Contents> ContentsFromRecords(mcap::McapReader& reader, const mcap::Summary& summary) {
  Contents contents;
  uint64_t chunks = 0;
  bool messages_outside_chunks = false;
  RECOG_RETURN_IF_ERROR(
      reader.ReadRecords([&](const mcap::Record& record, const mcap::RecordPosition& position) {
        if (const auto* schema = std::get_if<mcap::Schema>(&record)) {
          contents.schema_names[schema->id] = schema->name;
        } else if (const auto* channel = std::get_if<mcap::Channel>(&record)) {
          contents.channels[channel->id] = *channel;
        } else if (const auto* chunk = std::get_if<mcap::Chunk>(&record)) {
          ++chunks;
          AddCompression(chunk->compression, &contents);
        } else if (const auto* message = std::get_if<mcap::Message>(&record)) {
          if (!contents.channels.contains(message->channel_id)) {
            return Status::DataLoss("MCAP file '" + reader.path() + "': the message at byte " +
                                    std::to_string(position.offset) + " is on channel " +
                                    std::to_string(message->channel_id) +
                                    ", which no Channel record before it defines");
          }
          messages_outside_chunks |= position.chunk_offset == mcap::kNotInChunk;
          ++contents.channel_messages[message->channel_id];
          contents.start_time = contents.messages == 0
                                    ? message->log_time
                                    : std::min(contents.start_time, message->log_time);
          contents.end_time = std::max(contents.end_time, message->log_time);
          ++contents.messages;
        }
        return Status::Ok();
      }));
  contents.indexed =
      chunks > 0 && summary.chunk_indexes.size() == chunks && !messages_outside_chunks;
  return contents;
}

class McapStore : public BagStore {
 public:
  McapStore(std::unique_ptr<mcap::McapReader> reader, mcap::Summary index)
      : reader_(std::move(reader)), index_(std::move(index)) {}

  Status Load() {
    std::optional<Contents> from_summary = ContentsFromSummary(index_);
    Contents contents;
    if (from_summary) {
      contents = std::move(*from_summary);
    } else {
      RECOG_ASSIGN_OR_RETURN(contents, ContentsFromRecords(*reader_, index_));
    }
    indexed_ = contents.indexed;
    summary_.path = reader_->path();
    summary_.storage = "mcap";
    summary_.files = {reader_->path()};
    for (const std::string& compression : contents.compressions) {
      if (compression != "" && compression != "zstd" && compression != "lz4") {
        return Status::InvalidArgument("MCAP file '" + reader_->path() +
                                       "' has chunks of the unknown compression '" + compression +
                                       "'");
      }
      if (!summary_.compression.empty()) summary_.compression += ", ";
      summary_.compression += compression.empty() ? "none" : compression;
    }
    if (summary_.compression.empty()) summary_.compression = "none";
    summary_.messages = contents.messages;
    if (contents.messages > 0) {
      summary_.start_ns = int64_t(contents.start_time);
      summary_.end_ns = int64_t(contents.end_time);
    }
    std::map<std::string, TopicSummary> topics;
    for (const auto& [id, channel] : contents.channels) {
      RECOG_ASSIGN_OR_RETURN(const Serialization serialization,
                             SerializationOf(reader_->path(), channel));
      topic_channels_[channel.topic].insert(id);
      auto [topic, added] = topics.try_emplace(channel.topic);
      if (added) {
        topic->second.name = channel.topic;
        const auto schema = contents.schema_names.find(channel.schema_id);
        if (schema != contents.schema_names.end()) topic->second.type = schema->second;
        topic->second.serialization = serialization;
      }
      const auto count = contents.channel_messages.find(id);
      if (count != contents.channel_messages.end()) topic->second.messages += count->second;
    }
    for (auto& [name, topic] : topics) summary_.topics.push_back(std::move(topic));
    return Status::Ok();
  }

  const BagSummary& summary() const override { return summary_; }

  Status ForEachMessage(const std::string& topic,
                        const std::function<Status(const StoredMessage&)>& visit) override {
    RECOG_ASSIGN_OR_RETURN(const std::set<uint16_t>* channels, ChannelsOf(topic));
    const auto wanted = [channels](uint16_t id) { return channels->contains(id); };
    if (indexed_) {
      return reader_->ReadMessagesByTime(
          index_, wanted,
          [&](const mcap::Record& record, const mcap::RecordPosition& position) -> Status {
            const auto* message = std::get_if<mcap::Message>(&record);
            if (message == nullptr) return Status::Ok();
            RECOG_ASSIGN_OR_RETURN(const uint64_t id, IdOf(position));
            return visit({id, int64_t(message->log_time), message->data});
          });
    }
    // Without chunk indexes: the topic's messages found in a streamed pass, then read again in
    // log time order (the last chunk read is kept, so chunks in order decompress once).
    std::vector<std::pair<uint64_t, uint64_t>> found;  // (log time, id)
    RECOG_RETURN_IF_ERROR(reader_->ReadRecords(
        [&](const mcap::Record& record, const mcap::RecordPosition& position) -> Status {
          const auto* message = std::get_if<mcap::Message>(&record);
          if (message == nullptr || !wanted(message->channel_id)) return Status::Ok();
          RECOG_ASSIGN_OR_RETURN(const uint64_t id, IdOf(position));
          found.emplace_back(message->log_time, id);
          return Status::Ok();
        }));
    std::stable_sort(found.begin(), found.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    for (const auto& [log_time, id] : found) {
      RECOG_ASSIGN_OR_RETURN(const mcap::RecordPosition position, PositionOf(id));
      RECOG_ASSIGN_OR_RETURN(const mcap::Message message, reader_->ReadMessageAt(position));
      RECOG_RETURN_IF_ERROR(visit({id, int64_t(log_time), message.data}));
    }
    return Status::Ok();
  }

  Status ReadMessage(const std::string& topic, uint64_t id, std::vector<uint8_t>* data) override {
    RECOG_ASSIGN_OR_RETURN(const std::set<uint16_t>* channels, ChannelsOf(topic));
    RECOG_ASSIGN_OR_RETURN(const mcap::RecordPosition position, PositionOf(id));
    RECOG_ASSIGN_OR_RETURN(const mcap::Message message, reader_->ReadMessageAt(position));
    if (!channels->contains(message.channel_id)) {
      return Status::InvalidArgument("MCAP file '" + reader_->path() + "': message id " +
                                     std::to_string(id) + " is not a message of topic '" + topic +
                                     "'");
    }
    data->assign(message.data.begin(), message.data.end());
    return Status::Ok();
  }

 private:
  StatusOr<const std::set<uint16_t>*> ChannelsOf(const std::string& topic) const {
    const auto channels = topic_channels_.find(topic);
    if (channels == topic_channels_.end()) {
      return Status::NotFound("MCAP file '" + reader_->path() + "' has no topic '" + topic + "'");
    }
    return &channels->second;
  }

  StatusOr<uint64_t> IdOf(const mcap::RecordPosition& position) {
    if (position.chunk_offset == mcap::kNotInChunk) return position.offset;
    auto [entry, added] =
        chunk_numbers_.try_emplace(position.chunk_offset, uint64_t(chunk_offsets_.size()));
    if (added) {
      if (entry->second > kMaxChunkNumber) {
        chunk_numbers_.erase(entry);
        return Status::ResourceExhausted("MCAP file '" + reader_->path() + "' has more than " +
                                         std::to_string(kMaxChunkNumber) + " chunks");
      }
      chunk_offsets_.push_back(position.chunk_offset);
    }
    return kInChunkIdBit | (entry->second << 32) | position.offset;
  }

  StatusOr<mcap::RecordPosition> PositionOf(uint64_t id) const {
    const bool in_chunk = (id & kInChunkIdBit) != 0;
    const uint64_t chunk_number = (id & ~kInChunkIdBit) >> 32;
    if (in_chunk ? chunk_number >= chunk_offsets_.size() : id >= reader_->file_size()) {
      return Status::InvalidArgument("MCAP file '" + reader_->path() + "': message id " +
                                     std::to_string(id) + " was not given by this store");
    }
    if (!in_chunk) return mcap::RecordPosition{mcap::kNotInChunk, id};
    return mcap::RecordPosition{chunk_offsets_[chunk_number], id & 0xFFFFFFFFu};
  }

  std::unique_ptr<mcap::McapReader> reader_;
  mcap::Summary index_;
  bool indexed_ = false;
  BagSummary summary_;
  std::map<std::string, std::set<uint16_t>> topic_channels_;
  std::vector<uint64_t> chunk_offsets_;                   // by chunk number
  std::unordered_map<uint64_t, uint64_t> chunk_numbers_;  // by chunk offset
};

}  // namespace

StatusOr<std::unique_ptr<BagStore>> OpenMcapFile(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<mcap::McapReader> reader, mcap::McapReader::Open(path));
  RECOG_ASSIGN_OR_RETURN(mcap::Summary index, reader->ReadSummary());
  auto store = std::make_unique<McapStore>(std::move(reader), std::move(index));
  RECOG_RETURN_IF_ERROR(store->Load());
  return std::unique_ptr<BagStore>(std::move(store));
}

}  // namespace recog::bag
