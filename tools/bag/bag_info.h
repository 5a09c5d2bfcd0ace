// BagDescription: what `recog bag info` prints of a bag — what `rosbag info`, `ros2 bag info` and
// `mcap info` print: its storage, files, compression, duration with its first and last stamps,
// and per topic its type, serialization and message count; for an image topic also the encoding
// (or a compressed image's format) and the size of its first message.
#pragma once

#include <map>
#include <string>

#include <nlohmann/json_fwd.hpp>
#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "tools/bag/bag_store.h"

namespace recog::bag {

// An image topic's first message.
struct ImageTopicDescription {
  std::string encoding;  // sensor_msgs/Image's encoding, or CompressedImage's format
  cv::Size size;         // 0 x 0 when its data is not an image this project reads
};

struct BagDescription {
  BagSummary summary;
  std::map<std::string, ImageTopicDescription> images;  // by topic, for image topics with messages
};

// The description of the bag at `path`: OpenBag's errors, and the first message's of each image
// topic (a message that cannot be decoded, naming its topic).
StatusOr<BagDescription> DescribeBag(const std::string& path);

// As `recog bag info` prints it, and as its --json.
std::string DescriptionText(const BagDescription& description);
nlohmann::json DescriptionJson(const BagDescription& description);

}  // namespace recog::bag
