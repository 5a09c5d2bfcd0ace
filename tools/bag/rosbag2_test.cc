// rosbag2 folders and sqlite3 files (sqlite3_store.cc, rosbag2_folder.cc): every bag of the
// shared data's bags/rosbag2 against what it says of itself (its metadata.yaml, read here with
// yaml-cpp, or its .db3 tables, counted here with SQL), its db3/mcap twin, and damaged copies.

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "tests/testing/test_data.h"
#include "tools/bag/bag_store.h"
#include "tools/bag/decompress.h"

namespace recog::bag {
namespace {

namespace fs = std::filesystem;

struct TopicCount {
  std::string type;
  uint64_t messages = 0;
  bool operator==(const TopicCount&) const = default;
};
using TopicCounts = std::map<std::string, TopicCount>;

std::string Rosbag2(const std::string& name) { return testing::SharedData("bags/rosbag2/" + name); }

TopicCounts CountsOf(const BagSummary& summary) {
  TopicCounts counts;
  for (const TopicSummary& topic : summary.topics) {
    counts[topic.name] = {.type = topic.type, .messages = topic.messages};
  }
  return counts;
}

// topics_with_message_count of a metadata.yaml, and its message_count.
TopicCounts MetadataCounts(const std::string& folder, uint64_t* total) {
  const YAML::Node info = YAML::LoadFile(folder + "/metadata.yaml")["rosbag2_bagfile_information"];
  *total = info["message_count"].as<uint64_t>();
  TopicCounts counts;
  for (const YAML::Node& entry : info["topics_with_message_count"]) {
    const YAML::Node topic =
        entry["topic_metadata"] ? entry["topic_metadata"] : entry["topic_and_type"];
    counts[topic["name"].as<std::string>()] = {.type = topic["type"].as<std::string>(),
                                               .messages = entry["message_count"].as<uint64_t>()};
  }
  return counts;
}

// Runs `sql` on the .db3 at `path` (opened read-only and immutable unless `writable`), the
// columns of each row as text.
std::vector<std::vector<std::string>> Query(const std::string& path, const std::string& sql,
                                            bool writable = false) {
  sqlite3* db = nullptr;
  const std::string name = writable ? path : "file:" + path + "?immutable=1";
  EXPECT_EQ(sqlite3_open_v2(
                name.c_str(), &db,
                writable ? SQLITE_OPEN_READWRITE : SQLITE_OPEN_READONLY | SQLITE_OPEN_URI, nullptr),
            SQLITE_OK)
      << path;
  std::vector<std::vector<std::string>> rows;
  sqlite3_stmt* statement = nullptr;
  EXPECT_EQ(sqlite3_prepare_v2(db, sql.c_str(), -1, &statement, nullptr), SQLITE_OK)
      << sqlite3_errmsg(db);
  while (statement != nullptr && sqlite3_step(statement) == SQLITE_ROW) {
    std::vector<std::string>& row = rows.emplace_back();
    for (int column = 0; column < sqlite3_column_count(statement); ++column) {
      const auto* text = reinterpret_cast<const char*>(sqlite3_column_text(statement, column));
      row.push_back(text == nullptr ? "" : text);
    }
  }
  sqlite3_finalize(statement);
  sqlite3_close(db);
  return rows;
}

// The topics and message counts of .db3 files, summed, from their own tables.
TopicCounts Db3Counts(const std::vector<std::string>& files) {
  TopicCounts counts;
  for (const std::string& file : files) {
    for (const auto& row : Query(file,
                                 "SELECT name, type, (SELECT COUNT(*) FROM messages "
                                 "WHERE topic_id = topics.id) FROM topics")) {
      counts[row[0]].type = row[1];
      counts[row[0]].messages += std::stoull(row[2]);
    }
  }
  return counts;
}

std::vector<std::string> FilesIn(const std::string& folder, const std::string& extension) {
  std::vector<std::string> files;
  for (const fs::directory_entry& entry : fs::directory_iterator(folder)) {
    if (entry.path().string().ends_with(extension)) files.push_back(entry.path().string());
  }
  std::sort(files.begin(), files.end());
  return files;
}

// Every message of every topic visited: in log-time order, each readable again by its id with
// the same bytes. The count per topic.
std::map<std::string, uint64_t> VisitAll(BagStore& store) {
  std::map<std::string, uint64_t> visited;
  std::vector<uint8_t> again;
  for (const TopicSummary& topic : store.summary().topics) {
    int64_t last_time = INT64_MIN;
    uint64_t& count = visited[topic.name];
    const Status status = store.ForEachMessage(topic.name, [&](const StoredMessage& message) {
      EXPECT_GE(message.log_time_ns, last_time) << topic.name << " message " << message.id;
      last_time = message.log_time_ns;
      ++count;
      const std::vector<uint8_t> bytes(message.data.begin(), message.data.end());
      const Status read = store.ReadMessage(topic.name, message.id, &again);
      EXPECT_TRUE(read.ok()) << read.ToString();
      EXPECT_EQ(again, bytes) << topic.name << " message " << message.id;
      return Status::Ok();
    });
    EXPECT_TRUE(status.ok()) << status.ToString();
  }
  return visited;
}

std::map<std::string, uint64_t> MessagesPerTopic(const TopicCounts& counts) {
  std::map<std::string, uint64_t> messages;
  for (const auto& [name, count] : counts) messages[name] = count.messages;
  return messages;
}

std::unique_ptr<BagStore> OpenOrFail(StatusOr<std::unique_ptr<BagStore>> opened) {
  EXPECT_TRUE(opened.ok()) << opened.status().ToString();
  return opened.ok() ? std::move(opened).value() : nullptr;
}

// ---------------------------------------------------------------------------------------------
// Every bag under bags/rosbag2: each name is in exactly one of these lists, so a bag added to the
// shared data fails ListsEveryBag until it is given its check.

// Folders with a metadata.yaml whose topics and counts the store must give.
const std::vector<std::string> kFoldersWithMetadata = {
    "db3_bag_with_topics_and_service_events",
    "db3_cdr_test",
    "db3_convert_a",
    "db3_convert_b",
    "db3_empty_bag",
    "db3_talker",
    "db3_test_bag_for_seek",
    "db3_wbag",
    "mcap_bag_with_topics_and_service_events",
    "mcap_cdr_test",
    "mcap_convert_a",
    "mcap_convert_b",
    "mcap_talker",
    "mcap_test_bag_for_seek",
    "mcap_wbag",
    "old_db3_v1_2018_cdr_test",
    "old_db3_v1_2018_test",
    "old_db3_v4_2021_cdr_test",
    "old_db3_v4_test_msgs_string",
    "old_db3_zstd_FILE_compressed_bag",
};
// Folders whose metadata.yaml gives a serialization format that is not cdr.
const std::vector<std::string> kRefusedFolders = {"db3_wrong_rmw_test", "mcap_wrong_rmw_test"};
// Folders without metadata.yaml, and lone files: checked by the tests named after them.
const std::vector<std::string> kOthers = {
    "db3_reindex_test_bags_multiple_files",
    "mcap_reindex_test_bags_multiple_files",
    "old_db3_zstd_FILE_compression_nometa",
    "old_db3_zstd_MESSAGE_compression_nometa",
    "db3_cpp_topics_and_services.db3",
    "mcap_cpp_only_services.mcap",
    "mcap_cpp_only_topics.mcap",
    "mcap_cpp_topics_and_services.mcap",
};

TEST(Rosbag2Bags, ListsEveryBag) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2");
  std::set<std::string> listed;
  for (const auto* list : {&kFoldersWithMetadata, &kRefusedFolders, &kOthers}) {
    for (const std::string& name : *list) EXPECT_TRUE(listed.insert(name).second) << name;
  }
  std::set<std::string> present;
  for (const fs::directory_entry& entry : fs::directory_iterator(Rosbag2(""))) {
    present.insert(entry.path().filename().string());
  }
  EXPECT_EQ(listed, present);
}

class FolderWithMetadata : public ::testing::TestWithParam<std::string> {};

TEST_P(FolderWithMetadata, GivesTheTopicsAndCountsOfItsMetadata) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/" + GetParam());
  const std::string folder = Rosbag2(GetParam());
  uint64_t total = 0;
  const TopicCounts expected = MetadataCounts(folder, &total);
  const std::unique_ptr<BagStore> store = OpenOrFail(OpenRosbag2Folder(folder));
  ASSERT_NE(store, nullptr);
  const BagSummary& summary = store->summary();
  EXPECT_EQ(summary.path, folder);
  EXPECT_EQ(summary.storage, GetParam().starts_with("mcap") ? "mcap" : "sqlite3");
  EXPECT_EQ(summary.messages, total);
  const TopicCounts actual = CountsOf(summary);
  for (const auto& [name, count] : expected) {
    ASSERT_TRUE(actual.contains(name)) << name;
    EXPECT_EQ(actual.at(name).messages, count.messages) << name;
    EXPECT_EQ(actual.at(name).type, count.type) << name;
  }
  // Topics the files have and metadata.yaml leaves out (2018's /clock) hold no message.
  for (const auto& [name, count] : actual) {
    if (!expected.contains(name)) {
      EXPECT_EQ(count.messages, 0u) << name;
    }
  }
  for (const TopicSummary& topic : summary.topics) {
    EXPECT_EQ(topic.serialization, Serialization::kCdr) << topic.name;
  }
  EXPECT_EQ(VisitAll(*store), MessagesPerTopic(actual));
  if (total > 0) {
    EXPECT_LE(summary.start_ns, summary.end_ns);
  } else {
    EXPECT_EQ(summary.start_ns, 0);
    EXPECT_EQ(summary.end_ns, 0);
  }
  std::cout << GetParam() << ": " << summary.storage << ", " << summary.files.size()
            << " file(s), compression " << summary.compression << ", " << summary.topics.size()
            << " topics, " << summary.messages << " messages\n";
}

