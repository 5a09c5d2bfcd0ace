#include "core/vocabulary/vocabulary_trainer.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <limits>
#include <mutex>
#include <random>
#include <thread>

namespace recog {
namespace {

// SplitMix64 finaliser: derives independent seeds from (seed, path) so that every node's
// randomness depends only on where it sits in the tree, not on which thread built it.
uint64_t MixSeed(uint64_t seed, uint64_t salt) {
  uint64_t z = seed + 0x9e3779b97f4a7c15ULL * (salt + 1);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

// Runs body(chunk_begin, chunk_end, chunk_index) for `chunks` equal parts of [begin, end), spread
// over `threads` threads (the caller being one of them). The split depends on `chunks` only, so
// results merged in chunk order do not depend on the number of threads.
template <class Body>
void ParallelChunks(size_t begin, size_t end, size_t chunks, uint32_t threads, Body&& body) {
  chunks = std::max<size_t>(1, std::min(chunks, end - begin));
  const size_t step = (end - begin + chunks - 1) / chunks;
  auto run = [&](size_t first_chunk, size_t chunk_stride) {
    for (size_t c = first_chunk; c < chunks; c += chunk_stride) {
      const size_t b = begin + c * step;
      const size_t e = std::min(end, b + step);
      if (b < e) body(b, e, c);
    }
  };
  const size_t workers = std::max<size_t>(1, std::min<size_t>(threads, chunks));
  std::vector<std::thread> pool;
  for (size_t w = 1; w < workers; ++w) pool.emplace_back(run, w, workers);
  run(0, workers);
  for (std::thread& t : pool) t.join();
}

// Binary descriptors: Hamming distance, majority-bit (k-medians) centroids, 0 on a tie.
class BinarySpace {
 public:
  using Distance = uint32_t;
  explicit BinarySpace(size_t bytes) : bytes_(bytes) {
    for (int v = 0; v < 256; ++v) {
      uint64_t lanes = 0;  // byte j of lanes = bit (7 - j) of v: most significant bit first
      for (int j = 0; j < 8; ++j) lanes |= uint64_t((v >> (7 - j)) & 1) << (8 * j);
      spread_[v] = lanes;
    }
  }
  size_t bytes() const { return bytes_; }
  Distance operator()(const uint8_t* a, const uint8_t* b) const {
    return bytes_ == 32 ? Hamming256(a, b) : HammingDistance(a, b, bytes_);
  }
  static double Weight(Distance d) { return double(d) * double(d); }

  // Per-cluster bit sums. Bits are added 8 at a time into the byte lanes of one 64-bit word per
  // descriptor byte, and flushed to 32-bit counters before a lane can overflow.
  class Accumulators {
   public:
    Accumulators(const BinarySpace& space, size_t clusters)
        : space_(&space),
          bytes_(space.bytes_),
          lanes_(clusters * bytes_),
          counts_(clusters * bytes_ * 8),
          pending_(clusters),
          members_(clusters) {}
    void Reset() {
      std::fill(lanes_.begin(), lanes_.end(), 0);
      std::fill(counts_.begin(), counts_.end(), 0);
      std::fill(pending_.begin(), pending_.end(), 0);
      std::fill(members_.begin(), members_.end(), 0);
    }
    void Add(size_t c, const uint8_t* d) {
      uint64_t* lanes = &lanes_[c * bytes_];
      for (size_t b = 0; b < bytes_; ++b) lanes[b] += space_->spread_[d[b]];
      if (++pending_[c] == 255) Flush(c);
      ++members_[c];
    }
    void Merge(Accumulators& other) {
      for (size_t c = 0; c < members_.size(); ++c) {
        Flush(c);
        other.Flush(c);
        members_[c] += other.members_[c];
      }
      for (size_t i = 0; i < counts_.size(); ++i) counts_[i] += other.counts_[i];
    }
    uint64_t members(size_t c) const { return members_[c]; }
    // Majority bits of cluster c into `out`; a tie (exactly half) gives 0.
    void Centroid(size_t c, uint8_t* out) {
      Flush(c);
      const uint32_t* counts = &counts_[c * bytes_ * 8];
      for (size_t b = 0; b < bytes_; ++b) {
        uint8_t byte = 0;
        for (int j = 0; j < 8; ++j) {
          if (2 * uint64_t(counts[b * 8 + j]) > members_[c]) byte |= uint8_t(1u << (7 - j));
        }
        out[b] = byte;
      }
    }

   private:
    void Flush(size_t c) {
      uint64_t* lanes = &lanes_[c * bytes_];
      uint32_t* counts = &counts_[c * bytes_ * 8];
      for (size_t b = 0; b < bytes_; ++b) {
        for (int j = 0; j < 8; ++j) counts[b * 8 + j] += uint32_t((lanes[b] >> (8 * j)) & 0xff);
        lanes[b] = 0;
      }
      pending_[c] = 0;
    }
    const BinarySpace* space_;
    size_t bytes_;
    std::vector<uint64_t> lanes_;
    std::vector<uint32_t> counts_;
    std::vector<uint32_t> pending_;
    std::vector<uint64_t> members_;
  };

 private:
  size_t bytes_;
  std::array<uint64_t, 256> spread_{};
};

// Float descriptors: squared Euclidean distance, mean (k-means) centroids.
class FloatSpace {
 public:
  using Distance = float;
  explicit FloatSpace(size_t bytes) : bytes_(bytes) {}
  size_t bytes() const { return bytes_; }
  Distance operator()(const uint8_t* a, const uint8_t* b) const {
    return SquaredL2(reinterpret_cast<const float*>(a), reinterpret_cast<const float*>(b),
                     bytes_ / sizeof(float));
  }
  static double Weight(Distance d) { return double(d); }  // already squared

  // Per-cluster sums, in double so that the means do not drift.
  class Accumulators {
   public:
    Accumulators(const FloatSpace& space, size_t clusters)
        : dims_(space.bytes_ / sizeof(float)), sums_(clusters * dims_), members_(clusters) {}
    void Reset() {
      std::fill(sums_.begin(), sums_.end(), 0.0);
      std::fill(members_.begin(), members_.end(), 0);
    }
    void Add(size_t c, const uint8_t* d) {
      const auto* f = reinterpret_cast<const float*>(d);
      double* sums = &sums_[c * dims_];
      for (size_t i = 0; i < dims_; ++i) sums[i] += f[i];
      ++members_[c];
    }
    void Merge(Accumulators& other) {
      for (size_t i = 0; i < sums_.size(); ++i) sums_[i] += other.sums_[i];
      for (size_t c = 0; c < members_.size(); ++c) members_[c] += other.members_[c];
    }
    uint64_t members(size_t c) const { return members_[c]; }
    void Centroid(size_t c, uint8_t* out) {
      auto* f = reinterpret_cast<float*>(out);
      const double* sums = &sums_[c * dims_];
      for (size_t i = 0; i < dims_; ++i) f[i] = members_[c] ? float(sums[i] / members_[c]) : 0.f;
    }

   private:
    size_t dims_;
    std::vector<double> sums_;
    std::vector<uint64_t> members_;
  };

 private:
  size_t bytes_;
};

// Builds one tree of the vocabulary by hierarchical clustering of the rows of a TrainingSet.
template <class Space>
class TreeBuilder {
 public:
  TreeBuilder(const Space& space, const TrainingOptions& options, uint8_t* rows,
              uint32_t* image_of_row, size_t num_rows, std::atomic<uint64_t>* rows_done,
              uint64_t rows_total)
      : space_(space),
        options_(options),
        rows_(rows),
        image_of_row_(image_of_row),
        labels_(num_rows),
        min_distance_(num_rows),
        num_rows_(num_rows),
        rows_done_(rows_done),
        rows_total_(rows_total) {}

  TreeNodeTable Build(uint64_t tree_seed) {
    const size_t row = space_.bytes();
    table_.parent.assign(1, 0);
    table_.descriptors.assign(row, 0);
    table_.word.assign(1, kInvalidWordId);
    table_.weight.assign(1, 0.f);

    const uint32_t threads = options_.threads;
    // The root split is the largest single job: its Lloyd iterations use every thread. Below it,
    // whole subtrees go to the worker threads.
    Split({0, 0, num_rows_, 0, tree_seed}, threads);
    std::vector<std::thread> workers;
    for (uint32_t t = 0; t < threads; ++t) workers.emplace_back([this] { WorkerLoop(); });
    for (std::thread& w : workers) w.join();
    return std::move(table_);
  }

 private:
  struct Job {
    uint32_t node;
    size_t begin, end;
    uint32_t level;  // depth of `node`
    uint64_t seed;
  };

  void WorkerLoop() {
    for (;;) {
      Job job;
      {
        std::unique_lock lock(queue_mutex_);
        queue_cv_.wait(lock, [this] { return !queue_.empty() || active_ == 0; });
        if (queue_.empty()) return;  // no work left and nobody can add any
        job = queue_.back();
        queue_.pop_back();
        ++active_;
      }
      Split(job, 1);
      {
        std::lock_guard lock(queue_mutex_);
        --active_;
      }
      queue_cv_.notify_all();
    }
  }

  uint8_t* Row(size_t i) const { return rows_ + i * space_.bytes(); }

  // Appends children with the given centroids under `parent`; returns the first child's index.
  uint32_t AddChildren(uint32_t parent, const uint8_t* centroids, size_t count) {
    std::lock_guard lock(table_mutex_);
    const uint32_t first = uint32_t(table_.parent.size());
    table_.parent.insert(table_.parent.end(), count, parent);
    table_.descriptors.insert(table_.descriptors.end(), centroids,
                              centroids + count * space_.bytes());
    table_.word.insert(table_.word.end(), count, kInvalidWordId);
    table_.weight.insert(table_.weight.end(), count, 0.f);
    return first;
  }

  void ReportLeafRows(size_t rows) {
    // Counted under the lock that orders the reports, so that they never go backwards.
    std::lock_guard lock(progress_mutex_);
    const uint64_t done = rows_done_->fetch_add(rows) + rows;
    if (options_.progress) options_.progress("clustering", done, rows_total_);
  }

  // k-means++ seeding (Arthur & Vassilvitskii 2007): the first centre uniformly, each next one
  // with probability proportional to the squared distance to the nearest centre chosen so far.
  // Returns fewer than k centres when the range has fewer distinct descriptors.
  std::vector<uint8_t> SeedCenters(size_t begin, size_t end, uint32_t k, std::mt19937_64& rng) {
    const size_t row = space_.bytes();
    std::vector<uint8_t> centers;
    centers.reserve(k * row);
    const size_t first = begin + std::uniform_int_distribution<size_t>(0, end - begin - 1)(rng);
    centers.insert(centers.end(), Row(first), Row(first) + row);
    using D = typename Space::Distance;
    for (size_t i = begin; i < end; ++i) min_distance_[i] = double(space_(Row(i), Row(first)));
    while (centers.size() / row < k) {
      double total = 0.0;
      for (size_t i = begin; i < end; ++i) total += Space::Weight(D(min_distance_[i]));
      if (total <= 0.0) break;  // every row coincides with a centre
      double target = std::uniform_real_distribution<double>(0.0, total)(rng);
      size_t pick = end - 1;
      for (size_t i = begin; i < end; ++i) {
        target -= Space::Weight(D(min_distance_[i]));
        if (target < 0.0) {
          pick = i;
          break;
        }
      }
      if (min_distance_[pick] <= 0.0) {  // rounding landed on a covered row: take the farthest
        pick = size_t(std::max_element(min_distance_.begin() + begin, min_distance_.begin() + end) -
                      min_distance_.begin());
      }
      const uint8_t* c = Row(pick);
      centers.insert(centers.end(), c, c + row);
      for (size_t i = begin; i < end; ++i) {
        min_distance_[i] = std::min(min_distance_[i], double(space_(Row(i), c)));
      }
    }
    return centers;
  }

  // Assigns rows [begin, end) to their nearest centre (first on a tie); returns how many labels
  // changed and accumulates the members of each cluster into `acc`.
  size_t Assign(size_t b, size_t e, const std::vector<uint8_t>& centers, size_t k,
                typename Space::Accumulators& acc) {
    const size_t row = space_.bytes();
    size_t changed = 0;
    for (size_t i = b; i < e; ++i) {
      const uint8_t* d = Row(i);
      auto best = space_(d, centers.data());
      uint32_t label = 0;
      for (size_t c = 1; c < k; ++c) {
        const auto dist = space_(d, centers.data() + c * row);
        if (dist < best) {
          best = dist;
          label = uint32_t(c);
        }
      }
      changed += labels_[i] != label;
      labels_[i] = label;
      acc.Add(label, d);
    }
    return changed;
  }

  // Clusters the rows of one node, reorders them cluster by cluster, creates the children and
  // queues (or finishes) their subtrees.
  void Split(const Job& job, uint32_t threads) {
    const size_t row = space_.bytes();
    const size_t n = job.end - job.begin;
    const uint32_t k = options_.branching;
    const bool children_are_leaves = job.level + 1 >= options_.depth;

    if (n <= k) {  // each row is its own leaf
      AddChildren(job.node, Row(job.begin), n);
      ReportLeafRows(n);
      return;
    }
    std::mt19937_64 rng(job.seed);
    std::vector<uint8_t> centers = SeedCenters(job.begin, job.end, k, rng);
    size_t clusters = centers.size() / row;
    if (clusters == 1) {  // all rows are identical: one leaf
      AddChildren(job.node, centers.data(), 1);
      ReportLeafRows(n);
      return;
    }

    // Lloyd iterations. The loop always ends right after an assignment, so every row belongs to
    // the cluster of its nearest final centre, as a descent of the finished tree will find.
    std::fill(labels_.begin() + job.begin, labels_.begin() + job.end, UINT32_MAX);
    // Large ranges are cut into a fixed number of chunks (whatever the thread count, so that
    // float sums are added in the same order) and assigned in parallel.
    const size_t chunks = threads > 1 && n > 65536 ? 16 : 1;
    std::vector<typename Space::Accumulators> partial(
        chunks, typename Space::Accumulators(space_, clusters));
    std::vector<size_t> changed(chunks, 0);
    for (uint32_t iteration = 0;; ++iteration) {
      for (auto& p : partial) p.Reset();
      ParallelChunks(job.begin, job.end, chunks, threads, [&](size_t b, size_t e, size_t c) {
        changed[c] = Assign(b, e, centers, clusters, partial[c]);
      });
      size_t total_changed = changed[0];
      for (size_t c = 1; c < chunks; ++c) {
        total_changed += changed[c];
        partial[0].Merge(partial[c]);
      }
      if (total_changed == 0 || iteration + 1 >= options_.max_iterations) break;
      for (size_t j = 0; j < clusters; ++j) {
        if (partial[0].members(j) > 0) partial[0].Centroid(j, centers.data() + j * row);
      }
    }
    typename Space::Accumulators& acc = partial[0];

    // Drop empty clusters, then reorder the rows so that each cluster is one contiguous range
    // (an in-place k-way partition: every swap puts one row at its final place).
    std::vector<uint32_t> new_label(clusters, UINT32_MAX);
    std::vector<size_t> bucket_begin;
    std::vector<uint8_t> kept;
    size_t offset = job.begin;
    for (size_t j = 0; j < clusters; ++j) {
      if (acc.members(j) == 0) continue;
      new_label[j] = uint32_t(bucket_begin.size());
      bucket_begin.push_back(offset);
      offset += acc.members(j);
      kept.insert(kept.end(), centers.data() + j * row, centers.data() + (j + 1) * row);
    }
    const size_t buckets = bucket_begin.size();
    std::vector<size_t> bucket_end(buckets);
    for (size_t j = 0; j < buckets; ++j) {
      bucket_end[j] = j + 1 < buckets ? bucket_begin[j + 1] : job.end;
    }
    for (size_t i = job.begin; i < job.end; ++i) labels_[i] = new_label[labels_[i]];
    std::vector<size_t> next = bucket_begin;
    std::vector<uint8_t> tmp(row);
    for (size_t j = 0; j < buckets; ++j) {
      while (next[j] < bucket_end[j]) {
        const size_t i = next[j];
        const uint32_t l = labels_[i];
        if (l == j) {
          ++next[j];
          continue;
        }
        const size_t dst = next[l]++;
        std::memcpy(tmp.data(), Row(i), row);
        std::memcpy(Row(i), Row(dst), row);
        std::memcpy(Row(dst), tmp.data(), row);
        std::swap(image_of_row_[i], image_of_row_[dst]);
        std::swap(labels_[i], labels_[dst]);
      }
    }

    const uint32_t first_child = AddChildren(job.node, kept.data(), buckets);
    if (children_are_leaves || buckets == 1) {
      ReportLeafRows(n);
      return;
    }
    {
      std::lock_guard lock(queue_mutex_);
      for (size_t j = 0; j < buckets; ++j) {
        queue_.push_back({first_child + uint32_t(j), bucket_begin[j], bucket_end[j], job.level + 1,
                          MixSeed(job.seed, j)});
      }
    }
    queue_cv_.notify_all();
  }

  const Space& space_;
  const TrainingOptions& options_;
  uint8_t* rows_;
  uint32_t* image_of_row_;
  std::vector<uint32_t> labels_;
  std::vector<double> min_distance_;
  size_t num_rows_;
  std::atomic<uint64_t>* rows_done_;
  uint64_t rows_total_;

  TreeNodeTable table_;
  std::mutex table_mutex_;
  std::mutex progress_mutex_;
  std::mutex queue_mutex_;
  std::condition_variable queue_cv_;
  std::deque<Job> queue_;
  int active_ = 0;
};

// idf(word) = log(N / n_word), n_word = number of training images containing the word.
// Words never met keep weight 0 (left out of BoW vectors, as in DBoW2).
std::vector<float> ComputeWordWeights(const Vocabulary& vocabulary, const TrainingSet& set,
                                      const std::vector<uint32_t>& image_of_row,
                                      const TrainingOptions& options) {
  const size_t rows = set.num_descriptors();
  const size_t row = set.format.size_bytes;
  if (options.weighting == WeightingType::kTf || options.weighting == WeightingType::kBinary) {
    return std::vector<float>(vocabulary.num_words(), 1.f);
  }
  std::vector<uint64_t> word_image(rows);
  std::atomic<uint64_t> done{0};
  std::mutex progress_mutex;
  ParallelChunks(0, rows, 64, options.threads, [&](size_t b, size_t e, size_t) {
    for (size_t i = b; i < e; ++i) {
      const WordId w = vocabulary.TransformOne(set.descriptors.data() + i * row);
      word_image[i] = (uint64_t(w) << 32) | image_of_row[i];
      if ((i - b) % 65536 == 65535 || i + 1 == e) {
        // Counted under the lock that orders the reports, so that they never go backwards.
        std::lock_guard lock(progress_mutex);
        const uint64_t now = done.fetch_add((i - b) % 65536 + 1) + (i - b) % 65536 + 1;
        if (options.progress) options.progress("weighting", now, rows);
      }
    }
  });
  std::sort(word_image.begin(), word_image.end());
  std::vector<uint32_t> images_with_word(vocabulary.num_words(), 0);
  for (size_t i = 0; i < rows; ++i) {
    if (i == 0 || word_image[i] != word_image[i - 1]) ++images_with_word[word_image[i] >> 32];
  }
  const double n_images = double(set.num_images());
  std::vector<float> weights(vocabulary.num_words(), 0.f);
  for (size_t w = 0; w < weights.size(); ++w) {
    if (images_with_word[w] > 0) weights[w] = float(std::log(n_images / images_with_word[w]));
  }
  return weights;
}

template <class Space>
std::vector<TreeNodeTable> BuildTrees(const Space& space, TrainingSet& set,
                                      std::vector<uint32_t>& image_of_row,
                                      const TrainingOptions& options) {
  const size_t rows = set.num_descriptors();
  std::atomic<uint64_t> rows_done{0};
  std::vector<TreeNodeTable> trees;
  for (uint32_t t = 0; t < options.trees; ++t) {
    TreeBuilder<Space> builder(space, options, set.descriptors.data(), image_of_row.data(), rows,
                               &rows_done, uint64_t(rows) * options.trees);
    trees.push_back(builder.Build(MixSeed(options.seed, t)));
  }
  return trees;
}

}  // namespace

Status TrainingSet::AddImage(const cv::Mat& image_descriptors) {
  RECOG_RETURN_IF_ERROR(CheckDescriptorMatrix(image_descriptors, format));
  const size_t bytes =
      image_descriptors.empty() ? 0 : image_descriptors.total() * image_descriptors.elemSize();
  if (num_descriptors() + bytes / format.size_bytes > UINT32_MAX) {
    return Status::ResourceExhausted("training set exceeds 2^32 descriptors");
  }
  if (bytes > 0) {
    const uint8_t* p = image_descriptors.ptr<uint8_t>(0);
    descriptors.insert(descriptors.end(), p, p + bytes);
  }
  image_offsets.push_back(uint32_t(num_descriptors()));
  return Status::Ok();
}

Status TrainingOptions::Validate() const {
  if (branching < 2 || branching > 255) {
    return Status::InvalidArgument("k (branching) must be in 2..255, got " +
                                   std::to_string(branching));
  }
  if (depth < 1 || depth > 16) {
    return Status::InvalidArgument("L (depth) must be in 1..16, got " + std::to_string(depth));
  }
  if (trees < 1 || trees > 255) {
    return Status::InvalidArgument("trees must be in 1..255, got " + std::to_string(trees));
  }
  if (max_iterations < 1) return Status::InvalidArgument("max_iterations must be at least 1");
  if (std::pow(double(branching), double(depth)) * trees > 1e9) {
    return Status::InvalidArgument("k^L * trees exceeds 10^9 words");
  }
  return Status::Ok();
}

StatusOr<Vocabulary> TrainVocabulary(TrainingSet set, const TrainingOptions& options_in) {
  RECOG_RETURN_IF_ERROR(options_in.Validate());
  RECOG_RETURN_IF_ERROR(set.format.Validate());
  if (set.image_offsets.empty() || set.image_offsets.front() != 0 ||
      set.image_offsets.back() != set.num_descriptors() ||
      set.descriptors.size() % set.format.size_bytes != 0) {
    return Status::InvalidArgument("training set image offsets do not match its descriptors");
  }
  if (set.num_descriptors() == 0) {
    return Status::InvalidArgument("training set has no descriptors");
  }
  TrainingOptions options = options_in;
  if (options.threads == 0) options.threads = std::max(1u, std::thread::hardware_concurrency());

  // Which image each row came from; rows are reordered during clustering, this array with them.
  std::vector<uint32_t> image_of_row(set.num_descriptors());
  for (size_t img = 0; img < set.num_images(); ++img) {
    std::fill(image_of_row.begin() + set.image_offsets[img],
              image_of_row.begin() + set.image_offsets[img + 1], uint32_t(img));
  }
  std::vector<TreeNodeTable> trees =
      set.format.type == DescriptorType::kBinary
          ? BuildTrees(BinarySpace(set.format.size_bytes), set, image_of_row, options)
          : BuildTrees(FloatSpace(set.format.size_bytes), set, image_of_row, options);

  VocabularyInfo info;
  info.descriptor = set.format;
  info.branching = options.branching;
  info.depth = options.depth;
  info.num_trees = options.trees;
  info.weighting = options.weighting;
  info.scoring = options.scoring;
  RECOG_ASSIGN_OR_RETURN(Vocabulary vocabulary, Vocabulary::FromTrees(info, trees));
  trees.clear();
  vocabulary.SetWordWeights(ComputeWordWeights(vocabulary, set, image_of_row, options));
  return vocabulary;
}

}  // namespace recog
