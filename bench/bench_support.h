// Inputs shared by the benchmarks: real ORB descriptors of the corridor frames, and vocabularies
// of a given shape with random centroids (for sizes no training set here can fill, e.g. 1M words).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/bow/bow_vector.h"
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

// ORB descriptors of real images, one set per distinct photo: every shared Caltech photo (or,
// without the shared data, every bundled corridor frame) with at least 50 features, in a random
// order drawn from `seed`.
std::vector<cv::Mat> RealImageDescriptors(uint64_t seed);

// A fresh temporary file path in the system temp folder.
std::string TempPath(const std::string& name);

// Nearest-rank percentile `p` (0..100) of `sorted` (ascending), 0 when empty.
double Percentile(const std::vector<double>& sorted, double p);

}  // namespace recog::bench
