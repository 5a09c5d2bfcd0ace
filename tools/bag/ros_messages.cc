#include "tools/bag/ros_messages.h"

#include <optional>
#include <type_traits>
#include <utility>

#include "tools/bag/byte_reader.h"
#include "tools/bag/cdr_reader.h"

namespace recog::bag {
namespace {

constexpr int64_t kNanosecondsPerSecond = 1000000000;

// The fields of one message read in order, in either serialization, so that each message is
// decoded by one function for both. The first field that does not fit in the bytes is remembered
// (later reads give zeros and empty values) and Finish() reports it, naming the field.
class FieldReader {
 public:
  // `type` names the message in errors ("sensor_msgs/Image").
  static StatusOr<FieldReader> Open(Serialization serialization, std::span<const uint8_t> bytes,
                                    std::string_view type) {
    FieldReader fields(type, serialization, bytes.size());
    if (serialization == Serialization::kRos1) {
      fields.ros1_.emplace(bytes);
    } else {
      StatusOr<CdrReader> cdr = CdrReader::Open(bytes);
      if (!cdr.ok()) return Status::InvalidArgument(fields.What() + ": " + cdr.status().message());
      fields.cdr_.emplace(*std::move(cdr));
    }
    return fields;
  }

  uint8_t U8(const char* field) {
    return Checked(field, [](auto& r) { return r.U8(); });
  }
  uint32_t U32(const char* field) {
    return Checked(field, [](auto& r) { return r.U32(); });
  }
  double F64(const char* field) {
    return Checked(field, [](auto& r) { return r.F64(); });
  }

  std::string String(const char* field) {
    const uint32_t size = Count(field, 1);
    const std::span<const uint8_t> bytes = Elements(field, size);
    std::string text(bytes.begin(), bytes.end());
    // CDR counts a terminating NUL, which is not part of the text.
    if (cdr_.has_value() && !text.empty() && text.back() == '\0') text.pop_back();
    return text;
  }

  // A uint8[] (ROS 1) or sequence<uint8> (CDR), in place.
  std::span<const uint8_t> ByteSequence(const char* field) {
    return Elements(field, Count(field, 1));
  }

  // A float64[] (ROS 1) or sequence<double> (CDR).
  std::vector<double> F64Sequence(const char* field) {
    std::vector<double> values(Count(field, sizeof(double)));
    for (double& value : values) value = F64(field);
    return values;
  }

  // A float64[N] (ROS 1) or double[N] (CDR): no count.
  template <size_t N>
  void F64Array(const char* field, std::array<double, N>* values) {
    for (double& value : *values) value = F64(field);
  }

  // std_msgs/Header: ROS 1's uint32 seq (dropped) and time (uint32 sec, nsec), or ROS 2's
  // builtin_interfaces/Time (int32 sec, uint32 nanosec), then frame_id. A negative ROS 2 sec is a
  // time before the epoch, kept as a negative stamp: sec * 1e9 + nanosec, which int64 holds for
  // every value of both.
  MessageHeader Header() {
    MessageHeader header;
    if (ros1_.has_value()) U32("header.seq");
    const int64_t sec = ros1_.has_value()
                            ? int64_t(U32("header.stamp.sec"))
                            : int64_t(Checked("header.stamp.sec", [](auto& r) { return r.I32(); }));
    const uint32_t nanosec = U32("header.stamp.nanosec");
    header.stamp_ns = sec * kNanosecondsPerSecond + nanosec;
    header.frame_id = String("header.frame_id");
    return header;
  }

  // OK, or the error of the first field that did not fit.
  const Status& Finish() const { return error_; }

 private:
  FieldReader(std::string_view type, Serialization serialization, size_t size)
      : type_(type), serialization_(serialization), size_(size) {}

  // "sensor_msgs/Image (CDR, 120 bytes)".
  std::string What() const {
    return type_ + (serialization_ == Serialization::kRos1 ? " (ROS 1, " : " (CDR, ") +
           std::to_string(size_) + " bytes)";
  }

  // The byte of the message the next read starts from (CDR counts its encapsulation header).
  size_t Position() const {
    return ros1_.has_value() ? ros1_->position() : CdrReader::kEncapsulationSize + cdr_->position();
  }
  size_t Remaining() const { return ros1_.has_value() ? ros1_->remaining() : cdr_->remaining(); }
  bool ReaderFailed() const { return ros1_.has_value() ? ros1_->failed() : cdr_->failed(); }

