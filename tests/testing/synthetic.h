// Synthetic descriptors for unit tests: reproducible from a seed, with optional cluster structure
// (descriptors drawn around a few random centres), so that trained trees have something to find.
#pragma once

#include <cstdint>
#include <random>

#include <opencv2/core.hpp>

#include "core/common/descriptor.h"
#include "core/vocabulary/vocabulary_trainer.h"

namespace recog::testing {

// `rows` random descriptors in `format`; binary bits are fair coins, floats uniform in [0, 1).
inline cv::Mat RandomDescriptors(int rows, uint64_t seed,
                                 DescriptorFormat format = DescriptorFormat::Orb()) {
  std::mt19937_64 rng(seed);
  cv::Mat m(rows, format.cols(), format.cv_type());
  if (format.type == DescriptorType::kBinary) {
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < m.cols; ++c) m.at<uint8_t>(r, c) = uint8_t(rng());
    }
  } else {
    std::uniform_real_distribution<float> u(0.f, 1.f);
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < m.cols; ++c) m.at<float>(r, c) = u(rng);
    }
  }
  return m;
}

// Binary descriptors around `centres` random centres: each row is a centre with each bit
// flipped with probability `flip`.
inline cv::Mat ClusteredBinaryDescriptors(int rows, int centres, double flip, uint64_t seed) {
  std::mt19937_64 rng(seed);
  const cv::Mat c = RandomDescriptors(centres, seed ^ 0xabcdefULL);
  std::bernoulli_distribution coin(flip);
  cv::Mat m(rows, 32, CV_8U);
  for (int r = 0; r < rows; ++r) {
    const int k = int(rng() % uint64_t(centres));
    for (int b = 0; b < 32; ++b) {
      uint8_t byte = c.at<uint8_t>(k, b);
      for (int bit = 0; bit < 8; ++bit) {
        if (coin(rng)) byte ^= uint8_t(1u << bit);
      }
      m.at<uint8_t>(r, b) = byte;
    }
  }
  return m;
}

// A training set of `images` images with `per_image` clustered binary descriptors each.
inline TrainingSet ClusteredTrainingSet(int images, int per_image, uint64_t seed) {
  TrainingSet set;
  const cv::Mat all = ClusteredBinaryDescriptors(images * per_image, 40, 0.08, seed);
  for (int i = 0; i < images; ++i) {
    [[maybe_unused]] Status s = set.AddImage(all.rowRange(i * per_image, (i + 1) * per_image));
  }
  return set;
}

// Training options for small test vocabularies.
inline TrainingOptions SmallTrainingOptions(uint32_t k, uint32_t depth, uint32_t threads,
                                            uint64_t seed) {
  TrainingOptions o;
  o.branching = k;
  o.depth = depth;
  o.threads = threads;
  o.seed = seed;
  return o;
}

}  // namespace recog::testing
