// decompress.h: zstd and LZ4 frames decompressed to their declared size, damaged and cut data,
// unknown names, "bombs" refused before their output is allocated, and the streamed file variant.
#include "tools/bag/decompress.h"

#include <gtest/gtest.h>
#include <lz4frame.h>
#include <unistd.h>
#include <zstd.h>

#include <filesystem>
#include <fstream>
#include <random>

namespace recog::bag {
namespace {

std::vector<uint8_t> SampleData(size_t size) {
  std::vector<uint8_t> data(size);
  std::mt19937 random(7);
  // Compressible but not trivial: runs of a few random values.
  for (size_t i = 0; i < size; ++i) data[i] = uint8_t(random() % 4 + (i / 100) % 7);
  return data;
}

// One zstd frame, with its content size and a checksum (so that any damage is found).
std::vector<uint8_t> Zstd(const std::vector<uint8_t>& data, bool content_size = true) {
  ZSTD_CCtx* context = ZSTD_createCCtx();
  ZSTD_CCtx_setParameter(context, ZSTD_c_checksumFlag, 1);
  ZSTD_CCtx_setParameter(context, ZSTD_c_contentSizeFlag, content_size ? 1 : 0);
  std::vector<uint8_t> compressed(ZSTD_compressBound(data.size()));
  const size_t size =
      ZSTD_compress2(context, compressed.data(), compressed.size(), data.data(), data.size());
  ZSTD_freeCCtx(context);
  EXPECT_FALSE(ZSTD_isError(size));
  compressed.resize(size);
  return compressed;
}

// One LZ4 frame with a content checksum, as MCAP's "lz4" chunks are.
std::vector<uint8_t> Lz4(const std::vector<uint8_t>& data) {
  LZ4F_preferences_t preferences{};
  preferences.frameInfo.contentChecksumFlag = LZ4F_contentChecksumEnabled;
  std::vector<uint8_t> compressed(LZ4F_compressFrameBound(data.size(), &preferences));
  const size_t size = LZ4F_compressFrame(compressed.data(), compressed.size(), data.data(),
                                         data.size(), &preferences);
  EXPECT_FALSE(LZ4F_isError(size));
  compressed.resize(size);
  return compressed;
}

std::vector<uint8_t> Compress(const std::string& compression, const std::vector<uint8_t>& data) {
  if (compression == "zstd") return Zstd(data);
  if (compression == "lz4") return Lz4(data);
  return data;
}

class DecompressExactlyTest : public ::testing::TestWithParam<std::string> {};

TEST_P(DecompressExactlyTest, GivesTheDataBack) {
  for (const size_t size : {size_t(0), size_t(1), size_t(1000), size_t(3 << 20)}) {
    const std::vector<uint8_t> data = SampleData(size);
    std::vector<uint8_t> output = {9, 9, 9};
    const Status status = DecompressExactly(GetParam(), Compress(GetParam(), data), data.size(),
                                            &output, "test data");
    ASSERT_TRUE(status.ok()) << size << ": " << status.ToString();
    EXPECT_EQ(output, data);
  }
}

TEST_P(DecompressExactlyTest, RefusesAnotherSizeThanDeclared) {
  const std::vector<uint8_t> data = SampleData(5000);
  const std::vector<uint8_t> compressed = Compress(GetParam(), data);
  for (const uint64_t declared : {uint64_t(4999), uint64_t(5001), uint64_t(0), uint64_t(2500)}) {
    std::vector<uint8_t> output;
    const Status status =
        DecompressExactly(GetParam(), compressed, declared, &output, "chunk at byte 12");
    EXPECT_EQ(status.code(), StatusCode::kDataLoss) << declared << ": " << status.ToString();
    EXPECT_NE(status.message().find("chunk at byte 12"), std::string::npos) << status.message();
    EXPECT_LE(output.size(), declared);
  }
}

INSTANTIATE_TEST_SUITE_P(Compressions, DecompressExactlyTest,
                         ::testing::Values(std::string(""), std::string("zstd"),
                                           std::string("lz4")),
                         [](const auto& info) { return info.param.empty() ? "none" : info.param; });

TEST(DecompressExactly, FindsDamageAndCuts) {
  const std::vector<uint8_t> data = SampleData(20000);
  for (const std::string compression : {"zstd", "lz4"}) {
    const std::vector<uint8_t> compressed = Compress(compression, data);
    std::vector<uint8_t> output;
    for (size_t position = 0; position < compressed.size(); position += 7) {
      std::vector<uint8_t> damaged = compressed;
      damaged[position] ^= 0x5A;
      // The checksum finds any change, but for one that gives the same data (another offset to
      // an equal match).
      const Status status = DecompressExactly(compression, damaged, data.size(), &output, "x");
      EXPECT_TRUE(status.code() == StatusCode::kDataLoss || (status.ok() && output == data))
          << compression << ", byte " << position << ": " << status.ToString();
      const std::vector<uint8_t> cut(compressed.begin(), compressed.begin() + position);
      EXPECT_EQ(DecompressExactly(compression, cut, data.size(), &output, "cut").code(),
                StatusCode::kDataLoss)
          << compression << ", cut at " << position;
    }
  }
}

TEST(DecompressExactly, NamesAnUnknownCompression) {
  std::vector<uint8_t> output;
  const Status status = DecompressExactly("brotli", SampleData(10), 10, &output, "chunk at 8");
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("'brotli'"), std::string::npos) << status.message();
}

TEST(DecompressExactly, RefusesADeclaredSizeAboveTheLimit) {
  const std::vector<uint8_t> data = SampleData(1000);
  std::vector<uint8_t> output;
  EXPECT_EQ(DecompressExactly("zstd", Zstd(data), data.size(), &output, "x", 999).code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(DecompressExactly("zstd", Zstd(data), kMaxDecompressedBytes + 1, &output, "x").code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(output.capacity(), 0u);
  EXPECT_TRUE(DecompressExactly("zstd", Zstd(data), data.size(), &output, "x", 1000).ok());
}

// A few bytes declaring a gigabyte: refused before the gigabyte is allocated.
TEST(DecompressExactly, RefusesABombBeforeAllocating) {
  for (const std::string compression : {"zstd", "lz4"}) {
    const std::vector<uint8_t> tiny = Compress(compression, SampleData(100));
    std::vector<uint8_t> output;
    const Status status =
        DecompressExactly(compression, tiny, kMaxDecompressedBytes, &output, "bomb");
    EXPECT_EQ(status.code(), StatusCode::kDataLoss) << compression << ": " << status.ToString();
    EXPECT_EQ(output.capacity(), 0u) << compression;
  }
}

// Real bombs: a little data that decompresses to far more than declared.
TEST(DecompressExactly, StopsAtTheDeclaredSizeOfARealBomb) {
  const std::vector<uint8_t> zeros(64 << 20, 0);
  for (const std::string compression : {"zstd", "lz4"}) {
    const std::vector<uint8_t> bomb = Compress(compression, zeros);
    ASSERT_LT(bomb.size(), zeros.size() / 200) << compression;
    std::vector<uint8_t> output;
    const uint64_t declared = bomb.size() * 100;
    const Status status = DecompressExactly(compression, bomb, declared, &output, "bomb");
    EXPECT_EQ(status.code(), StatusCode::kDataLoss) << compression << ": " << status.ToString();
    EXPECT_LE(output.capacity(), declared) << compression;
  }
}

TEST(DecompressZstd, GivesFramesOfUnknownSizeBack) {
  const std::vector<uint8_t> first = SampleData(300000);
  const std::vector<uint8_t> second = SampleData(1234);
  std::vector<uint8_t> input = Zstd(first, /*content_size=*/false);
  const std::vector<uint8_t> more = Zstd(second);
  input.insert(input.end(), more.begin(), more.end());
  std::vector<uint8_t> output;
  ASSERT_TRUE(DecompressZstd(input, &output, "message 3").ok());
  std::vector<uint8_t> expected = first;
  expected.insert(expected.end(), second.begin(), second.end());
  EXPECT_EQ(output, expected);
  // Exactly at the limit is fine; a byte more is not.
  EXPECT_TRUE(DecompressZstd(input, &output, "message 3", expected.size()).ok());
  EXPECT_EQ(DecompressZstd(input, &output, "message 3", expected.size() - 1).code(),
            StatusCode::kResourceExhausted);
}

TEST(DecompressZstd, StopsABombAtTheLimit) {
  const std::vector<uint8_t> zeros(32 << 20, 0);
  std::vector<uint8_t> output;
  // Its size unknown, found while decompressing; its size in the frame, found before.
  for (const bool content_size : {false, true}) {
    const Status status = DecompressZstd(Zstd(zeros, content_size), &output, "bomb", 1 << 20);
    EXPECT_EQ(status.code(), StatusCode::kResourceExhausted) << status.ToString();
    EXPECT_NE(status.message().find("bomb"), std::string::npos);
    EXPECT_LE(output.capacity(), size_t(1) << 20);
  }
}

TEST(DecompressZstd, RefusesDamagedCutAndEmptyInput) {
  const std::vector<uint8_t> compressed = Zstd(SampleData(20000), /*content_size=*/false);
  std::vector<uint8_t> output;
  EXPECT_EQ(DecompressZstd({}, &output, "empty").code(), StatusCode::kDataLoss);
  EXPECT_EQ(DecompressZstd(SampleData(100), &output, "not zstd").code(), StatusCode::kDataLoss);
  for (size_t position = 0; position < compressed.size(); position += 11) {
    const std::vector<uint8_t> cut(compressed.begin(), compressed.begin() + position);
    EXPECT_EQ(DecompressZstd(cut, &output, "cut").code(), StatusCode::kDataLoss) << position;
    std::vector<uint8_t> damaged = compressed;
    damaged[position] ^= 0x21;
    EXPECT_EQ(DecompressZstd(damaged, &output, "damaged").code(), StatusCode::kDataLoss)
        << position;
  }
}

class DecompressZstdFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    folder_ = std::filesystem::path(::testing::TempDir()) /
              ("decompress_test_" + std::to_string(::getpid()));
    std::filesystem::create_directories(folder_);
    input_ = (folder_ / "bag.db3.zstd").string();
    output_ = (folder_ / "bag.db3").string();
  }
  void TearDown() override { std::filesystem::remove_all(folder_); }

  void WriteInput(const std::vector<uint8_t>& bytes) {
    std::ofstream(input_, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
  }
  std::vector<uint8_t> ReadOutput() {
    std::ifstream file(output_, std::ios::binary);
    return {std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>()};
  }

  std::filesystem::path folder_;
  std::string input_;
  std::string output_;
};

TEST_F(DecompressZstdFileTest, GivesTheFileBack) {
  const std::vector<uint8_t> data = SampleData(5 << 20);
  WriteInput(Zstd(data, /*content_size=*/false));
  const Status status = DecompressZstdFile(input_, output_, data.size());
  ASSERT_TRUE(status.ok()) << status.ToString();
  EXPECT_EQ(ReadOutput(), data);
}

TEST_F(DecompressZstdFileTest, RemovesTheOutputBeyondTheLimit) {
  const std::vector<uint8_t> data = SampleData(5 << 20);
  WriteInput(Zstd(data));
  const Status status = DecompressZstdFile(input_, output_, data.size() - 1);
  EXPECT_EQ(status.code(), StatusCode::kResourceExhausted) << status.ToString();
  EXPECT_FALSE(std::filesystem::exists(output_));
}

TEST_F(DecompressZstdFileTest, RemovesTheOutputOfACutOrDamagedFile) {
  const std::vector<uint8_t> compressed = Zstd(SampleData(1 << 20));
  WriteInput(std::vector<uint8_t>(compressed.begin(), compressed.end() - 10));
  EXPECT_EQ(DecompressZstdFile(input_, output_, 1 << 30).code(), StatusCode::kDataLoss);
  EXPECT_FALSE(std::filesystem::exists(output_));
  std::vector<uint8_t> damaged = compressed;
  damaged[damaged.size() / 2] ^= 0x40;
  WriteInput(damaged);
  EXPECT_EQ(DecompressZstdFile(input_, output_, 1 << 30).code(), StatusCode::kDataLoss);
  EXPECT_FALSE(std::filesystem::exists(output_));
  WriteInput({});
  EXPECT_EQ(DecompressZstdFile(input_, output_, 1 << 30).code(), StatusCode::kDataLoss);
}

TEST_F(DecompressZstdFileTest, MissingInputIsNotFound) {
  EXPECT_EQ(DecompressZstdFile(input_ + ".missing", output_, 1 << 30).code(),
            StatusCode::kNotFound);
  EXPECT_FALSE(std::filesystem::exists(output_));
}

}  // namespace
}  // namespace recog::bag