INSTANTIATE_TEST_SUITE_P(Rosbag2Bags, FolderWithMetadata, ::testing::ValuesIn(kFoldersWithMetadata),
                         [](const auto& info) { return info.param; });

class RefusedFolder : public ::testing::TestWithParam<std::string> {};

TEST_P(RefusedFolder, NamesTheWrongSerializationFormat) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/" + GetParam());
  const auto opened = OpenRosbag2Folder(Rosbag2(GetParam()));
  ASSERT_FALSE(opened.ok());
  EXPECT_EQ(opened.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(opened.status().message().find("wrong_format"), std::string::npos);
  const std::string message = opened.status().message();
  EXPECT_TRUE(message.find("topic '/test_topic'") != std::string::npos ||
              message.find("topic '/array_topic'") != std::string::npos)
      << message;
  EXPECT_NE(opened.status().message().find(GetParam()), std::string::npos);
  std::cout << GetParam() << ": " << opened.status().ToString() << "\n";
}

INSTANTIATE_TEST_SUITE_P(Rosbag2Bags, RefusedFolder, ::testing::ValuesIn(kRefusedFolders),
                         [](const auto& info) { return info.param; });

// The same recordings in both storages.
class Twins : public ::testing::TestWithParam<std::string> {};

TEST_P(Twins, GiveTheSameTopicsAndCounts) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_" + GetParam());
  const auto db3 = OpenOrFail(OpenRosbag2Folder(Rosbag2("db3_" + GetParam())));
  const auto mcap = OpenOrFail(OpenRosbag2Folder(Rosbag2("mcap_" + GetParam())));
  ASSERT_NE(db3, nullptr);
  ASSERT_NE(mcap, nullptr);
  EXPECT_EQ(MessagesPerTopic(CountsOf(db3->summary())),
            MessagesPerTopic(CountsOf(mcap->summary())));
  EXPECT_EQ(db3->summary().messages, mcap->summary().messages);
  EXPECT_EQ(db3->summary().files.size(), mcap->summary().files.size());
}

