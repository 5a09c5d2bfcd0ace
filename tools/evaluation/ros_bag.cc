#include "tools/evaluation/ros_bag.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <utility>

#include <rosbag/bag.h>
#include <rosbag/exceptions.h>
#include <rosbag/query.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/option_checks.h"

namespace recog::cli::bag_messages {

// The generated sensor_msgs headers name std::allocator<T>::rebind, which C++20 removed: their
// messages are instantiated with this allocator, std::allocator with rebind put back.
template <class T>
struct RosAllocator : std::allocator<T> {
  RosAllocator() = default;
  template <class U>
  RosAllocator(const RosAllocator<U>&) {}  // NOLINT: converting, as allocators are
  template <class U>
  struct rebind {
    using other = RosAllocator<U>;
  };
};

using CameraInfo = ::sensor_msgs::CameraInfo_<RosAllocator<void>>;
using Image = ::sensor_msgs::Image_<RosAllocator<void>>;
using CompressedImage = ::sensor_msgs::CompressedImage_<RosAllocator<void>>;

// A sensor_msgs/Image read in place: its fields, and its pixels as a pointer into the bag's read
// buffer, valid until the bag reads again (so that the pixels are copied once, by whoever
// converts them).
struct ImageView {
  ros::Time stamp;
  uint32_t height = 0, width = 0;
  std::string encoding;
  uint8_t is_bigendian = 0;
  uint32_t step = 0;
  const uint8_t* data = nullptr;
  uint32_t size = 0;
};

// A sensor_msgs/CompressedImage read in place, as ImageView.
struct CompressedView {
  ros::Time stamp;
  std::string format;
  const uint8_t* data = nullptr;
  uint32_t size = 0;
};

// How a message's pixels are stored.
enum class Pixels { kMono8, kRgb8, kBgr8, kRgba8, kBgra8, kDepth16, kDepth32, kJpeg, kPng };

// One message of a topic, checked at open.
struct TopicMessage {
  TopicMessage(const rosbag::MessageInstance& m, int64_t stamp) : message(m), stamp_ns(stamp) {}

  rosbag::MessageInstance message;
  int64_t stamp_ns = 0;
  Pixels pixels = Pixels::kMono8;
  cv::Size size;
  bool color = false;             // a colour image (raw or encoded)
  bool compressed_depth = false;  // compressed_depth_image_transport's header before the PNG
};

// The first fields of any message with a std_msgs/Header: its stamp (the rest unread).
template <typename Stream>
void ReadHeader(Stream& stream, ros::Time* stamp) {
  uint32_t seq = 0;
  stream.next(seq);
  stream.next(*stamp);
  uint32_t frame_id_size = 0;
  stream.next(frame_id_size);
  stream.advance(frame_id_size);
}

}  // namespace recog::cli::bag_messages

// The views are the messages of sensor_msgs (same MD5 sum, type and definition, which the bag
// checks), deserialized by the serializers below.
namespace ros::message_traits {

#define RECOG_BAG_VIEW_TRAITS(View, Message)                            \
  template <>                                                           \
  struct MD5Sum<View> {                                                 \
    static const char* value() { return MD5Sum<Message>::value(); }     \
    static const char* value(const View&) { return value(); }           \
  };                                                                    \
  template <>                                                           \
  struct DataType<View> {                                               \
    static const char* value() { return DataType<Message>::value(); }   \
    static const char* value(const View&) { return value(); }           \
  };                                                                    \
  template <>                                                           \
  struct Definition<View> {                                             \
    static const char* value() { return Definition<Message>::value(); } \
    static const char* value(const View&) { return value(); }           \
  };

RECOG_BAG_VIEW_TRAITS(recog::cli::bag_messages::ImageView, recog::cli::bag_messages::Image)
RECOG_BAG_VIEW_TRAITS(recog::cli::bag_messages::CompressedView,
                      recog::cli::bag_messages::CompressedImage)
#undef RECOG_BAG_VIEW_TRAITS

}  // namespace ros::message_traits

