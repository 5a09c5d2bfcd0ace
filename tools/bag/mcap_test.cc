// mcap.h and OpenMcapFile on small MCAP files written by the test-only writer of records
// (tests/testing/ros2_bag_writer.h): chunked and not, zstd and lz4 chunks, with and without a
// summary; the streamed and the indexed reading; damaged files (cut at every byte, bytes changed,
// wrong CRCs and sizes, lengths past the end, unknown compressions, bombs), which must give
// errors and never crash.
#include "tools/bag/mcap.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <set>

#include "tests/testing/ros2_bag_writer.h"
#include "tools/bag/bag_store.h"
#include "tools/bag/decompress.h"

namespace recog::bag::mcap {
namespace {

using testing::BagMessage;
using testing::BagTopic;
using testing::McapFields;
using McapOptions = testing::McapOptions;

// Two channels, as rosbag2 writes them: 1 "/camera/image" (sensor_msgs/msg/Image), 2 "/chatter"
// (std_msgs/msg/String), both of message encoding `encoding`.
std::vector<BagTopic> Channels(const std::string& encoding) {
  return {{1, "/camera/image", "sensor_msgs/msg/Image", encoding},
          {2, "/chatter", "std_msgs/msg/String", encoding}};
}

// A small MCAP file holding `messages` on those channels, laid out as `options` says.
std::string WriteMcap(const std::vector<BagMessage>& messages, const McapOptions& options,
                      const std::string& encoding = "cdr") {
  return testing::WriteMcapFile(Channels(encoding), messages, options);
}

// The size of the Header record's content as WriteMcap writes it: profile and library.
size_t HeaderFieldsSize() {
  const McapOptions options;
  return 4 + options.profile.size() + 4 + options.library.size();
}

// Messages on both channels, log times out of file order, with a tie.
std::vector<BagMessage> SampleMessages() {
  return {{1, 100, "image-a"}, {2, 105, "hello"},   {1, 90, "image-b"}, {2, 120, "world"},
          {1, 130, "image-c"}, {1, 125, "image-d"}, {2, 125, "tie"},    {1, 140, "image-e"},
          {2, 200, "late"},    {2, 210, "later"},   {2, 220, "latest"}};
}

class McapTest : public ::testing::Test {
 protected:
  void SetUp() override {
    folder_ =
        std::filesystem::path(::testing::TempDir()) / ("mcap_test_" + std::to_string(::getpid()));
    std::filesystem::create_directories(folder_);
  }
  void TearDown() override { std::filesystem::remove_all(folder_); }