INSTANTIATE_TEST_SUITE_P(Rosbag2Bags, Twins,
                         ::testing::Values("bag_with_topics_and_service_events", "cdr_test",
                                           "convert_a", "convert_b", "talker", "test_bag_for_seek",
                                           "wbag", "reindex_test_bags_multiple_files"));

TEST(Rosbag2Bags, EmptyBagListsItsTopicsWithoutMessages) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_empty_bag");
  const auto store = OpenOrFail(OpenRosbag2Folder(Rosbag2("db3_empty_bag")));
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(CountsOf(store->summary()),
            (TopicCounts{{"/parameter_events", {"rcl_interfaces/msg/ParameterEvent", 0}},
                         {"/rosout", {"rcl_interfaces/msg/Log", 0}}}));
  int visits = 0;
  EXPECT_TRUE(store
                  ->ForEachMessage("/rosout",
                                   [&](const StoredMessage&) {
                                     ++visits;
                                     return Status::Ok();
                                   })
                  .ok());
  EXPECT_EQ(visits, 0);
}

// A topic's messages, as (log time, bytes), in the order a store visits them.
using Visit = std::vector<std::pair<int64_t, std::vector<uint8_t>>>;
Visit VisitTopic(BagStore& store, const std::string& topic) {
  Visit visit;
  const Status status = store.ForEachMessage(topic, [&](const StoredMessage& message) {
    visit.emplace_back(message.log_time_ns,
                       std::vector<uint8_t>(message.data.begin(), message.data.end()));
    return Status::Ok();
  });
  EXPECT_TRUE(status.ok()) << status.ToString();
  return visit;
}

