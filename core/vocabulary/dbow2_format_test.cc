#include "core/vocabulary/dbow2_format.h"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "core/bow/scoring.h"
#include "tests/testing/test_data.h"

namespace recog {
namespace {

using ::testing::HasSubstr;
using Descriptor = std::array<uint8_t, 32>;

// --- Helpers. ---

Descriptor Filled(uint8_t value) {
  Descriptor d;
  d.fill(value);
  return d;
}

Descriptor With(Descriptor d, size_t index, uint8_t value) {
  d[index] = value;
  return d;
}

// "b0 b1 ... b31" (ORB notation).
std::string Decimal(const Descriptor& d) {
  std::string s;
  for (size_t i = 0; i < d.size(); ++i) {
    if (i != 0) s += ' ';
    s += std::to_string(d[i]);
  }
  return s;
}

// The 256-character BRIEF notation of the same bits: every byte as 8 binary digits,
// most-significant first, concatenated, then the whole string reversed.
std::string Binary(const Descriptor& d) {
  std::string s;
  for (uint8_t byte : d) {
    for (int bit = 7; bit >= 0; --bit) s += ((byte >> bit) & 1) ? '1' : '0';
  }
  std::reverse(s.begin(), s.end());
  return s;
}

double RelativeTolerance(double expected) { return 1e-6 * std::max(1.0, std::fabs(expected)); }

void WriteFileText(const std::string& path, const std::string& content) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << content;
  ASSERT_TRUE(out.good()) << path;
}

std::string ReadFileText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A folder of its own for each test, removed afterwards.
class Dbow2FormatTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const ::testing::TestInfo* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = std::filesystem::temp_directory_path() /
           ("recog_dbow2_" + std::to_string(::getpid()) + "_" + info->test_suite_name() + "_" +
            info->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  std::string Write(const std::string& name, const std::string& content) {
    const std::string path = Path(name);
    WriteFileText(path, content);
    return path;
  }

  std::filesystem::path dir_;
};

// --- The hand-made vocabulary used by the self-contained tests. ---
//
// k=2, L=2. Node ids are the text file's:
//   1 (root child, 0x00...)   -> leaves 2 (byte 0 = 0x0F, word 0), 5 (byte 0 = 0xF0, word 2)
//   3 (root child, 0xFF...)   -> leaves 4 (byte 31 = 0xF0, word 1), 6 (byte 31 = 0x0F, word 3)
// Leaves are interleaved in the file, so word ids (file order) differ from breadth-first order.
struct TinyNode {
  uint32_t id, parent;
  bool leaf;
  Descriptor descriptor;
  const char* weight;
};

std::vector<TinyNode> TinyNodes() {
  return {
      {1, 0, false, Filled(0x00), "0"},
      {2, 1, true, With(Filled(0x00), 0, 0x0F), "0.5"},
      {3, 0, false, Filled(0xFF), "0"},
      {4, 3, true, With(Filled(0xFF), 31, 0xF0), "1.25"},
      {5, 1, true, With(Filled(0x00), 0, 0xF0), "2"},
      {6, 3, true, With(Filled(0xFF), 31, 0x0F), "3.5"},
  };
}

// The tiny vocabulary as DBoW2 text, in the exact form ExportDbow2Text writes.
std::string TinyText(const std::string& header = "2 2 0 0") {
  std::string s = header + "\n";
  for (const TinyNode& n : TinyNodes()) {
    s += std::to_string(n.parent) + (n.leaf ? " 1 " : " 0 ") + Decimal(n.descriptor) + " " +
         n.weight + "\n";
  }
  return s;
}

// The same tree as DBoW2 YAML, nodes listed in the order 3, 1, 6, 5, 2, 4.
std::string TinyYaml(bool brief, bool with_words = true) {
  std::map<uint32_t, TinyNode> by_id;
  for (const TinyNode& n : TinyNodes()) by_id.emplace(n.id, n);
  std::string s =
      "%YAML:1.0\n---\nvocabulary:\n   k: 2\n   L: 2\n   scoringType: 0\n   weightingType: 0\n"
      "   nodes:\n";
  for (uint32_t id : {3u, 1u, 6u, 5u, 2u, 4u}) {
    const TinyNode& n = by_id.at(id);
    const std::string weight = n.weight;  // DBoW2 writes "0." for zero
    s += "      - { nodeId:" + std::to_string(id) + ", parentId:" + std::to_string(n.parent) +
         ", weight:" + (weight.find('.') == std::string::npos ? weight + "." : weight) +
         ",\n          descriptor:\"" +
         (brief ? Binary(n.descriptor) : Decimal(n.descriptor) + " ") + "\" }\n";
  }
  if (with_words) {
    s += "   words:\n";
    const std::pair<int, int> words[] = {{0, 2}, {1, 4}, {2, 5}, {3, 6}};
    for (auto [word, node] : words) {
      s += "      - { wordId:" + std::to_string(word) + ", nodeId:" + std::to_string(node) + " }\n";
    }
  }
  return s;
}

// Half zeros, half ones: as far from node 1 as from node 3, so the root's tie decides.
Descriptor HalfAndHalf() {
  Descriptor d = Filled(0x00);
  std::fill(d.begin() + 16, d.end(), 0xFF);
  return d;
}

// A random tree in DBoW2's creation order (the children of a node are created together, then
// each child is expanded in turn), with leaves at mixed depths. With `dbow2_word_ids` the word
// ids follow the leaves' order in the table as in DBoW2; otherwise Vocabulary::FromTrees assigns
// them in breadth-first order, as the trainer does.
TreeNodeTable RandomTree(uint32_t k, uint32_t depth, uint32_t seed, bool dbow2_word_ids) {
  std::mt19937 rng(seed);
  TreeNodeTable t;
  std::vector<uint8_t> has_children;
  auto add = [&](uint32_t parent) {
    t.parent.push_back(parent);
    for (int b = 0; b < 32; ++b) t.descriptors.push_back(uint8_t(rng()));
    t.word.push_back(kInvalidWordId);
    t.weight.push_back(float(rng() % 100000) / 7919.f);
    has_children.push_back(0);
    return uint32_t(t.parent.size() - 1);
  };
  add(0);
  std::function<void(uint32_t, uint32_t)> expand = [&](uint32_t node, uint32_t level) {
    has_children[node] = 1;
    const uint32_t count = 2 + uint32_t(rng() % (k - 1));
    std::vector<uint32_t> children;
    for (uint32_t c = 0; c < count; ++c) children.push_back(add(node));
    for (uint32_t child : children) {
      if (level + 1 < depth && rng() % 3 != 0) expand(child, level + 1);
    }
  };
  expand(0, 0);
  if (dbow2_word_ids) {
    WordId next = 0;
    for (size_t i = 1; i < t.size(); ++i) {
      if (!has_children[i]) t.word[i] = next++;
    }
  }
  return t;
}

StatusOr<Vocabulary> VocabularyOf(const TreeNodeTable& table, uint32_t k, uint32_t depth) {
  VocabularyInfo info;
  info.descriptor = DescriptorFormat::Orb();
  info.branching = k;
  info.depth = depth;
  info.num_trees = 1;
  return Vocabulary::FromTrees(info, std::span(&table, 1));
}

// --- DBoW2's own answers (the *.expected.txt files next to the shared vocabularies). ---

struct Dbow2Expectations {
  struct Word {
    int line;
    WordId word;
    double weight;
    Descriptor descriptor;
  };
  struct Score {
    int a, b;
    double value;
  };
  std::map<std::string, uint32_t> header;  // words, k, L, scoring, weighting
  std::vector<Word> words;
  std::map<int, cv::Mat> sets;
  std::map<int, std::vector<std::pair<WordId, double>>> bows;
  std::vector<Score> scores;
};

Descriptor ParseOrFail(const std::string& text, int line) {
  StatusOr<Descriptor> d = ParseDbow2Descriptor(text);
  if (!d.ok()) {
    ADD_FAILURE() << "expected file line " << line << ": " << d.status().ToString();
    return Descriptor{};
  }
  return *d;
}

Dbow2Expectations ReadExpectations(const std::string& path) {
  Dbow2Expectations e;
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << path;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    std::istringstream ss(line);
    std::string kind;
    ss >> kind;
    if (kind == "#") {
      std::string key;
      ss >> key;
      if (key != "kind") continue;
      std::string value;
      ss >> value;  // orb / brief
      uint32_t number = 0;
      while (ss >> key >> number) e.header[key] = number;
    } else if (kind == "word") {
      Dbow2Expectations::Word w{line_no, 0, 0.0, {}};
      ss >> w.word >> w.weight;
      std::string rest;
      std::getline(ss, rest);
      w.descriptor = ParseOrFail(rest, line_no);
      e.words.push_back(w);
    } else if (kind == "set") {
      int id = 0;
      int count = 0;
      ss >> id >> count;
      std::vector<std::string> tokens;
      for (std::string t; ss >> t;) tokens.push_back(t);
      cv::Mat mat(count, 32, CV_8U);
      const size_t per = tokens.size() == size_t(count) ? 1 : 32;
      EXPECT_EQ(tokens.size(), per * size_t(count)) << "expected file line " << line_no;
      for (int r = 0; r < count && size_t(r + 1) * per <= tokens.size(); ++r) {
        std::string text;
        for (size_t j = 0; j < per; ++j) text += tokens[r * per + j] + " ";
        const Descriptor d = ParseOrFail(text, line_no);
        std::copy(d.begin(), d.end(), mat.ptr<uint8_t>(r));
      }
      e.sets[id] = mat;
    } else if (kind == "bow") {
      int id = 0;
      size_t count = 0;
      ss >> id >> count;
      auto& entries = e.bows[id];
      for (std::string t; ss >> t;) {
        const size_t colon = t.find(':');
        entries.emplace_back(WordId(std::stoul(t.substr(0, colon))),
                             std::stod(t.substr(colon + 1)));
      }
      EXPECT_EQ(entries.size(), count) << "expected file line " << line_no;
    } else if (kind == "score") {
      Dbow2Expectations::Score s{};
      ss >> s.a >> s.b >> s.value;
      e.scores.push_back(s);
    } else if (!kind.empty()) {
      ADD_FAILURE() << "expected file line " << line_no << ": unknown kind '" << kind << "'";
    }
  }
  return e;
}

