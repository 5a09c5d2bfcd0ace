// FeatureVector: the direct-index entry of an image, vocabulary node -> features under it.
//
// For every feature of an image, Vocabulary::Transform records the vocabulary node at a chosen
// level above the words (thesis §4.3.2: level l counted up from the leaves) that the feature's
// descriptor went through. The FeatureVector groups feature indices by that node, with nodes in
// increasing order, so correspondences between two images are found by walking both node lists
// at once (thesis Algorithm 2) and comparing only features under a common node.
//
// Storage is compressed-sparse-row: one array of node ids, one of offsets, one of feature
// indices; all three are reused by Clear(), so steady-state conversion does not allocate.
#pragma once

#include <cstdint>
#include <span>
#include <utility>
#include <vector>

namespace recog {

using NodeId = uint32_t;

class FeatureVector {
 public:
  // Number of distinct nodes.
  size_t size() const { return nodes_.size(); }
  bool empty() const { return nodes_.empty(); }
  // Total number of features over all nodes.
  size_t num_features() const { return features_.size(); }

  NodeId node(size_t i) const { return nodes_[i]; }
  // Indices (rows of the descriptor matrix) of the features under node(i), increasing.
  std::span<const uint32_t> features(size_t i) const {
    return {features_.data() + offsets_[i], features_.data() + offsets_[i + 1]};
  }
  std::span<const NodeId> nodes() const { return nodes_; }
  // Position of node(i)'s first feature in the list of every node's features, node by node.
  size_t first_position(size_t i) const { return offsets_[i]; }

  void Clear();
  // Rebuilds the vector from (node, feature) pairs sorted by node then feature.
  void AssignSorted(std::span<const std::pair<NodeId, uint32_t>> sorted_pairs);
  // Low-level builder for decoders: appends a node with its (increasing) feature indices.
  // Nodes must be appended in strictly increasing order.
  void AppendNode(NodeId node, std::span<const uint32_t> feature_indices);

  friend bool operator==(const FeatureVector&, const FeatureVector&) = default;

 private:
  std::vector<NodeId> nodes_;
  std::vector<uint32_t> offsets_{0};
  std::vector<uint32_t> features_;
};

}  // namespace recog