TEST(Rosbag2Bags, SplitBagGivesItsFilesInOrder) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_wbag");
  for (const std::string name : {"db3_wbag", "mcap_wbag"}) {
    SCOPED_TRACE(name);
    const auto store = OpenOrFail(OpenRosbag2Folder(Rosbag2(name)));
    ASSERT_NE(store, nullptr);
    const bool db3 = name.starts_with("db3");
    std::vector<std::unique_ptr<BagStore>> files;
    std::vector<std::string> expected_files;
    for (int i = 0; i < 5; ++i) {
      expected_files.push_back(Rosbag2(name) + "/wbag_" + std::to_string(i) +
                               (db3 ? ".db3" : ".mcap"));
      files.push_back(OpenOrFail(db3 ? OpenSqlite3File(expected_files.back())
                                     : OpenMcapFile(expected_files.back())));
      ASSERT_NE(files.back(), nullptr);
    }
    EXPECT_EQ(store->summary().files, expected_files);
    // A topic's messages are its files' messages, file after file, in time order.
    uint64_t total = 0;
    for (const TopicSummary& topic : store->summary().topics) {
      Visit expected;
      for (const auto& file : files) {
        for (auto& message : VisitTopic(*file, topic.name)) expected.push_back(std::move(message));
      }
      const Visit visit = VisitTopic(*store, topic.name);
      EXPECT_EQ(visit, expected) << topic.name;
      EXPECT_TRUE(std::is_sorted(visit.begin(), visit.end(), [](const auto& a, const auto& b) {
        return a.first < b.first;
      })) << topic.name;
      total += visit.size();
    }
    EXPECT_EQ(total, 6074u);
    EXPECT_EQ(store->summary().messages, 6074u);
    EXPECT_EQ(store->summary().start_ns, 1000);
    EXPECT_EQ(store->summary().end_ns, 2998);
  }
}

TEST(Rosbag2Bags, Db3WithoutMetadataIsReadFromItsFiles) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_reindex_test_bags_multiple_files");
  const std::string folder = Rosbag2("db3_reindex_test_bags_multiple_files");
  const auto store = OpenOrFail(OpenRosbag2Folder(folder));
  ASSERT_NE(store, nullptr);
  const std::vector<std::string> files = FilesIn(folder, ".db3");
  EXPECT_EQ(store->summary().files, files);
  EXPECT_EQ(CountsOf(store->summary()), Db3Counts(files));
  EXPECT_EQ(store->summary().messages, 3177u);
  EXPECT_EQ(store->summary().compression, "none");
  EXPECT_EQ(VisitAll(*store), MessagesPerTopic(Db3Counts(files)));
}

TEST(Rosbag2Bags, McapWithoutMetadataIsReadFromItsFiles) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/mcap_reindex_test_bags_multiple_files");
  const std::string folder = Rosbag2("mcap_reindex_test_bags_multiple_files");
  const auto store = OpenOrFail(OpenRosbag2Folder(folder));
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->summary().storage, "mcap");
  EXPECT_EQ(store->summary().files, FilesIn(folder, ".mcap"));
  // Each file's own store, summed: the folder adds nothing and loses nothing.
  std::map<std::string, uint64_t> per_file_sum;
  for (const std::string& file : FilesIn(folder, ".mcap")) {
    const auto single = OpenOrFail(OpenMcapFile(file));
    ASSERT_NE(single, nullptr);
    for (const TopicSummary& topic : single->summary().topics) {
      per_file_sum[topic.name] += topic.messages;
    }
  }
  EXPECT_EQ(MessagesPerTopic(CountsOf(store->summary())), per_file_sum);
  EXPECT_EQ(VisitAll(*store), per_file_sum);
}

// A test's own folder under the system's temporary folder, removed at the end.
class ScratchFolder : public ::testing::Test {
 protected:
  void SetUp() override {
    scratch_ = fs::temp_directory_path() /
               ("rosbag2_test_" + std::to_string(getpid()) + "_" +
                ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(scratch_);
    fs::create_directories(scratch_);
  }
  void TearDown() override { fs::remove_all(scratch_); }

  // A copy of the shared bag folder or file `name` in the scratch folder.
  std::string Copy(const std::string& name) {
    const fs::path copy = scratch_ / name;
    fs::copy(Rosbag2(name), copy, fs::copy_options::recursive);
    for (const fs::directory_entry& entry : fs::recursive_directory_iterator(copy)) {
      fs::permissions(entry.path(), fs::perms::owner_write, fs::perm_options::add);
    }
    fs::permissions(copy, fs::perms::owner_write, fs::perm_options::add);
    return copy.string();
  }

  fs::path scratch_;
};

// An environment variable set for a scope, and then restored.
class TemporaryEnvironment {
 public:
  TemporaryEnvironment(std::string name, const std::string& value) : name_(std::move(name)) {
    if (const char* previous = std::getenv(name_.c_str()); previous != nullptr) {
      previous_ = previous;
    }
    setenv(name_.c_str(), value.c_str(), 1);
  }
  ~TemporaryEnvironment() {
    if (previous_.has_value()) {
      setenv(name_.c_str(), previous_->c_str(), 1);
    } else {
      unsetenv(name_.c_str());
    }
  }
  TemporaryEnvironment(const TemporaryEnvironment&) = delete;
  TemporaryEnvironment& operator=(const TemporaryEnvironment&) = delete;

