#include "bench/bench_support.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>

#include "core/features/feature_extractor.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tests/testing/data_paths.h"
#include "tools/common/cli_support.h"

namespace recog::bench {

std::vector<cv::Mat> CorridorDescriptorSets(int per_set) {
  std::vector<std::string> files;
  if (testing::HasSharedData("places/corridor/images/1.jpg")) {
    for (int i = 1; i <= 84; ++i) {
      files.push_back(testing::SharedData("places/corridor/images/" + std::to_string(i) + ".jpg"));
    }
  } else {
    for (const char* f : {"1.jpg", "20.jpg", "41.jpg", "60.jpg"}) {
      files.push_back(testing::ProjectTestData(std::string("corridor/") + f));
    }
  }
  auto extractor = CreateFeatureExtractor(PlaceFeatureOptions());
  cv::Mat all;
  FeatureSet features;
  for (const std::string& f : files) {
    auto image = ReadGrayImage(f);
    if (!image.ok() || !(*extractor)->Extract(*image, &features).ok()) continue;
    all.push_back(features.descriptors);
  }
  std::vector<cv::Mat> sets;
  for (int r = 0; r + per_set <= all.rows; r += per_set) {
    sets.push_back(all.rowRange(r, r + per_set).clone());
  }
  if (sets.empty()) {
    std::fprintf(stderr, "bench: no corridor images found\n");
    std::exit(2);
  }
  return sets;
}

Vocabulary RandomFullTreeVocabulary(uint32_t k, uint32_t levels, uint64_t seed) {
  TreeNodeTable t;
  // Nodes in breadth-first order: node i's children are k*i+1 .. k*i+k.
  size_t nodes = 1, level_size = 1;
  for (uint32_t l = 0; l < levels; ++l) {
    level_size *= k;
    nodes += level_size;
  }
  t.parent.resize(nodes);
  t.word.assign(nodes, kInvalidWordId);
  t.weight.resize(nodes);
  t.descriptors.resize(nodes * 32);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> weight(0.01f, 10.f);
  for (size_t i = 1; i < nodes; ++i) {
    t.parent[i] = uint32_t((i - 1) / k);
    t.weight[i] = weight(rng);
  }
  for (size_t i = 0; i < t.descriptors.size(); i += 8) {
    const uint64_t bits = rng();
    std::memcpy(&t.descriptors[i], &bits, 8);
  }
  VocabularyInfo info;
  info.branching = k;
  info.depth = levels;
  auto vocabulary = Vocabulary::FromTrees(info, std::span(&t, 1));
  if (!vocabulary.ok()) {
    std::fprintf(stderr, "bench: %s\n", vocabulary.status().ToString().c_str());
    std::exit(2);
  }
  return std::move(vocabulary).value();
}

Vocabulary LoadBundledPlaceVocabulary() {
  const std::string path = std::string(RECOG_SOURCE_DIR) + "/vocabularies/place_orb_k10_l5.rvoc";
  auto vocabulary = LoadVocabulary(path);
  if (!vocabulary.ok()) {
    std::fprintf(stderr, "bench: %s\n", vocabulary.status().ToString().c_str());
    std::exit(2);
  }
  return std::move(vocabulary).value();
}

std::vector<cv::Mat> RealImageDescriptors(uint64_t seed) {
  const std::string caltech = testing::SharedData("training/caltech101");
  auto listed = cli::ListImages(
      std::filesystem::exists(caltech) ? caltech : testing::ProjectTestData("corridor"));
  if (!listed.ok()) {
    std::fprintf(stderr, "bench: %s\n", listed.status().ToString().c_str());
    std::exit(2);
  }
  std::vector<std::string> files = std::move(listed).value();
  std::mt19937_64 rng(seed);
  std::shuffle(files.begin(), files.end(), rng);
  auto extractor = CreateFeatureExtractor(FeatureOptions{});
  std::vector<cv::Mat> descriptors;
  FeatureSet features;
  for (const std::string& f : files) {
    auto image = ReadGrayImage(f);
    if (!image.ok() || !(*extractor)->Extract(*image, &features).ok()) continue;
    if (features.size() >= 50) descriptors.push_back(features.descriptors.clone());
  }
  return descriptors;
}

std::string TempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("recog_bench_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

double Percentile(const std::vector<double>& sorted, double p) {
  if (sorted.empty()) return 0;
  const size_t rank = size_t(std::ceil(p / 100 * double(sorted.size())));
  return sorted[std::clamp<size_t>(rank, 1, sorted.size()) - 1];
}

}  // namespace recog::bench
