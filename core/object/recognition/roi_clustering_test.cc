#include "core/object/recognition/roi_clustering.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <numeric>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "core/features/feature_extractor.h"
#include "tests/testing/option_cases.h"
#include "tests/testing/test_data.h"

namespace recog {
namespace {

// Points with the blob each one was drawn from.
struct Scene {
  std::vector<cv::Point2f> points;
  std::vector<int> blob;
};

double Uniform(std::mt19937_64& rng) { return double(rng() >> 11) * 0x1.0p-53; }

// Adds `count` points of an isotropic Gaussian blob (Box-Muller on a seeded generator, so the
// scene is the same with every standard library).
void AddBlob(Scene* scene, cv::Point2f centre, double sigma, int count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  const int id =
      scene->blob.empty() ? 0 : *std::max_element(scene->blob.begin(), scene->blob.end()) + 1;
  for (int i = 0; i < count; ++i) {
    const double radius = sigma * std::sqrt(-2.0 * std::log(1.0 - Uniform(rng)));
    const double angle = 2.0 * std::numbers::pi * Uniform(rng);
    scene->points.emplace_back(float(centre.x + radius * std::cos(angle)),
                               float(centre.y + radius * std::sin(angle)));
    scene->blob.push_back(id);
  }
}

// Mixes the points of the blobs, so that region indices are not simply ranges.
void Shuffle(Scene* scene, uint64_t seed) {
  std::mt19937_64 rng(seed);
  for (size_t i = scene->points.size(); i > 1; --i) {
    const size_t j = size_t(Uniform(rng) * double(i));
    std::swap(scene->points[i - 1], scene->points[j]);
    std::swap(scene->blob[i - 1], scene->blob[j]);
  }
}

std::vector<RegionOfInterest> Cluster(const std::vector<cv::Point2f>& points,
                                      RoiOptions options = {}) {
  std::vector<RegionOfInterest> regions;
  RoiClusterer(options).Cluster(points, &regions);
  return regions;
}

// The blob all of the region's features come from, or -1 when they are mixed.
int BlobOf(const RegionOfInterest& region, const Scene& scene) {
  if (region.features.empty()) return -1;
  const int blob = scene.blob[region.features[0]];
  for (uint32_t f : region.features) {
    if (scene.blob[f] != blob) return -1;
  }
  return blob;
}

int CountOfBlob(const Scene& scene, int blob) {
  return int(std::count(scene.blob.begin(), scene.blob.end(), blob));
}

void ExpectIsWholeImage(const RegionOfInterest& region, size_t n) {
  EXPECT_TRUE(region.whole_image);
  std::vector<uint32_t> all(n);
  std::iota(all.begin(), all.end(), 0u);
  EXPECT_EQ(region.features, all);
}

bool SameRegions(const std::vector<RegionOfInterest>& a, const std::vector<RegionOfInterest>& b) {
  if (a.size() != b.size()) return false;
  for (size_t r = 0; r < a.size(); ++r) {
    if (a[r].features != b[r].features || a[r].bounds != b[r].bounds ||
        a[r].whole_image != b[r].whole_image) {
      return false;
    }
  }
  return true;
}

// The partition of the features made by the clustered regions (the whole-image one left out),
// as a set of feature sets, so that it can be compared whatever the region order.
std::set<std::vector<uint32_t>> Partition(const std::vector<RegionOfInterest>& regions) {
  std::set<std::vector<uint32_t>> parts;
  for (const RegionOfInterest& region : regions) {
    if (!region.whole_image) parts.insert(region.features);
  }
  return parts;
}

Scene TwoBlobs() {
  Scene scene;
  AddBlob(&scene, {150, 200}, 20, 400, 11);
  AddBlob(&scene, {480, 260}, 20, 350, 12);
  Shuffle(&scene, 13);
  return scene;
}

TEST(RoiClusteringTest, SeparatesTwoDistantBlobsIntoTwoRegions) {
  const Scene scene = TwoBlobs();
  const std::vector<RegionOfInterest> regions = Cluster(scene.points);
  ASSERT_EQ(regions.size(), 3u);
  EXPECT_FALSE(regions[0].whole_image);
  EXPECT_FALSE(regions[1].whole_image);
  // Each blob is exactly one region, the bigger blob first.
  EXPECT_EQ(BlobOf(regions[0], scene), 0);
  EXPECT_EQ(BlobOf(regions[1], scene), 1);
  EXPECT_EQ(int(regions[0].features.size()), CountOfBlob(scene, 0));
  EXPECT_EQ(int(regions[1].features.size()), CountOfBlob(scene, 1));
  ExpectIsWholeImage(regions[2], scene.points.size());
}

TEST(RoiClusteringTest, SeparatesThreeBlobsIntoThreeRegionsInDecreasingSize) {
  Scene scene;
  AddBlob(&scene, {100, 100}, 15, 150, 21);
  AddBlob(&scene, {500, 120}, 25, 450, 22);
  AddBlob(&scene, {300, 400}, 20, 300, 23);
  Shuffle(&scene, 24);
  const std::vector<RegionOfInterest> regions = Cluster(scene.points);
  ASSERT_EQ(regions.size(), 4u);
  EXPECT_EQ(BlobOf(regions[0], scene), 1);
  EXPECT_EQ(BlobOf(regions[1], scene), 2);
  EXPECT_EQ(BlobOf(regions[2], scene), 0);
  for (int r = 0; r < 3; ++r) {
    EXPECT_FALSE(regions[r].whole_image);
    EXPECT_EQ(int(regions[r].features.size()), CountOfBlob(scene, BlobOf(regions[r], scene)));
    EXPECT_TRUE(std::is_sorted(regions[r].features.begin(), regions[r].features.end()));
    EXPECT_EQ(std::adjacent_find(regions[r].features.begin(), regions[r].features.end()),
              regions[r].features.end());
  }
  ExpectIsWholeImage(regions[3], scene.points.size());
}

TEST(RoiClusteringTest, OneBlobIsOneRegionMarkedAsTheWholeImage) {
  Scene scene;
  AddBlob(&scene, {320, 240}, 30, 800, 31);
  const std::vector<RegionOfInterest> regions = Cluster(scene.points);
  ASSERT_EQ(regions.size(), 1u);
  ExpectIsWholeImage(regions[0], scene.points.size());
}

TEST(RoiClusteringTest, WithoutTheWholeImageRegionOnlyClustersAreReturned) {
  RoiOptions options;
  options.add_whole_image = false;
  const Scene two = TwoBlobs();
  const std::vector<RegionOfInterest> regions = Cluster(two.points, options);
  ASSERT_EQ(regions.size(), 2u);
  EXPECT_FALSE(regions[0].whole_image);
  EXPECT_FALSE(regions[1].whole_image);

  // A single cluster with every feature is not flagged as the whole-image query either.
  Scene one;
  AddBlob(&one, {320, 240}, 30, 500, 32);
  const std::vector<RegionOfInterest> single = Cluster(one.points, options);
  ASSERT_EQ(single.size(), 1u);
  EXPECT_FALSE(single[0].whole_image);
  EXPECT_EQ(single[0].features.size(), one.points.size());
}

TEST(RoiClusteringTest, SameInputAndOptionsGiveIdenticalRegions) {
  Scene scene;
  AddBlob(&scene, {120, 380}, 40, 500, 41);
  AddBlob(&scene, {420, 150}, 60, 500, 42);
  AddBlob(&scene, {560, 420}, 25, 100, 43);
  Shuffle(&scene, 44);
  const std::vector<RegionOfInterest> first = Cluster(scene.points);

  // A clusterer reused after another input gives the same answer as a fresh one.
  RoiClusterer reused;
  std::vector<RegionOfInterest> again;
  reused.Cluster(TwoBlobs().points, &again);
  reused.Cluster(scene.points, &again);
  EXPECT_TRUE(SameRegions(first, again));
  EXPECT_TRUE(SameRegions(first, Cluster(scene.points)));
}

TEST(RoiClusteringTest, AnotherSeedGivesTheSamePartitionOfSeparatedBlobs) {
  const Scene scene = TwoBlobs();
  const std::vector<RegionOfInterest> reference = Cluster(scene.points);
  for (uint64_t seed : {2u, 3u, 12345u}) {
    RoiOptions options;
    options.seed = seed;
    const std::vector<RegionOfInterest> regions = Cluster(scene.points, options);
    EXPECT_EQ(Partition(regions), Partition(reference)) << "seed " << seed;
  }
}

TEST(RoiClusteringTest, RegionsWithFewerThanMinFeaturesAreDropped) {
  Scene scene;
  AddBlob(&scene, {150, 150}, 20, 300, 51);
  AddBlob(&scene, {450, 300}, 20, 200, 52);
  AddBlob(&scene, {600, 50}, 5, 12, 53);  // far from the others, below min_features
  Shuffle(&scene, 54);
  const std::vector<RegionOfInterest> regions = Cluster(scene.points);
  ASSERT_EQ(regions.size(), 3u);
  EXPECT_EQ(BlobOf(regions[0], scene), 0);
  EXPECT_EQ(BlobOf(regions[1], scene), 1);
  ExpectIsWholeImage(regions[2], scene.points.size());  // the small blob is only found here

  RoiOptions options;
  options.min_features = 10;
  const std::vector<RegionOfInterest> kept = Cluster(scene.points, options);
  ASSERT_EQ(kept.size(), 4u);
  EXPECT_EQ(BlobOf(kept[2], scene), 2);
  EXPECT_EQ(kept[2].features.size(), 12u);
}

TEST(RoiClusteringTest, FewerPointsThanSeedsAreClusteredDirectly) {
  Scene scene;
  AddBlob(&scene, {100, 100}, 10, 30, 61);
  AddBlob(&scene, {400, 300}, 10, 25, 62);
  Shuffle(&scene, 63);
  RoiOptions options;
  options.seeds = 100;
  options.min_features = 5;
  ASSERT_LT(scene.points.size(), size_t(options.seeds));
  const std::vector<RegionOfInterest> regions = Cluster(scene.points, options);
  ASSERT_EQ(regions.size(), 3u);
  EXPECT_EQ(BlobOf(regions[0], scene), 0);
  EXPECT_EQ(regions[0].features.size(), 30u);
  EXPECT_EQ(BlobOf(regions[1], scene), 1);
  EXPECT_EQ(regions[1].features.size(), 25u);
  ExpectIsWholeImage(regions[2], scene.points.size());
}

TEST(RoiClusteringTest, CoincidentPointsFormOneRegion) {
  const std::vector<cv::Point2f> points(40, cv::Point2f(7.5f, 3.f));
  const std::vector<RegionOfInterest> regions = Cluster(points);
  ASSERT_EQ(regions.size(), 1u);
  ExpectIsWholeImage(regions[0], points.size());
  EXPECT_EQ(regions[0].bounds, cv::Rect2f(7.5f, 3.f, 0.f, 0.f));

  // More points than seeds: the k-means++ seeding runs out of distinct points.
  const std::vector<cv::Point2f> many(500, cv::Point2f(1.f, 2.f));
  const std::vector<RegionOfInterest> one = Cluster(many);
  ASSERT_EQ(one.size(), 1u);
  ExpectIsWholeImage(one[0], many.size());
}

TEST(RoiClusteringTest, TooFewPointsForAnyRegionStillGiveTheWholeImage) {
  const std::vector<cv::Point2f> points = {{10, 10}, {300, 20}, {50, 400}};
  const std::vector<RegionOfInterest> regions = Cluster(points);
  ASSERT_EQ(regions.size(), 1u);
  ExpectIsWholeImage(regions[0], points.size());
  EXPECT_EQ(regions[0].bounds, cv::Rect2f(10.f, 10.f, 290.f, 390.f));

  RoiOptions options;
  options.add_whole_image = false;
  EXPECT_TRUE(Cluster(points, options).empty());
}

TEST(RoiClusteringTest, EmptyInputGivesNoRegions) {
  RoiClusterer clusterer;
  std::vector<RegionOfInterest> regions;
  clusterer.Cluster(TwoBlobs().points, &regions);
  ASSERT_FALSE(regions.empty());
  clusterer.Cluster({}, &regions);
  EXPECT_TRUE(regions.empty());
}

TEST(RoiClusteringTest, BoundsAreTheBoundingBoxOfTheRegionFeatures) {
  // Two dense grids with known extents, interleaved: 11 x 9 points every 6 px from (100, 200)
  // and 8 x 8 points every 5 px from (400.5, 50.25).
  std::vector<cv::Point2f> points;
  for (int i = 0; i < 11 * 9; ++i) {
    points.emplace_back(100.f + 6.f * float(i % 11), 200.f + 6.f * float(i / 11));
    if (i < 8 * 8) points.emplace_back(400.5f + 5.f * float(i % 8), 50.25f + 5.f * float(i / 8));
  }
  const std::vector<RegionOfInterest> regions = Cluster(points);
  ASSERT_EQ(regions.size(), 3u);
  EXPECT_EQ(regions[0].features.size(), 99u);
  EXPECT_EQ(regions[0].bounds, cv::Rect2f(100.f, 200.f, 60.f, 48.f));
  EXPECT_EQ(regions[1].features.size(), 64u);
  EXPECT_EQ(regions[1].bounds, cv::Rect2f(400.5f, 50.25f, 35.f, 35.f));
  EXPECT_TRUE(regions[2].whole_image);
  EXPECT_EQ(regions[2].bounds, cv::Rect2f(100.f, 50.25f, 335.5f, 197.75f));
}

TEST(RoiClusteringTest, BandwidthDecidesWhetherNearbyBlobsMerge) {
  Scene scene;
  AddBlob(&scene, {250, 240}, 10, 300, 71);
  AddBlob(&scene, {350, 240}, 10, 300, 72);
  Shuffle(&scene, 73);

  RoiOptions wide;
  wide.bandwidth_px = 200;
  const std::vector<RegionOfInterest> merged = Cluster(scene.points, wide);
  ASSERT_EQ(merged.size(), 1u);
  ExpectIsWholeImage(merged[0], scene.points.size());

  RoiOptions narrow;
  narrow.bandwidth_px = 20;
  const std::vector<RegionOfInterest> split = Cluster(scene.points, narrow);
  ASSERT_EQ(split.size(), 3u);
  EXPECT_EQ(BlobOf(split[0], scene) + BlobOf(split[1], scene), 1);  // blobs 0 and 1, any order
  EXPECT_EQ(split[0].features.size(), 300u);
  EXPECT_EQ(split[1].features.size(), 300u);
  EXPECT_LT(split[0].features[0], split[1].features[0]);  // equal sizes: first feature decides
  EXPECT_TRUE(split[2].whole_image);
}

TEST(RoiClusteringTest, OrbFeaturesOfARealImageArePartitionedIntoRegions) {
  StatusOr<cv::Mat> image = ReadGrayImage(testing::ProjectTestData("corridor/1.jpg"));
  ASSERT_TRUE(image.ok()) << image.status().ToString();
  auto extractor = CreateFeatureExtractor(FeatureOptions{});
  ASSERT_TRUE(extractor.ok()) << extractor.status().ToString();
  FeatureSet features;
  ASSERT_TRUE((*extractor)->Extract(*image, &features).ok());
  ASSERT_GT(features.size(), 300u);
  std::vector<cv::Point2f> points;
  for (const cv::KeyPoint& k : features.keypoints) points.push_back(k.pt);

  RoiOptions options;
  options.add_whole_image = false;
  const std::vector<RegionOfInterest> regions = Cluster(points, options);
  ASSERT_GE(regions.size(), 2u);
  std::vector<int> owners(points.size(), 0);
  for (const RegionOfInterest& region : regions) {
    EXPECT_GE(int(region.features.size()), options.min_features);
    for (uint32_t f : region.features) ++owners[f];
  }
  EXPECT_EQ(*std::max_element(owners.begin(), owners.end()), 1);
  const auto covered = std::count(owners.begin(), owners.end(), 1);
  EXPECT_GE(double(covered), 0.8 * double(points.size()));

  // With the default options the same clusters come first, the whole image last.
  const std::vector<RegionOfInterest> with_whole = Cluster(points);
  ASSERT_EQ(with_whole.size(), regions.size() + 1);
  EXPECT_TRUE(SameRegions({with_whole.begin(), with_whole.end() - 1}, regions));
  ExpectIsWholeImage(with_whole.back(), points.size());
}

TEST(RoiOptionsTest, TheDefaultsAndTheEndsOfTheRangesAreValid) {
  EXPECT_TRUE(RoiOptions().Validate().ok());
  RoiOptions edges;
  edges.seeds = RoiOptions::kMaxSeeds;
  edges.kmeans_iterations = 0;
  edges.bandwidth_px = 0;  // every k-means cluster its own mode
  edges.min_features = 0;
  EXPECT_TRUE(edges.Validate().ok()) << edges.Validate().ToString();
}

// One field out of its range at a time, NaN and infinity among the values.
TEST(RoiOptionsTest, EachFieldOutOfRangeIsRefusedWithItsNameAndValue) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<testing::BadOption<RoiOptions>> cases = {
      {"seeds = 0", [](RoiOptions& o) { o.seeds = 0; }},
      {"seeds = 2049", [](RoiOptions& o) { o.seeds = RoiOptions::kMaxSeeds + 1; }},
      {"kmeans_iterations = -1", [](RoiOptions& o) { o.kmeans_iterations = -1; }},
      {"bandwidth_px = nan", [&](RoiOptions& o) { o.bandwidth_px = nan; }},
      {"bandwidth_px = inf", [&](RoiOptions& o) { o.bandwidth_px = inf; }},
      {"bandwidth_px = -5", [](RoiOptions& o) { o.bandwidth_px = -5; }},
      {"min_features = -1", [](RoiOptions& o) { o.min_features = -1; }},
  };
  testing::ExpectEachRefused("RoiOptions", cases);
  RoiOptions named;
  named.bandwidth_px = nan;
  EXPECT_EQ(named.Validate("RecognitionOptions.roi").message(),
            "RecognitionOptions.roi.bandwidth_px = nan: must be finite and >= 0");
}

}  // namespace
}  // namespace recog