  std::string WriteFile(const std::string& bytes, const std::string& name = "test.mcap") {
    const std::string path = (folder_ / name).string();
    std::ofstream(path, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
    return path;
  }

 public:
  // Every record of the streamed reading: its type, and for messages "type:data@log_time".
  static StatusOr<std::vector<std::string>> Stream(const std::string& path) {
    RECOG_ASSIGN_OR_RETURN(std::unique_ptr<McapReader> reader, McapReader::Open(path));
    std::vector<std::string> seen;
    RECOG_RETURN_IF_ERROR(reader->ReadRecords([&](const Record& record, const RecordPosition&) {
      std::string text = std::visit(
          [](const auto& r) {
            using T = std::decay_t<decltype(r)>;
            if constexpr (std::is_same_v<T, Message>) {
              return "Message:" + std::string(r.data.begin(), r.data.end()) + "@" +
                     std::to_string(r.log_time);
            } else if constexpr (std::is_same_v<T, Chunk>) {
              return "Chunk:" + r.compression;
            } else {
              return std::string();
            }
          },
          record);
      if (text.empty()) text = OpcodeName(OpcodeOf(record));
      seen.push_back(text);
      return Status::Ok();
    }));
    return seen;
  }

 protected:
  std::filesystem::path folder_;
};

// The message records of a streamed reading, and the other records' names.
std::vector<std::string> Messages(const std::vector<std::string>& records) {
  std::vector<std::string> messages;
  for (const std::string& record : records) {
    if (record.starts_with("Message:")) messages.push_back(record);
  }
  return messages;
}
std::vector<std::string> Others(const std::vector<std::string>& records) {
  std::vector<std::string> others;
  for (const std::string& record : records) {
    if (!record.starts_with("Message:")) others.push_back(record);
  }
  return others;
}
std::vector<std::string> InFileOrder(const std::vector<BagMessage>& messages) {
  std::vector<std::string> texts;
  for (const BagMessage& m : messages) {
    texts.push_back("Message:" + m.data + "@" + std::to_string(m.log_time));
  }
  return texts;
}

TEST_F(McapTest, StreamsEveryRecordInFileOrder) {
  const StatusOr<std::vector<std::string>> records =
      Stream(WriteFile(WriteMcap(SampleMessages(), {})));
  ASSERT_TRUE(records.ok()) << records.status().ToString();
  EXPECT_EQ(Messages(*records), InFileOrder(SampleMessages()));
  EXPECT_EQ(
      Others(*records),
      (std::vector<std::string>{"Header", "Schema", "Schema", "Channel", "Channel", "DataEnd",
                                "Schema", "Schema", "Channel", "Channel", "Statistics", "Footer"}));
}

TEST_F(McapTest, StreamsEachChunksRecordsInItsPlace) {
  for (const std::string compression : {"", "zstd", "lz4"}) {
    SCOPED_TRACE(compression);
    const std::string chunk = "Chunk:" + compression;
    const McapOptions options = McapOptions().Chunked(4, compression).WithAttachment("fx: 500");
    const StatusOr<std::vector<std::string>> records =
        Stream(WriteFile(WriteMcap(SampleMessages(), options)));
    ASSERT_TRUE(records.ok()) << records.status().ToString();
    EXPECT_EQ(Messages(*records), InFileOrder(SampleMessages()));
    EXPECT_EQ(
        Others(*records),
        (std::vector<std::string>{
            "Header",  "Attachment",   chunk,          "Schema",     "Schema",       "Channel",
            "Channel", "MessageIndex", "MessageIndex", chunk,        "MessageIndex", "MessageIndex",
            chunk,     "MessageIndex", "DataEnd",      "Schema",     "Schema",       "Channel",
            "Channel", "Statistics",   "ChunkIndex",   "ChunkIndex", "ChunkIndex",   "Footer"}));
  }
}

TEST_F(McapTest, SkipsUnknownRecordsAndBytesAfterKnownFields) {
  const std::string plain =
      WriteMcap(SampleMessages(), McapOptions().WithoutSummary().WithoutCrcs());
  std::string padded = plain;
  // After the header (magic, then opcode, length and fields): an unknown record.
  const size_t after_header = kMagic.size() + 9 + HeaderFieldsSize();
  padded.insert(after_header, McapFields().U8(0x80).U64(3).Raw("abc").bytes());
  // The header with 5 bytes more than its fields.
  padded.insert(after_header, "xxxxx");
  padded[kMagic.size() + 1] = char(HeaderFieldsSize() + 5);
  const StatusOr<std::vector<std::string>> expected = Stream(WriteFile(plain, "plain.mcap"));
  const StatusOr<std::vector<std::string>> records = Stream(WriteFile(padded));
  ASSERT_TRUE(expected.ok()) << expected.status().ToString();
  ASSERT_TRUE(records.ok()) << records.status().ToString();
  EXPECT_EQ(*records, *expected);
}

TEST_F(McapTest, IndexedReadingMergesChunksByLogTime) {
  for (const std::string compression : {"", "zstd", "lz4"}) {
    SCOPED_TRACE(compression);
    StatusOr<std::unique_ptr<McapReader>> reader = McapReader::Open(
        WriteFile(WriteMcap(SampleMessages(), McapOptions().Chunked(3, compression))));
    ASSERT_TRUE(reader.ok()) << reader.status().ToString();
    StatusOr<Summary> summary = (*reader)->ReadSummary();
    ASSERT_TRUE(summary.ok()) << summary.status().ToString();
    EXPECT_EQ(summary->chunk_indexes.size(), 4u);
    EXPECT_EQ(summary->channels.size(), 2u);
    ASSERT_TRUE(summary->statistics.has_value());
    EXPECT_EQ(summary->statistics->message_count, 11u);
    for (const auto& [wanted_channels, expected] :
         std::vector<std::pair<std::set<uint16_t>, std::vector<std::string>>>{
             {{1, 2},
              {"image-b", "image-a", "hello", "world", "image-d", "tie", "image-c", "image-e",
               "late", "later", "latest"}},
             {{1}, {"image-b", "image-a", "image-d", "image-c", "image-e"}},
             {{2}, {"hello", "world", "tie", "late", "later", "latest"}}}) {
      std::vector<std::string> seen;
      std::vector<RecordPosition> positions;
      int definitions = 0;
      const Status status = (*reader)->ReadMessagesByTime(
          *summary, [&](uint16_t id) { return wanted_channels.contains(id); },
          [&](const Record& record, const RecordPosition& position) {
            if (const auto* message = std::get_if<Message>(&record)) {
              seen.emplace_back(message->data.begin(), message->data.end());
              positions.push_back(position);
            } else {
              ++definitions;
            }
            return Status::Ok();
          });
      ASSERT_TRUE(status.ok()) << status.ToString();
      EXPECT_EQ(seen, expected);
      EXPECT_EQ(definitions, 4);  // the first chunk's, read for every channel
      for (size_t i = 0; i < positions.size(); ++i) {
        const StatusOr<Message> message = (*reader)->ReadMessageAt(positions[i]);
        ASSERT_TRUE(message.ok()) << message.status().ToString();
        EXPECT_EQ(std::string(message->data.begin(), message->data.end()), seen[i]);
      }
    }
  }
}

// The last chunk holds only /chatter (channel 2): reading the images does not read it, so damage
// there is seen by /chatter only.
TEST_F(McapTest, IndexedReadingReadsOnlyTheWantedChannelsChunks) {
  std::string bytes = WriteMcap(SampleMessages(), McapOptions().Chunked(3));
  StatusOr<std::unique_ptr<McapReader>> intact = McapReader::Open(WriteFile(bytes, "intact.mcap"));
  ASSERT_TRUE(intact.ok());
  const StatusOr<Summary> summary = (*intact)->ReadSummary();
  ASSERT_TRUE(summary.ok());
  const ChunkIndex& last = summary->chunk_indexes.back();
  ASSERT_EQ(last.message_index_offsets.size(), 1u);
  bytes[last.chunk_start_offset + last.chunk_length - 2] ^= 0x01;  // a message's data
  StatusOr<std::unique_ptr<McapReader>> reader = McapReader::Open(WriteFile(bytes));
  ASSERT_TRUE(reader.ok());
  const auto count = [&](uint16_t channel) {
    return (*reader)->ReadMessagesByTime(
        *summary, [&](uint16_t id) { return id == channel; },
        [](const Record&, const RecordPosition&) { return Status::Ok(); });
  };
  EXPECT_TRUE(count(1).ok()) << count(1).ToString();
  const Status damaged = count(2);
  EXPECT_EQ(damaged.code(), StatusCode::kDataLoss) << damaged.ToString();
  EXPECT_NE(damaged.message().find("CRC"), std::string::npos) << damaged.message();
}

struct StoreCase {
  std::string name;
  McapOptions options;
  std::string compression;
};

TEST_F(McapTest, StoreGivesTopicsAndMessagesInLogTimeOrder) {
  const std::vector<StoreCase> cases = {
      {"unchunked", {}, "none"},
      {"unchunked_without_summary", McapOptions().WithoutSummary(), "none"},
      {"zstd_chunks", McapOptions().Chunked(3, "zstd"), "zstd"},
      {"lz4_chunks_without_summary", McapOptions().Chunked(2, "lz4").WithoutSummary(), "lz4"},
      {"uncompressed_chunks", McapOptions().Chunked(4), "none"},
  };
  for (const StoreCase& test : cases) {
    SCOPED_TRACE(test.name);
    StatusOr<std::unique_ptr<BagStore>> store =
        OpenMcapFile(WriteFile(WriteMcap(SampleMessages(), test.options), test.name + ".mcap"));
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    const BagSummary& summary = (*store)->summary();
    EXPECT_EQ(summary.storage, "mcap");
    EXPECT_EQ(summary.compression, test.compression);
    EXPECT_EQ(summary.messages, 11u);
    EXPECT_EQ(summary.start_ns, 90);
    EXPECT_EQ(summary.end_ns, 220);
    ASSERT_EQ(summary.topics.size(), 2u);
    EXPECT_EQ(summary.topics[0].name, "/camera/image");
    EXPECT_EQ(summary.topics[0].type, "sensor_msgs/msg/Image");
    EXPECT_EQ(summary.topics[0].serialization, Serialization::kCdr);
    EXPECT_EQ(summary.topics[0].messages, 5u);
    EXPECT_EQ(summary.topics[1].name, "/chatter");
    EXPECT_EQ(summary.topics[1].messages, 6u);

    std::vector<std::string> images;
    std::vector<int64_t> times;
    std::vector<uint64_t> ids;
    ASSERT_TRUE((*store)
                    ->ForEachMessage("/camera/image",
                                     [&](const StoredMessage& message) {
                                       images.emplace_back(message.data.begin(),
                                                           message.data.end());
                                       times.push_back(message.log_time_ns);
                                       ids.push_back(message.id);
                                       return Status::Ok();
                                     })
                    .ok());
    EXPECT_EQ(images,
              (std::vector<std::string>{"image-b", "image-a", "image-d", "image-c", "image-e"}));
    EXPECT_EQ(times, (std::vector<int64_t>{90, 100, 125, 130, 140}));
    std::vector<uint8_t> data = {1, 2, 3};
    for (size_t i = ids.size(); i-- > 0;) {  // backwards: chunks read again out of order
      const Status status = (*store)->ReadMessage("/camera/image", ids[i], &data);
      ASSERT_TRUE(status.ok()) << status.ToString();
      EXPECT_EQ(std::string(data.begin(), data.end()), images[i]);
    }
    // An id of another topic, a topic the bag does not have, and a visit's own error.
    EXPECT_EQ((*store)->ReadMessage("/chatter", ids[0], &data).code(),
              StatusCode::kInvalidArgument);
    EXPECT_EQ((*store)->ReadMessage("/camera/image", uint64_t(1) << 62, &data).code(),
              StatusCode::kInvalidArgument);
    EXPECT_EQ((*store)
                  ->ForEachMessage("/missing", [](const StoredMessage&) { return Status::Ok(); })
                  .code(),
              StatusCode::kNotFound);
    int visited = 0;
    const Status stopped = (*store)->ForEachMessage("/chatter", [&](const StoredMessage&) {
      return ++visited == 2 ? Status::Unavailable("enough") : Status::Ok();
    });
    EXPECT_EQ(stopped.code(), StatusCode::kUnavailable);
    EXPECT_EQ(visited, 2);
  }
}

TEST_F(McapTest, StoreChecksTheMessageEncodingAtOpen) {
  for (const McapOptions& options : {McapOptions(), McapOptions().WithoutSummary()}) {
    StatusOr<std::unique_ptr<BagStore>> ros1 =
        OpenMcapFile(WriteFile(WriteMcap(SampleMessages(), options, "ros1"), "ros1.mcap"));
    ASSERT_TRUE(ros1.ok()) << ros1.status().ToString();
    EXPECT_EQ((*ros1)->summary().topics[0].serialization, Serialization::kRos1);
    const StatusOr<std::unique_ptr<BagStore>> wrong =
        OpenMcapFile(WriteFile(WriteMcap(SampleMessages(), options, "wrong_format")));
    EXPECT_EQ(wrong.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(wrong.status().message().find("'/camera/image'"), std::string::npos);
    EXPECT_NE(wrong.status().message().find("'wrong_format'"), std::string::npos);
  }
}

TEST_F(McapTest, StoreOfAnEmptyBag) {
  for (const size_t chunk_messages : {size_t(0), size_t(3)}) {
    StatusOr<std::unique_ptr<BagStore>> store =
        OpenMcapFile(WriteFile(WriteMcap({}, McapOptions().Chunked(chunk_messages))));
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    EXPECT_EQ((*store)->summary().messages, 0u);
    EXPECT_EQ((*store)->summary().start_ns, 0);
    EXPECT_EQ((*store)->summary().topics.size(), 2u);
    EXPECT_EQ((*store)->summary().topics[0].messages, 0u);
  }
}

TEST_F(McapTest, MissingFileIsNotFoundAndOtherFilesAreNotMcap) {
  EXPECT_EQ(McapReader::Open((folder_ / "missing.mcap").string()).status().code(),
            StatusCode::kNotFound);
  EXPECT_EQ(OpenMcapFile(WriteFile("#ROSBAG V2.0\nnot mcap at all")).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(OpenMcapFile(WriteFile("")).status().code(), StatusCode::kInvalidArgument);
}

// Reads `path` as a store: every topic's messages, each read again by its id.
Status ReadAsStore(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<BagStore> store, OpenMcapFile(path));
  for (const TopicSummary& topic : store->summary().topics) {
    RECOG_RETURN_IF_ERROR(store->ForEachMessage(topic.name, [&](const StoredMessage& message) {
      std::vector<uint8_t> data;
      return store->ReadMessage(topic.name, message.id, &data);
    }));
  }
  return Status::Ok();
}

// A file cut anywhere has no footer and closing magic: every cut is an error (an empty file is
// not MCAP; any other cut is DATA_LOSS), for every reading.
TEST_F(McapTest, EveryCutIsAnError) {
  for (const McapOptions& options : {McapOptions(), McapOptions().Chunked(4, "zstd"),
                                     McapOptions().Chunked(4, "lz4").WithoutSummary()}) {
    const std::string bytes = WriteMcap(SampleMessages(), options);
    const std::string whole = WriteFile(bytes, "whole.mcap");
    ASSERT_TRUE(Stream(whole).ok());
    ASSERT_TRUE(ReadAsStore(whole).ok());
    for (size_t size = 0; size < bytes.size(); ++size) {
      const std::string path = WriteFile(bytes.substr(0, size));
      const Status streamed = Stream(path).status();
      EXPECT_EQ(streamed.code(), size == 0 ? StatusCode::kInvalidArgument : StatusCode::kDataLoss)
          << "cut at " << size << ": " << streamed.ToString();
      EXPECT_EQ(OpenMcapFile(path).status().code(), streamed.code()) << "cut at " << size;
    }
  }
}

// Any byte changed: an error or a reading, never a crash. With CRCs, the streamed reading finds
// every change.
TEST_F(McapTest, ChangedBytesNeverCrash) {
  for (const McapOptions& options :
       {McapOptions(), McapOptions().Chunked(3, "zstd"), McapOptions().Chunked(3, "lz4"),
        McapOptions().Chunked(3).WithoutSummary().WithoutCrcs()}) {
    const std::string bytes = WriteMcap(SampleMessages(), options);
    for (size_t position = 0; position < bytes.size(); ++position) {
      // A low bit or all bits, alternately.
      const uint8_t change = position % 2 == 0 ? 0xFF : 0x01;
      std::string changed = bytes;
      changed[position] = char(changed[position] ^ change);
      const std::string path = WriteFile(changed);
      const Status streamed = Stream(path).status();
      static_cast<void>(ReadAsStore(path));  // any outcome but a crash
      EXPECT_TRUE(!streamed.ok() || !options.crcs)
          << "byte " << position << " of " << bytes.size() << " (chunks: \"" << options.compression
          << "\") ^ " << int(change) << " went unseen";
    }
  }
}

TEST_F(McapTest, WrongCrcsAreDataLoss) {
  // The data section's CRC: a message's data changed, in a file without chunks.
  std::string bytes = WriteMcap(SampleMessages(), {});
  bytes[bytes.find("image-c")] = 'X';
  Status status = Stream(WriteFile(bytes)).status();
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_NE(status.message().find("DataEnd record"), std::string::npos) << status.message();
  // A chunk's CRC.
  bytes = WriteMcap(SampleMessages(), McapOptions().Chunked(4));
  bytes[bytes.find("image-c")] = 'X';
  status = Stream(WriteFile(bytes)).status();
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_NE(status.message().find("Chunk record at byte"), std::string::npos) << status.message();
  // The summary's CRC, which the store checks at open.
  bytes = WriteMcap(SampleMessages(), McapOptions().Chunked(4));
  bytes[bytes.rfind("/chatter")] = 'X';
  EXPECT_EQ(Stream(WriteFile(bytes)).status().code(), StatusCode::kDataLoss);
  status = OpenMcapFile(WriteFile(bytes)).status();
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_NE(status.message().find("Footer record"), std::string::npos) << status.message();
  // An attachment's CRC.
  bytes = WriteMcap(SampleMessages(), McapOptions().WithoutCrcs().WithAttachment("fx: 500"));
  ASSERT_TRUE(Stream(WriteFile(bytes)).ok());
  bytes[bytes.find("fx: 500")] = 'X';
  status = Stream(WriteFile(bytes)).status();
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_NE(status.message().find("Attachment record"), std::string::npos) << status.message();
}

TEST_F(McapTest, ChunksOfAnotherSizeThanDeclaredAreDataLoss) {
  const std::string records_size_probe = WriteMcap(SampleMessages(), McapOptions().Chunked(20));
  StatusOr<std::unique_ptr<McapReader>> reader =
      McapReader::Open(WriteFile(records_size_probe, "probe.mcap"));
  ASSERT_TRUE(reader.ok());
  const uint64_t size = (*reader)->ReadSummary()->chunk_indexes[0].uncompressed_size;
  for (const std::string compression : {"", "zstd", "lz4"}) {
    for (const uint64_t declared : {size - 1, size + 1}) {
      const std::string path = WriteFile(
          WriteMcap(SampleMessages(),
                    McapOptions().Chunked(20, compression).DeclaringUncompressedSize(declared)));
      const Status status = Stream(path).status();
      EXPECT_EQ(status.code(), StatusCode::kDataLoss) << compression << " " << declared;
      EXPECT_NE(status.message().find("Chunk record at byte"), std::string::npos);
    }
  }
}

TEST_F(McapTest, LengthsPastTheEndAreDataLoss) {
  for (const size_t chunk_messages : {size_t(0), size_t(4)}) {
    std::string bytes = WriteMcap(SampleMessages(), McapOptions().Chunked(chunk_messages));
    // The first record after the header: its length made larger than the file.
    const size_t record = kMagic.size() + 9 + HeaderFieldsSize();
    for (const uint64_t length : {uint64_t(bytes.size()), ~uint64_t(0), uint64_t(1) << 40}) {
      std::string changed = bytes;
      changed.replace(record + 1, 8, McapFields().U64(length).bytes());
      const Status status = Stream(WriteFile(changed)).status();
      EXPECT_EQ(status.code(), StatusCode::kDataLoss) << length << ": " << status.ToString();
      EXPECT_NE(status.message().find("runs past"), std::string::npos) << status.message();
    }
  }
}

TEST_F(McapTest, UnknownCompressionIsInvalidArgument) {
  const std::string path =
      WriteFile(WriteMcap(SampleMessages(), McapOptions().Chunked(4, "brotli")));
  for (const Status& status : {Stream(path).status(), OpenMcapFile(path).status()}) {
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << status.ToString();
    EXPECT_NE(status.message().find("'brotli'"), std::string::npos) << status.message();
  }
}

// Chunks declaring far more than their few compressed bytes can hold are refused before their
// buffer is allocated; above the reader's limit they are RESOURCE_EXHAUSTED.
TEST_F(McapTest, BombsAreRefused) {
  for (const std::string compression : {"zstd", "lz4"}) {
    for (const auto& [declared, code] : std::vector<std::pair<uint64_t, StatusCode>>{
             {kMaxDecompressedBytes, StatusCode::kDataLoss},
             {kMaxDecompressedBytes + 1, StatusCode::kResourceExhausted},
             {~uint64_t(0), StatusCode::kResourceExhausted}}) {
      const std::string path = WriteFile(
          WriteMcap(SampleMessages(),
                    McapOptions().Chunked(20, compression).DeclaringUncompressedSize(declared)));
      EXPECT_EQ(Stream(path).status().code(), code) << compression << " " << declared;
      StatusOr<std::unique_ptr<BagStore>> store = OpenMcapFile(path);
      ASSERT_TRUE(store.ok()) << store.status().ToString();  // the summary is intact
      EXPECT_EQ((*store)
                    ->ForEachMessage("/chatter", [](const StoredMessage&) { return Status::Ok(); })
                    .code(),
                code);
    }
  }
}

}  // namespace
}  // namespace recog::bag::mcap
