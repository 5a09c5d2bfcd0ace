#include "tools/evaluation/ros_bag.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <map>
#include <utility>

#include "core/common/option_checks.h"
#include "tools/bag/ros_images.h"
#include "tools/bag/ros_messages.h"
#include "tools/evaluation/camera_calibration.h"

namespace recog::cli {
namespace {

using bag::BagStore;
using bag::ImageLayout;
using bag::ImageRole;
using bag::IsMessageType;
using bag::StoredMessage;
using bag::TopicSummary;

std::string Quoted(const std::string& text) { return "'" + text + "'"; }

std::string SecondsText(int64_t ns) {
  char text[32];
  std::snprintf(text, sizeof(text), "%.6g s", double(ns) * 1e-9);
  return text;
}

bool IsImageType(const std::string& type) {
  return IsMessageType(type, "sensor_msgs", "Image") ||
         IsMessageType(type, "sensor_msgs", "CompressedImage");
}
bool IsCompressedType(const std::string& type) {
  return IsMessageType(type, "sensor_msgs", "CompressedImage");
}
bool IsCameraInfoType(const std::string& type) {
  return IsMessageType(type, "sensor_msgs", "CameraInfo");
}

std::vector<BagTopicInfo> TopicsOf(const BagStore& store) {
  std::vector<BagTopicInfo> topics;
  for (const TopicSummary& t : store.summary().topics)
    topics.push_back({t.name, t.type, t.messages});
  return topics;
}

// "/a (sensor_msgs/Image, 84 messages), /b (...)".
std::string TopicList(const std::vector<BagTopicInfo>& topics) {
  if (topics.empty()) return "none";
  std::string text;
  for (const BagTopicInfo& t : topics) {
    text += (text.empty() ? "" : ", ") + t.topic + " (" + t.type + ", " +
            std::to_string(t.messages) + " message" + (t.messages == 1 ? "" : "s") + ")";
  }
  return text;
}

// One message of an image topic, checked at open: where to read it again, and what it holds.
struct TopicMessage {
  uint64_t id = 0;
  int64_t stamp_ns = 0;
  ImageLayout layout;
};

// An image topic of the bag: its messages' serialization and kind, and the decoding of one.
struct ImageTopic {
  std::string name;
  bag::Serialization serialization = bag::Serialization::kCdr;
  bool compressed = false;
  ImageRole role = ImageRole::kImage;

  // Decodes `bytes` as this topic's message and passes it to `use`, which is called with an
  // ImageMessage or a CompressedImageMessage.
  template <typename Use>
  Status Decoded(std::span<const uint8_t> bytes, Use&& use) const {
    if (compressed) {
      RECOG_ASSIGN_OR_RETURN(const bag::CompressedImageMessage m,
                             bag::DecodeCompressedImageMessage(serialization, bytes));
      return use(m);
    }
    RECOG_ASSIGN_OR_RETURN(const bag::ImageMessage m,
                           bag::DecodeImageMessage(serialization, bytes));
    return use(m);
  }
};

// For each frame stamp, the message of `partners` (sorted by stamp) nearest to it within
// `max_offset_ns`, or npos; *nearest_ns gets each frame's nearest offset (for messages).
std::vector<size_t> MatchByStamp(const std::vector<int64_t>& frames,
                                 const std::vector<std::pair<int64_t, size_t>>& partners,
                                 int64_t max_offset_ns, std::vector<int64_t>* nearest_ns) {
  std::vector<size_t> matches(frames.size(), std::string::npos);
  nearest_ns->assign(frames.size(), std::numeric_limits<int64_t>::max());
  for (size_t i = 0; i < frames.size(); ++i) {
    const auto later = std::lower_bound(
        partners.begin(), partners.end(), frames[i],
        [](const std::pair<int64_t, size_t>& p, int64_t t) { return p.first < t; });
    for (auto it : {later, later == partners.begin() ? later : later - 1}) {
      if (it == partners.end()) continue;
      const int64_t offset = std::abs(it->first - frames[i]);
      if (offset > (*nearest_ns)[i]) continue;
      (*nearest_ns)[i] = offset;
      if (offset <= max_offset_ns) matches[i] = it->second;
    }
  }
  return matches;
}

}  // namespace

std::string BagStampText(int64_t ns) {
  char text[40];
  std::snprintf(text, sizeof(text), "%s%lld.%09lld", ns < 0 ? "-" : "",
                std::abs(static_cast<long long>(ns / 1000000000)),
                std::abs(static_cast<long long>(ns % 1000000000)));
  return text;
}

Status BagReadOptions::Validate(std::string_view name) const {
  OptionChecks check(name);
  check.InRange("max_depth_offset", max_depth_offset, RealRange::AtLeast(0));
  check.InRange("max_right_offset", max_right_offset, RealRange::AtLeast(0));
  return check.status();
}

struct RosBagReader::Impl {
  std::string path;
  BagTopics topics;
  BagReadOptions options;
  std::unique_ptr<BagStore> store;
  ImageTopic image_topic, depth_topic, right_topic;
  std::vector<TopicMessage> images, depths, rights;
  std::vector<size_t> order;  // images in stamp order
  std::vector<double> stamps;
  std::vector<size_t> depth_of, right_of;  // per frame: the partner's index, or npos
  std::optional<BagCameraInfo> camera, right_camera;
  std::vector<uint8_t> buffer;  // the message being decoded