 private:
  std::string name_;
  std::optional<std::string> previous_;
};

using FileCompression = ScratchFolder;

TEST_F(FileCompression, FolderWithoutMetadataIsDecompressedToATemporaryFolder) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/old_db3_zstd_FILE_compression_nometa");
  const std::string folder = Rosbag2("old_db3_zstd_FILE_compression_nometa");
  // The expected counts: each file decompressed here and counted with SQL.
  std::vector<std::string> decompressed;
  for (const std::string& file : FilesIn(folder, ".db3.zstd")) {
    decompressed.push_back((scratch_ / fs::path(file).stem()).string());
    ASSERT_TRUE(DecompressZstdFile(file, decompressed.back(), uint64_t(1) << 30).ok());
  }
  ASSERT_EQ(decompressed.size(), 4u);
  const TopicCounts expected = Db3Counts(decompressed);

  // The store's temporary files go to TMPDIR: here, to see them made and removed.
  const fs::path temporary = scratch_ / "tmp";
  fs::create_directories(temporary);
  const TemporaryEnvironment tmpdir("TMPDIR", temporary.string());
  {
    const auto store = OpenOrFail(OpenRosbag2Folder(folder));
    ASSERT_NE(store, nullptr);
    EXPECT_EQ(store->summary().compression, "zstd (file)");
    EXPECT_EQ(store->summary().storage, "sqlite3");
    EXPECT_EQ(store->summary().files, FilesIn(folder, ".db3.zstd"));
    EXPECT_EQ(CountsOf(store->summary()), expected);
    EXPECT_EQ(VisitAll(*store), MessagesPerTopic(expected));
    EXPECT_FALSE(fs::is_empty(temporary));
  }
  EXPECT_TRUE(fs::is_empty(temporary));
}

TEST(Rosbag2Bags, FileCompressedBagWithMetadata) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/old_db3_zstd_FILE_compressed_bag");
  const auto store = OpenOrFail(OpenRosbag2Folder(Rosbag2("old_db3_zstd_FILE_compressed_bag")));
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->summary().compression, "zstd (file)");
  EXPECT_EQ(store->summary().messages, 0u);
}

TEST(Rosbag2Bags, MessageCompressedFilesWithoutMetadataAreDetected) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/old_db3_zstd_MESSAGE_compression_nometa");
  const std::string folder = Rosbag2("old_db3_zstd_MESSAGE_compression_nometa");
  const auto store = OpenOrFail(OpenRosbag2Folder(folder));
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->summary().compression, "zstd (message)");
  const std::vector<std::string> files = FilesIn(folder, ".db3");
  EXPECT_EQ(store->summary().files, files);
  EXPECT_EQ(CountsOf(store->summary()), Db3Counts(files));
  EXPECT_EQ(VisitAll(*store), MessagesPerTopic(Db3Counts(files)));
  // Decompressed: a CDR message starts with its encapsulation header, not with zstd's magic.
  int checked = 0;
  ASSERT_TRUE(store
                  ->ForEachMessage("/topic",
                                   [&](const StoredMessage& message) {
                                     EXPECT_GE(message.data.size(), 4u);
                                     EXPECT_EQ(message.data[0], 0);
                                     EXPECT_LE(message.data[1], 1);
                                     ++checked;
                                     return Status::Ok();
                                   })
                  .ok());
  EXPECT_EQ(checked, Db3Counts(files).at("/topic").messages);
  // A lone file detects it too.
  const auto single = OpenOrFail(OpenSqlite3File(files[0]));
  ASSERT_NE(single, nullptr);
  EXPECT_EQ(single->summary().compression, "zstd (message)");
}

TEST(Rosbag2Bags, LoneDb3IsReadWithItsTables) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_cpp_topics_and_services.db3");
  const std::string file = Rosbag2("db3_cpp_topics_and_services.db3");
  const auto store = OpenOrFail(OpenSqlite3File(file));
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->summary().storage, "sqlite3");
  EXPECT_EQ(store->summary().files, std::vector<std::string>{file});
  EXPECT_EQ(store->summary().compression, "none");
  EXPECT_EQ(CountsOf(store->summary()), Db3Counts({file}));
  EXPECT_EQ(store->summary().messages, 13u);
  EXPECT_EQ(VisitAll(*store), MessagesPerTopic(Db3Counts({file})));
  const auto twin = OpenOrFail(OpenMcapFile(Rosbag2("mcap_cpp_topics_and_services.mcap")));
  ASSERT_NE(twin, nullptr);
  EXPECT_EQ(MessagesPerTopic(CountsOf(twin->summary())),
            MessagesPerTopic(CountsOf(store->summary())));
}

