#include "core/vocabulary/vocabulary.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <set>

#include <gtest/gtest.h>

#include "core/vocabulary/vocabulary_trainer.h"
#include "tests/testing/synthetic.h"

namespace recog {
namespace {

using testing::ClusteredBinaryDescriptors;
using testing::ClusteredTrainingSet;
using testing::RandomDescriptors;

Vocabulary TrainSmall(uint32_t k, uint32_t depth, uint32_t trees, uint64_t seed = 1) {
  TrainingOptions options = testing::SmallTrainingOptions(k, depth, /*threads=*/1, seed);
  options.trees = trees;
  auto vocabulary = TrainVocabulary(ClusteredTrainingSet(40, 100, seed), options);
  EXPECT_TRUE(vocabulary.ok()) << vocabulary.status().ToString();
  return std::move(vocabulary).value();
}

// Greedy descent written against the public tree accessors: at each level the nearest child,
// the first one on a tie; over several trees the nearest leaf, the first tree on a tie.
WordId BruteForceWord(const Vocabulary& voc, const uint8_t* d) {
  double best = std::numeric_limits<double>::infinity();
  WordId word = kInvalidWordId;
  for (uint32_t t = 0; t < voc.info().num_trees; ++t) {
    NodeId node = voc.Root(t);
    double node_distance = 0;
    while (!voc.IsLeaf(node)) {
      NodeId best_child = voc.FirstChild(node);
      double best_child_distance = std::numeric_limits<double>::infinity();
      for (uint32_t c = 0; c < voc.ChildCount(node); ++c) {
        const NodeId child = voc.FirstChild(node) + c;
        const double dist = DescriptorDistance(voc.info().descriptor, d, voc.NodeDescriptor(child));
        if (dist < best_child_distance) {
          best_child_distance = dist;
          best_child = child;
        }
      }
      node = best_child;
      node_distance = best_child_distance;
    }
    if (node_distance < best) {
      best = node_distance;
      word = voc.WordOf(node);
    }
  }
  return word;
}

TEST(VocabularyTest, TransformOneEqualsABruteForceGreedyDescent) {
  const Vocabulary voc = TrainSmall(10, 3, 1);
  const cv::Mat queries = RandomDescriptors(500, 99);
  for (int r = 0; r < queries.rows; ++r) {
    EXPECT_EQ(voc.TransformOne(queries.ptr<uint8_t>(r)),
              BruteForceWord(voc, queries.ptr<uint8_t>(r)));
  }
}

TEST(VocabularyTest, SeveralTreesPickTheNearestLeafOverAllTrees) {
  const Vocabulary voc = TrainSmall(5, 3, 4);
  ASSERT_EQ(voc.info().num_trees, 4u);
  const cv::Mat queries = ClusteredBinaryDescriptors(300, 40, 0.1, 5);
  std::set<uint32_t> trees_used;
  for (int r = 0; r < queries.rows; ++r) {
    const WordId w = voc.TransformOne(queries.ptr<uint8_t>(r));
    EXPECT_EQ(w, BruteForceWord(voc, queries.ptr<uint8_t>(r)));
  }
  // Word ids are global over the trees: all distinct, 0..num_words-1.
  std::set<WordId> words;
  for (NodeId n = 0; n < voc.num_nodes(); ++n) {
    if (voc.IsLeaf(n)) words.insert(voc.WordOf(n));
  }
  EXPECT_EQ(words.size(), voc.num_words());
  EXPECT_EQ(*words.rbegin(), voc.num_words() - 1);
}

// TransformEach and Transform descend rows in batches of 8; TransformOne one row at a time. They
// must agree on every row's word and direct-index node, for one tree and for several (the node
// nearest over all trees), at every level and for a row count that is not a multiple of 8.
TEST(VocabularyTest, BatchedTransformsAgreeWithTransformOneRowByRow) {
  const cv::Mat queries = ClusteredBinaryDescriptors(203, 40, 0.1, 17);
  for (uint32_t trees : {1u, 4u}) {
    const Vocabulary voc = TrainSmall(5, 3, trees);
    std::set<NodeId> nodes_seen;
    for (int levels_up : {0, 1, 2, 3, 9}) {
      std::vector<WordId> words;
      std::vector<NodeId> nodes;
      ASSERT_TRUE(voc.TransformEach(queries, &words, &nodes, levels_up).ok());
      ASSERT_EQ(words.size(), size_t(queries.rows));
      ASSERT_EQ(nodes.size(), size_t(queries.rows));
      BowVector bow;
      FeatureVector fv;
      ASSERT_TRUE(voc.Transform(queries, &bow, &fv, levels_up).ok());
      std::vector<NodeId> node_in_fv(size_t(queries.rows), std::numeric_limits<NodeId>::max());
      for (size_t i = 0; i < fv.size(); ++i) {
        for (uint32_t f : fv.features(i)) node_in_fv[f] = fv.node(i);
      }
      for (int r = 0; r < queries.rows; ++r) {
        NodeId node = 0;
        const WordId word = voc.TransformOne(queries.ptr<uint8_t>(r), &node, levels_up);
        EXPECT_EQ(words[size_t(r)], word) << trees << " trees, row " << r;
        EXPECT_EQ(nodes[size_t(r)], node) << trees << " trees, levels_up " << levels_up;
        EXPECT_EQ(node_in_fv[size_t(r)], node) << trees << " trees, levels_up " << levels_up;
        nodes_seen.insert(node);
      }
    }
    if (trees > 1) {
      // The nodes come from more than the first tree.
      EXPECT_TRUE(std::any_of(nodes_seen.begin(), nodes_seen.end(),
                              [&](NodeId n) { return n >= voc.Root(1); }));
    }
  }
}

TEST(VocabularyTest, TransformEachRejectsWhatTransformRejects) {
  const Vocabulary voc = TrainSmall(6, 2, 2);
  std::vector<WordId> words = {1, 2};
  EXPECT_EQ(voc.TransformEach(cv::Mat(10, 64, CV_8U, cv::Scalar(0)), &words).code(),
            StatusCode::kInvalidArgument);
  ASSERT_TRUE(voc.TransformEach(cv::Mat(0, 32, CV_8U), &words).ok());
  EXPECT_TRUE(words.empty());
  EXPECT_EQ(Vocabulary().TransformEach(RandomDescriptors(3, 1), &words).code(),
            StatusCode::kFailedPrecondition);
}

TEST(VocabularyTest, TfIdfBowIsTheL1NormalisedSumOfWordWeights) {
  const Vocabulary voc = TrainSmall(8, 3, 1);
  const cv::Mat d = ClusteredBinaryDescriptors(200, 40, 0.08, 21);
  BowVector bow;
  ASSERT_TRUE(voc.Transform(d, &bow).ok());
  std::map<WordId, double> expected;
  double total = 0.0;
  for (int r = 0; r < d.rows; ++r) {
    const WordId w = voc.TransformOne(d.ptr<uint8_t>(r));
    if (voc.WordWeight(w) > 0) {
      expected[w] += voc.WordWeight(w);
      total += voc.WordWeight(w);
    }
  }
  ASSERT_EQ(bow.size(), expected.size());
  for (const BowEntry& e : bow.entries()) {
    EXPECT_NEAR(e.value, expected[e.word] / total, 1e-6);
  }
}

TEST(VocabularyTest, UnnormalisedTfIdfDividesByTheNumberOfFeatures) {
  const Vocabulary voc = TrainSmall(8, 3, 1);
  const cv::Mat d = ClusteredBinaryDescriptors(50, 40, 0.08, 22);
  BowVector bow;
  ASSERT_TRUE(voc.Transform(d, &bow, nullptr, 0, BowNormalization::kNone).ok());
  double sum = 0.0, expected = 0.0;
  for (const BowEntry& e : bow.entries()) sum += e.value;
  for (int r = 0; r < d.rows; ++r) expected += voc.WordWeight(voc.TransformOne(d.ptr<uint8_t>(r)));
  EXPECT_NEAR(sum, expected / d.rows, 1e-5);
}

TEST(VocabularyTest, FeatureVectorGroupsEveryFeatureUnderItsNodeAtTheRequestedLevel) {
  const Vocabulary voc = TrainSmall(6, 4, 1);
  const cv::Mat d = ClusteredBinaryDescriptors(300, 40, 0.08, 23);
  for (int levels_up : {0, 1, 2, 4, 9}) {
    BowVector bow;
    FeatureVector fv;
    ASSERT_TRUE(voc.Transform(d, &bow, &fv, levels_up).ok());
    EXPECT_EQ(fv.num_features(), size_t(d.rows));
    EXPECT_TRUE(std::is_sorted(fv.nodes().begin(), fv.nodes().end()));
    std::set<uint32_t> seen;
    for (size_t i = 0; i < fv.size(); ++i) {
      for (uint32_t f : fv.features(i)) {
        NodeId node = 0;
        voc.TransformOne(d.ptr<uint8_t>(int(f)), &node, levels_up);
        EXPECT_EQ(node, fv.node(i));
        seen.insert(f);
      }
    }
    EXPECT_EQ(seen.size(), size_t(d.rows)) << "levels_up " << levels_up;
    if (levels_up >= 4) {
      EXPECT_EQ(fv.size(), 1u) << "the root holds every feature";
    }
  }
}

TEST(VocabularyTest, DirectIndexNodeAtLevelZeroIsTheWordsLeaf) {
  const Vocabulary voc = TrainSmall(6, 3, 1);
  const cv::Mat d = RandomDescriptors(50, 3);
  for (int r = 0; r < d.rows; ++r) {
    NodeId node = 0;
    const WordId w = voc.TransformOne(d.ptr<uint8_t>(r), &node, 0);
    ASSERT_TRUE(voc.IsLeaf(node));
    EXPECT_EQ(voc.WordOf(node), w);
  }
}

// A hand-made one-level tree of two words: word 0 under centroid 0x00.., word 1 under 0xff..
TreeNodeTable TwoWordTree(float weight0, float weight1) {
  TreeNodeTable t;
  t.parent = {0, 0, 0};
  t.descriptors.assign(3 * 32, 0);
  std::fill(t.descriptors.begin() + 64, t.descriptors.end(), 0xff);
  t.word = {kInvalidWordId, kInvalidWordId, kInvalidWordId};
  t.weight = {0.f, weight0, weight1};
  return t;
}

VocabularyInfo TwoWordInfo(WeightingType weighting) {
  VocabularyInfo info;
  info.branching = 2;
  info.depth = 1;
  info.weighting = weighting;
  return info;
}

TEST(VocabularyTest, WeightingTypesFollowTheirDefinitions) {
  const TreeNodeTable t = TwoWordTree(2.f, 0.5f);
  cv::Mat d(3, 32, CV_8U, cv::Scalar(0));
  d.row(2).setTo(0xff);  // two features of word 0, one of word 1
  const double n = 3;
  struct Case {
    WeightingType weighting;
    double w0, w1;  // unnormalised
  };
  for (const Case& c :
       {Case{WeightingType::kTfIdf, 2 * 2.0 / n, 0.5 / n},
        Case{WeightingType::kTf, 2 * 2.0 / n, 0.5 / n}, Case{WeightingType::kIdf, 2.0, 0.5},
        Case{WeightingType::kBinary, 2.0, 0.5}}) {
    auto voc = Vocabulary::FromTrees(TwoWordInfo(c.weighting), std::span(&t, 1));
    ASSERT_TRUE(voc.ok()) << voc.status().ToString();
    BowVector bow;
    ASSERT_TRUE(voc->Transform(d, &bow, nullptr, 0, BowNormalization::kNone).ok());
    EXPECT_NEAR(bow.ValueOf(0), c.w0, 1e-6) << WeightingName(c.weighting);
    EXPECT_NEAR(bow.ValueOf(1), c.w1, 1e-6) << WeightingName(c.weighting);
  }
}

TEST(VocabularyTest, WordsOfWeightZeroAreLeftOutOfTheBow) {
  const TreeNodeTable t = TwoWordTree(0.f, 1.f);
  auto voc = Vocabulary::FromTrees(TwoWordInfo(WeightingType::kTfIdf), std::span(&t, 1));
  ASSERT_TRUE(voc.ok());
  cv::Mat d(2, 32, CV_8U, cv::Scalar(0));
  d.row(1).setTo(0xff);
  BowVector bow;
  ASSERT_TRUE(voc->Transform(d, &bow).ok());
  ASSERT_EQ(bow.size(), 1u);
  EXPECT_EQ(bow.entries()[0].word, 1u);
  EXPECT_FLOAT_EQ(bow.entries()[0].value, 1.f);
}

TEST(VocabularyTest, FloatDescriptorsUseTheSameCodePathWithL2) {
  TrainingSet set;
  set.format = DescriptorFormat::Sift();
  for (int i = 0; i < 20; ++i) {
    ASSERT_TRUE(set.AddImage(RandomDescriptors(50, 100 + i, DescriptorFormat::Sift())).ok());
  }
  TrainingOptions options;
  options.branching = 5;
  options.depth = 2;
  options.threads = 1;
  auto voc = TrainVocabulary(std::move(set), options);
  ASSERT_TRUE(voc.ok()) << voc.status().ToString();
  EXPECT_EQ(voc->info().descriptor, DescriptorFormat::Sift());
  const cv::Mat q = RandomDescriptors(100, 7, DescriptorFormat::Sift());
  for (int r = 0; r < q.rows; ++r) {
    EXPECT_EQ(voc->TransformOne(q.ptr<uint8_t>(r)), BruteForceWord(*voc, q.ptr<uint8_t>(r)));
  }
  BowVector bow;
  EXPECT_TRUE(voc->Transform(q, &bow).ok());
  EXPECT_FALSE(bow.empty());
}

TEST(VocabularyTest, TransformRejectsDescriptorsOfAnotherFormat) {
  const Vocabulary voc = TrainSmall(6, 2, 1);
  BowVector bow;
  const Status wrong_length = voc.Transform(cv::Mat(10, 64, CV_8U, cv::Scalar(0)), &bow);
  EXPECT_EQ(wrong_length.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(wrong_length.message().find("64 columns"), std::string::npos) << wrong_length.message();
  EXPECT_EQ(voc.Transform(cv::Mat(10, 32, CV_32F, cv::Scalar(0)), &bow).code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(voc.Transform(cv::Mat(10, 32, CV_8UC2, cv::Scalar(0)), &bow).code(),
            StatusCode::kInvalidArgument);
}

TEST(VocabularyTest, TransformOfNoDescriptorsGivesEmptyOutputs) {
  const Vocabulary voc = TrainSmall(6, 2, 1);
  BowVector bow({{1, 1.f}});
  FeatureVector fv;
  ASSERT_TRUE(voc.Transform(cv::Mat(0, 32, CV_8U), &bow, &fv).ok());
  EXPECT_TRUE(bow.empty());
  EXPECT_TRUE(fv.empty());
  ASSERT_TRUE(voc.Transform(cv::Mat(), &bow, &fv).ok());
}

TEST(VocabularyTest, AnEmptyVocabularyRefusesToTransform) {
  Vocabulary empty;
  BowVector bow;
  EXPECT_EQ(empty.Transform(RandomDescriptors(3, 1), &bow).code(), StatusCode::kFailedPrecondition);
}

TEST(VocabularyTest, FromTreesRejectsInconsistentTables) {
  VocabularyInfo info;
  info.branching = 2;
  info.depth = 2;
  TreeNodeTable good;
  good.parent = {0, 0, 0};
  good.descriptors.assign(3 * 32, 0);
  good.word = {kInvalidWordId, kInvalidWordId, kInvalidWordId};
  good.weight = {0.f, 1.f, 1.f};
  ASSERT_TRUE(Vocabulary::FromTrees(info, std::span(&good, 1)).ok());

  TreeNodeTable cyclic = good;
  cyclic.parent = {0, 2, 1};  // 1 and 2 are each other's parents: unreachable from the root
  EXPECT_EQ(Vocabulary::FromTrees(info, std::span(&cyclic, 1)).status().code(),
            StatusCode::kInvalidArgument);
  TreeNodeTable orphan = good;
  orphan.parent = {0, 0, 7};
  EXPECT_EQ(Vocabulary::FromTrees(info, std::span(&orphan, 1)).status().code(),
            StatusCode::kInvalidArgument);
  TreeNodeTable short_rows = good;
  short_rows.descriptors.resize(40);
  EXPECT_FALSE(Vocabulary::FromTrees(info, std::span(&short_rows, 1)).ok());
  TreeNodeTable duplicate_words = good;
  duplicate_words.word = {kInvalidWordId, 0, 0};
  EXPECT_FALSE(Vocabulary::FromTrees(info, std::span(&duplicate_words, 1)).ok());
  TreeNodeTable root_only;
  root_only.parent = {0};
  root_only.descriptors.assign(32, 0);
  root_only.word = {kInvalidWordId};
  root_only.weight = {0.f};
  EXPECT_FALSE(Vocabulary::FromTrees(info, std::span(&root_only, 1)).ok());
  VocabularyInfo two_trees = info;
  two_trees.num_trees = 2;
  EXPECT_FALSE(Vocabulary::FromTrees(two_trees, std::span(&good, 1)).ok());
  VocabularyInfo bad_k = info;
  bad_k.branching = 1;
  EXPECT_FALSE(Vocabulary::FromTrees(bad_k, std::span(&good, 1)).ok());
}

TEST(VocabularyTest, GivenWordIdsArePreservedAndTiesGoToTheFirstChild) {
  VocabularyInfo info;
  info.branching = 2;
  info.depth = 1;
  TreeNodeTable t;
  t.parent = {0, 0, 0};
  t.descriptors.assign(3 * 32, 0);  // both children identical: every descriptor ties
  t.word = {kInvalidWordId, 1, 0};
  t.weight = {0.f, 0.5f, 0.25f};
  auto voc = Vocabulary::FromTrees(info, std::span(&t, 1));
  ASSERT_TRUE(voc.ok());
  const cv::Mat d = RandomDescriptors(1, 4);
  EXPECT_EQ(voc->TransformOne(d.ptr<uint8_t>(0)), 1u);
  EXPECT_FLOAT_EQ(voc->WordWeight(1), 0.5f);
  EXPECT_FLOAT_EQ(voc->WordWeight(0), 0.25f);
}

TEST(VocabularyTest, MemoryOfABinaryVocabularyIsAboutThirtySevenBytesPerNode) {
  const Vocabulary voc = TrainSmall(10, 3, 1);
  const double per_node = double(voc.MemoryBytes()) / double(voc.num_nodes());
  EXPECT_LT(per_node, 37.0 + 4.0 + 8.0);  // node arrays + word weights + alignment padding
}

}  // namespace
}  // namespace recog