  const TopicSummary* Find(const std::string& topic) const {
    for (const TopicSummary& t : store->summary().topics) {
      if (t.name == topic) return &t;
    }
    return nullptr;
  }

  // The topics asked for are in the bag, of the types their role takes.
  Status CheckTopics() const {
    struct Wanted {
      const std::string& topic;
      const char* flag;
      bool image;  // an image topic; else camera info
    };
    const Wanted wanted[] = {{topics.image, "image", true},
                             {topics.camera_info, "camera info", false},
                             {topics.depth, "depth", true},
                             {topics.right, "right", true},
                             {topics.right_camera_info, "right camera info", false}};
    for (const Wanted& w : wanted) {
      if (w.topic.empty()) continue;
      const TopicSummary* found = Find(w.topic);
      if (found == nullptr) {
        return Status::NotFound("bag " + Quoted(path) + " has no topic " + w.topic + " (the " +
                                w.flag + " topic); its topics: " + TopicList(TopicsOf(*store)));
      }
      if (w.image ? !IsImageType(found->type) : !IsCameraInfoType(found->type)) {
        return Status::InvalidArgument("topic " + w.topic + " (the " + w.flag + " topic) of bag " +
                                       Quoted(path) + " is " + found->type + "; expected " +
                                       (w.image ? "sensor_msgs/Image or sensor_msgs/CompressedImage"
                                                : "sensor_msgs/CameraInfo") +
                                       ". The bag's topics: " + TopicList(TopicsOf(*store)));
      }
    }
    return Status::Ok();
  }

  ImageTopic TopicOf(const std::string& name, ImageRole role) const {
    const TopicSummary* t = Find(name);
    return {name, t->serialization, IsCompressedType(t->type), role};
  }

  // "topic /camera/image_raw, message 3 (stamp 12.000000000) of bag 'x.bag'".
  std::string Where(const std::string& topic, size_t message, std::optional<int64_t> stamp) const {
    return "topic " + topic + ", message " + std::to_string(message + 1) +
           (stamp.has_value() ? " at stamp " + BagStampText(*stamp) : "") + " of bag " +
           Quoted(path);
  }

  // Every message of `topic`: its fields decoded and checked for its role, its pixels not.
  Status ReadTopic(const ImageTopic& topic, std::vector<TopicMessage>* messages) const {
    return store->ForEachMessage(topic.name, [&](const StoredMessage& stored) -> Status {
      const size_t n = messages->size();
      TopicMessage t;
      t.id = stored.id;
      std::optional<int64_t> stamp;  // once the message's fields are decoded
      const Status s = topic.Decoded(stored.data, [&](const auto& m) -> Status {
        stamp = t.stamp_ns = m.header.stamp_ns;
        RECOG_ASSIGN_OR_RETURN(t.layout, bag::InspectImage(m, topic.role));
        return Status::Ok();
      });
      if (!s.ok()) return s.WithContext(Where(topic.name, n, stamp));
      messages->push_back(t);
      return Status::Ok();
    });
  }

