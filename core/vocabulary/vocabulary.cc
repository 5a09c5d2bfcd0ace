#include "core/vocabulary/vocabulary.h"

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <numeric>
#include <utility>

#include <xxhash.h>

#include "core/common/radix_sort.h"

namespace recog {
namespace {

constexpr size_t kAlignment = 64;

size_t AlignUp(size_t n) { return (n + kAlignment - 1) / kAlignment * kAlignment; }

// Byte offsets of the arrays inside the layout buffer.
struct LayoutOffsets {
  size_t roots, descriptors, child_begin, child_count, word_weight, total;
};

LayoutOffsets ComputeOffsets(const VocabularyInfo& info, uint32_t num_nodes, uint32_t num_words) {
  LayoutOffsets o{};
  o.roots = 0;
  o.descriptors = AlignUp(size_t(info.num_trees) * sizeof(uint32_t));
  o.child_begin = o.descriptors + AlignUp(size_t(num_nodes) * info.descriptor.size_bytes);
  o.child_count = o.child_begin + AlignUp(size_t(num_nodes) * sizeof(uint32_t));
  o.word_weight = o.child_count + AlignUp(num_nodes);
  o.total = o.word_weight + AlignUp(size_t(num_words) * sizeof(float));
  return o;
}

Status ValidateInfo(const VocabularyInfo& info) {
  RECOG_RETURN_IF_ERROR(info.descriptor.Validate());
  if (info.branching < 2 || info.branching > 255) {
    return Status::InvalidArgument("branching factor k=" + std::to_string(info.branching) +
                                   " is out of range 2..255");
  }
  if (info.depth < 1 || info.depth > 255) {
    return Status::InvalidArgument("depth L=" + std::to_string(info.depth) +
                                   " is out of range 1..255");
  }
  if (info.num_trees < 1 || info.num_trees > 255) {
    return Status::InvalidArgument("number of trees " + std::to_string(info.num_trees) +
                                   " is out of range 1..255");
  }
  if (uint8_t(info.weighting) > uint8_t(WeightingType::kBinary)) {
    return Status::InvalidArgument("unknown weighting " + std::to_string(int(info.weighting)));
  }
  if (uint8_t(info.scoring) > uint8_t(ScoringType::kDotProduct)) {
    return Status::InvalidArgument("unknown scoring " + std::to_string(int(info.scoring)));
  }
  return Status::Ok();
}

// Distance functors for Descend(); each returns an ordered value, smaller = nearer.
struct Hamming256Distance {
  uint32_t operator()(const uint8_t* a, const uint8_t* b) const { return Hamming256(a, b); }
};
struct HammingAnyDistance {
  size_t bytes;
  uint32_t operator()(const uint8_t* a, const uint8_t* b) const {
    return HammingDistance(a, b, bytes);
  }
};
struct SquaredL2Distance {
  size_t dims;
  float operator()(const uint8_t* a, const uint8_t* b) const {
    return SquaredL2(reinterpret_cast<const float*>(a), reinterpret_cast<const float*>(b), dims);
  }
};

// Calls f(distance functor) with the functor matching the format.
template <class F>
decltype(auto) WithDistance(const DescriptorFormat& format, F&& f) {
  if (format.type == DescriptorType::kFloat) {
    return f(SquaredL2Distance{format.size_bytes / sizeof(float)});
  }
  if (format.size_bytes == 32) return f(Hamming256Distance{});
  return f(HammingAnyDistance{format.size_bytes});
}

}  // namespace

std::string_view WeightingName(WeightingType type) {
  switch (type) {
    case WeightingType::kTfIdf:
      return "tf-idf";
    case WeightingType::kTf:
      return "tf";
    case WeightingType::kIdf:
      return "idf";
    case WeightingType::kBinary:
      return "binary";
  }
  return "unknown";
}

StatusOr<WeightingType> ParseWeighting(std::string_view name) {
  for (WeightingType t :
       {WeightingType::kTfIdf, WeightingType::kTf, WeightingType::kIdf, WeightingType::kBinary}) {
    if (name == WeightingName(t)) return t;
  }
  return Status::InvalidArgument("unknown weighting '" + std::string(name) +
                                 "' (expected tf-idf, tf, idf or binary)");
}

size_t Vocabulary::BufferSize(const VocabularyInfo& info, uint32_t num_nodes, uint32_t num_words) {
  return ComputeOffsets(info, num_nodes, num_words).total;
}

void Vocabulary::BindArrays() {
  const LayoutOffsets o = ComputeOffsets(info_, num_nodes_, num_words_);
  const uint8_t* base = buffer_.data();
  roots_ = reinterpret_cast<const uint32_t*>(base + o.roots);
  descriptors_ = base + o.descriptors;
  child_begin_or_word_ = reinterpret_cast<const uint32_t*>(base + o.child_begin);
  child_count_ = base + o.child_count;
  word_weight_ = reinterpret_cast<const float*>(base + o.word_weight);
  stride_ = info_.descriptor.size_bytes;
}

StatusOr<Vocabulary> Vocabulary::FromTrees(const VocabularyInfo& info,
                                           std::span<const TreeNodeTable> trees) {
  RECOG_RETURN_IF_ERROR(ValidateInfo(info));
  if (trees.size() != info.num_trees) {
    return Status::InvalidArgument("vocabulary declares " + std::to_string(info.num_trees) +
                                   " trees but " + std::to_string(trees.size()) + " were given");
  }
  const size_t row = info.descriptor.size_bytes;

  // Breadth-first order of every tree: order[t][new position] = table index.
  std::vector<std::vector<uint32_t>> order(trees.size());
  size_t total_nodes = 0;
  size_t total_leaves = 0;
  size_t given_word_ids = 0;
  for (size_t t = 0; t < trees.size(); ++t) {
    const TreeNodeTable& tree = trees[t];
    const size_t n = tree.size();
    const std::string where = "tree " + std::to_string(t) + ": ";
    if (n < 2) return Status::InvalidArgument(where + "has no node below the root");
    if (tree.word.size() != n || tree.weight.size() != n || tree.descriptors.size() != n * row) {
      return Status::InvalidArgument(where + "node arrays have inconsistent sizes");
    }
    // Children lists in index order (CSR).
    std::vector<uint32_t> child_count(n, 0);
    for (size_t i = 1; i < n; ++i) {
      const uint32_t p = tree.parent[i];
      if (p >= n || p == i) {
        return Status::InvalidArgument(where + "node " + std::to_string(i) +
                                       " has an invalid parent " + std::to_string(p));
      }
      if (++child_count[p] > 255) {
        return Status::InvalidArgument(where + "node " + std::to_string(p) +
                                       " has more than 255 children");
      }
    }
    std::vector<uint32_t> first(n + 1, 0);
    for (size_t i = 0; i < n; ++i) first[i + 1] = first[i] + child_count[i];
    std::vector<uint32_t> children(n > 0 ? n - 1 : 0);
    std::vector<uint32_t> fill(first.begin(), first.end() - 1);
    for (size_t i = 1; i < n; ++i) children[fill[tree.parent[i]]++] = uint32_t(i);

    std::vector<uint32_t>& bfs = order[t];
    std::vector<uint8_t> depth(n, 0);
    bfs.reserve(n);
    bfs.push_back(0);
    for (size_t head = 0; head < bfs.size(); ++head) {
      const uint32_t node = bfs[head];
      for (uint32_t c = first[node]; c < first[node + 1]; ++c) {
        const uint32_t child = children[c];
        if (depth[node] == 255) return Status::InvalidArgument(where + "is deeper than 255");
        depth[child] = uint8_t(depth[node] + 1);
        bfs.push_back(child);
      }
    }
    if (bfs.size() != n) {
      return Status::InvalidArgument(where + std::to_string(n - bfs.size()) +
                                     " nodes are not reachable from the root");
    }
    for (size_t i = 0; i < n; ++i) {
      if (i != 0 && child_count[i] == 0) {
        ++total_leaves;
        if (tree.word[i] != kInvalidWordId) ++given_word_ids;
      }
    }
    total_nodes += n;
  }
  if (total_nodes > std::numeric_limits<uint32_t>::max() / 2) {
    return Status::InvalidArgument("vocabulary has too many nodes");
  }
  if (given_word_ids != 0 && given_word_ids != total_leaves) {
    return Status::InvalidArgument("word ids must be given for all leaves or for none (" +
                                   std::to_string(given_word_ids) + " of " +
                                   std::to_string(total_leaves) + " given)");
  }

  Vocabulary v;
  v.info_ = info;
  v.num_nodes_ = uint32_t(total_nodes);
  v.num_words_ = uint32_t(total_leaves);
  v.buffer_ = LayoutBuffer::Allocate(BufferSize(info, v.num_nodes_, v.num_words_));
  const LayoutOffsets o = ComputeOffsets(info, v.num_nodes_, v.num_words_);
  uint8_t* base = v.buffer_.mutable_data();
  auto* roots = reinterpret_cast<uint32_t*>(base + o.roots);
  uint8_t* descriptors = base + o.descriptors;
  auto* child_begin = reinterpret_cast<uint32_t*>(base + o.child_begin);
  uint8_t* child_count = base + o.child_count;
  auto* word_weight = reinterpret_cast<float*>(base + o.word_weight);

  std::vector<uint8_t> word_seen(total_leaves, 0);
  uint32_t next_node = 0;
  uint32_t next_word = 0;
  for (size_t t = 0; t < trees.size(); ++t) {
    const TreeNodeTable& tree = trees[t];
    const std::vector<uint32_t>& bfs = order[t];
    std::vector<uint32_t> position(tree.size());
    for (uint32_t p = 0; p < bfs.size(); ++p) position[bfs[p]] = next_node + p;
    roots[t] = next_node;
    // In BFS order the children of a node are consecutive, and the first child of each node is
    // the first node whose parent it is.
    for (uint32_t p = 0; p < bfs.size(); ++p) {
      const uint32_t index = bfs[p];
      const uint32_t at = next_node + p;
      if (index != 0) {
        std::memcpy(descriptors + size_t(at) * row, tree.descriptors.data() + size_t(index) * row,
                    row);
        const uint32_t parent_at = position[tree.parent[index]];
        if (child_count[parent_at]++ == 0) child_begin[parent_at] = at;
      }
    }
    for (uint32_t p = 1; p < bfs.size(); ++p) {
      const uint32_t index = bfs[p];
      const uint32_t at = next_node + p;
      if (child_count[at] != 0) continue;
      const WordId word = given_word_ids != 0 ? tree.word[index] : next_word++;
      if (word >= total_leaves || word_seen[word]) {
        return Status::InvalidArgument("tree " + std::to_string(t) + ": word id " +
                                       std::to_string(word) + " is duplicated or out of range 0.." +
                                       std::to_string(total_leaves - 1));
      }
      word_seen[word] = 1;
      child_begin[at] = word;
      word_weight[word] = tree.weight[index];
    }
    next_node += uint32_t(bfs.size());
  }
  v.BindArrays();
  v.checksum_ = XXH3_64bits(v.buffer_.data(), v.buffer_.size());
  return v;
}

StatusOr<Vocabulary> Vocabulary::FromLayout(const VocabularyInfo& info, uint32_t num_nodes,
                                            uint32_t num_words, LayoutBuffer buffer) {
  if (Status s = ValidateInfo(info); !s.ok()) return Status::DataLoss(s.message());
  if (num_words == 0 || num_words > num_nodes) {
    return Status::DataLoss("vocabulary has " + std::to_string(num_words) + " words for " +
                            std::to_string(num_nodes) + " nodes");
  }
  if (buffer.size() != BufferSize(info, num_nodes, num_words)) {
    return Status::DataLoss("vocabulary layout has " + std::to_string(buffer.size()) +
                            " bytes; its counts imply " +
                            std::to_string(BufferSize(info, num_nodes, num_words)));
  }
  Vocabulary v;
  v.info_ = info;
  v.num_nodes_ = num_nodes;
  v.num_words_ = num_words;
  v.buffer_ = std::move(buffer);
  v.BindArrays();
  RECOG_RETURN_IF_ERROR(v.CheckLayout());
  v.checksum_ = XXH3_64bits(v.buffer_.data(), v.buffer_.size());
  return v;
}

Status Vocabulary::CheckLayout() const {
  // Children always come after their parent, so every descent ends; every index stays in range.
  for (uint32_t t = 0; t < info_.num_trees; ++t) {
    if (roots_[t] >= num_nodes_ || child_count_[roots_[t]] == 0) {
      return Status::DataLoss("vocabulary tree " + std::to_string(t) + " has an invalid root");
    }
  }
  for (uint32_t node = 0; node < num_nodes_; ++node) {
    const uint32_t count = child_count_[node];
    const uint32_t value = child_begin_or_word_[node];
    if (count == 0 ? value >= num_words_
                   : (value <= node || uint64_t(value) + count > num_nodes_)) {
      return Status::DataLoss("vocabulary node " + std::to_string(node) +
                              " has an invalid child range or word id");
    }
  }
  return Status::Ok();
}

void Vocabulary::SetWordWeights(std::span<const float> weights) {
  const LayoutOffsets o = ComputeOffsets(info_, num_nodes_, num_words_);
  std::memcpy(buffer_.mutable_data() + o.word_weight, weights.data(),
              std::min(weights.size(), size_t(num_words_)) * sizeof(float));
  checksum_ = XXH3_64bits(buffer_.data(), buffer_.size());
}

int Vocabulary::DirectIndexDepth(int levels_up) const {
  return std::max(0, int(info_.depth) - std::max(0, levels_up));
}

template <class Distance>
WordId Vocabulary::Descend(const Distance& distance, const uint8_t* descriptor, int di_depth,
                           NodeId* di_node) const {
  using D = decltype(distance(descriptor, descriptor));
  constexpr D kFar = std::numeric_limits<D>::max();
  WordId best_word = kInvalidWordId;
  D best_word_distance = kFar;
  // Depth 0 means the root of the first tree, which every feature shares.
  NodeId best_di = roots_[0];
  D best_di_distance = di_depth == 0 ? D(0) : kFar;

  for (uint32_t t = 0; t < info_.num_trees; ++t) {
    NodeId node = roots_[t];
    int depth = 0;
    D node_distance = kFar;
    while (child_count_[node] != 0) {
      const uint32_t first = child_begin_or_word_[node];
      const uint32_t count = child_count_[node];
      const uint8_t* rows = descriptors_ + size_t(first) * stride_;
      D best = distance(descriptor, rows);
      uint32_t best_child = 0;
      for (uint32_t c = 1; c < count; ++c) {
        const D d = distance(descriptor, rows + size_t(c) * stride_);
        if (d < best) {
          best = d;
          best_child = c;
        }
      }
      node = first + best_child;
      node_distance = best;
      if (++depth == di_depth && best < best_di_distance) {
        best_di_distance = best;
        best_di = node;
      }
    }
    // A leaf above the direct-index depth stands for itself.
    if (depth < di_depth && node_distance < best_di_distance) {
      best_di_distance = node_distance;
      best_di = node;
    }
    if (node_distance < best_word_distance) {
      best_word_distance = node_distance;
      best_word = child_begin_or_word_[node];
    }
  }
  if (di_node != nullptr) *di_node = best_di;
  return best_word;
}

template <class Distance, class Emit>
void Vocabulary::DescendBinaryBatch(const Distance& distance, const uint8_t* rows, size_t count,
                                    int di_depth, Emit&& emit) const {
  // With 8 rows in flight, the cache misses of one row's next level are hidden behind the
  // distance computations of the 7 others (8, 16 and 32 measured: 8 is fastest here).
  constexpr size_t kBatch = 8;
  constexpr size_t kCacheLine = 64;
  constexpr uint32_t kFar = UINT32_MAX;
  for (size_t base = 0; base < count; base += kBatch) {
    const size_t n = std::min(kBatch, count - base);
    // Over all trees so far: the nearest leaf's word, and the nearest node at the direct-index
    // depth (depth 0: the first root, which every row shares).
    WordId word[kBatch];
    uint32_t word_distance[kBatch];
    NodeId di_node[kBatch];
    uint32_t di_distance[kBatch];
    for (size_t j = 0; j < n; ++j) {
      word[j] = kInvalidWordId;
      word_distance[j] = kFar;
      di_node[j] = roots_[0];
      di_distance[j] = di_depth == 0 ? 0 : kFar;
    }
    for (uint32_t tree = 0; tree < info_.num_trees; ++tree) {
      // In this tree: the current node, its distance, and the deepest node up to the
      // direct-index depth with its distance (a leaf above that depth stands for itself).
      NodeId node[kBatch];
      uint32_t node_distance[kBatch];
      NodeId tree_di[kBatch];
      uint32_t tree_di_distance[kBatch];
      for (size_t j = 0; j < n; ++j) {
        node[j] = tree_di[j] = roots_[tree];
        node_distance[j] = tree_di_distance[j] = kFar;
      }
      bool descending = true;
      for (int depth = 1; descending; ++depth) {
        descending = false;
        for (size_t j = 0; j < n; ++j) {
          const uint32_t children = child_count_[node[j]];
          if (children == 0) continue;  // reached its leaf earlier
          const uint32_t first = child_begin_or_word_[node[j]];
          const uint8_t* block = descriptors_ + size_t(first) * stride_;
          const uint8_t* row = rows + (base + j) * stride_;
          // Branch-free arg-min: distance in the high bits, child index in the low 8 bits, so
          // the smallest key is the nearest child and, on a tie, the first one.
          uint32_t best = UINT32_MAX;
          for (uint32_t c = 0; c < children; ++c) {
            best = std::min(best, (uint32_t(distance(row, block + size_t(c) * stride_)) << 8) | c);
          }
          const NodeId next = first + (best & 0xffu);
          node[j] = next;
          node_distance[j] = best >> 8;
          if (depth <= di_depth) {
            tree_di[j] = next;
            tree_di_distance[j] = best >> 8;
          }
          if (child_count_[next] != 0) {
            const uint32_t next_first = child_begin_or_word_[next];
            const uint8_t* next_block = descriptors_ + size_t(next_first) * stride_;
            const size_t bytes = size_t(child_count_[next]) * stride_;
            for (size_t offset = 0; offset < bytes; offset += kCacheLine) {
              __builtin_prefetch(next_block + offset);
            }
            __builtin_prefetch(child_begin_or_word_ + next_first);
            __builtin_prefetch(child_count_ + next_first);
            descending = true;
          }
        }
      }
      for (size_t j = 0; j < n; ++j) {
        if (node_distance[j] < word_distance[j]) {
          word_distance[j] = node_distance[j];
          word[j] = child_begin_or_word_[node[j]];
        }
        if (tree_di_distance[j] < di_distance[j]) {
          di_distance[j] = tree_di_distance[j];
          di_node[j] = tree_di[j];
        }
      }
    }
    for (size_t j = 0; j < n; ++j) emit(base + j, word[j], di_node[j]);
  }
}

template <class Emit>
void Vocabulary::DescendRows(const uint8_t* rows, size_t count, int di_depth, Emit&& emit) const {
  if (info_.descriptor.type == DescriptorType::kBinary) {
    if (stride_ == 32) {
      DescendBinaryBatch(Hamming256Distance{}, rows, count, di_depth, emit);
    } else {
      DescendBinaryBatch(HammingAnyDistance{stride_}, rows, count, di_depth, emit);
    }
    return;
  }
  WithDistance(info_.descriptor, [&](const auto& distance) {
    for (size_t i = 0; i < count; ++i) {
      NodeId node = 0;
      const WordId word = Descend(distance, rows + i * stride_, di_depth, &node);
      emit(i, word, node);
    }
    return 0;
  });
}

WordId Vocabulary::TransformOne(const uint8_t* descriptor, NodeId* node, int levels_up) const {
  if (empty()) return kInvalidWordId;
  const int di_depth = DirectIndexDepth(levels_up);
  return WithDistance(info_.descriptor, [&](const auto& distance) {
    return Descend(distance, descriptor, di_depth, node);
  });
}

Status Vocabulary::TransformEach(const cv::Mat& descriptors, std::vector<WordId>* words,
                                 std::vector<NodeId>* nodes, int levels_up) const {
  if (empty()) return Status::FailedPrecondition("the vocabulary is empty");
  RECOG_RETURN_IF_ERROR(CheckDescriptorMatrix(descriptors, info_.descriptor));
  const size_t n = descriptors.empty() ? 0 : size_t(descriptors.rows);
  words->resize(n);
  if (nodes != nullptr) nodes->resize(n);
  if (n == 0) return Status::Ok();
  WordId* word_out = words->data();
  NodeId* node_out = nodes != nullptr ? nodes->data() : nullptr;
  DescendRows(descriptors.ptr<uint8_t>(0), n, DirectIndexDepth(levels_up),
              [&](size_t i, WordId word, NodeId node) {
                word_out[i] = word;
                if (node_out != nullptr) node_out[i] = node;
              });
  return Status::Ok();
}

Status Vocabulary::Transform(const cv::Mat& descriptors, BowVector* bow, FeatureVector* features,
                             int levels_up, BowNormalization normalization) const {
  if (empty()) return Status::FailedPrecondition("the vocabulary is empty");
  RECOG_RETURN_IF_ERROR(CheckDescriptorMatrix(descriptors, info_.descriptor));
  bow->Clear();
  if (features != nullptr) features->Clear();
  const size_t n = descriptors.empty() ? 0 : size_t(descriptors.rows);
  if (n == 0) return Status::Ok();

  // Per-thread scratch so that steady-state conversion does not allocate.
  thread_local std::vector<std::pair<NodeId, uint32_t>> node_of_feature, node_scratch;
  thread_local std::vector<BowEntry> entry_scratch;
  std::vector<BowEntry>& entries = bow->mutable_entries();
  entries.resize(n);
  if (features != nullptr) node_of_feature.resize(n);

  const int di_depth = DirectIndexDepth(levels_up);
  BowEntry* entry = entries.data();
  auto* pairs = features != nullptr ? node_of_feature.data() : nullptr;
  DescendRows(descriptors.ptr<uint8_t>(0), n, di_depth, [&](size_t i, WordId word, NodeId node) {
    entry[i] = {word, word_weight_[word]};
    if (pairs != nullptr) pairs[i] = {node, uint32_t(i)};
  });

  // Group by word. tf weightings add up the occurrences, idf/binary count a word once; words of
  // weight 0 are left out (they carry no information, and DBoW2 leaves them out too).
  RadixSortByKey(entries, entry_scratch, num_words_ - 1, [](const BowEntry& e) { return e.word; });
  const bool accumulate =
      info_.weighting == WeightingType::kTfIdf || info_.weighting == WeightingType::kTf;
  const double scale = accumulate ? 1.0 / double(n) : 1.0;
  size_t out = 0;
  for (size_t i = 0; i < n;) {
    const WordId word = entries[i].word;
    const double weight = entries[i].value;
    size_t j = i + 1;
    while (j < n && entries[j].word == word) ++j;
    if (weight > 0.0) {
      const double occurrences = accumulate ? double(j - i) : 1.0;
      entries[out++] = {word, float(weight * occurrences * scale)};
    }
    i = j;
  }
  entries.resize(out);
  bow->Normalize(normalization);

  if (features != nullptr) {
    // Stable: features stay in increasing order within a node.
    RadixSortByKey(node_of_feature, node_scratch, num_nodes_ - 1,
                   [](const std::pair<NodeId, uint32_t>& p) { return p.first; });
    features->AssignSorted(node_of_feature);
  }
  return Status::Ok();
}

}  // namespace recog
