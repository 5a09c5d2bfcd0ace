// Training a vocabulary from the descriptors of a set of training images.
//
// Each tree is built by hierarchical clustering (thesis §3.1.2, §4.2.3): the descriptors are split
// into k clusters with k-means++ seeding and Lloyd iterations, then each cluster is split again,
// down to `depth` levels. Centroids are majority bits for binary descriptors (k-medians; a tie
// gives 0) and means for float descriptors (k-means). A node with k or fewer descriptors becomes
// a leaf holding them, as in DBoW2. Several trees (thesis §5.4.3) differ only by their seed.
// Finally every training image is converted and each word gets idf = log(N / n_i), where N is the
// number of images and n_i the number of images in which the word occurs.
//
// Memory: the descriptors are reordered in place, cluster by cluster, so that every subtree works
// on one contiguous range; the only extra memory is one scratch copy of the descriptors and a few
// 4-byte arrays per descriptor. Work is split over `threads` threads: the top levels split each
// Lloyd iteration over the threads, the lower levels give whole subtrees to threads.
//
// Deterministic: the same descriptors, options and seed give a bit-identical vocabulary, whatever
// the number of threads.
#pragma once

#include <cstdint>
#include <functional>
#include <string_view>
#include <vector>

#include "core/common/status.h"
#include "core/vocabulary/vocabulary.h"

namespace recog {

// Descriptors of the training images, all in one contiguous buffer.
struct TrainingSet {
  DescriptorFormat format = DescriptorFormat::Orb();
  std::vector<uint8_t> descriptors;  // row i at i * format.size_bytes
  std::vector<uint32_t> image_offsets{
      0};  // image j owns rows [image_offsets[j], image_offsets[j+1])

  size_t num_descriptors() const { return descriptors.size() / format.size_bytes; }
  size_t num_images() const { return image_offsets.size() - 1; }
  // Appends the rows of one image (a matrix in `format`, possibly empty).
  Status AddImage(const cv::Mat& image_descriptors);
};

// Called from the training threads (serialised) as work completes.
// `stage` is "clustering" or "weighting"; done <= total.
using TrainingProgress = std::function<void(std::string_view stage, uint64_t done, uint64_t total)>;

struct TrainingOptions {
  uint32_t branching = 10;  // k, 2..255
  uint32_t depth = 5;       // L, 1..16
  uint32_t trees = 1;       // T, 1..255
  WeightingType weighting = WeightingType::kTfIdf;
  ScoringType scoring = ScoringType::kL1;
  uint64_t seed = 42;
  uint32_t threads = 0;          // 0 = all hardware threads
  uint32_t max_iterations = 10;  // Lloyd iterations per split (stops earlier when stable)
  TrainingProgress progress;     // optional

  Status Validate() const;
};

// Trains a vocabulary. `set` is consumed: its rows are reordered during clustering.
// Fails on invalid options, an invalid format, or a set without descriptors.
StatusOr<Vocabulary> TrainVocabulary(TrainingSet set, const TrainingOptions& options);

}  // namespace recog
