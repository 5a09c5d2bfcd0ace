#include "bench/bench_support.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <numeric>
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

std::vector<FeatureSet> RealImageFeatures(uint64_t seed) {
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
  std::vector<FeatureSet> photos;
  FeatureSet features;
  for (const std::string& f : files) {
    auto image = ReadGrayImage(f);
    if (!image.ok() || !(*extractor)->Extract(*image, &features).ok()) continue;
    if (features.size() < 50) continue;
    features.descriptors = features.descriptors.clone();
    photos.push_back(std::move(features));
    features = {};
  }
  return photos;
}

std::vector<cv::Mat> RealImageDescriptors(uint64_t seed) {
  std::vector<cv::Mat> descriptors;
  for (FeatureSet& photo : RealImageFeatures(seed)) descriptors.push_back(photo.descriptors);
  return descriptors;
}

BowVector Transform(const Vocabulary& vocabulary, const cv::Mat& descriptors) {
  BowVector bow;
  if (!vocabulary.Transform(descriptors, &bow).ok()) std::abort();
  return bow;
}

void RandomSubset(const cv::Mat& all, std::mt19937_64& rng, std::vector<int>* rows,
                  cv::Mat* subset) {
  std::uniform_real_distribution<double> keep(0.6, 1.0);
  rows->resize(size_t(all.rows));
  std::iota(rows->begin(), rows->end(), 0);
  std::shuffle(rows->begin(), rows->end(), rng);
  rows->resize(size_t(all.rows * keep(rng)));
  subset->create(int(rows->size()), all.cols, all.type());
  for (size_t r = 0; r < rows->size(); ++r) all.row((*rows)[r]).copyTo(subset->row(int(r)));
}

void RandomSubset(const FeatureSet& all, std::mt19937_64& rng, std::vector<int>* rows,
                  FeatureSet* subset) {
  RandomSubset(all.descriptors, rng, rows, &subset->descriptors);
  subset->keypoints.clear();
  for (int r : *rows) subset->keypoints.push_back(all.keypoints[size_t(r)]);
  subset->image_size = all.image_size;
}

void AddEntry(Database& db, const BowVector& bow, int features) {
  static const cv::Mat descriptors(1000, 32, CV_8U, cv::Scalar(0));
  static const std::vector<uint32_t> all = [] {
    std::vector<uint32_t> v(1000);
    std::iota(v.begin(), v.end(), 0u);
    return v;
  }();
  FeatureSet f;
  f.descriptors = descriptors.rowRange(0, features);
  f.keypoints.resize(size_t(features));
  FeatureVector direct;
  direct.AppendNode(0, std::span(all.data(), size_t(features)));
  if (!db.AddConverted(bow, direct, f).ok()) std::abort();
}

namespace {

// GrowRealDatabase's order: add(photo) for every photo once when `db` is empty, then add(subset)
// with random subsets of the photos in turn (RandomSubset) until `db` holds `entries` entries.
template <typename Photo, typename Add>
void GrowFromPhotos(Database& db, std::span<const Photo> photos, size_t entries,
                    std::mt19937_64& rng, Add add) {
  if (db.size() == 0) {
    for (const Photo& photo : photos) add(photo);
  }
  std::vector<int> rows;
  Photo subset;
  for (size_t i = db.size() - photos.size(); db.size() < entries; ++i) {
    RandomSubset(photos[i % photos.size()], rng, &rows, &subset);
    add(subset);
  }
}

}  // namespace

void GrowRealDatabase(Database& db, std::span<const cv::Mat> photos, size_t entries,
                      std::mt19937_64& rng, std::vector<double>* insert_ms, int features) {
  GrowFromPhotos(db, photos, entries, rng, [&](const cv::Mat& descriptors) {
    const BowVector bow = Transform(db.vocabulary(), descriptors);
    const auto start = std::chrono::steady_clock::now();
    AddEntry(db, bow, features);
    if (insert_ms != nullptr) {
      insert_ms->push_back(
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
              .count());
    }
  });
}

void GrowRealDatabase(Database& db, std::span<const FeatureSet> photos, size_t entries,
                      std::mt19937_64& rng) {
  GrowFromPhotos(db, photos, entries, rng, [&](const FeatureSet& features) {
    if (!db.Add(features).ok()) std::abort();
  });
}

uint64_t DirectoryBytes(const std::string& dir, const std::string& only_under) {
  uint64_t bytes = 0;
  for (const auto& f : std::filesystem::recursive_directory_iterator(dir)) {
    if (!f.is_regular_file()) continue;
    if (!only_under.empty() && f.path().string().rfind(only_under, 0) != 0) continue;
    bytes += f.file_size();
  }
  return bytes;
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
