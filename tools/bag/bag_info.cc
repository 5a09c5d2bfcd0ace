#include "tools/bag/bag_info.h"

#include <algorithm>
#include <cstdio>
#include <ctime>

#include <nlohmann/json.hpp>

#include "tools/bag/ros_images.h"
#include "tools/bag/ros_messages.h"

namespace recog::bag {
namespace {

const char* SerializationName(Serialization s) {
  return s == Serialization::kRos1 ? "ros1" : "cdr";
}

// "2020-04-02 22:23:55.112411371 UTC (1585866235.112)".
std::string StampText(int64_t ns) {
  const std::time_t seconds = std::time_t(ns / 1000000000);
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  char date[32];
  std::strftime(date, sizeof(date), "%Y-%m-%d %H:%M:%S", &utc);
  char text[96];
  std::snprintf(text, sizeof(text), "%s.%09lld UTC (%.3f)", date,
                static_cast<long long>(ns % 1000000000), double(ns) * 1e-9);
  return text;
}

// The size of an image message for either role it may have (a depth image's compressedDepth is
// no image for the image role).
template <typename Message>
cv::Size SizeOf(const Message& message) {
  for (const ImageRole role : {ImageRole::kImage, ImageRole::kDepth}) {
    const StatusOr<ImageLayout> layout = InspectImage(message, role);
    if (layout.ok()) return layout->size;
  }
  return {};
}

StatusOr<ImageTopicDescription> DescribeFirstImage(BagStore& store, const TopicSummary& topic) {
  std::vector<uint8_t> first;
  bool taken = false;
  RECOG_RETURN_IF_ERROR(store.ForEachMessage(topic.name, [&](const StoredMessage& m) {
    if (!taken) first.assign(m.data.begin(), m.data.end());
    taken = true;
    return Status::Ok();
  }));
  ImageTopicDescription d;
  if (IsMessageType(topic.type, "sensor_msgs", "CompressedImage")) {
    RECOG_ASSIGN_OR_RETURN(const CompressedImageMessage m,
                           DecodeCompressedImageMessage(topic.serialization, first));
    d.encoding = m.format;
    d.size = SizeOf(m);
  } else {
    RECOG_ASSIGN_OR_RETURN(const ImageMessage m, DecodeImageMessage(topic.serialization, first));
    d.encoding = m.encoding;
    d.size = cv::Size(int(m.width), int(m.height));
  }
  return d;
}

}  // namespace

StatusOr<BagDescription> DescribeBag(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(const std::unique_ptr<BagStore> store, OpenBag(path));
  BagDescription description;
  description.summary = store->summary();
  for (const TopicSummary& topic : description.summary.topics) {
    const bool image = IsMessageType(topic.type, "sensor_msgs", "Image") ||
                       IsMessageType(topic.type, "sensor_msgs", "CompressedImage");
    if (!image || topic.messages == 0) continue;
    StatusOr<ImageTopicDescription> d = DescribeFirstImage(*store, topic);
    if (!d.ok()) {
      return d.status().WithContext("bag '" + path + "', topic " + topic.name + ", first message");
    }
    description.images.emplace(topic.name, *d);
  }
  return description;
}

std::string DescriptionText(const BagDescription& description) {
  const BagSummary& s = description.summary;
  std::string text;
  const auto line = [&](const char* name, const std::string& value) {
    char label[16];
    std::snprintf(label, sizeof(label), "%-13s", name);
    text += label;
    text += value;
    text += '\n';
  };
  line("path:", s.path);
  line("storage:", s.storage);
  for (size_t i = 0; i < s.files.size(); ++i) line(i == 0 ? "files:" : "", s.files[i]);
  line("compression:", s.compression);
  char duration[32];
  std::snprintf(duration, sizeof(duration), "%.9f s", double(s.end_ns - s.start_ns) * 1e-9);
  line("duration:", duration);
  if (s.messages > 0) {
    line("start:", StampText(s.start_ns));
    line("end:", StampText(s.end_ns));
  }
  line("messages:", std::to_string(s.messages));
  text += "topics:\n";
  // One line per topic, in columns: name, type, count, serialization, then an image's encoding
  // and size.
  size_t name_width = 0, type_width = 0, count_width = 0;
  for (const TopicSummary& t : s.topics) {
    name_width = std::max(name_width, t.name.size());
    type_width = std::max(type_width, t.type.size());
    count_width = std::max(count_width, std::to_string(t.messages).size());
  }
  const auto padded = [](const std::string& field, size_t width, bool right) {
    const std::string pad(width - field.size(), ' ');
    return right ? pad + field : field + pad;
  };
  for (const TopicSummary& t : s.topics) {
    text.append("  ").append(padded(t.name, name_width, false)).append("  ");
    text.append(padded(t.type, type_width, false)).append("  ");
    text.append(padded(std::to_string(t.messages), count_width, true));
    text.append(t.messages == 1 ? " message   " : " messages  ");
    text.append(SerializationName(t.serialization));
    if (const auto image = description.images.find(t.name); image != description.images.end()) {
      text.append("  ").append(image->second.encoding);
      if (image->second.size.area() > 0) {
        text.append(" (").append(std::to_string(image->second.size.width)).append(" x ");
        text.append(std::to_string(image->second.size.height)).append(")");
      }
    }
    text.append("\n");
  }
  return text;
}

nlohmann::json DescriptionJson(const BagDescription& description) {
  const BagSummary& s = description.summary;
  nlohmann::json topics = nlohmann::json::array();
  for (const TopicSummary& t : s.topics) {
    nlohmann::json topic = {{"name", t.name},
                            {"type", t.type},
                            {"serialization", SerializationName(t.serialization)},
                            {"messages", t.messages}};
    if (const auto image = description.images.find(t.name); image != description.images.end()) {
      topic["encoding"] = image->second.encoding;
      topic["width"] = image->second.size.width;
      topic["height"] = image->second.size.height;
    }
    topics.push_back(std::move(topic));
  }
  return {{"path", s.path},         {"storage", s.storage},
          {"files", s.files},       {"compression", s.compression},
          {"messages", s.messages}, {"start_ns", s.start_ns},
          {"end_ns", s.end_ns},     {"duration_s", double(s.end_ns - s.start_ns) * 1e-9},
          {"topics", topics}};
}

}  // namespace recog::bag
