// Vocabulary: a hierarchical visual vocabulary (one or several k-medians/k-means trees) that
// turns descriptors into visual words, bag-of-words vectors and direct-index entries.
//
// A descriptor goes down a tree from the root, choosing at each level the child whose centroid is
// nearest (Hamming distance for binary descriptors, squared L2 for float ones; the first child wins
// a tie). The leaf it reaches is its word. A vocabulary of several trees (thesis §5.4.3, used for
// objects) sends the descriptor down every tree and keeps the leaf nearest to it; word ids are
// global over the trees. Each word carries a weight (idf for tf-idf, 1 for tf), so
// Transform() produces the thesis's tf-idf bag of words (§3.1.3) plus the direct-index entry
// (§4.3.2): for each feature, the node `levels_up` levels above the leaves it went through.
//
// Memory layout. All nodes of all trees live in one aligned buffer, in breadth-first order per
// tree so that the children of a node are contiguous: the descriptors of the k children of a node
// are k consecutive rows, read in one streak while descending. The buffer is also the body of the
// project's vocabulary file (vocabulary_io.h), so loading is one mmap and a checksum. A 1M-word
// k=10, L=6 binary vocabulary takes 32 + 4 + 1 bytes per node and 4 bytes per word: about 45 MB.
//
// Thread safety: a Vocabulary is immutable after construction; any number of threads may call
// its const methods at once.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "core/bow/bow_vector.h"
#include "core/bow/feature_vector.h"
#include "core/bow/scoring.h"
#include "core/common/descriptor.h"
#include "core/common/status.h"
#include "core/vocabulary/layout_buffer.h"

namespace recog {

// How a word's occurrences in an image become its value in the BoW vector (DBoW2's numbering).
enum class WeightingType : uint8_t {
  kTfIdf = 0,   // (occurrences / features) * idf
  kTf = 1,      // occurrences / features
  kIdf = 2,     // idf, once per word present
  kBinary = 3,  // 1 per word present
};
std::string_view WeightingName(WeightingType type);  // "tf-idf", "tf", "idf", "binary"
StatusOr<WeightingType> ParseWeighting(std::string_view name);

// What a vocabulary is, independently of its nodes.
struct VocabularyInfo {
  DescriptorFormat descriptor = DescriptorFormat::Orb();
  uint32_t branching = 10;  // k: the most children a node has
  uint32_t depth = 5;       // L: the most levels below a root
  uint32_t num_trees = 1;   // T: 1 for places, several (12) for objects
  WeightingType weighting = WeightingType::kTfIdf;
  ScoringType scoring = ScoringType::kL1;  // the score this vocabulary is meant for

  friend bool operator==(const VocabularyInfo&, const VocabularyInfo&) = default;
};

// One tree in parent-pointer form, the common currency of the trainer and the importers.
// Node 0 is the root. Node i > 0 has parent[i] < i is not required, but every node must be
// reachable from the root, and children keep their relative order by index (first = lowest index).
struct TreeNodeTable {
  std::vector<uint32_t> parent;      // parent[0] is ignored
  std::vector<uint8_t> descriptors;  // row i = descriptor of node i; the root's row is ignored
  // Leaves: the word id (unique over all trees of the vocabulary), or kInvalidWordId to have ids
  // assigned in breadth-first leaf order. Internal nodes: ignored.
  std::vector<WordId> word;
  std::vector<float> weight;  // leaves: the word weight (idf); internal nodes: ignored

  size_t size() const { return parent.size(); }
};

struct TrainingSet;      // vocabulary_trainer.h
struct TrainingOptions;  // vocabulary_trainer.h

class Vocabulary {
 public:
  Vocabulary() = default;  // an empty vocabulary: no words, Transform() fails
  Vocabulary(Vocabulary&&) noexcept = default;
  Vocabulary& operator=(Vocabulary&&) noexcept = default;
  Vocabulary(const Vocabulary&) = delete;
  Vocabulary& operator=(const Vocabulary&) = delete;

  // Lays out the given trees. Fails on an inconsistent table (orphan or cyclic nodes, a node with
  // more than 255 children, a tree deeper than 255, duplicate or missing word ids, wrong
  // descriptor row size). Word ids must be either all given or all kInvalidWordId.
  static StatusOr<Vocabulary> FromTrees(const VocabularyInfo& info,
                                        std::span<const TreeNodeTable> trees);

  const VocabularyInfo& info() const { return info_; }
  bool empty() const { return num_words_ == 0; }
  size_t num_words() const { return num_words_; }
  size_t num_nodes() const { return num_nodes_; }
  // XXH3-64 of the layout buffer: equal checksums mean equal vocabularies. Databases record it
  // to refuse entries computed with another vocabulary.
  uint64_t checksum() const { return checksum_; }
  // Bytes held by the loaded vocabulary.
  size_t MemoryBytes() const { return buffer_.size(); }

  float WordWeight(WordId word) const { return word_weight_[word]; }

