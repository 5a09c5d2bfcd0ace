// Inputs shared by the benchmarks: real ORB descriptors of the corridor frames and photos, maps
// grown to any size from real photos' bags of words, and vocabularies of a given shape with random
// centroids (for sizes no training set here can fill, e.g. 1M words).
#pragma once

#include <cstdint>
#include <random>
#include <span>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/bow/bow_vector.h"
#include "core/index/database.h"
#include "core/vocabulary/vocabulary.h"

namespace recog::bench {

// ORB descriptors (1000 features per frame at most) of the corridor sequence, from the shared
// data when present (84 frames), else from the 4 frames bundled in tests/data, cut into sets of
// `per_set` consecutive rows.
std::vector<cv::Mat> CorridorDescriptorSets(int per_set);

// A complete tree: every internal node has k children, every leaf is at depth L. Centroids are
// random bits, word weights random in (0, 10]. k=10, L=6 gives 1,000,000 words.
Vocabulary RandomFullTreeVocabulary(uint32_t k, uint32_t levels, uint64_t seed);

// The bundled place vocabulary (vocabularies/place_orb_k10_l5.rvoc); aborts the benchmark
// binary with a message when it is missing.
Vocabulary LoadBundledPlaceVocabulary();

// ORB features of real images, one set per distinct photo: every shared Caltech photo (or,
// without the shared data, every bundled corridor frame) with at least 50 features, in a random
// order drawn from `seed`.
std::vector<FeatureSet> RealImageFeatures(uint64_t seed);
// The descriptors alone of RealImageFeatures(seed).
std::vector<cv::Mat> RealImageDescriptors(uint64_t seed);

// The bag of words of `descriptors` (aborts on failure).
BowVector Transform(const Vocabulary& vocabulary, const cv::Mat& descriptors);

// A random 60-100 % of the rows of `all` into `subset` (`rows` is scratch).
void RandomSubset(const cv::Mat& all, std::mt19937_64& rng, std::vector<int>* rows,
                  cv::Mat* subset);
// The same of the features (descriptors and keypoints) of `all`: the rows drawn are those the
// descriptor version draws from the same `rng`.
void RandomSubset(const FeatureSet& all, std::mt19937_64& rng, std::vector<int>* rows,
                  FeatureSet* subset);

// Adds an entry with the given bag of words and `features` placeholder features (at most 1000:
// zero descriptors, default keypoints, all under one direct-index node).
void AddEntry(Database& db, const BowVector& bow, int features);

// Grows `db` to `entries` entries of real word statistics: every photo of `photos` (ORB
// descriptors, e.g. RealImageDescriptors) once when `db` is empty, then random 60-100 % subsets
// of their features, the photos in turn (none when `entries` is at most their number). `rng`
// carries on across calls; `insert_ms`, when not null, receives the time of each insertion. Each
// entry has `features` placeholder features (AddEntry): the bags of words are real, the stored
// features are not.
void GrowRealDatabase(Database& db, std::span<const cv::Mat> photos, size_t entries,
                      std::mt19937_64& rng, std::vector<double>* insert_ms = nullptr,
                      int features = 1000);
// The same, each entry storing the real features it was made from (Database::Add: its bag of
// words, direct index, keypoints and descriptors), as a map of real frames holds them; from the
// same `rng`, the same bags of words as the version above.
void GrowRealDatabase(Database& db, std::span<const FeatureSet> photos, size_t entries,
                      std::mt19937_64& rng);

// The bytes of the files under `dir` (only those under `only_under` when given).
uint64_t DirectoryBytes(const std::string& dir, const std::string& only_under = "");

// A fresh temporary file path in the system temp folder.
std::string TempPath(const std::string& name);

// Nearest-rank percentile `p` (0..100) of `sorted` (ascending), 0 when empty.
double Percentile(const std::vector<double>& sorted, double p);

}  // namespace recog::bench