// Checks words, weights, BoW vectors and scores against DBoW2's answers.
void ExpectDbow2Answers(const Vocabulary& vocabulary, const Dbow2Expectations& e) {
  ASSERT_FALSE(e.words.empty());
  ASSERT_FALSE(e.sets.empty());
  ASSERT_FALSE(e.scores.empty());
  for (const auto& w : e.words) {
    const WordId got = vocabulary.TransformOne(w.descriptor.data());
    EXPECT_EQ(got, w.word) << "expected file line " << w.line;
    if (got < vocabulary.num_words()) {
      EXPECT_NEAR(vocabulary.WordWeight(w.word), w.weight, RelativeTolerance(w.weight))
          << "expected file line " << w.line;
    }
  }
  const BowNormalization norm = TraitsOf(vocabulary.info().scoring).normalization;
  std::map<int, BowVector> bows;
  for (const auto& [id, descriptors] : e.sets) {
    BowVector& bow = bows[id];
    ASSERT_TRUE(vocabulary.Transform(descriptors, &bow, nullptr, 0, norm).ok());
    ASSERT_EQ(e.bows.count(id), 1u) << "set " << id;
    const auto& expected = e.bows.at(id);
    ASSERT_EQ(bow.size(), expected.size()) << "set " << id;
    for (size_t i = 0; i < expected.size(); ++i) {
      EXPECT_EQ(bow.entries()[i].word, expected[i].first) << "set " << id << " entry " << i;
      EXPECT_NEAR(bow.entries()[i].value, expected[i].second, RelativeTolerance(expected[i].second))
          << "set " << id << " entry " << i;
    }
  }
  for (const auto& s : e.scores) {
    EXPECT_NEAR(Score(vocabulary.info().scoring, bows.at(s.a), bows.at(s.b)), s.value, 1e-6)
        << "score " << s.a << " " << s.b;
  }
}

