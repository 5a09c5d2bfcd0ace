#include "tools/evaluation/ground_truth.h"

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

#include "tests/testing/test_data.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

class GroundTruthTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("recog_ground_truth_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Write(const std::string& name, const std::string& text) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path, std::ios::binary) << text;
    return path;
  }
  static std::string Slurp(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream text;
    text << in.rdbuf();
    return text.str();
  }
  // 5 frames: 3 matches 1, 4 matches 1 and 2 (0-based: 2 -> 0, 3 -> 0 1).
  static GroundTruth Example() {
    GroundTruth truth;
    truth.frames = 5;
    truth.matches = {{}, {}, {0}, {0, 1}, {}};
    return truth;
  }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  fs::path dir_;
};

TEST_F(GroundTruthTest, MatchesAndQueryCountsFollowTheLists) {
  const GroundTruth truth = Example();
  EXPECT_TRUE(truth.Validate().ok());
  EXPECT_TRUE(truth.Matches(3, 1));
  EXPECT_TRUE(truth.Matches(2, 0));
  EXPECT_FALSE(truth.Matches(1, 3));
  EXPECT_FALSE(truth.Matches(4, 0));
  EXPECT_FALSE(truth.Matches(-1, 0));
  EXPECT_FALSE(truth.Matches(5, 0));
  EXPECT_EQ(truth.QueriesWithMatches(), 2);
  EXPECT_EQ(truth.NumPairs(), 3);
}