namespace ros::serialization {

template <>
struct Serializer<recog::cli::bag_messages::ImageView> {
  template <typename Stream>
  static void read(Stream& stream, recog::cli::bag_messages::ImageView& m) {
    recog::cli::bag_messages::ReadHeader(stream, &m.stamp);
    stream.next(m.height);
    stream.next(m.width);
    stream.next(m.encoding);
    stream.next(m.is_bigendian);
    stream.next(m.step);
    stream.next(m.size);
    m.data = stream.advance(m.size);
  }
};

template <>
struct Serializer<recog::cli::bag_messages::CompressedView> {
  template <typename Stream>
  static void read(Stream& stream, recog::cli::bag_messages::CompressedView& m) {
    recog::cli::bag_messages::ReadHeader(stream, &m.stamp);
    stream.next(m.format);
    stream.next(m.size);
    m.data = stream.advance(m.size);
  }
};

}  // namespace ros::serialization

namespace recog::cli {
namespace {

namespace fs = std::filesystem;
using bag_messages::CompressedView;
using bag_messages::ImageView;
using bag_messages::Pixels;
using bag_messages::TopicMessage;

constexpr char kImageType[] = "sensor_msgs/Image";
constexpr char kCompressedType[] = "sensor_msgs/CompressedImage";
constexpr char kCameraInfoType[] = "sensor_msgs/CameraInfo";
// compressed_depth_image_transport's header before the PNG: a format enum and two floats.
constexpr size_t kCompressedDepthHeader = 12;

std::string Quoted(const std::string& text) { return "'" + text + "'"; }

// "1305031102.175304000": a stamp as the messages show it.
std::string StampText(int64_t ns) {
  char text[40];
  std::snprintf(text, sizeof(text), "%lld.%09lld", static_cast<long long>(ns / 1000000000),
                static_cast<long long>(ns % 1000000000));
  return text;
}

int64_t Nanoseconds(const ros::Time& t) { return int64_t(t.sec) * 1000000000 + int64_t(t.nsec); }

// ---- The file ----

uint32_t Le32(const unsigned char* p) {
  return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}

// A ROS 2 bag (a folder with metadata.yaml, an SQLite .db3 or an MCAP file): named, with what
// to do.
Status Ros2Bag(const std::string& path, const std::string& what) {
  return Status::InvalidArgument(
      Quoted(path) + " is a ROS 2 bag (" + what +
      "): only ROS 1 bags are read; convert it first (docs/cli.md, \"ROS bags\")");
}

// What the file at `path` is, before rosbag opens it: a ROS 1 bag whose header says where its
// index is, and whose index is in the file (the library's own errors do not say that a bag is
// truncated, or unindexed because its recording was not closed).
Status CheckBagFile(const std::string& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    if (fs::exists(fs::path(path) / "metadata.yaml", ec)) return Ros2Bag(path, "metadata.yaml");
    return Status::InvalidArgument(Quoted(path) + " is a folder, not a ROS bag file");
  }
  if (!fs::exists(path, ec)) return Status::NotFound("bag " + Quoted(path) + " does not exist");
  const uintmax_t file_size = fs::file_size(path, ec);
  std::ifstream in(path, std::ios::binary);
  if (ec || !in) return Status::NotFound("bag " + Quoted(path) + " cannot be read");
  std::string start(13, '\0');
  in.read(start.data(), std::streamsize(start.size()));
  start.resize(size_t(in.gcount()));
  if (start.rfind("SQLite format 3", 0) == 0) return Ros2Bag(path, "SQLite storage");
  if (start.rfind("\x89MCAP", 0) == 0) return Ros2Bag(path, "MCAP storage");
  if (start.rfind("#ROSBAG V1.2", 0) == 0) return Status::Ok();  // the old format: no header
  if (start != "#ROSBAG V2.0\n") {
    return Status::InvalidArgument(Quoted(path) +
                                   " is not a ROS 1 bag: it does not start with #ROSBAG V2.0");
  }
  // The bag header record: its header's fields (length, "name=value") hold index_pos.
  unsigned char length[4];
  const auto truncated = [&] {
    return Status::DataLoss("bag " + Quoted(path) + " is truncated: it ends (at byte " +
                            std::to_string(file_size) + ") inside its header");
  };
  if (!in.read(reinterpret_cast<char*>(length), 4)) return truncated();
  std::string header(Le32(length), '\0');
  if (header.size() > 1 << 16 || !in.read(header.data(), std::streamsize(header.size()))) {
    return truncated();
  }
  std::optional<uint64_t> index_pos;
  for (size_t at = 0; at + 4 <= header.size();) {
    const uint32_t field = Le32(reinterpret_cast<const unsigned char*>(header.data() + at));
    if (at + 4 + field > header.size()) break;
    const std::string_view text(header.data() + at + 4, field);
    if (text.rfind("index_pos=", 0) == 0 && text.size() == 10 + 8) {
      uint64_t value = 0;
      std::memcpy(&value, text.data() + 10, 8);  // little endian, as x86 and ARM are
      index_pos = value;
    }
    at += 4 + field;
  }
  if (!index_pos.has_value()) {
    return Status::DataLoss("bag " + Quoted(path) + " is damaged: its header has no index_pos");
  }
  if (*index_pos == 0) {
    return Status::DataLoss("bag " + Quoted(path) +
                            " is unindexed: its recording was not closed (or is still going "
                            "on); run `rosbag reindex " +
                            path + "` to rebuild its index");
  }
  if (*index_pos >= file_size) {
    return Status::DataLoss("bag " + Quoted(path) + " is truncated: it ends at byte " +
                            std::to_string(file_size) + ", before its index (byte " +
                            std::to_string(*index_pos) +
                            "); copy it again, or run `rosbag reindex` on a copy to keep the "
                            "messages before the cut");
  }
  return Status::Ok();
}

// Runs `read` (rosbag and roscpp_serialization throw); their exceptions become DATA_LOSS naming
// the bag and `what` was read.
template <typename Read>
Status Guarded(const std::string& path, const std::string& what, Read&& read) {
  try {
    return read();
  } catch (const rosbag::BagUnindexedException&) {
    return Status::DataLoss("bag " + Quoted(path) + " is unindexed: run `rosbag reindex " + path +
                            "` to rebuild its index");
  } catch (const std::exception& e) {
    return Status::DataLoss("bag " + Quoted(path) + " cannot be read (" + what + "): " + e.what() +
                            " (a damaged or truncated file?)");
  }
}

StatusOr<std::unique_ptr<rosbag::Bag>> OpenBagFile(const std::string& path) {
  RECOG_RETURN_IF_ERROR(CheckBagFile(path));
  auto bag = std::make_unique<rosbag::Bag>();
  RECOG_RETURN_IF_ERROR(Guarded(path, "its index", [&] {
    bag->open(path, rosbag::bagmode::Read);
    return Status::Ok();
  }));
  return bag;
}

std::vector<BagTopicInfo> TopicsOf(rosbag::Bag& bag) {
  std::map<std::string, BagTopicInfo> topics;
  rosbag::View all(bag);
  for (const rosbag::ConnectionInfo* c : all.getConnections()) {
    BagTopicInfo& t = topics[c->topic];
    t.topic = c->topic;
    if (t.type.empty()) {
      t.type = c->datatype;
    } else if (t.type.find(c->datatype) == std::string::npos) {
      t.type += " and " + c->datatype;
    }
  }
  std::vector<BagTopicInfo> listed;
  for (auto& [name, t] : topics) {
    t.messages = rosbag::View(bag, rosbag::TopicQuery(name)).size();
    listed.push_back(std::move(t));
  }
  return listed;
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

// ---- Messages ----

// What a topic is for: the pixels it accepts.
enum class Role { kImage, kDepth };

constexpr const char* kImageEncodings = "mono8, 8UC1, rgb8, bgr8, rgba8, bgra8";
constexpr const char* kDepthEncodings = "16UC1 (millimetres), 32FC1 (metres)";

std::optional<Pixels> RawPixels(const std::string& encoding, Role role) {
  if (role == Role::kDepth) {
    if (encoding == "16UC1") return Pixels::kDepth16;
    if (encoding == "32FC1") return Pixels::kDepth32;
    return std::nullopt;
  }
  if (encoding == "mono8" || encoding == "8UC1") return Pixels::kMono8;
  if (encoding == "rgb8") return Pixels::kRgb8;
  if (encoding == "bgr8") return Pixels::kBgr8;
  if (encoding == "rgba8") return Pixels::kRgba8;
  if (encoding == "bgra8") return Pixels::kBgra8;
  return std::nullopt;
}

int BytesPerPixel(Pixels p) {
  switch (p) {
    case Pixels::kMono8:
      return 1;
    case Pixels::kRgb8:
    case Pixels::kBgr8:
      return 3;
    case Pixels::kRgba8:
    case Pixels::kBgra8:
    case Pixels::kDepth32:
      return 4;
    case Pixels::kDepth16:
      return 2;
    case Pixels::kJpeg:
    case Pixels::kPng:
      return 0;
  }
  return 0;
}

uint32_t Be16(const uint8_t* p) { return uint32_t(p[0]) << 8 | p[1]; }
uint32_t Be32(const uint8_t* p) { return Be16(p) << 16 | Be16(p + 2); }

// What the header of an encoded image says.
struct EncodedHeader {
  Pixels pixels = Pixels::kJpeg;
  cv::Size size;
  bool color = false;
  int bit_depth = 8;
};

// The size of a PNG (IHDR) or a JPEG (its first SOF marker) from its header; none when `data`
// is neither.
std::optional<EncodedHeader> ReadEncodedHeader(const uint8_t* data, size_t size) {
  static constexpr uint8_t kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  EncodedHeader h;
  if (size >= 26 && std::memcmp(data, kPng, 8) == 0 && std::memcmp(data + 12, "IHDR", 4) == 0) {
    h.pixels = Pixels::kPng;
    h.size = cv::Size(int(Be32(data + 16)), int(Be32(data + 20)));
    h.bit_depth = data[24];
    h.color = data[25] == 2 || data[25] == 3 || data[25] == 6;  // RGB, palette, RGBA
    return h;
  }
  if (size < 4 || data[0] != 0xff || data[1] != 0xd8) return std::nullopt;
  for (size_t at = 2; at + 4 <= size;) {
    if (data[at] != 0xff) return std::nullopt;
    const uint8_t marker = data[at + 1];
    if (marker == 0xff) {  // fill byte
      ++at;
      continue;
    }
    if (marker == 0x01 || (marker >= 0xd0 && marker <= 0xd8)) {  // no length
      at += 2;
      continue;
    }
    const bool sof =
        marker >= 0xc0 && marker <= 0xcf && marker != 0xc4 && marker != 0xc8 && marker != 0xcc;
    if (sof) {
      if (at + 10 > size) return std::nullopt;
      h.size = cv::Size(int(Be16(data + at + 7)), int(Be16(data + at + 5)));
      h.color = data[at + 9] >= 3;
      return h;
    }
    if (marker == 0xda || marker == 0xd9) return std::nullopt;  // scan or end before a frame
    at += 2 + Be16(data + at + 2);
  }
  return std::nullopt;
}

// The image messages of one topic, checked one by one; `role` says which encodings it takes.
class TopicReader {
 public:
  TopicReader(std::string path, std::string topic, Role role)
      : path_(std::move(path)), topic_(std::move(topic)), role_(role) {}

  // Reads every message's fields (not its pixels) and checks them.
  Status ReadAll(rosbag::Bag& bag, std::vector<TopicMessage>* messages) {
    return Guarded(path_, "topic " + topic_, [&]() -> Status {
      rosbag::View view(bag, rosbag::TopicQuery(topic_));
      for (const rosbag::MessageInstance& m : view) {
        if (m.getDataType() == kImageType) {
          const boost::shared_ptr<ImageView> v = m.instantiate<ImageView>();
          if (!v) return OtherDefinition(m);
          RECOG_ASSIGN_OR_RETURN(TopicMessage checked, CheckRaw(m, *v));
          messages->push_back(std::move(checked));
        } else {
          const boost::shared_ptr<CompressedView> v = m.instantiate<CompressedView>();
          if (!v) return OtherDefinition(m);
          RECOG_ASSIGN_OR_RETURN(TopicMessage checked, CheckCompressed(m, *v));
          messages->push_back(std::move(checked));
        }
      }
      return Status::Ok();
    });
  }

 private:
  Status OtherDefinition(const rosbag::MessageInstance& m) const {
    return Status::InvalidArgument("topic " + topic_ + " of bag " + Quoted(path_) + ": its " +
                                   m.getDataType() + " messages have another definition (MD5 " +
                                   m.getMD5Sum() + ") than ROS 1's");
  }

  // "topic /camera/image_raw, message at stamp 12.000000000 of bag 'x.bag'".
  std::string Where(int64_t stamp_ns) const {
    return "topic " + topic_ + ", message at stamp " + StampText(stamp_ns) + " of bag " +
           Quoted(path_);
  }

  StatusOr<TopicMessage> CheckRaw(const rosbag::MessageInstance& m, const ImageView& v) const {
    TopicMessage t(m, Nanoseconds(v.stamp));
    const std::optional<Pixels> pixels = RawPixels(v.encoding, role_);
    if (!pixels.has_value()) {
      return Status::InvalidArgument(
          Where(t.stamp_ns) + ": encoding " + Quoted(v.encoding) + " is not supported (" +
          (role_ == Role::kDepth ? kDepthEncodings : kImageEncodings) + ")");
    }
    t.pixels = *pixels;
    t.size = cv::Size(int(v.width), int(v.height));
    t.color = *pixels == Pixels::kRgb8 || *pixels == Pixels::kBgr8 || *pixels == Pixels::kRgba8 ||
              *pixels == Pixels::kBgra8;
    if (v.width == 0 || v.height == 0 || v.width > 1 << 16 || v.height > 1 << 16) {
      return Status::InvalidArgument(Where(t.stamp_ns) + ": an image of " +
                                     std::to_string(v.width) + " x " + std::to_string(v.height) +
                                     " pixels");
    }
    const uint64_t row = uint64_t(v.width) * uint64_t(BytesPerPixel(*pixels));
    if (v.step < row || uint64_t(v.size) < uint64_t(v.step) * v.height) {
      return Status::InvalidArgument(Where(t.stamp_ns) + ": " + std::to_string(v.size) +
                                     " bytes of data and a step of " + std::to_string(v.step) +
                                     " for " + std::to_string(v.width) + " x " +
                                     std::to_string(v.height) + " " + v.encoding + " pixels");
    }
    if (v.is_bigendian != 0 && BytesPerPixel(*pixels) == 2) {
      return Status::InvalidArgument(Where(t.stamp_ns) + ": big-endian " + v.encoding +
                                     " is not supported");
    }
    if (v.is_bigendian != 0 && *pixels == Pixels::kDepth32) {
      return Status::InvalidArgument(Where(t.stamp_ns) + ": big-endian " + v.encoding +
                                     " is not supported");
    }
    return t;
  }

  StatusOr<TopicMessage> CheckCompressed(const rosbag::MessageInstance& m,
                                         const CompressedView& v) const {
    TopicMessage t(m, Nanoseconds(v.stamp));
    std::string format = v.format;
    std::transform(format.begin(), format.end(), format.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    t.compressed_depth = format.find("compresseddepth") != std::string::npos;
    const bool named = format.find("jpeg") != std::string::npos ||
                       format.find("jpg") != std::string::npos ||
                       format.find("png") != std::string::npos;
    if (!named || (t.compressed_depth && role_ != Role::kDepth)) {
      return Status::InvalidArgument(Where(t.stamp_ns) + ": format " + Quoted(v.format) +
                                     " is not supported (JPEG or PNG" +
                                     (role_ == Role::kDepth ? "; 16-bit PNG for depth" : "") + ")");
    }
    const size_t skip = t.compressed_depth ? kCompressedDepthHeader : 0;
    const std::optional<EncodedHeader> header =
        v.size >= skip ? ReadEncodedHeader(v.data + skip, v.size - skip) : std::nullopt;
    if (!header.has_value()) {
      return Status::InvalidArgument(Where(t.stamp_ns) + ": format " + Quoted(v.format) +
                                     ", but its data is neither a JPEG nor a PNG");
    }
    if (role_ == Role::kDepth &&
        (header->pixels != Pixels::kPng || header->bit_depth != 16 || header->color)) {
      return Status::InvalidArgument(Where(t.stamp_ns) + ": format " + Quoted(v.format) +
                                     " is not supported for depth (a 16-bit grey PNG is)");
    }
    if (header->size.width <= 0 || header->size.height <= 0) {
      return Status::InvalidArgument(Where(t.stamp_ns) + ": an encoded image without pixels");
    }
    t.pixels = header->pixels;
    t.size = header->size;
    t.color = header->color;
    return t;
  }

  std::string path_, topic_;
  Role role_;
};

// A message's pixels as the frame holds them. Its view's pointer is used before the bag reads
// anything else.
Status DecodeImage(const TopicMessage& t, bool keep_color, cv::Mat* gray, cv::Mat* color) {
  *gray = cv::Mat();
  if (color != nullptr) *color = cv::Mat();
  if (t.pixels == Pixels::kJpeg || t.pixels == Pixels::kPng) {
    const boost::shared_ptr<CompressedView> v = t.message.instantiate<CompressedView>();
    if (!v) return Status::DataLoss("the message cannot be read again");
    const cv::Mat bytes(1, int(v->size), CV_8UC1, const_cast<uint8_t*>(v->data));
    if (keep_color && t.color && color != nullptr) {
      *color = cv::imdecode(bytes, cv::IMREAD_COLOR);
      if (!color->empty()) cv::cvtColor(*color, *gray, cv::COLOR_BGR2GRAY);
    } else {
      // As ReadGrayImage reads an image file: the decoder's own grey.
      *gray = cv::imdecode(bytes, cv::IMREAD_GRAYSCALE);
    }
  } else {
    const boost::shared_ptr<ImageView> v = t.message.instantiate<ImageView>();
    if (!v) return Status::DataLoss("the message cannot be read again");
    const int channels = BytesPerPixel(t.pixels);
    const cv::Mat pixels(int(v->height), int(v->width), CV_8UC(channels),
                         const_cast<uint8_t*>(v->data), v->step);
    const bool keep = keep_color && color != nullptr;
    switch (t.pixels) {
      case Pixels::kMono8:
        *gray = pixels.clone();
        break;
      case Pixels::kRgb8:
        cv::cvtColor(pixels, *gray, cv::COLOR_RGB2GRAY);
        if (keep) cv::cvtColor(pixels, *color, cv::COLOR_RGB2BGR);
        break;
      case Pixels::kBgr8:
        cv::cvtColor(pixels, *gray, cv::COLOR_BGR2GRAY);
        if (keep) *color = pixels.clone();
        break;
      case Pixels::kRgba8:
        cv::cvtColor(pixels, *gray, cv::COLOR_RGBA2GRAY);
        if (keep) cv::cvtColor(pixels, *color, cv::COLOR_RGBA2BGR);
        break;
      case Pixels::kBgra8:
        cv::cvtColor(pixels, *gray, cv::COLOR_BGRA2GRAY);
        if (keep) cv::cvtColor(pixels, *color, cv::COLOR_BGRA2BGR);
        break;
      default:
        return Status::Internal("not an image encoding");
    }
  }
  if (gray->size() != t.size) {
    return Status::InvalidArgument("the image does not decode to its " +
                                   std::to_string(t.size.width) + " x " +
                                   std::to_string(t.size.height) + " pixels");
  }
  return Status::Ok();
}

Status DecodeDepth(const TopicMessage& t, cv::Mat* depth) {
  if (t.pixels == Pixels::kPng) {
    const boost::shared_ptr<CompressedView> v = t.message.instantiate<CompressedView>();
    if (!v) return Status::DataLoss("the message cannot be read again");
    const size_t skip = t.compressed_depth ? kCompressedDepthHeader : 0;
    const cv::Mat bytes(1, int(v->size - skip), CV_8UC1, const_cast<uint8_t*>(v->data + skip));
    *depth = cv::imdecode(bytes, cv::IMREAD_ANYDEPTH);
    if (depth->type() != CV_16UC1 || depth->size() != t.size) {
      return Status::InvalidArgument("the depth PNG does not decode to 16-bit pixels");
    }
    return Status::Ok();
  }
  const boost::shared_ptr<ImageView> v = t.message.instantiate<ImageView>();
  if (!v) return Status::DataLoss("the message cannot be read again");
  // The pixels may sit at any address in the buffer: copied row by row, which memcpy allows.
  const int type = t.pixels == Pixels::kDepth16 ? CV_16UC1 : CV_32FC1;
  depth->create(int(v->height), int(v->width), type);
  const size_t row = depth->cols * depth->elemSize();
  for (int y = 0; y < depth->rows; ++y) {
    std::memcpy(depth->ptr(y), v->data + size_t(y) * v->step, row);
  }
  return Status::Ok();
}

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

std::string SecondsText(int64_t ns) {
  char text[32];
  std::snprintf(text, sizeof(text), "%.6g s", double(ns) * 1e-9);
  return text;
}

}  // namespace

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
  std::unique_ptr<rosbag::Bag> bag;
  std::vector<TopicMessage> images, depths, rights;
  std::vector<size_t> order;  // images in stamp order
  std::vector<double> stamps;
  std::vector<size_t> depth_of, right_of;  // per frame: the partner's index, or npos
  std::optional<BagCameraInfo> camera, right_camera;

  // The topics asked for are in the bag, of the types their role takes.
  Status CheckTopics(const std::vector<BagTopicInfo>& listed) const {
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
      const auto found = std::find_if(listed.begin(), listed.end(),
                                      [&](const BagTopicInfo& t) { return t.topic == w.topic; });
      if (found == listed.end()) {
        return Status::NotFound("bag " + Quoted(path) + " has no topic " + w.topic + " (the " +
                                w.flag + " topic); its topics: " + TopicList(listed));
      }
      const bool ok = w.image ? found->type == kImageType || found->type == kCompressedType
                              : found->type == kCameraInfoType;
      if (!ok) {
        return Status::InvalidArgument("topic " + w.topic + " (the " + w.flag + " topic) of bag " +
                                       Quoted(path) + " is " + found->type + "; expected " +
                                       (w.image ? std::string(kImageType) + " or " + kCompressedType
                                                : std::string(kCameraInfoType)) +
                                       ". The bag's topics: " + TopicList(listed));
      }
    }
    return Status::Ok();
  }