void ExpectHeader(const Vocabulary& vocabulary, const Dbow2Expectations& e) {
  EXPECT_EQ(vocabulary.num_words(), e.header.at("words"));
  EXPECT_EQ(vocabulary.info().branching, e.header.at("k"));
  EXPECT_EQ(vocabulary.info().depth, e.header.at("L"));
  EXPECT_EQ(uint32_t(vocabulary.info().scoring), e.header.at("scoring"));
  EXPECT_EQ(uint32_t(vocabulary.info().weighting), e.header.at("weighting"));
  EXPECT_EQ(vocabulary.info().num_trees, 1u);
  EXPECT_EQ(vocabulary.info().descriptor, DescriptorFormat::Orb());
}

constexpr char kOrbYaml[] = "vocabularies/orb_k9_l3_dbow2.yml.gz";
constexpr char kOrbExpected[] = "vocabularies/orb_k9_l3_dbow2.expected.txt";
constexpr char kBriefYaml[] = "vocabularies/brief_k10_l6_dbow2.yml.gz";
constexpr char kBriefExpected[] = "vocabularies/brief_k10_l6_dbow2.expected.txt";

// --- Descriptor notation. ---

TEST(ParseDbow2DescriptorTest, ReadsThirtyTwoDecimalBytes) {
  Descriptor d{};
  for (size_t i = 0; i < d.size(); ++i) d[i] = uint8_t(i * 8 + 3);
  StatusOr<Descriptor> parsed = ParseDbow2Descriptor(Decimal(d) + " ");
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  EXPECT_EQ(*parsed, d);
}

TEST(ParseDbow2DescriptorTest, ReadsBriefStringsBackwardsMostSignificantBitFirst) {
  // The last character is bit 0: the most-significant bit of byte 0.
  std::string last(256, '0');
  last[255] = '1';
  StatusOr<Descriptor> d = ParseDbow2Descriptor(last);
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(*d, With(Filled(0), 0, 0x80));
  // The first character is bit 255: the least-significant bit of byte 31.
  std::string first(256, '0');
  first[0] = '1';
  d = ParseDbow2Descriptor(first);
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(*d, With(Filled(0), 31, 0x01));
}

TEST(ParseDbow2DescriptorTest, BothNotationsOfTheSameBitsGiveTheSameBytes) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 20; ++trial) {
    Descriptor d;
    for (uint8_t& b : d) b = uint8_t(rng());
    StatusOr<Descriptor> from_decimal = ParseDbow2Descriptor(Decimal(d));
    StatusOr<Descriptor> from_binary = ParseDbow2Descriptor(Binary(d));
    ASSERT_TRUE(from_decimal.ok());
    ASSERT_TRUE(from_binary.ok());
    EXPECT_EQ(*from_decimal, d);
    EXPECT_EQ(*from_binary, d);
  }
}

TEST(ParseDbow2DescriptorTest, RejectsWrongCountsValuesAndCharacters) {
  const std::string decimal = Decimal(Filled(1));
  EXPECT_EQ(ParseDbow2Descriptor(decimal.substr(0, decimal.size() - 2)).status().code(),
            StatusCode::kDataLoss);  // 31 values
  EXPECT_THAT(ParseDbow2Descriptor(decimal + " 1").status().message(), HasSubstr("33 values"));
  EXPECT_THAT(ParseDbow2Descriptor("256" + decimal.substr(1)).status().message(),
              HasSubstr("'256'"));
  EXPECT_EQ(ParseDbow2Descriptor("-1" + decimal.substr(1)).status().code(), StatusCode::kDataLoss);
  EXPECT_EQ(ParseDbow2Descriptor("1.5" + decimal.substr(1)).status().code(), StatusCode::kDataLoss);
  EXPECT_EQ(ParseDbow2Descriptor("").status().code(), StatusCode::kDataLoss);
  std::string brief(256, '1');
  brief[10] = '2';
  EXPECT_EQ(ParseDbow2Descriptor(brief).status().code(), StatusCode::kDataLoss);
  EXPECT_EQ(ParseDbow2Descriptor(std::string(255, '1')).status().code(), StatusCode::kDataLoss);
  EXPECT_EQ(ParseDbow2Descriptor(std::string(257, '1')).status().code(), StatusCode::kDataLoss);
}

// --- Real DBoW2 vocabularies (shared data). ---

TEST(Dbow2RealVocabularyTest, OrbYamlImportReproducesDbow2WordsBowVectorsAndScores) {
  RECOG_SKIP_WITHOUT_SHARED_DATA(kOrbYaml);
  RECOG_SKIP_WITHOUT_SHARED_DATA(kOrbExpected);
  StatusOr<Vocabulary> vocabulary = ImportDbow2Yaml(testing::SharedData(kOrbYaml));
  ASSERT_TRUE(vocabulary.ok()) << vocabulary.status().ToString();
  const Dbow2Expectations e = ReadExpectations(testing::SharedData(kOrbExpected));
  ExpectHeader(*vocabulary, e);
  EXPECT_EQ(vocabulary->num_words(), 692u);
  ExpectDbow2Answers(*vocabulary, e);
}

TEST(Dbow2RealVocabularyTest, BriefYamlImportReproducesDbow2WordsBowVectorsAndScores) {
  RECOG_SKIP_WITHOUT_SHARED_DATA(kBriefYaml);
  RECOG_SKIP_WITHOUT_SHARED_DATA(kBriefExpected);
  StatusOr<Vocabulary> vocabulary = ImportDbow2Yaml(testing::SharedData(kBriefYaml));
  ASSERT_TRUE(vocabulary.ok()) << vocabulary.status().ToString();
  const Dbow2Expectations e = ReadExpectations(testing::SharedData(kBriefExpected));
  ExpectHeader(*vocabulary, e);
  EXPECT_EQ(vocabulary->num_words(), 24830u);
  ExpectDbow2Answers(*vocabulary, e);
}