  // Converts a set of descriptors (one per row) into a BoW vector and, when `features` is not
  // null, the direct-index entry at `levels_up` levels above the words (0 = the words themselves,
  // >= depth = the root, i.e. one node holding every feature; see DirectIndexDepth). `bow` gets
  // the vocabulary's weighting and the normalisation `normalization`; words of weight 0 are left
  // out, as DBoW2 does. Outputs are cleared first and their memory reused.
  // Fails with INVALID_ARGUMENT when the matrix does not match the descriptor format.
  Status Transform(const cv::Mat& descriptors, BowVector* bow, FeatureVector* features = nullptr,
                   int levels_up = 0, BowNormalization normalization = BowNormalization::kL1) const;

  // The word of one descriptor (`descriptor` points at size_bytes bytes); when `node` is not null
  // it receives the direct-index node at `levels_up` levels above the words.
  WordId TransformOne(const uint8_t* descriptor, NodeId* node = nullptr, int levels_up = 0) const;
  // TransformOne for every row of `descriptors`, in one batch (much faster than a loop over
  // TransformOne: the rows descend together, their cache misses overlapped). (*words)[i] and,
  // when `nodes` is not null, (*nodes)[i] are row i's; both are resized, their memory reused.
  // Fails as Transform does.
  Status TransformEach(const cv::Mat& descriptors, std::vector<WordId>* words,
                       std::vector<NodeId>* nodes = nullptr, int levels_up = 0) const;

  // Depth below the root of the direct-index node for `levels_up`: max(0, depth - levels_up).
  // For several trees, the node at that depth nearest to the descriptor over all trees is used
  // (thesis §5.4.4.3: "the closest node in the first discretization level of all the trees").
  int DirectIndexDepth(int levels_up) const;

  // --- Tree structure, for tests, exporters and tools (not for hot paths). ---
  NodeId Root(uint32_t tree) const { return roots_[tree]; }
  bool IsLeaf(NodeId node) const { return child_count_[node] == 0; }
  uint32_t ChildCount(NodeId node) const { return child_count_[node]; }
  NodeId FirstChild(NodeId node) const { return child_begin_or_word_[node]; }
  WordId WordOf(NodeId leaf) const { return child_begin_or_word_[leaf]; }
  const uint8_t* NodeDescriptor(NodeId node) const { return descriptors_ + size_t(node) * stride_; }

  // The raw layout buffer, for the file writer.
  std::span<const uint8_t> buffer() const { return {buffer_.data(), buffer_.size()}; }
  // Adopts a layout buffer read back from a file (BufferSize bytes, e.g. a file mapping) after
  // checking that it is consistent with `info` and the counts (child ranges, word ids), so that
  // a corrupt file cannot make Transform read out of bounds. DATA_LOSS when it is not.
  static StatusOr<Vocabulary> FromLayout(const VocabularyInfo& info, uint32_t num_nodes,
                                         uint32_t num_words, LayoutBuffer buffer);
  // Size in bytes of the layout buffer for these counts.
  static size_t BufferSize(const VocabularyInfo& info, uint32_t num_nodes, uint32_t num_words);

 private:
  void BindArrays();  // points the typed arrays into buffer_
  Status CheckLayout() const;

  // Sends one descriptor down every tree; returns the nearest leaf's word and, in *di_node, the
  // direct-index node at depth di_depth (see DirectIndexDepth).
  friend StatusOr<Vocabulary> TrainVocabulary(TrainingSet set, const TrainingOptions& options);
  // Replaces the word weights (training computes them after the layout) and the checksum.
  // Only for vocabularies built in memory (FromTrees), never for a mapped file.
  void SetWordWeights(std::span<const float> weights);

  template <class Distance>
  WordId Descend(const Distance& distance, const uint8_t* descriptor, int di_depth,
                 NodeId* di_node) const;
  // The descent of Descend for `count` binary rows, run level by level over batches of rows
  // with the next level prefetched; calls emit(i, word, direct-index node) for every row i.
  template <class Distance, class Emit>
  void DescendBinaryBatch(const Distance& distance, const uint8_t* rows, size_t count, int di_depth,
                          Emit&& emit) const;
  // emit(i, word, direct-index node) for each of `count` rows: DescendBinaryBatch for binary
  // descriptors, Descend row by row otherwise.
  template <class Emit>
  void DescendRows(const uint8_t* rows, size_t count, int di_depth, Emit&& emit) const;

  VocabularyInfo info_;
  uint32_t num_nodes_ = 0;
  uint32_t num_words_ = 0;
  uint32_t stride_ = 0;  // bytes between two node descriptors
  uint64_t checksum_ = 0;
  LayoutBuffer buffer_;

  // Views into buffer_.
  const uint32_t* roots_ = nullptr;                // [num_trees]
  const uint8_t* descriptors_ = nullptr;           // [num_nodes * stride_]
  const uint32_t* child_begin_or_word_ = nullptr;  // [num_nodes]: first child, or word for leaves
  const uint8_t* child_count_ = nullptr;           // [num_nodes]: 0 for leaves
  const float* word_weight_ = nullptr;             // [num_words]
};

}  // namespace recog
