#include "core/vocabulary/vocabulary_trainer.h"

#include <cmath>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/testing/synthetic.h"

namespace recog {
namespace {

using testing::ClusteredBinaryDescriptors;
using testing::ClusteredTrainingSet;
using testing::RandomDescriptors;

TrainingOptions Options(uint32_t k, uint32_t depth, uint32_t threads, uint64_t seed = 3) {
  return testing::SmallTrainingOptions(k, depth, threads, seed);
}

// Largest depth of any leaf and most children of any node, from the public accessors.
void TreeShape(const Vocabulary& v, uint32_t* max_depth, uint32_t* max_children) {
  *max_depth = 0;
  *max_children = 0;
  for (uint32_t t = 0; t < v.info().num_trees; ++t) {
    std::vector<std::pair<NodeId, uint32_t>> stack{{v.Root(t), 0}};
    while (!stack.empty()) {
      auto [node, depth] = stack.back();
      stack.pop_back();
      *max_depth = std::max(*max_depth, depth);
      *max_children = std::max(*max_children, v.ChildCount(node));
      for (uint32_t c = 0; c < v.ChildCount(node); ++c)
        stack.push_back({v.FirstChild(node) + c, depth + 1});
    }
  }
}

TEST(VocabularyTrainerTest, TreesRespectBranchingAndDepth) {
  auto voc = TrainVocabulary(ClusteredTrainingSet(50, 200, 1), Options(7, 3, 1));
  ASSERT_TRUE(voc.ok()) << voc.status().ToString();
  uint32_t depth = 0, children = 0;
  TreeShape(*voc, &depth, &children);
  EXPECT_EQ(depth, 3u);
  EXPECT_EQ(children, 7u);
  EXPECT_GT(voc->num_words(), 7u * 7u);
  EXPECT_LE(voc->num_words(), 7u * 7u * 7u);
}

TEST(VocabularyTrainerTest, TrainingIsDeterministicForASeedWhateverTheThreadCount) {
  auto a = TrainVocabulary(ClusteredTrainingSet(60, 200, 2), Options(8, 3, 1, 77));
  auto b = TrainVocabulary(ClusteredTrainingSet(60, 200, 2), Options(8, 3, 2, 77));
  auto c = TrainVocabulary(ClusteredTrainingSet(60, 200, 2), Options(8, 3, 2, 78));
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  EXPECT_EQ(a->checksum(), b->checksum());
  ASSERT_EQ(a->buffer().size(), b->buffer().size());
  EXPECT_TRUE(std::equal(a->buffer().begin(), a->buffer().end(), b->buffer().begin()));
  EXPECT_NE(a->checksum(), c->checksum()) << "another seed should give another vocabulary";
}

TEST(VocabularyTrainerTest, LargeRootSplitsAreDeterministicAcrossThreadCounts) {
  // Over 65536 rows the root's Lloyd iterations run in parallel chunks.
  auto a = TrainVocabulary(ClusteredTrainingSet(100, 700, 4), Options(10, 2, 1, 5));
  auto b = TrainVocabulary(ClusteredTrainingSet(100, 700, 4), Options(10, 2, 2, 5));
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->checksum(), b->checksum());
}

TEST(VocabularyTrainerTest, IdfIsLogOfImagesOverImagesContainingTheWord) {
  TrainingSet set = ClusteredTrainingSet(30, 80, 9);
  TrainingSet copy = set;
  auto voc = TrainVocabulary(std::move(set), Options(6, 2, 1));
  ASSERT_TRUE(voc.ok());
  std::map<WordId, std::set<size_t>> images_of_word;
  for (size_t img = 0; img < copy.num_images(); ++img) {
    for (uint32_t r = copy.image_offsets[img]; r < copy.image_offsets[img + 1]; ++r) {
      images_of_word[voc->TransformOne(copy.descriptors.data() + size_t(r) * 32)].insert(img);
    }
  }
  for (WordId w = 0; w < voc->num_words(); ++w) {
    const double n = double(images_of_word[w].size());
    const double expected = n > 0 ? std::log(30.0 / n) : 0.0;
    EXPECT_NEAR(voc->WordWeight(w), expected, 1e-6) << "word " << w;
  }
}

TEST(VocabularyTrainerTest, TrainingDescriptorsReachTheLeafOfTheirOwnCluster) {
  // Tight, well separated clusters: every training descriptor of a cluster ends in few words.
  TrainingSet set;
  const cv::Mat d = ClusteredBinaryDescriptors(2000, 8, 0.01, 12);
  ASSERT_TRUE(set.AddImage(d).ok());
  auto voc = TrainVocabulary(std::move(set), Options(8, 1, 1));
  ASSERT_TRUE(voc.ok());
  EXPECT_EQ(voc->num_words(), 8u);
}

TEST(VocabularyTrainerTest, FewerDescriptorsThanBranchesGiveOneLeafEach) {
  TrainingSet set;
  ASSERT_TRUE(set.AddImage(RandomDescriptors(4, 1)).ok());
  auto voc = TrainVocabulary(std::move(set), Options(10, 3, 1));
  ASSERT_TRUE(voc.ok());
  EXPECT_EQ(voc->num_words(), 4u);
}

TEST(VocabularyTrainerTest, IdenticalDescriptorsGiveASingleWord) {
  TrainingSet set;
  ASSERT_TRUE(set.AddImage(cv::Mat(500, 32, CV_8U, cv::Scalar(0x5a))).ok());
  auto voc = TrainVocabulary(std::move(set), Options(10, 4, 2));
  ASSERT_TRUE(voc.ok()) << voc.status().ToString();
  EXPECT_EQ(voc->num_words(), 1u);
}

TEST(VocabularyTrainerTest, SeveralTreesAreTrainedWithDifferentSeeds) {
  TrainingOptions o = Options(6, 2, 2);
  o.trees = 3;
  auto voc = TrainVocabulary(ClusteredTrainingSet(40, 100, 3), o);
  ASSERT_TRUE(voc.ok());
  ASSERT_EQ(voc->info().num_trees, 3u);
  // The first-level centroids of the trees are not all the same.
  const auto first_child_row = [&](uint32_t t) {
    const uint8_t* p = voc->NodeDescriptor(voc->FirstChild(voc->Root(t)));
    return std::vector<uint8_t>(p, p + 32);
  };
  EXPECT_TRUE(first_child_row(0) != first_child_row(1) || first_child_row(1) != first_child_row(2));
}

TEST(VocabularyTrainerTest, ProgressIsReportedUpToTheTotal) {
  TrainingOptions o = Options(5, 3, 2);
  std::map<std::string, std::pair<uint64_t, uint64_t>> last;
  o.progress = [&](std::string_view stage, uint64_t done, uint64_t total) {
    auto& [d, t] = last[std::string(stage)];
    EXPECT_GE(done, d);
    d = done;
    t = total;
  };
  auto voc = TrainVocabulary(ClusteredTrainingSet(20, 100, 6), o);
  ASSERT_TRUE(voc.ok());
  ASSERT_TRUE(last.count("clustering") && last.count("weighting"));
  EXPECT_EQ(last["clustering"].first, last["clustering"].second);
  EXPECT_EQ(last["weighting"].first, last["weighting"].second);
  EXPECT_EQ(last["weighting"].second, 2000u);
}

TEST(VocabularyTrainerTest, InvalidOptionsAndSetsAreRejected) {
  EXPECT_EQ(TrainVocabulary(ClusteredTrainingSet(2, 10, 1), Options(1, 3, 1)).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(TrainVocabulary(ClusteredTrainingSet(2, 10, 1), Options(10, 0, 1)).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(TrainVocabulary(ClusteredTrainingSet(2, 10, 1), Options(10, 12, 1)).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(TrainVocabulary(TrainingSet{}, Options(10, 3, 1)).status().code(),
            StatusCode::kInvalidArgument);
  TrainingSet set;
  EXPECT_EQ(set.AddImage(cv::Mat(3, 16, CV_8U)).code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(set.AddImage(cv::Mat()).ok()) << "an image without features is fine";
  EXPECT_EQ(set.num_images(), 1u);
}

}  // namespace
}  // namespace recog