using Dbow2RealVocabularyFileTest = Dbow2FormatTest;

TEST_F(Dbow2RealVocabularyFileTest, TextRoundTripOfTheOrbVocabularyKeepsWordsAndWeights) {
  RECOG_SKIP_WITHOUT_SHARED_DATA(kOrbYaml);
  RECOG_SKIP_WITHOUT_SHARED_DATA(kOrbExpected);
  StatusOr<Vocabulary> original = ImportDbow2Yaml(testing::SharedData(kOrbYaml));
  ASSERT_TRUE(original.ok()) << original.status().ToString();
  const std::string text = Path("orb.txt");
  ASSERT_TRUE(ExportDbow2Text(*original, text).ok());
  StatusOr<Vocabulary> copy = ImportDbow2Text(text);
  ASSERT_TRUE(copy.ok()) << copy.status().ToString();

  EXPECT_EQ(copy->info(), original->info());
  EXPECT_EQ(copy->num_words(), original->num_words());
  EXPECT_EQ(copy->num_nodes(), original->num_nodes());
  for (WordId w = 0; w < original->num_words(); ++w) {
    ASSERT_EQ(copy->WordWeight(w), original->WordWeight(w)) << "word " << w;
  }
  // Same tree, same word ids, same weights: the same layout.
  EXPECT_EQ(copy->checksum(), original->checksum());
  ExpectDbow2Answers(*copy, ReadExpectations(testing::SharedData(kOrbExpected)));
}

TEST_F(Dbow2RealVocabularyFileTest, TextRoundTripOfTheBriefVocabularyKeepsTheLayout) {
  RECOG_SKIP_WITHOUT_SHARED_DATA(kBriefYaml);
  StatusOr<Vocabulary> original = ImportDbow2Yaml(testing::SharedData(kBriefYaml));
  ASSERT_TRUE(original.ok()) << original.status().ToString();
  const std::string text = Path("brief.txt");
  ASSERT_TRUE(ExportDbow2Text(*original, text).ok());
  StatusOr<Vocabulary> copy = ImportDbow2Text(text);
  ASSERT_TRUE(copy.ok()) << copy.status().ToString();
  EXPECT_EQ(copy->info(), original->info());
  EXPECT_EQ(copy->num_words(), 24830u);
  EXPECT_EQ(copy->checksum(), original->checksum());
}

TEST_F(Dbow2RealVocabularyFileTest, GzipIsRecognisedByContentNotByName) {
  RECOG_SKIP_WITHOUT_SHARED_DATA(kOrbYaml);
  const std::string renamed = Path("orb_vocabulary.yml");
  std::filesystem::copy_file(testing::SharedData(kOrbYaml), renamed);
  StatusOr<Vocabulary> vocabulary = ImportDbow2Yaml(renamed);
  ASSERT_TRUE(vocabulary.ok()) << vocabulary.status().ToString();
  EXPECT_EQ(vocabulary->num_words(), 692u);
}

TEST_F(Dbow2RealVocabularyFileTest, TruncatedGzipYamlIsDataLoss) {
  RECOG_SKIP_WITHOUT_SHARED_DATA(kOrbYaml);
  const std::string whole = ReadFileText(testing::SharedData(kOrbYaml));
  ASSERT_GT(whole.size(), 1000u);
  std::mt19937 rng(11);
  for (int trial = 0; trial < 8; ++trial) {
    const size_t cut = 1 + rng() % (whole.size() - 1);
    const std::string path = Write("cut.yml.gz", whole.substr(0, cut));
    StatusOr<Vocabulary> vocabulary = ImportDbow2Yaml(path);
    EXPECT_EQ(vocabulary.status().code(), StatusCode::kDataLoss) << "cut at " << cut;
  }
}

// --- Self-contained: text import. ---

using Dbow2TextImportTest = Dbow2FormatTest;

TEST_F(Dbow2TextImportTest, ReadsTheTreeWeightsAndHeader) {
  StatusOr<Vocabulary> v = ImportDbow2Text(Write("tiny.txt", TinyText("2 2 1 2")));
  ASSERT_TRUE(v.ok()) << v.status().ToString();
  EXPECT_EQ(v->info().branching, 2u);
  EXPECT_EQ(v->info().depth, 2u);
  EXPECT_EQ(v->info().num_trees, 1u);
  EXPECT_EQ(v->info().scoring, ScoringType::kL2);
  EXPECT_EQ(v->info().weighting, WeightingType::kIdf);
  EXPECT_EQ(v->info().descriptor, DescriptorFormat::Orb());
  EXPECT_EQ(v->num_words(), 4u);
  EXPECT_EQ(v->num_nodes(), 7u);
  const NodeId root = v->Root(0);
  ASSERT_EQ(v->ChildCount(root), 2u);
  const NodeId first = v->FirstChild(root);
  EXPECT_TRUE(
      std::equal(v->NodeDescriptor(first), v->NodeDescriptor(first) + 32, Filled(0x00).begin()));
  EXPECT_TRUE(std::equal(v->NodeDescriptor(first + 1), v->NodeDescriptor(first + 1) + 32,
                         Filled(0xFF).begin()));
  EXPECT_FALSE(v->IsLeaf(first));
  EXPECT_EQ(v->ChildCount(first), 2u);
  // Word ids follow the leaves' order in the file: node 2, 4, 5, 6.
  EXPECT_EQ(v->WordOf(v->FirstChild(first)), 0u);          // node 2
  EXPECT_EQ(v->WordOf(v->FirstChild(first) + 1), 2u);      // node 5
  EXPECT_EQ(v->WordOf(v->FirstChild(first + 1)), 1u);      // node 4
  EXPECT_EQ(v->WordOf(v->FirstChild(first + 1) + 1), 3u);  // node 6
  EXPECT_FLOAT_EQ(v->WordWeight(0), 0.5f);
  EXPECT_FLOAT_EQ(v->WordWeight(1), 1.25f);
  EXPECT_FLOAT_EQ(v->WordWeight(2), 2.f);
  EXPECT_FLOAT_EQ(v->WordWeight(3), 3.5f);
}