  StatusOr<std::optional<BagCameraInfo>> ReadCameraInfo(const std::string& topic) {
    if (topic.empty()) return std::optional<BagCameraInfo>();
    std::optional<BagCameraInfo> info;
    RECOG_RETURN_IF_ERROR(Guarded(path, "topic " + topic, [&]() -> Status {
      rosbag::View view(*bag, rosbag::TopicQuery(topic));
      for (const rosbag::MessageInstance& m : view) {
        const boost::shared_ptr<bag_messages::CameraInfo> c =
            m.instantiate<bag_messages::CameraInfo>();
        if (!c) {
          return Status::InvalidArgument("topic " + topic + " of bag " + Quoted(path) +
                                         ": its CameraInfo messages have another definition");
        }
        BagCameraInfo& i = info.emplace();
        i.topic = topic;
        i.size = cv::Size(int(c->width), int(c->height));
        i.distortion_model = c->distortion_model;
        i.camera = {c->K[0], c->K[4], c->K[2], c->K[5], {}};
        if (std::any_of(c->D.begin(), c->D.end(), [](double d) { return d != 0; })) {
          i.camera.distortion.assign(c->D.begin(), c->D.end());
        }
        i.rectified = {c->P[0], c->P[5], c->P[2], c->P[6], {}};
        i.projection_tx = c->P[3];
        return Status::Ok();  // the first message
      }
      return Status::Ok();
    }));
    if (!info.has_value()) {
      return Status::InvalidArgument("topic " + topic + " of bag " + Quoted(path) +
                                     " has no message");
    }
    if (!info->camera.Validate().ok()) {
      return Status::InvalidArgument("topic " + topic + " of bag " + Quoted(path) +
                                     ": the camera is not calibrated (K has no positive focal "
                                     "lengths)");
    }
    const bool known_model = info->distortion_model.empty() ||
                             info->distortion_model == "plumb_bob" ||
                             info->distortion_model == "rational_polynomial";
    if (!info->camera.distortion.empty() && !known_model) {
      return Status::InvalidArgument("topic " + topic + " of bag " + Quoted(path) +
                                     ": distortion model " + Quoted(info->distortion_model) +
                                     " is not supported (plumb_bob, rational_polynomial)");
    }
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
                                       ": two messages have the stamp " + StampText(stamp) +
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
                                StampText(frames[f]) + ") of " + topics.image;
      if (matches[f] == std::string::npos) {
        if (options.keep_unmatched_frames) continue;
        return Status::InvalidArgument(
            "bag " + Quoted(path) + ": " + frame + " has no " + what + " image on " + topic +
            " within " + SecondsText(max_ns) +
            (nearest[f] == std::numeric_limits<int64_t>::max()
                 ? std::string(" (the topic has no message)")
                 : " (the nearest is " + SecondsText(nearest[f]) + " away)"));
      }
      const cv::Size a = images[order[f]].size, b = partners[matches[f]].size;
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
    if (info->size == image->size) return Status::Ok();
    return Status::InvalidArgument("bag " + Quoted(path) + ": camera info " + info->topic +
                                   " is calibrated for " + std::to_string(info->size.width) +
                                   " x " + std::to_string(info->size.height) + " images, " + topic +
                                   " has " + std::to_string(image->size.width) + " x " +
                                   std::to_string(image->size.height));
  }
};

