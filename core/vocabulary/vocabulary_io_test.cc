#include "core/vocabulary/vocabulary_io.h"

#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>

#include <gtest/gtest.h>

#include "tests/testing/synthetic.h"

namespace recog {
namespace {

namespace fs = std::filesystem;

class VocabularyIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("recog_io_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
    TrainingOptions o;
    o.branching = 6;
    o.depth = 3;
    o.threads = 1;
    o.trees = 2;
    auto voc = TrainVocabulary(testing::ClusteredTrainingSet(30, 100, 8), o);
    ASSERT_TRUE(voc.ok());
    voc_ = std::move(voc).value();
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  std::vector<char> ReadAll(const std::string& p) const {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
  }
  void WriteAll(const std::string& p, const std::vector<char>& bytes) const {
    std::ofstream out(p, std::ios::binary);
    out.write(bytes.data(), std::streamsize(bytes.size()));
  }

  fs::path dir_;
  Vocabulary voc_;
};

TEST_F(VocabularyIoTest, SaveThenLoadIsBitIdentical) {
  const std::string p = Path("v.rvoc");
  ASSERT_TRUE(SaveVocabulary(voc_, p).ok());
  auto loaded = LoadVocabulary(p);
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_EQ(loaded->info(), voc_.info());
  EXPECT_EQ(loaded->num_words(), voc_.num_words());
  EXPECT_EQ(loaded->checksum(), voc_.checksum());
  ASSERT_EQ(loaded->buffer().size(), voc_.buffer().size());
  EXPECT_TRUE(std::equal(voc_.buffer().begin(), voc_.buffer().end(), loaded->buffer().begin()));
  // Saving the loaded copy writes the same bytes.
  ASSERT_TRUE(SaveVocabulary(*loaded, Path("w.rvoc")).ok());
  EXPECT_EQ(ReadAll(p), ReadAll(Path("w.rvoc")));
  // And it converts descriptors the same way.
  const cv::Mat d = testing::RandomDescriptors(100, 4);
  BowVector a, b;
  ASSERT_TRUE(voc_.Transform(d, &a).ok());
  ASSERT_TRUE(loaded->Transform(d, &b).ok());
  EXPECT_EQ(a, b);
}

TEST_F(VocabularyIoTest, FormatIsDetectedFromTheContents) {
  const std::string p = Path("v.bin");
  ASSERT_TRUE(SaveVocabulary(voc_, p).ok());
  auto format = DetectVocabularyFormat(p);
  ASSERT_TRUE(format.ok());
  EXPECT_EQ(*format, VocabularyFileFormat::kRecog);
  auto any = LoadAnyVocabulary(p);
  ASSERT_TRUE(any.ok());
  EXPECT_EQ(any->checksum(), voc_.checksum());
  WriteAll(Path("junk"), {'\x01', '\x02', 'x'});
  EXPECT_EQ(DetectVocabularyFormat(Path("junk")).status().code(), StatusCode::kDataLoss);
}

TEST_F(VocabularyIoTest, MissingFilesAreNotFoundAndDirectoriesAreRefused) {
  EXPECT_EQ(LoadVocabulary(Path("nope.rvoc")).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(LoadAnyVocabulary(Path("nope.rvoc")).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(LoadVocabulary(dir_.string()).status().code(), StatusCode::kInvalidArgument);
}

TEST_F(VocabularyIoTest, EveryTruncationIsDataLoss) {
  const std::string p = Path("v.rvoc");
  ASSERT_TRUE(SaveVocabulary(voc_, p).ok());
  const std::vector<char> bytes = ReadAll(p);
  std::mt19937 rng(1);
  std::vector<size_t> cuts{0, 1, 8, 64, 127, 128, 129, bytes.size() - 1};
  for (int i = 0; i < 20; ++i) cuts.push_back(rng() % bytes.size());
  for (size_t cut : cuts) {
    WriteAll(Path("cut.rvoc"), std::vector<char>(bytes.begin(), bytes.begin() + long(cut)));
    const Status s = LoadVocabulary(Path("cut.rvoc")).status();
    EXPECT_EQ(s.code(), StatusCode::kDataLoss) << "cut at " << cut << ": " << s.ToString();
  }
  std::vector<char> padded = bytes;
  padded.push_back('x');
  WriteAll(Path("padded.rvoc"), padded);
  EXPECT_EQ(LoadVocabulary(Path("padded.rvoc")).status().code(), StatusCode::kDataLoss);
}

TEST_F(VocabularyIoTest, AnyFlippedByteIsDetected) {
  const std::string p = Path("v.rvoc");
  ASSERT_TRUE(SaveVocabulary(voc_, p).ok());
  const std::vector<char> bytes = ReadAll(p);
  std::mt19937 rng(2);
  for (int i = 0; i < 60; ++i) {
    std::vector<char> corrupt = bytes;
    // Half the flips in the header (only its first 72 bytes matter), half in the body.
    const size_t at = i % 2 == 0 ? rng() % 72 : 128 + rng() % (bytes.size() - 128);
    corrupt[at] = char(corrupt[at] ^ (1 << (rng() % 8)));
    WriteAll(Path("bad.rvoc"), corrupt);
    const Status s = LoadVocabulary(Path("bad.rvoc")).status();
    EXPECT_EQ(s.code(), StatusCode::kDataLoss) << "flip at " << at << ": " << s.ToString();
  }
}

TEST_F(VocabularyIoTest, SavingAnEmptyVocabularyOrToAMissingFolderFails) {
  EXPECT_EQ(SaveVocabulary(Vocabulary(), Path("e.rvoc")).code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(SaveVocabulary(voc_, Path("no/such/dir/v.rvoc")).ok());
  EXPECT_FALSE(fs::exists(Path("no/such/dir/v.rvoc.tmp")));
}

}  // namespace
}  // namespace recog