TEST_F(Dbow2TextImportTest, FindsHandComputedWordsAndBreaksTiesTowardsTheFirstChildInTheFile) {
  StatusOr<Vocabulary> v = ImportDbow2Text(Write("tiny.txt", TinyText()));
  ASSERT_TRUE(v.ok()) << v.status().ToString();
  EXPECT_EQ(v->TransformOne(With(Filled(0), 0, 0xE0).data()), 2u);      // nearest node 5
  EXPECT_EQ(v->TransformOne(With(Filled(0), 0, 0x07).data()), 0u);      // nearest node 2
  EXPECT_EQ(v->TransformOne(With(Filled(0xFF), 31, 0x0F).data()), 3u);  // node 6
  // Ties: 4 bits from both leaves of node 1 -> node 2; from both leaves of node 3 -> node 4.
  EXPECT_EQ(v->TransformOne(Filled(0x00).data()), 0u);
  EXPECT_EQ(v->TransformOne(Filled(0xFF).data()), 1u);
  // Tie at the root too (128 bits from nodes 1 and 3): node 1, then node 2.
  EXPECT_EQ(v->TransformOne(HalfAndHalf().data()), 0u);
}

TEST_F(Dbow2TextImportTest, AcceptsOrbSlamSpacingCarriageReturnsAndTrailingBlankLines) {
  // ORB-SLAM writes "k L  scoring weighting" and a blank before the weight.
  std::string text;
  std::istringstream lines(TinyText());
  std::string line;
  bool header = true;
  while (std::getline(lines, line)) {
    if (header) {
      text += "2 2  0 0\r\n";
      header = false;
      continue;
    }
    const size_t last = line.rfind(' ');
    text += line.substr(0, last) + "  " + line.substr(last + 1) + " \r\n";
  }
  text += "\r\n\n";
  StatusOr<Vocabulary> v = ImportDbow2Text(Write("orbslam.txt", text));
  ASSERT_TRUE(v.ok()) << v.status().ToString();
  StatusOr<Vocabulary> reference = ImportDbow2Text(Write("tiny.txt", TinyText()));
  ASSERT_TRUE(reference.ok());
  EXPECT_EQ(v->checksum(), reference->checksum());
}

// --- Self-contained: YAML import. ---

using Dbow2YamlImportTest = Dbow2FormatTest;

TEST_F(Dbow2YamlImportTest, KeepsChildrenInFileOrderAndWordIdsFromTheWordsList) {
  StatusOr<Vocabulary> v = ImportDbow2Yaml(Write("tiny.yml", TinyYaml(/*brief=*/false)));
  ASSERT_TRUE(v.ok()) << v.status().ToString();
  EXPECT_EQ(v->num_words(), 4u);
  EXPECT_EQ(v->num_nodes(), 7u);
  EXPECT_EQ(v->info().branching, 2u);
  EXPECT_EQ(v->info().depth, 2u);
  // Word ids come from the words list whatever the order of the nodes.
  EXPECT_EQ(v->TransformOne(With(Filled(0), 0, 0x07).data()), 0u);      // node 2
  EXPECT_EQ(v->TransformOne(With(Filled(0), 0, 0xE0).data()), 2u);      // node 5
  EXPECT_EQ(v->TransformOne(With(Filled(0xFF), 31, 0xF1).data()), 1u);  // node 4
  EXPECT_EQ(v->TransformOne(With(Filled(0xFF), 31, 0x0F).data()), 3u);  // node 6
  EXPECT_FLOAT_EQ(v->WordWeight(0), 0.5f);
  EXPECT_FLOAT_EQ(v->WordWeight(3), 3.5f);
  // The file lists node 3 before node 1, 5 before 2 and 6 before 4, so ties go the other way
  // than in the text file.
  EXPECT_EQ(v->TransformOne(Filled(0x00).data()), 2u);
  EXPECT_EQ(v->TransformOne(Filled(0xFF).data()), 3u);
  EXPECT_EQ(v->TransformOne(HalfAndHalf().data()), 3u);
}

TEST_F(Dbow2YamlImportTest, BriefStringsDescribeTheSameVocabularyAsDecimalBytes) {
  StatusOr<Vocabulary> decimal = ImportDbow2Yaml(Write("orb.yml", TinyYaml(false)));
  StatusOr<Vocabulary> brief = ImportDbow2Yaml(Write("brief.yml", TinyYaml(true)));
  ASSERT_TRUE(decimal.ok()) << decimal.status().ToString();
  ASSERT_TRUE(brief.ok()) << brief.status().ToString();
  EXPECT_EQ(decimal->checksum(), brief->checksum());
}

TEST_F(Dbow2YamlImportTest, MissingOrGarbageYamlIsAClearError) {
  EXPECT_EQ(ImportDbow2Yaml(Path("nope.yml")).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(ImportDbow2Yaml(Write("empty.yml", "")).status().code(), StatusCode::kDataLoss);
  const Status garbage =
      ImportDbow2Yaml(Write("garbage.yml", "%YAML:1.0\n---\n{[}: ]]\n\x01\x02")).status();
  EXPECT_EQ(garbage.code(), StatusCode::kDataLoss) << garbage.ToString();
  const Status binary =
      ImportDbow2Yaml(Write("binary.yml", std::string("\x7f\x00\x13garbage", 10))).status();
  EXPECT_EQ(binary.code(), StatusCode::kDataLoss) << binary.ToString();
  const Status other = ImportDbow2Yaml(Write("other.yml", "%YAML:1.0\n---\nfoo: 1\n")).status();
  EXPECT_EQ(other.code(), StatusCode::kDataLoss);
  EXPECT_THAT(other.message(), HasSubstr("vocabulary"));
}

TEST_F(Dbow2YamlImportTest, MissingWordsListIsDataLoss) {
  const Status s = ImportDbow2Yaml(Write("nowords.yml", TinyYaml(false, false))).status();
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_THAT(s.message(), HasSubstr("words"));
}

// Replaces the first occurrence of `from` in the tiny YAML.
std::string TinyYamlWith(const std::string& from, const std::string& to) {
  std::string s = TinyYaml(false);
  const size_t at = s.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) s.replace(at, from.size(), to);
  return s;
}