TEST_F(GroundTruthTest, ValidateRejectsLaterOrUnsortedMatches) {
  GroundTruth truth = Example();
  truth.matches[2] = {2};
  EXPECT_EQ(truth.Validate().code(), StatusCode::kInvalidArgument);
  truth = Example();
  truth.matches[3] = {1, 0};
  EXPECT_EQ(truth.Validate().code(), StatusCode::kInvalidArgument);
  truth = Example();
  truth.matches.pop_back();
  EXPECT_EQ(truth.Validate().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(WriteDenseGroundTruth(truth, Path("x.txt")).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(WriteSparseGroundTruth(truth, Path("y.txt")).code(), StatusCode::kInvalidArgument);
}

TEST_F(GroundTruthTest, DenseFileIsAZeroOneMatrixWithSingleSpaces) {
  ASSERT_TRUE(WriteDenseGroundTruth(Example(), Path("gt.txt")).ok());
  EXPECT_EQ(Slurp(Path("gt.txt")),
            "0 0 0 0 0\n"
            "0 0 0 0 0\n"
            "1 0 0 0 0\n"
            "1 1 0 0 0\n"
            "0 0 0 0 0\n");
  auto truth = ReadGroundTruth(Path("gt.txt"));
  ASSERT_TRUE(truth.ok()) << truth.status().ToString();
  EXPECT_EQ(truth->frames, 5);
  EXPECT_EQ(truth->matches, Example().matches);
  EXPECT_EQ(truth->ignored_entries, 0);
}

TEST_F(GroundTruthTest, SparseFileListsOneBasedMatchesPerQuery) {
  ASSERT_TRUE(WriteSparseGroundTruth(Example(), Path("gt.sparse.txt")).ok());
  EXPECT_EQ(Slurp(Path("gt.sparse.txt")),
            "# recog sparse ground truth v1 5\n"
            "3: 1\n"
            "4: 1 2\n");
  auto truth = ReadGroundTruth(Path("gt.sparse.txt"));
  ASSERT_TRUE(truth.ok()) << truth.status().ToString();
  EXPECT_EQ(truth->frames, 5);
  EXPECT_EQ(truth->matches, Example().matches);
}

TEST_F(GroundTruthTest, ReaderToleratesCrLfBlankLinesAndSparseComments) {
  auto dense = ReadGroundTruth(Write("crlf.txt", "0 0 0\r\n1 0 0\r\n0 1 0\r\n\r\n"));
  ASSERT_TRUE(dense.ok()) << dense.status().ToString();
  EXPECT_EQ(dense->matches, (std::vector<std::vector<int>>{{}, {0}, {1}}));
  auto sparse =
      ReadGroundTruth(Write("c.txt", "# recog sparse ground truth v1 3\n# note\n\n3: 1 2\r\n"));
  ASSERT_TRUE(sparse.ok()) << sparse.status().ToString();
  EXPECT_EQ(sparse->matches, (std::vector<std::vector<int>>{{}, {}, {0, 1}}));
}

TEST_F(GroundTruthTest, DenseOnesOnOrAboveTheDiagonalAreIgnoredAndCounted) {
  // A symmetric matrix, as some data sets ship them: only the lower triangle is a loop.
  auto truth = ReadGroundTruth(Write("sym.txt", "1 0 1\n0 0 0\n1 0 0\n"));
  ASSERT_TRUE(truth.ok()) << truth.status().ToString();
  EXPECT_EQ(truth->matches, (std::vector<std::vector<int>>{{}, {}, {0}}));
  EXPECT_EQ(truth->ignored_entries, 2);
}

TEST_F(GroundTruthTest, DenseLineWithTheWrongNumberOfValuesIsDataLossWithItsLineNumber) {
  auto truth = ReadGroundTruth(Write("short.txt", "0 0 0\n1 0 0\n0 1\n"));
  EXPECT_EQ(truth.status().code(), StatusCode::kDataLoss);
  EXPECT_NE(truth.status().message().find("line 3"), std::string::npos) << truth.status().message();
}

TEST_F(GroundTruthTest, DenseMatrixWithMissingOrExtraRowsIsDataLoss) {
  EXPECT_EQ(ReadGroundTruth(Write("rows.txt", "0 0 0\n1 0 0\n")).status().code(),
            StatusCode::kDataLoss);
  EXPECT_EQ(ReadGroundTruth(Write("extra.txt", "0 0\n1 0\n1 0\n")).status().code(),
            StatusCode::kDataLoss);
}

TEST_F(GroundTruthTest, DenseValueOtherThanZeroOrOneIsDataLoss) {
  auto truth = ReadGroundTruth(Write("two.txt", "0 0 0\n2 0 0\n0 0 0\n"));
  EXPECT_EQ(truth.status().code(), StatusCode::kDataLoss);
  EXPECT_NE(truth.status().message().find("line 2"), std::string::npos);
  EXPECT_NE(truth.status().message().find("'2'"), std::string::npos);
  EXPECT_EQ(ReadGroundTruth(Write("frac.txt", "0 0\n0.5 0\n")).status().code(),
            StatusCode::kDataLoss);
}

TEST_F(GroundTruthTest, SparseMatchThatIsNotEarlierIsDataLoss) {
  auto same = ReadGroundTruth(Write("same.txt", "# recog sparse ground truth v1 4\n3: 3\n"));
  EXPECT_EQ(same.status().code(), StatusCode::kDataLoss);
  EXPECT_NE(same.status().message().find("line 2"), std::string::npos);
  EXPECT_EQ(ReadGroundTruth(Write("later.txt", "# recog sparse ground truth v1 4\n2: 4\n"))
                .status()
                .code(),
            StatusCode::kDataLoss);
  EXPECT_EQ(ReadGroundTruth(Write("zero.txt", "# recog sparse ground truth v1 4\n2: 0\n"))
                .status()
                .code(),
            StatusCode::kDataLoss);
}

TEST_F(GroundTruthTest, SparseIndicesOutsideTheSequenceOrOutOfOrderAreDataLoss) {
  const auto code = [&](const std::string& body) {
    return ReadGroundTruth(Write("s.txt", "# recog sparse ground truth v1 4\n" + body))
        .status()
        .code();
  };
  EXPECT_EQ(code("5: 1\n"), StatusCode::kDataLoss);        // query beyond N
  EXPECT_EQ(code("0: 1\n"), StatusCode::kDataLoss);        // 1-based
  EXPECT_EQ(code("4: 2 1\n"), StatusCode::kDataLoss);      // matches not increasing
  EXPECT_EQ(code("4: 1\n3: 1\n"), StatusCode::kDataLoss);  // queries not increasing
  EXPECT_EQ(code("4 1 2\n"), StatusCode::kDataLoss);       // no colon
  EXPECT_EQ(code("4: x\n"), StatusCode::kDataLoss);        // not a number
  EXPECT_EQ(code("-4: 1\n"), StatusCode::kDataLoss);
}

TEST_F(GroundTruthTest, SparseFileWithABadHeaderIsDataLoss) {
  EXPECT_EQ(
      ReadGroundTruth(Write("h1.txt", "# recog sparse ground truth v2 4\n3: 1\n")).status().code(),
      StatusCode::kDataLoss);
  EXPECT_EQ(
      ReadGroundTruth(Write("h2.txt", "# recog sparse ground truth v1\n3: 1\n")).status().code(),
      StatusCode::kDataLoss);
  EXPECT_EQ(ReadGroundTruth(Write("h3.txt", "# some comment\n0 0\n1 0\n")).status().code(),
            StatusCode::kDataLoss);
}

TEST_F(GroundTruthTest, EmptyFileIsDataLossAndMissingFileIsNotFound) {
  EXPECT_EQ(ReadGroundTruth(Write("empty.txt", "")).status().code(), StatusCode::kDataLoss);
  EXPECT_EQ(ReadGroundTruth(Write("blank.txt", "\n\n")).status().code(), StatusCode::kDataLoss);
  EXPECT_EQ(ReadGroundTruth(Path("missing.txt")).status().code(), StatusCode::kNotFound);
}

TEST(CorridorGroundTruthTest, RealCorridorFileHas84FramesAnd44QueriesWithMatches) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("places/corridor/ground_truth.txt");
  auto truth = ReadGroundTruth(testing::SharedData("places/corridor/ground_truth.txt"));
  ASSERT_TRUE(truth.ok()) << truth.status().ToString();
  EXPECT_EQ(truth->frames, 84);
  EXPECT_EQ(truth->QueriesWithMatches(), 44);
  EXPECT_EQ(truth->ignored_entries, 0);
  EXPECT_TRUE(truth->Validate().ok());
  // Line 41 of the file (frame 40, 0-based) matches the first three frames.
  EXPECT_EQ(truth->matches[40], (std::vector<int>{0, 1, 2}));
}

TEST(CorridorGroundTruthTest, RealCorridorFileSurvivesADenseRewriteByteForByte) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("places/corridor/ground_truth.txt");
  const std::string original = testing::SharedData("places/corridor/ground_truth.txt");
  auto truth = ReadGroundTruth(original);
  ASSERT_TRUE(truth.ok()) << truth.status().ToString();
  const std::string copy =
      (fs::temp_directory_path() / ("recog_corridor_gt_" + std::to_string(::getpid()) + ".txt"))
          .string();
  ASSERT_TRUE(WriteDenseGroundTruth(*truth, copy).ok());
  std::ifstream a(original, std::ios::binary), b(copy, std::ios::binary);
  std::stringstream sa, sb;
  sa << a.rdbuf();
  sb << b.rdbuf();
  EXPECT_EQ(sa.str(), sb.str());
  fs::remove(copy);
}

}  // namespace
}  // namespace recog::cli
