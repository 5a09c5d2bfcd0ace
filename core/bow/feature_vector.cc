#include "core/bow/feature_vector.h"

namespace recog {

void FeatureVector::Clear() {
  nodes_.clear();
  offsets_.assign(1, 0);
  features_.clear();
}

void FeatureVector::AssignSorted(std::span<const std::pair<NodeId, uint32_t>> sorted_pairs) {
  Clear();
  for (const auto& [node, feature] : sorted_pairs) {
    if (nodes_.empty() || nodes_.back() != node) {
      if (!nodes_.empty()) offsets_.push_back(uint32_t(features_.size()));
      nodes_.push_back(node);
    }
    features_.push_back(feature);
  }
  if (!nodes_.empty()) offsets_.push_back(uint32_t(features_.size()));
}

void FeatureVector::AppendNode(NodeId node, std::span<const uint32_t> feature_indices) {
  nodes_.push_back(node);
  features_.insert(features_.end(), feature_indices.begin(), feature_indices.end());
  offsets_.push_back(uint32_t(features_.size()));
}

}  // namespace recog
