#include "core/common/feature_set.h"

#include <string>

namespace recog {

Status CheckFeatureSet(const FeatureSet& features, const DescriptorFormat& format) {
  if (features.size() == 0) return Status::Ok();
  if (size_t(features.descriptors.rows) != features.size()) {
    return Status::InvalidArgument(std::to_string(features.size()) + " keypoints but " +
                                   std::to_string(features.descriptors.rows) +
                                   " descriptor rows (one per keypoint expected)");
  }
  return CheckDescriptorMatrix(features.descriptors, format);
}

}  // namespace recog