TEST_F(Dbow2YamlImportTest, InconsistentNodesAndWordsAreDataLoss) {
  const struct {
    const char* from;
    const char* to;
    const char* message;
  } cases[] = {
      {"nodeId:1,", "nodeId:3,", "appears twice"},
      {"nodeId:1,", "nodeId:9,", "out of range"},
      {"parentId:1,", "parentId:8,", "out of range"},
      {"{ wordId:1, nodeId:4 }", "{ wordId:1, nodeId:3 }", "has children"},
      {"{ wordId:1, nodeId:4 }", "{ wordId:1, nodeId:2 }", "already is word"},
      {"{ wordId:1, nodeId:4 }", "{ wordId:0, nodeId:4 }", "appears twice"},
      {"{ wordId:1, nodeId:4 }", "{ wordId:7, nodeId:4 }", "out of range"},
      {"k: 2", "k: 1", "k=1"},
      {"L: 2", "L: 1", "deeper than L=1"},
      {"scoringType: 0", "scoringType: 9", "scoring"},
      {"weightingType: 0", "weightingType: -1", "weightingType"},
      {"weight:0.5,", "weight:abc,", "weight"},
      {"descriptor:\"0 ", "descriptor:\"", "31 values"},
      {"nodeId:3, parentId:0", "nodeId:3, parentId:3", "own parent"},
      // Nodes 3 and 6 parent each other: a cycle cut off from the root.
      {"nodeId:3, parentId:0", "nodeId:3, parentId:6", "nodeId 3 is not reachable"},
  };
  for (const auto& c : cases) {
    const std::string yaml = TinyYamlWith(c.from, c.to);
    const Status s = ImportDbow2Yaml(Write("bad.yml", yaml)).status();
    EXPECT_EQ(s.code(), StatusCode::kDataLoss) << c.from << " -> " << c.to << ": " << s.ToString();
    EXPECT_THAT(s.message(), HasSubstr(c.message)) << c.from << " -> " << c.to;
  }
  // A leaf that no word refers to.
  std::string yaml = TinyYaml(false);
  yaml.erase(yaml.find("      - { wordId:3"));
  const Status s = ImportDbow2Yaml(Write("leaf.yml", yaml)).status();
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_THAT(s.message(), HasSubstr("nodeId 6 is a leaf but no word"));
}

TEST_F(Dbow2YamlImportTest, TruncatedYamlNeverCrashes) {
  const std::string whole = TinyYaml(true);
  size_t failures = 0;
  for (size_t cut = 0; cut < whole.size(); cut += 7) {
    StatusOr<Vocabulary> v = ImportDbow2Yaml(Write("cut.yml", whole.substr(0, cut)));
    if (!v.ok()) {
      ++failures;
      EXPECT_EQ(v.status().code(), StatusCode::kDataLoss) << "cut at " << cut;
    }
  }
  EXPECT_GT(failures, 0u);
}

// --- Self-contained: corrupt text. ---

using Dbow2TextCorruptTest = Dbow2FormatTest;

TEST_F(Dbow2TextCorruptTest, MissingFileIsNotFoundAndEmptyFileIsDataLoss) {
  const Status missing = ImportDbow2Text(Path("nope.txt")).status();
  EXPECT_EQ(missing.code(), StatusCode::kNotFound);
  EXPECT_THAT(missing.message(), HasSubstr("nope.txt"));
  EXPECT_EQ(ImportDbow2Text(Write("empty.txt", "")).status().code(), StatusCode::kDataLoss);
  EXPECT_EQ(ImportDbow2Text(Write("blank.txt", "\n\n")).status().code(), StatusCode::kDataLoss);
  const Status header_only = ImportDbow2Text(Write("header.txt", "10 6 0 0\n")).status();
  EXPECT_EQ(header_only.code(), StatusCode::kDataLoss);
  EXPECT_THAT(header_only.message(), HasSubstr("no node"));
  EXPECT_EQ(ImportDbow2Text(dir_.string()).status().code(), StatusCode::kNotFound);
}

TEST_F(Dbow2TextCorruptTest, EveryCutInsideALineIsDataLoss) {
  const std::string whole = TinyText();
  for (size_t cut = 0; cut < whole.size(); ++cut) {
    StatusOr<Vocabulary> v = ImportDbow2Text(Write("cut.txt", whole.substr(0, cut)));
    if (cut == 0 || whole[cut - 1] != '\n') {
      EXPECT_EQ(v.status().code(), StatusCode::kDataLoss) << "cut at " << cut;
    } else if (!v.ok()) {
      // At a line boundary the rest may still be a whole vocabulary; if not, it must say so.
      EXPECT_EQ(v.status().code(), StatusCode::kDataLoss) << "cut at " << cut;
    }
  }
  // Cut in the middle of the last weight ("3.5" -> "3."): the missing end of line tells.
  const Status s = ImportDbow2Text(Write("cut.txt", whole.substr(0, whole.size() - 2))).status();
  EXPECT_THAT(s.message(), HasSubstr("line 7"));
  EXPECT_THAT(s.message(), HasSubstr("truncated"));
}

