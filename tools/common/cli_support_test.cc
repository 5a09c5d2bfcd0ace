#include "tools/common/cli_support.h"

#include <algorithm>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <unistd.h>

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

TEST(CliSupportTest, NaturalOrderComparesDigitRunsAsNumbers) {
  std::vector<std::string> names = {"10.jpg",    "2.jpg", "1.jpg", "img_010.png",
                                    "img_9.png", "b.jpg", "a.jpg", "02.jpg"};
  std::sort(names.begin(), names.end(), NaturalLess);
  EXPECT_EQ(names, (std::vector<std::string>{"1.jpg", "2.jpg", "02.jpg", "10.jpg", "a.jpg", "b.jpg",
                                             "img_9.png", "img_010.png"}));
  EXPECT_FALSE(NaturalLess("5", "5"));
}

TEST(CliSupportTest, ListImagesFindsImagesRecursivelyInNaturalOrder) {
  const fs::path dir = fs::temp_directory_path() / ("recog_cli_" + std::to_string(::getpid()));
  fs::create_directories(dir / "sub");
  for (const char* name : {"10.jpg", "2.PNG", "notes.txt", "sub/1.jpeg"}) {
    std::ofstream(dir / name) << "x";
  }
  auto files = ListImages(dir.string());
  ASSERT_TRUE(files.ok()) << files.status().ToString();
  ASSERT_EQ(files->size(), 3u);
  EXPECT_EQ(fs::path((*files)[0]).filename(), "2.PNG");
  EXPECT_EQ(fs::path((*files)[1]).filename(), "10.jpg");
  EXPECT_EQ(fs::path((*files)[2]).filename(), "1.jpeg");
  fs::remove_all(dir / "sub");
  fs::remove(dir / "10.jpg");
  fs::remove(dir / "2.PNG");
  EXPECT_EQ(ListImages(dir.string()).status().code(), StatusCode::kInvalidArgument);
  fs::remove_all(dir);
  EXPECT_EQ(ListImages(dir.string()).status().code(), StatusCode::kNotFound);
}

TEST(CliSupportTest, ChecksumsPrintAsSixteenHexDigits) {
  EXPECT_EQ(HexChecksum(0xabcULL), "0x0000000000000abc");
}

TEST(CliSupportTest, PeakMemoryIsPositive) { EXPECT_GT(PeakRssMiB(), 1.0); }

}  // namespace
}  // namespace recog::cli