TEST(Rosbag2Bags, LoneMcapFilesOpen) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/mcap_cpp_only_topics.mcap");
  for (const std::string name : {"mcap_cpp_only_services.mcap", "mcap_cpp_only_topics.mcap",
                                 "mcap_cpp_topics_and_services.mcap"}) {
    const auto store = OpenOrFail(OpenMcapFile(Rosbag2(name)));
    ASSERT_NE(store, nullptr);
    EXPECT_EQ(store->summary().storage, "mcap");
    EXPECT_GT(store->summary().messages, 0u) << name;
    EXPECT_EQ(VisitAll(*store), MessagesPerTopic(CountsOf(store->summary()))) << name;
    std::cout << name << ": " << store->summary().topics.size() << " topics, "
              << store->summary().messages << " messages\n";
  }
}

TEST(Rosbag2Bags, ReadingWritesNothingBesideTheFiles) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2");
  std::set<std::string> before;
  for (const auto& entry : fs::recursive_directory_iterator(Rosbag2(""))) {
    before.insert(entry.path().string());
  }
  for (const std::string& name : kFoldersWithMetadata) {
    if (name.starts_with("mcap")) continue;
    (void)OpenOrFail(OpenRosbag2Folder(Rosbag2(name)));
  }
  std::set<std::string> after;
  for (const auto& entry : fs::recursive_directory_iterator(Rosbag2(""))) {
    after.insert(entry.path().string());
  }
  EXPECT_EQ(before, after);
}

using Rosbag2Failures = ScratchFolder;

TEST_F(Rosbag2Failures, WalModeCopyGetsNoWalOrShmFile) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_talker");
  const std::string folder = Copy("db3_talker");
  // Bytes 18 and 19 of an SQLite header: 2 and 2 for a WAL-mode database.
  std::ifstream header(folder + "/talker.db3", std::ios::binary);
  header.seekg(18);
  ASSERT_EQ(header.get(), 2);
  ASSERT_EQ(header.get(), 2);
  {
    const auto store = OpenOrFail(OpenRosbag2Folder(folder));
    ASSERT_NE(store, nullptr);
    EXPECT_EQ(VisitAll(*store).at("/topic"), 10u);
  }
  EXPECT_FALSE(fs::exists(folder + "/talker.db3-wal"));
  EXPECT_FALSE(fs::exists(folder + "/talker.db3-shm"));
}

TEST_F(Rosbag2Failures, UnclosedRecordingIsReadWithItsWriteAheadLog) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_talker");
  const std::string file = Copy("db3_talker") + "/talker.db3";
  // A writer that has not closed: its last message is in talker.db3-wal only.
  sqlite3* writer = nullptr;
  ASSERT_EQ(sqlite3_open(file.c_str(), &writer), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(writer,
                         "PRAGMA wal_autocheckpoint = 0; INSERT INTO messages(topic_id, "
                         "timestamp, data) SELECT topic_id, timestamp + 1, data FROM messages "
                         "WHERE id = (SELECT MAX(id) FROM messages)",
                         nullptr, nullptr, nullptr),
            SQLITE_OK)
      << sqlite3_errmsg(writer);
  ASSERT_GT(fs::file_size(file + "-wal"), 0u);
  const auto store = OpenOrFail(OpenSqlite3File(file));
  sqlite3_close(writer);
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->summary().messages, 21u);
  EXPECT_EQ(VisitAll(*store), MessagesPerTopic(CountsOf(store->summary())));
}

TEST_F(Rosbag2Failures, MetadataNamingAMissingFile) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_cdr_test");
  const std::string folder = Copy("db3_cdr_test");
  fs::remove(folder + "/cdr_test_0.db3");
  const auto opened = OpenRosbag2Folder(folder);
  ASSERT_FALSE(opened.ok());
  EXPECT_EQ(opened.status().code(), StatusCode::kNotFound);
  EXPECT_NE(opened.status().message().find("metadata.yaml"), std::string::npos);
  EXPECT_NE(opened.status().message().find("cdr_test_0.db3"), std::string::npos);
}