TEST_F(Dbow2TextCorruptTest, RandomCutsOfALargerFileGiveAnErrorOrAVocabularyButNeverCrash) {
  StatusOr<Vocabulary> original = VocabularyOf(RandomTree(6, 4, 3, false), 6, 4);
  ASSERT_TRUE(original.ok()) << original.status().ToString();
  const std::string path = Path("random.txt");
  ASSERT_TRUE(ExportDbow2Text(*original, path).ok());
  const std::string whole = ReadFileText(path);
  std::mt19937 rng(5);
  size_t loaded = 0;
  for (int trial = 0; trial < 100; ++trial) {
    const size_t cut = rng() % whole.size();
    StatusOr<Vocabulary> v = ImportDbow2Text(Write("cut.txt", whole.substr(0, cut)));
    if (v.ok()) {
      ++loaded;
      EXPECT_EQ(whole[cut - 1], '\n') << "cut at " << cut;
      EXPECT_LT(v->num_nodes(), original->num_nodes());
    } else {
      EXPECT_EQ(v.status().code(), StatusCode::kDataLoss) << "cut at " << cut;
    }
  }
  EXPECT_LT(loaded, 100u);
}

// Replaces line `line` (1-based) of the tiny text.
std::string TinyTextWithLine(size_t line, const std::string& replacement) {
  std::istringstream in(TinyText());
  std::string out;
  std::string l;
  for (size_t i = 1; std::getline(in, l); ++i) out += (i == line ? replacement : l) + "\n";
  return out;
}

TEST_F(Dbow2TextCorruptTest, MalformedLinesAreDataLossNamingTheLine) {
  const std::string zeros = Decimal(Filled(0));
  const struct {
    size_t line;
    std::string text;
    std::string message;
  } cases[] = {
      {1, "0 2 0 0", "k=0"},
      {1, "1 2 0 0", "k=1"},
      {1, "256 2 0 0", "k=256"},
      {1, "2 0 0 0", "L=0"},
      {1, "2 2 9 0", "scoring type 9"},
      {1, "2 2 0 4", "weighting type 4"},
      {1, "2 2 0", "expected 'k L scoring weighting'"},
      {1, "2 2 0 0 0", "expected 'k L scoring weighting'"},
      {1, "2 -2 0 0", "'-2'"},
      {1, "ten 2 0 0", "'ten'"},
      {3, "1 1 " + zeros, "found 34"},                 // no weight
      {3, "1 1 " + zeros + " 0.5 7", "more than 35"},  // one field too many
      {3, "1 1 300" + zeros.substr(1) + " 0.5", "descriptor byte 0 is 300"},
      {3, "1 1 1x" + zeros.substr(1) + " 0.5", "descriptor byte 0 '1x'"},
      {3, "1 2 " + zeros + " 0.5", "is_leaf is 2"},
      {3, "1 1 " + zeros + " abc", "weight 'abc'"},
      {3, "1 1 " + zeros + " nan", "weight 'nan'"},
      {3, "1 1 " + zeros + " inf", "weight 'inf'"},
      {3, "1 1 " + zeros + " 1e60", "weight '1e60'"},
      {3, "5 1 " + zeros + " 0.5", "parent 5 is not an earlier node"},
      {3, "2 1 " + zeros + " 0.5", "parent 2 is not an earlier node"},  // itself
      {5, "2 1 " + zeros + " 0.5", "parent 2 is a leaf"},
      {5, "0 1 " + zeros + " 0.5", "more than k=2 children"},
      {4, "", "empty line"},
  };
  for (const auto& c : cases) {
    const Status s = ImportDbow2Text(Write("bad.txt", TinyTextWithLine(c.line, c.text))).status();
    EXPECT_EQ(s.code(), StatusCode::kDataLoss) << c.text << ": " << s.ToString();
    EXPECT_THAT(s.message(), HasSubstr("line " + std::to_string(c.line) + ":")) << c.text;
    EXPECT_THAT(s.message(), HasSubstr(c.message)) << c.text;
  }
  // Reported on the first node too deep.
  const Status deep = ImportDbow2Text(Write("deep.txt", TinyTextWithLine(1, "2 1 0 0"))).status();
  EXPECT_EQ(deep.code(), StatusCode::kDataLoss);
  EXPECT_THAT(deep.message(), HasSubstr("line 3: node 2 is at depth 2, deeper than L=1"));
  // Node 3 marked internal (is_leaf 0) but without children.
  const std::string childless =
      "2 2 0 0\n0 0 " + zeros + " 0\n1 1 " + zeros + " 1\n0 0 " + zeros + " 0\n";
  const Status s = ImportDbow2Text(Write("childless.txt", childless)).status();
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_THAT(s.message(), HasSubstr("line 4: node 3 is not a leaf"));
}

// --- Export. ---

using Dbow2TextExportTest = Dbow2FormatTest;

TEST_F(Dbow2TextExportTest, ReproducesTheImportedFileLineForLine) {
  StatusOr<Vocabulary> v = ImportDbow2Text(Write("tiny.txt", TinyText("2 2 4 1")));
  ASSERT_TRUE(v.ok()) << v.status().ToString();
  const std::string out = Path("out.txt");
  ASSERT_TRUE(ExportDbow2Text(*v, out).ok());
  EXPECT_EQ(ReadFileText(out), TinyText("2 2 4 1"));
}

TEST_F(Dbow2TextExportTest, YamlToTextKeepsTieBreakingAndRenumbersWordsInLeafOrder) {
  // The tiny YAML lists node 5 (word 2) before its sibling node 2 (word 0): no text file can
  // keep both the sibling order and the word ids, so the words follow the leaf order of the
  // export (5, 2, 6, 4), as DBoW2 itself would number them, and everything else is kept.
  StatusOr<Vocabulary> v = ImportDbow2Yaml(Write("tiny.yml", TinyYaml(true)));
  ASSERT_TRUE(v.ok()) << v.status().ToString();
  const std::string out = Path("out.txt");
  ASSERT_TRUE(ExportDbow2Text(*v, out).ok());
  StatusOr<Vocabulary> copy = ImportDbow2Text(out);
  ASSERT_TRUE(copy.ok()) << copy.status().ToString();
  const WordId renumbered[4] = {1, 3, 0, 2};  // old word id -> new word id
  for (WordId w = 0; w < 4; ++w) EXPECT_EQ(copy->WordWeight(renumbered[w]), v->WordWeight(w));
  for (const Descriptor& d : {Filled(0x00), Filled(0xFF), HalfAndHalf(), With(Filled(0), 0, 7),
                              With(Filled(0xFF), 31, 0xF1)}) {
    EXPECT_EQ(copy->TransformOne(d.data()), renumbered[v->TransformOne(d.data())]);
  }
}