RosBagReader::RosBagReader(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
RosBagReader::RosBagReader(RosBagReader&&) noexcept = default;
RosBagReader& RosBagReader::operator=(RosBagReader&&) noexcept = default;
RosBagReader::~RosBagReader() = default;

StatusOr<std::vector<BagTopicInfo>> RosBagReader::ListTopics(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<rosbag::Bag> bag, OpenBagFile(path));
  std::vector<BagTopicInfo> topics;
  RECOG_RETURN_IF_ERROR(Guarded(path, "its connections", [&] {
    topics = TopicsOf(*bag);
    return Status::Ok();
  }));
  return topics;
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
  RECOG_ASSIGN_OR_RETURN(impl->bag, OpenBagFile(path));
  std::vector<BagTopicInfo> listed;
  RECOG_RETURN_IF_ERROR(Guarded(path, "its connections", [&] {
    listed = TopicsOf(*impl->bag);
    return Status::Ok();
  }));
  RECOG_RETURN_IF_ERROR(impl->CheckTopics(listed));
  RECOG_RETURN_IF_ERROR(
      TopicReader(path, topics.image, Role::kImage).ReadAll(*impl->bag, &impl->images));
  RECOG_RETURN_IF_ERROR(impl->OrderFrames());
  if (!topics.depth.empty()) {
    RECOG_RETURN_IF_ERROR(
        TopicReader(path, topics.depth, Role::kDepth).ReadAll(*impl->bag, &impl->depths));
  }
  if (!topics.right.empty()) {
    RECOG_RETURN_IF_ERROR(
        TopicReader(path, topics.right, Role::kImage).ReadAll(*impl->bag, &impl->rights));
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
  const std::string where = "bag " + Quoted(impl_->path) + ", frame " + std::to_string(i + 1) +
                            " (stamp " + StampText(image.stamp_ns) + ")";
  const auto read = [&](const std::string& topic, auto decode) -> Status {
    Status s;
    RECOG_RETURN_IF_ERROR(Guarded(impl_->path, "topic " + topic, [&] {
      s = decode();
      return Status::Ok();
    }));
    return s.ok() ? s : s.WithContext(where + " on " + topic);
  };
  RECOG_RETURN_IF_ERROR(read(impl_->topics.image, [&] {
    return DecodeImage(image, impl_->options.keep_color, &frame.gray, &frame.color);
  }));
  if (const size_t d = impl_->depth_of[i]; d != std::string::npos) {
    RECOG_RETURN_IF_ERROR(
        read(impl_->topics.depth, [&] { return DecodeDepth(impl_->depths[d], &frame.depth); }));
  }
  if (const size_t r = impl_->right_of[i]; r != std::string::npos) {
    RECOG_RETURN_IF_ERROR(read(impl_->topics.right, [&] {
      return DecodeImage(impl_->rights[r], false, &frame.right, nullptr);
    }));
  }
  return frame;
}

StatusOr<bool> RosBagReader::Next(BagFrame* frame) {
  if (next_ >= size()) return false;
  RECOG_ASSIGN_OR_RETURN(*frame, Read(next_++));
  return true;
}

}  // namespace recog::cli
