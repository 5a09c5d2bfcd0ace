// The MCAP format's own conformance suite (shared data, bags/mcap-conformance): every file's
// streamed reading, printed in the suite's JSON form, is the records its .json lists; for every
// file with chunk indexes the indexed reading gives the same schemas, channels and messages.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/testing/test_data.h"
#include "tools/bag/mcap.h"

namespace recog::bag::mcap {
namespace {

using nlohmann::json;

json Number(uint64_t value) { return std::to_string(value); }

json Bytes(std::span<const uint8_t> bytes) {
  json array = json::array();
  for (const uint8_t byte : bytes) array.push_back(std::to_string(byte));
  return array;
}

json StringMap(const std::map<std::string, std::string>& map) {
  json object = json::object();
  for (const auto& [key, value] : map) object[key] = value;
  return object;
}

json IdMap(const std::map<uint16_t, uint64_t>& map) {
  json object = json::object();
  for (const auto& [key, value] : map) object[std::to_string(key)] = Number(value);
  return object;
}

// The suite's form of a record: {"type": name, "fields": [[name, value], ...]} sorted by name.
json ToJson(const Record& record) {
  std::map<std::string, json> fields;
  std::string type;
  std::visit(
      [&](const auto& r) {
        using T = std::decay_t<decltype(r)>;
        if constexpr (std::is_same_v<T, Header>) {
          type = "Header";
          fields = {{"profile", r.profile}, {"library", r.library}};
        } else if constexpr (std::is_same_v<T, Footer>) {
          type = "Footer";
          fields = {{"summary_start", Number(r.summary_start)},
                    {"summary_offset_start", Number(r.summary_offset_start)},
                    {"summary_crc", Number(r.summary_crc)}};
        } else if constexpr (std::is_same_v<T, Schema>) {
          type = "Schema";
          fields = {{"id", Number(r.id)},
                    {"name", r.name},
                    {"encoding", r.encoding},
                    {"data", Bytes(r.data)}};
        } else if constexpr (std::is_same_v<T, Channel>) {
          type = "Channel";
          fields = {{"id", Number(r.id)},
                    {"schema_id", Number(r.schema_id)},
                    {"topic", r.topic},
                    {"message_encoding", r.message_encoding},
                    {"metadata", StringMap(r.metadata)}};
        } else if constexpr (std::is_same_v<T, Message>) {
          type = "Message";
          fields = {{"channel_id", Number(r.channel_id)},
                    {"sequence", Number(r.sequence)},
                    {"log_time", Number(r.log_time)},
                    {"publish_time", Number(r.publish_time)},
                    {"data", Bytes(r.data)}};
        } else if constexpr (std::is_same_v<T, Chunk>) {
          type = "Chunk";
        } else if constexpr (std::is_same_v<T, MessageIndex>) {
          type = "MessageIndex";
        } else if constexpr (std::is_same_v<T, ChunkIndex>) {
          type = "ChunkIndex";
          fields = {{"message_start_time", Number(r.message_start_time)},
                    {"message_end_time", Number(r.message_end_time)},
                    {"chunk_start_offset", Number(r.chunk_start_offset)},
                    {"chunk_length", Number(r.chunk_length)},
                    {"message_index_offsets", IdMap(r.message_index_offsets)},
                    {"message_index_length", Number(r.message_index_length)},
                    {"compression", r.compression},
                    {"compressed_size", Number(r.compressed_size)},
                    {"uncompressed_size", Number(r.uncompressed_size)}};
        } else if constexpr (std::is_same_v<T, Attachment>) {
          type = "Attachment";
          fields = {{"log_time", Number(r.log_time)},
                    {"create_time", Number(r.create_time)},
                    {"name", r.name},
                    {"media_type", r.media_type},
                    {"data", Bytes(r.data)}};
        } else if constexpr (std::is_same_v<T, AttachmentIndex>) {
          type = "AttachmentIndex";
          fields = {{"offset", Number(r.offset)},       {"length", Number(r.length)},
                    {"log_time", Number(r.log_time)},   {"create_time", Number(r.create_time)},
                    {"data_size", Number(r.data_size)}, {"name", r.name},
                    {"media_type", r.media_type}};
        } else if constexpr (std::is_same_v<T, Statistics>) {
          type = "Statistics";
          fields = {{"message_count", Number(r.message_count)},
                    {"schema_count", Number(r.schema_count)},
                    {"channel_count", Number(r.channel_count)},
                    {"attachment_count", Number(r.attachment_count)},
                    {"metadata_count", Number(r.metadata_count)},
                    {"chunk_count", Number(r.chunk_count)},
                    {"message_start_time", Number(r.message_start_time)},
                    {"message_end_time", Number(r.message_end_time)},
                    {"channel_message_counts", IdMap(r.channel_message_counts)}};
        } else if constexpr (std::is_same_v<T, Metadata>) {
          type = "Metadata";
          fields = {{"name", r.name}, {"metadata", StringMap(r.metadata)}};
        } else if constexpr (std::is_same_v<T, MetadataIndex>) {
          type = "MetadataIndex";
          fields = {{"offset", Number(r.offset)}, {"length", Number(r.length)}, {"name", r.name}};
        } else if constexpr (std::is_same_v<T, SummaryOffset>) {
          type = "SummaryOffset";
          fields = {{"group_opcode", Number(r.group_opcode)},
                    {"group_start", Number(r.group_start)},
                    {"group_length", Number(r.group_length)}};
        } else {
          static_assert(std::is_same_v<T, DataEnd>);
          type = "DataEnd";
          fields = {{"data_section_crc", Number(r.data_section_crc)}};
        }
      },
      record);
  json sorted = json::array();
  for (auto& [name, value] : fields) sorted.push_back(json::array({name, std::move(value)}));
  return {{"type", type}, {"fields", std::move(sorted)}};
}

// The schemas and channels (by id) and the messages (in log time order, ties in file order) of
// one reading.
struct Contents {
  std::map<uint16_t, json> schemas;
  std::map<uint16_t, json> channels;
  std::vector<json> messages;
  bool operator==(const Contents&) const = default;
};

// Adds a Schema, Channel or Message record to `contents`.
void Add(const Record& record, Contents* contents) {
  if (const auto* schema = std::get_if<Schema>(&record)) {
    contents->schemas[schema->id] = ToJson(record);
  } else if (const auto* channel = std::get_if<Channel>(&record)) {
    contents->channels[channel->id] = ToJson(record);
  } else if (std::holds_alternative<Message>(record)) {
    contents->messages.push_back(ToJson(record));
  }
}

std::string LogTime(const json& message) {
  for (const json& field : message["fields"]) {
    if (field[0] == "log_time") return field[1];
  }
  return "";
}

std::vector<std::filesystem::path> ConformanceFiles() {
  std::vector<std::filesystem::path> files;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(
           recog::testing::SharedData("bags/mcap-conformance"))) {
    if (entry.path().extension() == ".mcap") files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

TEST(McapConformanceTest, EveryFileReadsAsTheSuiteSays) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/mcap-conformance");
  const std::vector<std::filesystem::path> files = ConformanceFiles();
  int streamed_matches = 0;
  int indexed_files = 0;
  int indexed_matches = 0;
  for (const std::filesystem::path& file : files) {
    SCOPED_TRACE(file.string());
    std::ifstream json_file(std::filesystem::path(file).replace_extension(".json"));
    ASSERT_TRUE(json_file) << "no .json beside it";
    const json expected = json::parse(json_file)["records"];

    StatusOr<std::unique_ptr<McapReader>> reader = McapReader::Open(file.string());
    ASSERT_TRUE(reader.ok()) << reader.status().ToString();
    json streamed = json::array();
    Contents streamed_contents;
    const Status read = (*reader)->ReadRecords([&](const Record& record, const RecordPosition&) {
      if (!std::holds_alternative<Chunk>(record) && !std::holds_alternative<MessageIndex>(record)) {
        streamed.push_back(ToJson(record));
      }
      Add(record, &streamed_contents);
      return Status::Ok();
    });
    EXPECT_TRUE(read.ok()) << read.ToString();
    EXPECT_EQ(streamed, expected);
    if (read.ok() && streamed == expected) ++streamed_matches;

    StatusOr<Summary> summary = (*reader)->ReadSummary();
    ASSERT_TRUE(summary.ok()) << summary.status().ToString();
    if (summary->chunk_indexes.empty()) continue;
    ++indexed_files;
    Contents indexed_contents;
    for (const auto& [id, schema] : summary->schemas) Add(schema, &indexed_contents);
    for (const auto& [id, channel] : summary->channels) Add(channel, &indexed_contents);
    std::vector<std::vector<uint8_t>> indexed_data;
    std::vector<RecordPosition> positions;
    const Status indexed = (*reader)->ReadMessagesByTime(
        *summary, [](uint16_t) { return true; },
        [&](const Record& record, const RecordPosition& position) {
          Add(record, &indexed_contents);
          if (const auto* message = std::get_if<Message>(&record)) {
            indexed_data.emplace_back(message->data.begin(), message->data.end());
            positions.push_back(position);
          }
          return Status::Ok();
        });
    EXPECT_TRUE(indexed.ok()) << indexed.ToString();
    std::stable_sort(streamed_contents.messages.begin(), streamed_contents.messages.end(),
                     [](const json& a, const json& b) {
                       return std::stoull(LogTime(a)) < std::stoull(LogTime(b));
                     });
    EXPECT_EQ(indexed_contents, streamed_contents);
    // Each message read again from the position the indexed reading gave it.
    bool reread_matches = true;
    for (size_t i = 0; i < positions.size(); ++i) {
      StatusOr<Message> message = (*reader)->ReadMessageAt(positions[i]);
      reread_matches &= message.ok() && std::equal(message->data.begin(), message->data.end(),
                                                   indexed_data[i].begin(), indexed_data[i].end());
    }
    EXPECT_TRUE(reread_matches);
    if (indexed.ok() && indexed_contents == streamed_contents && reread_matches) ++indexed_matches;
  }
  std::cout << "streamed reading as the suite's .json: " << streamed_matches << "/" << files.size()
            << " files; indexed reading as the streamed one: " << indexed_matches << "/"
            << indexed_files << " files with chunk indexes\n";
  EXPECT_EQ(files.size(), 416u);
  EXPECT_EQ(streamed_matches, int(files.size()));
  EXPECT_EQ(indexed_matches, indexed_files);
  EXPECT_GT(indexed_files, 0);
}

}  // namespace
}  // namespace recog::bag::mcap