  // The value `read` reads from the message's reader; the field is reported when it does not fit.
  template <typename Read>
  std::invoke_result_t<Read&, ByteReader&> Checked(const char* field, Read read) {
    const size_t at = Position();
    const auto value = ros1_.has_value() ? read(*ros1_) : read(*cdr_);
    if (ReaderFailed() && error_.ok()) {
      error_ = Status::InvalidArgument(What() + " is cut short: it ends in field '" + field +
                                       "', at byte " + std::to_string(at));
    }
    return value;
  }

  // The count of a string, byte array or sequence of `element_size`-byte elements (CDR: aligned
  // to that size), 0 when its elements would not fit in what is left: nothing is allocated for a
  // count the message cannot hold.
  uint32_t Count(const char* field, size_t element_size) {
    const uint32_t count = U32(field);
    if (count == 0 || !error_.ok()) return 0;
    if (cdr_.has_value()) cdr_->Align(element_size);
    if (ReaderFailed() || uint64_t(count) * element_size > Remaining()) {
      error_ = Status::InvalidArgument(
          What() + ": field '" + field + "' declares " + std::to_string(count) + " element" +
          (count == 1 ? "" : "s") + " of " + std::to_string(element_size) + " byte" +
          (element_size == 1 ? "" : "s") + ", but only " + std::to_string(Remaining()) +
          " bytes are left");
      return 0;
    }
    return count;
  }

  // `size` bytes, whose count Count() has checked.
  std::span<const uint8_t> Elements(const char* field, uint32_t size) {
    return Checked(field, [size](auto& r) { return r.Bytes(size); });
  }

  std::string type_;
  Serialization serialization_;
  size_t size_ = 0;
  std::optional<ByteReader> ros1_;
  std::optional<CdrReader> cdr_;
  Status error_;
};

}  // namespace

StatusOr<ImageMessage> DecodeImageMessage(Serialization serialization,
                                          std::span<const uint8_t> bytes) {
  RECOG_ASSIGN_OR_RETURN(FieldReader fields,
                         FieldReader::Open(serialization, bytes, "sensor_msgs/Image"));
  ImageMessage message;
  message.header = fields.Header();
  message.height = fields.U32("height");
  message.width = fields.U32("width");
  message.encoding = fields.String("encoding");
  message.is_bigendian = fields.U8("is_bigendian") != 0;
  message.step = fields.U32("step");
  message.data = fields.ByteSequence("data");
  RECOG_RETURN_IF_ERROR(fields.Finish());
  return message;
}

StatusOr<CompressedImageMessage> DecodeCompressedImageMessage(Serialization serialization,
                                                              std::span<const uint8_t> bytes) {
  RECOG_ASSIGN_OR_RETURN(FieldReader fields,
                         FieldReader::Open(serialization, bytes, "sensor_msgs/CompressedImage"));
  CompressedImageMessage message;
  message.header = fields.Header();
  message.format = fields.String("format");
  message.data = fields.ByteSequence("data");
  RECOG_RETURN_IF_ERROR(fields.Finish());
  return message;
}

StatusOr<CameraInfoMessage> DecodeCameraInfoMessage(Serialization serialization,
                                                    std::span<const uint8_t> bytes) {
  RECOG_ASSIGN_OR_RETURN(FieldReader fields,
                         FieldReader::Open(serialization, bytes, "sensor_msgs/CameraInfo"));
  CameraInfoMessage message;
  message.header = fields.Header();
  message.height = fields.U32("height");
  message.width = fields.U32("width");
  message.distortion_model = fields.String("distortion_model");
  message.d = fields.F64Sequence("d");
  fields.F64Array("k", &message.k);
  fields.F64Array("r", &message.r);
  fields.F64Array("p", &message.p);
  // Read so that a message cut short in them is refused; the project has no use for them.
  for (const char* field :
       {"binning_x", "binning_y", "roi.x_offset", "roi.y_offset", "roi.height", "roi.width"}) {
    fields.U32(field);
  }
  fields.U8("roi.do_rectify");
  RECOG_RETURN_IF_ERROR(fields.Finish());
  return message;
}

}  // namespace recog::bag
