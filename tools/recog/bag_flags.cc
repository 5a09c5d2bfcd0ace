#include "tools/recog/bag_flags.h"

#include <vector>

namespace recog::cli {

void BagFlags::AddTo(CLI::App* command, CLI::Option* folder) {
  CLI::Option* bag_option =
      command
          ->add_option("--bag", bag,
                       "A ROS 1 or ROS 2 bag (a rosbag2 folder, an .mcap, a .db3, a .bag) "
                       "instead of " +
                           folder->get_name() +
                           ": the frames of --topic in header-stamp order, their stamps as "
                           "timestamps (docs/cli.md, \"ROS bags\")")
          ->excludes(folder);
  const auto topic = [&](const char* name, std::string* value, const std::string& help) {
    command->add_option(name, *value, help)->needs(bag_option);
  };
  topic("--topic", &topics.image,
        "With --bag: the image topic (sensor_msgs/Image in mono8, rgb8, bgr8, rgba8 or bgra8, or "
        "sensor_msgs/CompressedImage in JPEG or PNG)");
  topic("--camera-info-topic", &topics.camera_info,
        "With --bag: the image topic's sensor_msgs/CameraInfo, the frames' intrinsics (its K, or "
        "its P with --right-topic)");
  topic("--depth-topic", &topics.depth,
        "With --bag: depth registered to the images (16UC1 or mono16 millimetres, 32FC1 metres, a "
        "16-bit PNG or image_transport's compressedDepth), the nearest within --max-depth-offset "
        "of each frame");
  topic("--right-topic", &topics.right,
        "With --bag: the right images of a rectified stereo pair (equal stamps)");
  topic("--right-camera-info-topic", &topics.right_camera_info,
        "With --bag: the right camera's sensor_msgs/CameraInfo, whose P gives the baseline");
  command
      ->add_option("--max-depth-offset", options.max_depth_offset,
                   "With --depth-topic: the largest stamp difference (s) of a frame and its depth "
                   "image; a frame without one is an error")
      ->capture_default_str()
      ->needs(bag_option);
}

CLI::Option* BagFlags::AddImageTo(CLI::App* command, CLI::Option* folder, const std::string& help) {
  CLI::Option* bag_option = command->add_option("--bag", bag, help)->excludes(folder);
  command
      ->add_option("--topic", topics.image,
                   "With --bag: the image topic (sensor_msgs/Image in mono8, rgb8, bgr8, rgba8 or "
                   "bgra8, or sensor_msgs/CompressedImage in JPEG or PNG), read as grey")
      ->needs(bag_option);
  command
      ->add_option("--camera-info-topic", topics.camera_info,
                   "With --bag: the image topic's sensor_msgs/CameraInfo, whose K and D are the "
                   "frames' camera instead of --camera")
      ->needs(bag_option);
  return bag_option;
}

StatusOr<FrameSource> BagFlags::Open() const {
  if (topics.image.empty()) {
    RECOG_ASSIGN_OR_RETURN(const std::vector<BagTopicInfo> listed, RosBagReader::ListTopics(bag));
    std::string images;
    for (const BagTopicInfo& t : listed) {
      if (!bag::IsMessageType(t.type, "sensor_msgs", "Image") &&
          !bag::IsMessageType(t.type, "sensor_msgs", "CompressedImage")) {
        continue;
      }
      images += (images.empty() ? "" : ", ") + t.topic + " (" + t.type + ", " +
                std::to_string(t.messages) + " messages)";
    }
    return Status::InvalidArgument("--bag needs --topic, one of the bag's image topics: " +
                                   (images.empty() ? std::string("none") : images));
  }
  return FrameSource::OpenBag(bag, topics, options);
}

}  // namespace recog::cli