TEST_F(Rosbag2Failures, CorruptMetadata) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_cdr_test");
  const std::string folder = Copy("db3_cdr_test");
  const std::string metadata = folder + "/metadata.yaml";
  const auto open_with = [&](const std::string& text) {
    std::ofstream(metadata, std::ios::trunc) << text;
    return OpenRosbag2Folder(folder).status();
  };
  const Status not_yaml = open_with("rosbag2_bagfile_information: {version: 4, [unclosed");
  EXPECT_EQ(not_yaml.code(), StatusCode::kDataLoss) << not_yaml.ToString();
  EXPECT_NE(not_yaml.message().find("metadata.yaml"), std::string::npos);
  const Status no_version =
      open_with("rosbag2_bagfile_information:\n  storage_identifier: sqlite3\n");
  EXPECT_EQ(no_version.code(), StatusCode::kInvalidArgument) << no_version.ToString();
  const Status bad_version = open_with("rosbag2_bagfile_information:\n  version: many\n");
  EXPECT_EQ(bad_version.code(), StatusCode::kInvalidArgument) << bad_version.ToString();
  const Status unknown_compression = open_with(
      "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n"
      "  relative_file_paths: [cdr_test_0.db3]\n  compression_format: brotli\n"
      "  compression_mode: FILE\n");
  EXPECT_EQ(unknown_compression.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(unknown_compression.message().find("brotli"), std::string::npos);
  const Status unknown_storage = open_with(
      "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: leveldb\n"
      "  relative_file_paths: [cdr_test_0.db3]\n");
  EXPECT_EQ(unknown_storage.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(unknown_storage.message().find("leveldb"), std::string::npos);
  // A later version is read when its fields are there.
  const Status later = open_with(
      "rosbag2_bagfile_information:\n  version: 99\n  storage_identifier: sqlite3\n"
      "  relative_file_paths: [cdr_test_0.db3]\n");
  EXPECT_TRUE(later.ok()) << later.ToString();
}

TEST_F(Rosbag2Failures, TruncatedDb3) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_cdr_test");
  const std::string folder = Copy("db3_cdr_test");
  const std::string file = folder + "/cdr_test_0.db3";
  for (const uintmax_t size : {uintmax_t(20000), uintmax_t(4096), uintmax_t(50)}) {
    fs::resize_file(file, size);
    const auto opened = OpenSqlite3File(file);
    ASSERT_FALSE(opened.ok()) << size;
    EXPECT_EQ(opened.status().code(), StatusCode::kDataLoss) << opened.status().ToString();
    EXPECT_NE(opened.status().message().find(file), std::string::npos);
    const auto folder_opened = OpenRosbag2Folder(folder);
    EXPECT_EQ(folder_opened.status().code(), StatusCode::kDataLoss) << size;
  }
}

TEST_F(Rosbag2Failures, DamagedPagesAreDataLoss) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_cdr_test");
  const std::string file = Copy("db3_cdr_test") + "/cdr_test_0.db3";
  {
    std::fstream bytes(file, std::ios::in | std::ios::out | std::ios::binary);
    bytes.seekp(4096);
    const std::string garbage(fs::file_size(file) - 4096, '\xA5');
    bytes.write(garbage.data(), std::streamsize(garbage.size()));
  }
  const auto opened = OpenSqlite3File(file);
  ASSERT_FALSE(opened.ok());
  EXPECT_EQ(opened.status().code(), StatusCode::kDataLoss) << opened.status().ToString();
  EXPECT_NE(opened.status().message().find(file), std::string::npos);
}

