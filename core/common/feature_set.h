// FeatureSet: the local features of one image, the unit every core module passes around.
//
// Keypoints and descriptors are parallel: row i of `descriptors` describes keypoints[i], in one
// DescriptorFormat (core/common/descriptor.h). Extractors (core/features/) fill it; the
// vocabulary, the index, the loop detector and the object recogniser only read it, so this type
// lives in core's bottom layer and none of them needs the extractors' header.
#pragma once

#include <cstddef>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/descriptor.h"
#include "core/common/status.h"

namespace recog {

struct FeatureSet {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;  // one row per keypoint, in the extractor's DescriptorFormat
  // The size of the image the features come from (the extractors set it; 0 x 0 when unknown,
  // e.g. features from elsewhere that did not say).
  cv::Size image_size = cv::Size(0, 0);

  size_t size() const { return keypoints.size(); }
};

// OK for an empty set or one descriptor row per keypoint in `format`; INVALID_ARGUMENT saying
// what differs otherwise. For features that come from outside (a robot, a file).
Status CheckFeatureSet(const FeatureSet& features, const DescriptorFormat& format);

}  // namespace recog