TEST_F(Dbow2TextExportTest, RoundTripKeepsBreadthFirstAndDbow2WordOrders) {
  for (bool dbow2_ids : {false, true}) {
    for (uint32_t seed = 1; seed <= 4; ++seed) {
      StatusOr<Vocabulary> v = VocabularyOf(RandomTree(5, 4, seed, dbow2_ids), 5, 4);
      ASSERT_TRUE(v.ok()) << v.status().ToString();
      const std::string out = Path("random.txt");
      ASSERT_TRUE(ExportDbow2Text(*v, out).ok());
      StatusOr<Vocabulary> copy = ImportDbow2Text(out);
      ASSERT_TRUE(copy.ok()) << copy.status().ToString();
      EXPECT_EQ(copy->num_words(), v->num_words());
      EXPECT_EQ(copy->checksum(), v->checksum()) << "seed " << seed << " dbow2 ids " << dbow2_ids;
      std::mt19937 rng(seed);
      for (int i = 0; i < 50; ++i) {
        Descriptor d;
        for (uint8_t& b : d) b = uint8_t(rng());
        EXPECT_EQ(copy->TransformOne(d.data()), v->TransformOne(d.data()));
      }
    }
  }
}

TEST_F(Dbow2TextExportTest, WordIdsAgainstSiblingOrderBecomeLeafOrderAsInDbow2) {
  // Root with two leaves whose word ids run against their order: no DBoW2 text file can keep
  // them; the export is still the same tree, and words are renumbered in leaf order.
  TreeNodeTable t;
  t.parent = {0, 0, 0};
  t.descriptors.resize(3 * 32, 0);
  std::fill(t.descriptors.begin() + 64, t.descriptors.end(), 0xFF);
  t.word = {kInvalidWordId, 1, 0};
  t.weight = {0.f, 0.25f, 4.f};
  StatusOr<Vocabulary> v = VocabularyOf(t, 2, 1);
  ASSERT_TRUE(v.ok()) << v.status().ToString();
  ASSERT_EQ(v->TransformOne(Filled(0x00).data()), 1u);
  const std::string out = Path("swapped.txt");
  ASSERT_TRUE(ExportDbow2Text(*v, out).ok());
  StatusOr<Vocabulary> copy = ImportDbow2Text(out);
  ASSERT_TRUE(copy.ok()) << copy.status().ToString();
  EXPECT_EQ(copy->TransformOne(Filled(0x00).data()), 0u);
  EXPECT_EQ(copy->TransformOne(Filled(0xFF).data()), 1u);
  EXPECT_EQ(copy->WordWeight(0), 0.25f);
  EXPECT_EQ(copy->WordWeight(1), 4.f);
}

TEST_F(Dbow2TextExportTest, RejectsVocabulariesDbow2TextCannotHold) {
  EXPECT_EQ(ExportDbow2Text(Vocabulary(), Path("empty.txt")).code(), StatusCode::kInvalidArgument);

  const TreeNodeTable tree = RandomTree(3, 2, 9, false);
  VocabularyInfo two_trees;
  two_trees.branching = 3;
  two_trees.depth = 2;
  two_trees.num_trees = 2;
  const TreeNodeTable trees[2] = {tree, tree};
  StatusOr<Vocabulary> forest = Vocabulary::FromTrees(two_trees, trees);
  ASSERT_TRUE(forest.ok()) << forest.status().ToString();
  EXPECT_EQ(ExportDbow2Text(*forest, Path("forest.txt")).code(), StatusCode::kInvalidArgument);

  TreeNodeTable wide = tree;
  wide.descriptors.resize(tree.size() * 64, 0);
  VocabularyInfo wide_info = two_trees;
  wide_info.num_trees = 1;
  wide_info.descriptor = {DescriptorType::kBinary, 64};
  StatusOr<Vocabulary> v64 = Vocabulary::FromTrees(wide_info, std::span(&wide, 1));
  ASSERT_TRUE(v64.ok()) << v64.status().ToString();
  EXPECT_EQ(ExportDbow2Text(*v64, Path("wide.txt")).code(), StatusCode::kInvalidArgument);

  TreeNodeTable sift = tree;
  sift.descriptors.assign(tree.size() * 128 * sizeof(float), 0);
  VocabularyInfo sift_info = wide_info;
  sift_info.descriptor = DescriptorFormat::Sift();
  StatusOr<Vocabulary> vsift = Vocabulary::FromTrees(sift_info, std::span(&sift, 1));
  ASSERT_TRUE(vsift.ok()) << vsift.status().ToString();
  EXPECT_EQ(ExportDbow2Text(*vsift, Path("sift.txt")).code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(std::filesystem::exists(Path("sift.txt")));
}

TEST_F(Dbow2TextExportTest, ReplacesAnExistingFileAndLeavesNoTemporaryBehind) {
  StatusOr<Vocabulary> v = ImportDbow2Text(Write("tiny.txt", TinyText()));
  ASSERT_TRUE(v.ok());
  const std::string out = Write("out.txt", "old content\n");
  ASSERT_TRUE(ExportDbow2Text(*v, out).ok());
  EXPECT_EQ(ReadFileText(out), TinyText());
  size_t files = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(dir_)) ++files;
  EXPECT_EQ(files, 2u);  // tiny.txt and out.txt

  const Status missing_dir = ExportDbow2Text(*v, Path("no/such/dir/out.txt"));
  EXPECT_FALSE(missing_dir.ok());
  EXPECT_EQ(missing_dir.code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace recog