  StatusOr<std::optional<BagCameraInfo>> ReadCameraInfo(const std::string& topic) {
    if (topic.empty()) return std::optional<BagCameraInfo>();
    const TopicSummary* summary = Find(topic);
    std::optional<BagCameraInfo> info;
    Status read = store->ForEachMessage(topic, [&](const StoredMessage& stored) -> Status {
      if (info.has_value()) return Status::Ok();  // the first message is the calibration
      RECOG_ASSIGN_OR_RETURN(const bag::CameraInfoMessage c,
                             bag::DecodeCameraInfoMessage(summary->serialization, stored.data));
      BagCameraInfo& i = info.emplace();
      i.topic = topic;
      i.size = cv::Size(int(c.width), int(c.height));
      i.distortion_model = c.distortion_model;
      i.camera = {c.k[0], c.k[4], c.k[2], c.k[5], c.d};  // D: its lens below
      i.rectified = {c.p[0], c.p[5], c.p[2], c.p[6], {}};
      i.projection_tx = c.p[3];
      return Status::Ok();
    });
    const std::string where = "topic " + topic + " of bag " + Quoted(path);
    if (!read.ok()) return read.WithContext(where);
    if (!info.has_value()) return Status::InvalidArgument(where + " has no message");
    if (!(info->camera.fx > 0) || !(info->camera.fy > 0)) {
      return Status::InvalidArgument(where +
                                     ": the camera is not calibrated (K has no positive focal "
                                     "lengths)");
    }
    StatusOr<CameraIntrinsics> camera = RosCameraIntrinsics(info->camera, info->distortion_model);
    if (!camera.ok()) return camera.status().WithContext(where);
    info->camera = *std::move(camera);
    return info;
  }

  // The image topic's frames in stamp order, each stamp unique.
  Status OrderFrames() {
    if (images.empty()) {
      return Status::InvalidArgument("topic " + topics.image + " of bag " + Quoted(path) +
                                     " has no message");
    }
    order.resize(images.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(),
                     [&](size_t a, size_t b) { return images[a].stamp_ns < images[b].stamp_ns; });
    for (size_t i = 1; i < order.size(); ++i) {
      const int64_t stamp = images[order[i]].stamp_ns;
      if (stamp == images[order[i - 1]].stamp_ns) {
        return Status::InvalidArgument("topic " + topics.image + " of bag " + Quoted(path) +
                                       ": two messages have the stamp " + BagStampText(stamp) +
                                       (stamp == 0 ? " (header.stamp not set by the driver)" : "") +
                                       "; frames need distinct stamps");
      }
    }
    for (size_t i : order) stamps.push_back(double(images[i].stamp_ns) * 1e-9);
    return Status::Ok();
  }

  // Each frame's depth or right image: the nearest within `max_offset` seconds, of its size.
  StatusOr<std::vector<size_t>> Partners(const std::vector<TopicMessage>& partners,
                                         const std::string& topic, const char* what,
                                         double max_offset) const {
    if (topic.empty()) return std::vector<size_t>(order.size(), std::string::npos);
    std::vector<std::pair<int64_t, size_t>> by_stamp;
    for (size_t i = 0; i < partners.size(); ++i) by_stamp.emplace_back(partners[i].stamp_ns, i);
    std::sort(by_stamp.begin(), by_stamp.end());
    std::vector<int64_t> frames, nearest;
    for (size_t i : order) frames.push_back(images[i].stamp_ns);
    const auto max_ns = int64_t(std::llround(max_offset * 1e9));
    std::vector<size_t> matches = MatchByStamp(frames, by_stamp, max_ns, &nearest);
    for (size_t f = 0; f < frames.size(); ++f) {
      const std::string frame = "frame " + std::to_string(f + 1) + " (stamp " +
                                BagStampText(frames[f]) + ") of " + topics.image;
      if (matches[f] == std::string::npos) {
        if (options.keep_unmatched_frames) continue;
        return Status::InvalidArgument(
            "bag " + Quoted(path) + ": " + frame + " has no " + what + " image on " + topic +
            " within " + SecondsText(max_ns) +
            (nearest[f] == std::numeric_limits<int64_t>::max()
                 ? std::string(" (the topic has no message)")
                 : " (the nearest is " + SecondsText(nearest[f]) + " away)"));
      }
      const cv::Size a = images[order[f]].layout.size, b = partners[matches[f]].layout.size;
      if (a != b) {
        return Status::InvalidArgument("bag " + Quoted(path) + ": " + frame + " is " +
                                       std::to_string(a.width) + " x " + std::to_string(a.height) +
                                       ", its " + what + " image on " + topic + " " +
                                       std::to_string(b.width) + " x " + std::to_string(b.height));
      }
    }
    return matches;
  }

