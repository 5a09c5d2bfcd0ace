// InfoLogFile: lines reach the LOG file, previous logs are rolled and bounded, and a full disk
// loses lines (counted) instead of stopping the process; lines are written again once there is
// room.
#include "storage/info_log_file.h"

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "storage/store_test_util.h"

namespace recog::storage {
namespace {

namespace fs = std::filesystem;

std::string ReadText(const fs::path& file) {
  std::ifstream in(file);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

int CountOldLogs(const fs::path& dir) {
  int old_logs = 0;
  for (const fs::directory_entry& file : fs::directory_iterator(dir)) {
    old_logs += file.path().filename().string().starts_with("LOG.old.");
  }
  return old_logs;
}

TEST(InfoLogFileTest, LinesAreWrittenWithATimeAndOldLogsAreRolledAndBounded) {
  recog::testing::TempDir dir("info_log");
  const fs::path store = dir.Sub("store");  // created by Open
  for (int opened = 1; opened <= 6; ++opened) {
    auto log = InfoLogFile::Open(store.string(), 3);
    ASSERT_TRUE(log.ok()) << log.status().ToString();
    rocksdb::Log(rocksdb::InfoLogLevel::INFO_LEVEL, *log, "opening %d of %s", opened, "six");
    EXPECT_EQ((*log)->lost_lines(), 0u);
    EXPECT_EQ(CountOldLogs(store), std::min(opened - 1, 3));
  }
  const std::string text = ReadText(store / "LOG");
  EXPECT_NE(text.find("opening 6 of six\n"), std::string::npos) << text;
  EXPECT_EQ(text.find("opening 5"), std::string::npos) << "the previous open's lines were rolled";
  EXPECT_TRUE(text.starts_with("20")) << "lines start with the UTC date: " << text;
}

TEST(InfoLogFileTest, AFullDiskLosesLinesWithoutStoppingAndLoggingResumesWithRoom) {
  recog::testing::SmallFilesystem disk("info_log_full", 1 << 20);
  if (!disk.error().empty()) GTEST_SKIP() << disk.error();
  auto log = InfoLogFile::Open(disk.Sub("store"), 3);
  ASSERT_TRUE(log.ok()) << log.status().ToString();
  disk.Fill(0);
  const std::string long_line(100000, 'x');
  for (int i = 0; i < 20; ++i) {
    rocksdb::Log(rocksdb::InfoLogLevel::INFO_LEVEL, *log, "%s", long_line.c_str());
  }
  const uint64_t lost = (*log)->lost_lines();
  EXPECT_GT(lost, 0u);
  disk.FreeSpace();
  rocksdb::Log(rocksdb::InfoLogLevel::INFO_LEVEL, *log, "room again");
  EXPECT_EQ((*log)->lost_lines(), lost);
  EXPECT_NE(ReadText(disk.Sub("store/LOG")).find("room again\n"), std::string::npos);
}

}  // namespace
}  // namespace recog::storage