TEST_F(Rosbag2Failures, NotABag) {
  const std::string text = (scratch_ / "notes.db3").string();
  std::ofstream(text) << "these are not the messages you are looking for";
  EXPECT_EQ(OpenSqlite3File(text).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(OpenSqlite3File((scratch_ / "absent.db3").string()).status().code(),
            StatusCode::kNotFound);
  EXPECT_EQ(OpenRosbag2Folder((scratch_ / "absent").string()).status().code(),
            StatusCode::kNotFound);
  EXPECT_EQ(OpenRosbag2Folder(text).status().code(), StatusCode::kInvalidArgument);
  // A folder with neither metadata.yaml nor a bag file.
  EXPECT_EQ(OpenRosbag2Folder(scratch_.string()).status().code(), StatusCode::kInvalidArgument);
  // An sqlite3 file that is not rosbag2's.
  const std::string other = (scratch_ / "other.db3").string();
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(other.c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT)", nullptr,
                         nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(db);
  const Status no_messages = OpenSqlite3File(other).status();
  EXPECT_EQ(no_messages.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(no_messages.message().find("messages"), std::string::npos);
  EXPECT_NE(no_messages.message().find(other), std::string::npos);
  // A view where the messages table should be: its query is not run.
  Query(other, "CREATE VIEW messages AS SELECT 1 AS id, 1 AS topic_id, 0 AS timestamp, x'' AS data",
        /*writable=*/true);
  const Status view = OpenSqlite3File(other).status();
  EXPECT_EQ(view.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(view.message().find("view"), std::string::npos) << view.ToString();
}

TEST_F(Rosbag2Failures, UnknownSerializationFormatInTheFile) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_cdr_test");
  const std::string file = Copy("db3_cdr_test") + "/cdr_test_0.db3";
  Query(file, "UPDATE topics SET serialization_format = 'ros1' WHERE name = '/array_topic'",
        /*writable=*/true);
  const Status status = OpenSqlite3File(file).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  for (const std::string& part : {file, std::string("/array_topic"), std::string("'ros1'")}) {
    EXPECT_NE(status.message().find(part), std::string::npos) << status.ToString();
  }
}

TEST_F(Rosbag2Failures, DamagedZstdMessage) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/old_db3_zstd_MESSAGE_compression_nometa");
  const std::string file =
      Copy("old_db3_zstd_MESSAGE_compression_nometa") + "/message_compression_0.db3";
  // Message 5 (of /rosout) keeps its frame's first 12 bytes only.
  Query(file, "UPDATE messages SET data = substr(data, 1, 12) WHERE id = 5", /*writable=*/true);
  const auto store = OpenOrFail(OpenSqlite3File(file));
  ASSERT_NE(store, nullptr);
  uint64_t visited = 0;
  const Status status = store->ForEachMessage("/rosout", [&](const StoredMessage&) {
    ++visited;
    return Status::Ok();
  });
  EXPECT_EQ(status.code(), StatusCode::kDataLoss) << status.ToString();
  EXPECT_NE(status.message().find(file), std::string::npos);
  EXPECT_NE(status.message().find("message id 5"), std::string::npos);
  EXPECT_EQ(visited, 4u);
  std::vector<uint8_t> data;
  EXPECT_EQ(store->ReadMessage("/rosout", 5, &data).code(), StatusCode::kDataLoss);
  EXPECT_TRUE(store->ReadMessage("/rosout", 4, &data).ok());
}

TEST_F(Rosbag2Failures, LookupsOfWhatIsNotThere) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_wbag");
  const auto store = OpenOrFail(OpenRosbag2Folder(Rosbag2("db3_wbag")));
  ASSERT_NE(store, nullptr);
  const auto never = [](const StoredMessage&) { return Status::Ok(); };
  EXPECT_EQ(store->ForEachMessage("/nothing", never).code(), StatusCode::kNotFound);
  std::vector<uint8_t> data;
  EXPECT_EQ(store->ReadMessage("AAA", UINT64_MAX, &data).code(), StatusCode::kNotFound);
  EXPECT_EQ(store->ReadMessage("AAA", 999999, &data).code(), StatusCode::kNotFound);
  // An id of another topic.
  uint64_t first_bbb = 0;
  ASSERT_TRUE(store
                  ->ForEachMessage("BBB",
                                   [&](const StoredMessage& message) {
                                     first_bbb = message.id;
                                     return Status::InvalidArgument("enough");
                                   })
                  .code() == StatusCode::kInvalidArgument);
  EXPECT_EQ(store->ReadMessage("AAA", first_bbb, &data).code(), StatusCode::kNotFound);
  EXPECT_TRUE(store->ReadMessage("BBB", first_bbb, &data).ok());
}

TEST_F(Rosbag2Failures, TypeConflictBetweenFiles) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_reindex_test_bags_multiple_files");
  const std::string folder = Copy("db3_reindex_test_bags_multiple_files");
  Query(folder + "/multiple_files_1.db3", "UPDATE topics SET type = 'std_msgs/msg/Int32'",
        /*writable=*/true);
  const Status status = OpenRosbag2Folder(folder).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("/chatter"), std::string::npos) << status.ToString();
  EXPECT_NE(status.message().find("multiple_files_1.db3"), std::string::npos);
}

TEST_F(Rosbag2Failures, FilesWithoutMetadataAreInNumericOrder) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("bags/rosbag2/db3_test_bag_for_seek");
  const fs::path folder = scratch_ / "eleven";
  fs::create_directories(folder);
  std::vector<std::string> expected;
  for (int i = 0; i <= 10; ++i) {
    expected.push_back((folder / ("part_" + std::to_string(i) + ".db3")).string());
    fs::copy_file(Rosbag2("db3_test_bag_for_seek/test_bag_for_seek_0.db3"), expected.back());
  }
  std::ofstream(folder / "README") << "not a bag file";
  const auto store = OpenOrFail(OpenRosbag2Folder(folder.string()));
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->summary().files, expected);
  EXPECT_EQ(store->summary().messages, 55u);
}

}  // namespace
}  // namespace recog::bag