  // A camera info's size, when it has one, is its images'.
  Status CheckCameraSize(const std::optional<BagCameraInfo>& info, const TopicMessage* image,
                         const std::string& topic) const {
    if (!info.has_value() || image == nullptr || info->size.area() == 0) return Status::Ok();
    if (info->size == image->layout.size) return Status::Ok();
    return Status::InvalidArgument("bag " + Quoted(path) + ": camera info " + info->topic +
                                   " is calibrated for " + std::to_string(info->size.width) +
                                   " x " + std::to_string(info->size.height) + " images, " + topic +
                                   " has " + std::to_string(image->layout.size.width) + " x " +
                                   std::to_string(image->layout.size.height));
  }

  // The bytes of compressed image `message` of `topic`, as the bag holds them.
  Status EncodedBytes(const ImageTopic& topic, const TopicMessage& message,
                      std::vector<uint8_t>* bytes) {
    RECOG_RETURN_IF_ERROR(store->ReadMessage(topic.name, message.id, &buffer));
    RECOG_ASSIGN_OR_RETURN(const bag::CompressedImageMessage m,
                           bag::DecodeCompressedImageMessage(topic.serialization, buffer));
    bytes->assign(m.data.begin(), m.data.end());
    return Status::Ok();
  }

  // The pixels of `message` of `topic`: grey (and colour) for an image topic, depth for a depth
  // topic.
  Status DecodePixels(const ImageTopic& topic, const TopicMessage& message, cv::Mat* pixels,
                      cv::Mat* color) {
    RECOG_RETURN_IF_ERROR(store->ReadMessage(topic.name, message.id, &buffer));
    return topic.Decoded(buffer, [&](const auto& m) {
      return topic.role == ImageRole::kDepth ? bag::DecodeDepth(m, pixels)
                                             : bag::DecodeGray(m, pixels, color);
    });
  }
};

RosBagReader::RosBagReader(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
RosBagReader::RosBagReader(RosBagReader&&) noexcept = default;
RosBagReader& RosBagReader::operator=(RosBagReader&&) noexcept = default;
RosBagReader::~RosBagReader() = default;

StatusOr<std::vector<BagTopicInfo>> RosBagReader::ListTopics(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(const std::unique_ptr<BagStore> store, bag::OpenBag(path));
  return TopicsOf(*store);
}

StatusOr<RosBagReader> RosBagReader::Open(const std::string& path, const BagTopics& topics,
                                          const BagReadOptions& options) {
  RECOG_RETURN_IF_ERROR(options.Validate());
  if (topics.image.empty()) return Status::InvalidArgument("a bag is read with an image topic");
  if (!topics.right_camera_info.empty() && topics.right.empty()) {
    return Status::InvalidArgument("a right camera info topic goes with a right image topic");
  }
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  impl->topics = topics;
  impl->options = options;
  RECOG_ASSIGN_OR_RETURN(impl->store, bag::OpenBag(path));
  RECOG_RETURN_IF_ERROR(impl->CheckTopics());
  impl->image_topic = impl->TopicOf(topics.image, ImageRole::kImage);
  RECOG_RETURN_IF_ERROR(impl->ReadTopic(impl->image_topic, &impl->images));
  RECOG_RETURN_IF_ERROR(impl->OrderFrames());
  if (!topics.depth.empty()) {
    impl->depth_topic = impl->TopicOf(topics.depth, ImageRole::kDepth);
    RECOG_RETURN_IF_ERROR(impl->ReadTopic(impl->depth_topic, &impl->depths));
  }
  if (!topics.right.empty()) {
    impl->right_topic = impl->TopicOf(topics.right, ImageRole::kImage);
    RECOG_RETURN_IF_ERROR(impl->ReadTopic(impl->right_topic, &impl->rights));
  }
  RECOG_ASSIGN_OR_RETURN(impl->depth_of, impl->Partners(impl->depths, topics.depth, "depth",
                                                        options.max_depth_offset));
  RECOG_ASSIGN_OR_RETURN(impl->right_of, impl->Partners(impl->rights, topics.right, "right",
                                                        options.max_right_offset));
  RECOG_ASSIGN_OR_RETURN(impl->camera, impl->ReadCameraInfo(topics.camera_info));
  RECOG_ASSIGN_OR_RETURN(impl->right_camera, impl->ReadCameraInfo(topics.right_camera_info));
  RECOG_RETURN_IF_ERROR(
      impl->CheckCameraSize(impl->camera, &impl->images[impl->order[0]], topics.image));
  RECOG_RETURN_IF_ERROR(impl->CheckCameraSize(
      impl->right_camera, impl->rights.empty() ? nullptr : &impl->rights[0], topics.right));
  return RosBagReader(std::move(impl));
}

const std::string& RosBagReader::path() const { return impl_->path; }
const BagTopics& RosBagReader::topics() const { return impl_->topics; }
const bag::BagSummary& RosBagReader::summary() const { return impl_->store->summary(); }
size_t RosBagReader::size() const { return impl_->order.size(); }
const std::vector<double>& RosBagReader::stamps() const { return impl_->stamps; }
const std::optional<BagCameraInfo>& RosBagReader::camera() const { return impl_->camera; }
const std::optional<BagCameraInfo>& RosBagReader::right_camera() const {
  return impl_->right_camera;
}

std::optional<CameraIntrinsics> RosBagReader::FrameCamera() const {
  if (!impl_->camera.has_value()) return std::nullopt;
  return impl_->topics.right.empty() ? impl_->camera->camera : impl_->camera->rectified;
}

StatusOr<std::optional<double>> RosBagReader::StereoBaseline() const {
  if (!impl_->right_camera.has_value()) return std::optional<double>();
  const BagCameraInfo& right = *impl_->right_camera;
  const double baseline = right.rectified.fx > 0 ? -right.projection_tx / right.rectified.fx : 0;
  if (!(baseline > 0) || !std::isfinite(baseline)) {
    return Status::InvalidArgument("camera info " + right.topic + " of bag " + Quoted(impl_->path) +
                                   " is not a rectified right camera: its P gives no positive "
                                   "baseline (P[3] = -fx' * baseline)");
  }
  return std::optional<double>(baseline);
}

StatusOr<BagFrame> RosBagReader::Read(size_t i) {
  if (i >= impl_->order.size()) {
    return Status::InvalidArgument("frame " + std::to_string(i) + " of a bag of " +
                                   std::to_string(impl_->order.size()) + " frames");
  }
  BagFrame frame;
  frame.index = i;
  frame.stamp = impl_->stamps[i];
  const TopicMessage& image = impl_->images[impl_->order[i]];
  frame.stamp_ns = image.stamp_ns;
  const std::string where = "bag " + Quoted(impl_->path) + ", frame " + std::to_string(i + 1) +
                            " (stamp " + BagStampText(image.stamp_ns) + ") on ";
  Status s;
  if (impl_->options.keep_encoded && impl_->image_topic.compressed) {
    s = impl_->EncodedBytes(impl_->image_topic, image, &frame.encoded);
  } else {
    s = impl_->DecodePixels(impl_->image_topic, image, &frame.gray,
                            impl_->options.keep_color ? &frame.color : nullptr);
  }
  if (!s.ok()) return s.WithContext(where + impl_->topics.image);
  if (const size_t d = impl_->depth_of[i]; d != std::string::npos) {
    s = impl_->DecodePixels(impl_->depth_topic, impl_->depths[d], &frame.depth, nullptr);
    if (!s.ok()) return s.WithContext(where + impl_->topics.depth);
  }
  if (const size_t r = impl_->right_of[i]; r != std::string::npos) {
    s = impl_->DecodePixels(impl_->right_topic, impl_->rights[r], &frame.right, nullptr);
    if (!s.ok()) return s.WithContext(where + impl_->topics.right);
  }
  return frame;
}

StatusOr<bool> RosBagReader::Next(BagFrame* frame) {
  if (next_ >= size()) return false;
  RECOG_ASSIGN_OR_RETURN(*frame, Read(next_++));
  return true;
}

}  // namespace recog::cli
