#include "storage/record_codec.h"

#include <bit>
#include <climits>
#include <cstring>
#include <type_traits>

namespace recog::storage {
namespace {

// Values are written with memcpy in host order; the format says little-endian.
static_assert(std::endian::native == std::endian::little,
              "record_codec writes little-endian values with memcpy");

template <class T>
void Put(std::string* out, T value) {
  static_assert(std::is_trivially_copyable_v<T>);
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out->append(bytes, sizeof(T));
}

void PutBigEndian32(std::string* out, uint32_t value) {
  const char bytes[4] = {char(value >> 24), char(value >> 16), char(value >> 8), char(value)};
  out->append(bytes, 4);
}

uint32_t GetBigEndian32(const char* p) {
  const auto* u = reinterpret_cast<const uint8_t*>(p);
  return (uint32_t(u[0]) << 24) | (uint32_t(u[1]) << 16) | (uint32_t(u[2]) << 8) | uint32_t(u[3]);
}

// Reads values from a byte string, never past its end. Every Read* returns false, leaving the
// output untouched, when fewer bytes are left than it needs.
class Reader {
 public:
  explicit Reader(std::string_view bytes) : bytes_(bytes) {}

  size_t left() const { return bytes_.size() - pos_; }

  template <class T>
  bool Read(T* value) {
    static_assert(std::is_trivially_copyable_v<T>);
    if (left() < sizeof(T)) return false;
    std::memcpy(value, bytes_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return true;
  }
  // Points *out at the next n bytes.
  bool Skip(size_t n, const char** out) {
    if (left() < n) return false;
    *out = bytes_.data() + pos_;
    pos_ += n;
    return true;
  }

 private:
  std::string_view bytes_;
  size_t pos_ = 0;
};

std::string StartValue() {
  std::string out;
  out.push_back(char(kRecordFormat));
  return out;
}

// The DATA_LOSS status of a malformed record.
Status Malformed(std::string_view what, const RecordContext& context, const std::string& why) {
  return Status::DataLoss(std::string(what) + " of " + context.Describe() + ": " + why);
}

// Reads and checks the leading format byte.
Status ReadFormat(Reader* reader, std::string_view what, const RecordContext& context) {
  uint8_t format = 0;
  if (!reader->Read(&format)) return Malformed(what, context, "empty record");
  if (format != kRecordFormat) {
    return Malformed(what, context,
                     "unknown record format " + std::to_string(format) + " (this build reads " +
                         std::to_string(kRecordFormat) + ")");
  }
  return Status::Ok();
}

Status Truncated(std::string_view what, const RecordContext& context, const Reader& reader) {
  return Malformed(what, context,
                   "truncated record (" + std::to_string(reader.left()) + " bytes left)");
}

Status ExpectEnd(std::string_view what, const RecordContext& context, const Reader& reader) {
  if (reader.left() == 0) return Status::Ok();
  return Malformed(what, context, std::to_string(reader.left()) + " unexpected trailing bytes");
}

// True when `count` items of `item_size` bytes fit in what the reader has left.
bool Fits(const Reader& reader, uint64_t count, uint64_t item_size) {
  return item_size == 0 || count <= reader.left() / item_size;
}

// The flags byte of a kMetadataFormat record.
constexpr uint8_t kMetadataHasTimestamp = 1;

constexpr size_t kKeyPointBytes = 6 * 4;

}  // namespace

std::string RecordContext::Describe() const {
  std::string out = "map " + std::to_string(map);
  if (entry != kInvalidEntryId) out += " entry " + std::to_string(entry);
  return out;
}

// --- Keys ---

std::string EntryKey(MapId map, EntryId id) {
  std::string key;
  key.reserve(kEntryKeySize);
  PutBigEndian32(&key, map);
  PutBigEndian32(&key, id);
  return key;
}

std::string MapEntriesBegin(MapId map) { return EntryKey(map, 0); }

std::string MapEntriesEnd(MapId map) {
  // The map's largest key followed by one more byte: greater than every 8-byte key of the map and
  // smaller than every key of map + 1, without overflowing when map is the largest id.
  std::string key = EntryKey(map, UINT32_MAX);
  key.push_back('\xff');
  return key;
}

bool DecodeEntryKey(std::string_view key, MapId* map, EntryId* id) {
  if (key.size() != kEntryKeySize) return false;
  *map = GetBigEndian32(key.data());
  *id = GetBigEndian32(key.data() + 4);
  return true;
}

std::string MapInfoKey(const std::string& name) { return kMapInfoTag + name; }

std::string NextEntryIdKey(MapId map) {
  std::string key(1, kNextEntryIdTag);
  PutBigEndian32(&key, map);
  return key;
}

bool DecodeNextEntryIdKey(std::string_view key, MapId* map) {
  if (key.size() != 5 || key[0] != kNextEntryIdTag) return false;
  *map = GetBigEndian32(key.data() + 1);
  return true;
}

// --- Catalog values ---

std::string EncodeStoreRecord(const StoreRecord& record) {
  std::string out = StartValue();
  Put<uint32_t>(&out, record.next_map_id);
  return out;
}

Status DecodeStoreRecord(std::string_view bytes, StoreRecord* out) {
  Reader reader(bytes);
  uint8_t format = 0;
  if (!reader.Read(&format)) return Status::DataLoss("the store record is empty");
  if (format != kRecordFormat) {
    return Status::FailedPrecondition("the store was written with record format " +
                                      std::to_string(format) + "; this build reads format " +
                                      std::to_string(kRecordFormat));
  }
  StoreRecord record;
  if (!reader.Read(&record.next_map_id) || reader.left() != 0) {
    return Status::DataLoss("the store record has " + std::to_string(bytes.size()) +
                            " bytes, expected 5");
  }
  if (record.next_map_id == 0) return Status::DataLoss("the store record has next map id 0");
  *out = record;
  return Status::Ok();
}

std::string EncodeMapInfo(const MapInfo& info) {
  const MapConfig& c = info.config;
  std::string out = StartValue();
  Put<uint32_t>(&out, info.id);
  Put<int64_t>(&out, info.created_unix_ms);
  Put<uint64_t>(&out, c.vocabulary_checksum);
  Put<uint32_t>(&out, c.vocabulary_words);
  Put<uint32_t>(&out, c.vocabulary_nodes);
  Put<uint8_t>(&out, uint8_t(c.descriptor.type));
  Put<uint32_t>(&out, c.descriptor.size_bytes);
  Put<uint8_t>(&out, uint8_t(c.scoring));
  Put<uint32_t>(&out, c.direct_index_levels_up);
  return out;
}

Status DecodeMapInfo(std::string_view name, std::string_view bytes, MapInfo* out) {
  const std::string what = "catalog record of map '" + std::string(name) + "'";
  Reader reader(bytes);
  uint8_t format = 0;
  if (!reader.Read(&format) || format != kRecordFormat) {
    return Status::DataLoss(what + ": empty record or unknown record format");
  }
  MapInfo info;
  MapConfig& c = info.config;
  c.name = std::string(name);
  uint8_t descriptor_type = 0;
  uint8_t scoring = 0;
  const bool complete = reader.Read(&info.id) && reader.Read(&info.created_unix_ms) &&
                        reader.Read(&c.vocabulary_checksum) && reader.Read(&c.vocabulary_words) &&
                        reader.Read(&c.vocabulary_nodes) && reader.Read(&descriptor_type) &&
                        reader.Read(&c.descriptor.size_bytes) && reader.Read(&scoring) &&
                        reader.Read(&c.direct_index_levels_up);
  if (!complete) return Status::DataLoss(what + ": truncated record");
  if (reader.left() != 0) return Status::DataLoss(what + ": unexpected trailing bytes");
  if (descriptor_type != uint8_t(DescriptorType::kBinary) &&
      descriptor_type != uint8_t(DescriptorType::kFloat)) {
    return Status::DataLoss(what + ": unknown descriptor type " + std::to_string(descriptor_type));
  }
  c.descriptor.type = DescriptorType(descriptor_type);
  c.scoring = ScoringType(scoring);
  if (info.id == 0) return Status::DataLoss(what + ": map id 0");
  const Status valid = c.Validate();
  if (!valid.ok()) return valid.WithContext(what, StatusCode::kDataLoss);
  *out = std::move(info);
  return Status::Ok();
}

std::string EncodeNextEntryId(EntryId next) {
  std::string out = StartValue();
  Put<uint32_t>(&out, next);
  return out;
}

Status DecodeNextEntryId(std::string_view bytes, const RecordContext& context, EntryId* out) {
  constexpr std::string_view kWhat = "next entry id";
  Reader reader(bytes);
  RECOG_RETURN_IF_ERROR(ReadFormat(&reader, kWhat, context));
  EntryId next = 0;
  if (!reader.Read(&next)) return Truncated(kWhat, context, reader);
  RECOG_RETURN_IF_ERROR(ExpectEnd(kWhat, context, reader));
  *out = next;
  return Status::Ok();
}

// --- Entry parts ---

Status CheckStorable(const EntryRecord& entry) {
  const std::string which = "entry " + std::to_string(entry.id);
  const std::span<const BowEntry> bow = entry.bow.entries();
  for (size_t i = 1; i < bow.size(); ++i) {
    if (bow[i].word <= bow[i - 1].word) {
      return Status::InvalidArgument("bow words of " + which + " are not strictly increasing");
    }
  }
  const FeatureVector& direct = entry.direct;
  for (size_t i = 0; i < direct.size(); ++i) {
    if (i > 0 && direct.node(i) <= direct.node(i - 1)) {
      return Status::InvalidArgument("direct-index nodes of " + which +
                                     " are not strictly increasing");
    }
    const std::span<const uint32_t> under = direct.features(i);
    for (size_t k = 1; k < under.size(); ++k) {
      if (under[k] <= under[k - 1]) {
        return Status::InvalidArgument("direct-index features of " + which + " under node " +
                                       std::to_string(direct.node(i)) + " are not increasing");
      }
    }
  }
  if (entry.descriptors.dims > 2 || entry.descriptors.channels() > 4) {
    return Status::InvalidArgument("descriptors of " + which +
                                   " must be a matrix of at most two dimensions and four channels");
  }
  if (entry.metadata.user_data.size() > UINT32_MAX ||
      entry.metadata.client_id.size() > UINT32_MAX || entry.keypoints.size() > UINT32_MAX) {
    return Status::InvalidArgument(which + " is too large to store");
  }
  return Status::Ok();
}

std::string EncodeMetadata(const EntryMetadata& metadata) {
  std::string out(1, char(kMetadataFormat));
  out.reserve(1 + 1 + 8 + 4 + 4 + metadata.user_data.size() + 4 + metadata.client_id.size());
  out.push_back(char(metadata.timestamp.has_value() ? kMetadataHasTimestamp : 0));
  if (metadata.timestamp.has_value()) Put<double>(&out, *metadata.timestamp);
  Put<uint32_t>(&out, metadata.num_features);
  Put<uint32_t>(&out, uint32_t(metadata.user_data.size()));
  out += metadata.user_data;
  Put<uint32_t>(&out, uint32_t(metadata.client_id.size()));
  out += metadata.client_id;
  return out;
}

Status DecodeMetadata(std::string_view bytes, const RecordContext& context, EntryMetadata* out) {
  constexpr std::string_view kWhat = "metadata";
  Reader reader(bytes);
  uint8_t format = 0;
  if (!reader.Read(&format)) return Malformed(kWhat, context, "empty record");
  if (format != kRecordFormat && format != kMetadataWithClientIdFormat &&
      format != kMetadataFormat) {
    return Malformed(kWhat, context, "unknown record format " + std::to_string(format));
  }
  EntryMetadata metadata;
  double timestamp = 0;
  if (format == kMetadataFormat) {
    uint8_t flags = 0;
    if (!reader.Read(&flags)) return Truncated(kWhat, context, reader);
    if ((flags & ~kMetadataHasTimestamp) != 0) {
      return Malformed(kWhat, context, "unknown flags " + std::to_string(flags));
    }
    if (flags & kMetadataHasTimestamp) {
      if (!reader.Read(&timestamp)) return Truncated(kWhat, context, reader);
      metadata.timestamp = timestamp;
    }
  } else {
    if (!reader.Read(&timestamp)) return Truncated(kWhat, context, reader);
    if (timestamp != 0.0) metadata.timestamp = timestamp;  // 0 meant "none" then
  }
  uint32_t user_data_size = 0;
  const char* user_data = nullptr;
  if (!reader.Read(&metadata.num_features) || !reader.Read(&user_data_size) ||
      !reader.Skip(user_data_size, &user_data)) {
    return Truncated(kWhat, context, reader);
  }
  metadata.user_data.assign(user_data, user_data_size);
  if (format != kRecordFormat) {
    uint32_t client_id_size = 0;
    const char* client_id = nullptr;
    if (!reader.Read(&client_id_size) || !reader.Skip(client_id_size, &client_id)) {
      return Truncated(kWhat, context, reader);
    }
    metadata.client_id.assign(client_id, client_id_size);
  }
  RECOG_RETURN_IF_ERROR(ExpectEnd(kWhat, context, reader));
  *out = std::move(metadata);
  return Status::Ok();
}

std::string EncodeBow(const BowVector& bow) {
  std::string out = StartValue();
  out.reserve(1 + 4 + bow.size() * 8);
  Put<uint32_t>(&out, uint32_t(bow.size()));
  for (const BowEntry& e : bow.entries()) {
    Put<uint32_t>(&out, e.word);
    Put<float>(&out, e.value);
  }
  return out;
}

Status DecodeBow(std::string_view bytes, const RecordContext& context, BowVector* out) {
  constexpr std::string_view kWhat = "bow";
  Reader reader(bytes);
  RECOG_RETURN_IF_ERROR(ReadFormat(&reader, kWhat, context));
  uint32_t count = 0;
  if (!reader.Read(&count)) return Truncated(kWhat, context, reader);
  if (uint64_t(count) * 8 != reader.left()) {
    return Malformed(kWhat, context,
                     std::to_string(count) + " words need " + std::to_string(uint64_t(count) * 8) +
                         " bytes, the record has " + std::to_string(reader.left()));
  }
  BowVector bow;
  std::vector<BowEntry>& entries = bow.mutable_entries();
  entries.reserve(count);
  for (uint32_t i = 0; i < count; ++i) {
    BowEntry e{};
    reader.Read(&e.word);
    reader.Read(&e.value);
    if (!entries.empty() && e.word <= entries.back().word) {
      return Malformed(kWhat, context, "words are not strictly increasing");
    }
    entries.push_back(e);
  }
  *out = std::move(bow);
  return Status::Ok();
}

std::string EncodeDirect(const FeatureVector& direct) {
  std::string out = StartValue();
  const size_t n = direct.size();
  out.reserve(1 + 8 + (2 * n + 1 + direct.num_features()) * 4);
  Put<uint32_t>(&out, uint32_t(n));
  Put<uint32_t>(&out, uint32_t(direct.num_features()));
  for (NodeId node : direct.nodes()) Put<uint32_t>(&out, node);
  uint32_t offset = 0;
  Put<uint32_t>(&out, offset);
  for (size_t i = 0; i < n; ++i) {
    offset += uint32_t(direct.features(i).size());
    Put<uint32_t>(&out, offset);
  }
  for (size_t i = 0; i < n; ++i) {
    for (uint32_t feature : direct.features(i)) Put<uint32_t>(&out, feature);
  }
  return out;
}

Status DecodeDirect(std::string_view bytes, const RecordContext& context, FeatureVector* out) {
  constexpr std::string_view kWhat = "direct index";
  Reader reader(bytes);
  RECOG_RETURN_IF_ERROR(ReadFormat(&reader, kWhat, context));
  uint32_t n = 0;
  uint32_t m = 0;
  if (!reader.Read(&n) || !reader.Read(&m)) return Truncated(kWhat, context, reader);
  const uint64_t needed = (uint64_t(n) * 2 + 1 + m) * 4;
  if (needed != reader.left()) {
    return Malformed(kWhat, context,
                     std::to_string(n) + " nodes and " + std::to_string(m) + " features need " +
                         std::to_string(needed) + " bytes, the record has " +
                         std::to_string(reader.left()));
  }
  std::vector<uint32_t> nodes(n);
  std::vector<uint32_t> offsets(size_t(n) + 1);
  std::vector<uint32_t> features(m);
  for (uint32_t& v : nodes) reader.Read(&v);
  for (uint32_t& v : offsets) reader.Read(&v);
  for (uint32_t& v : features) reader.Read(&v);
  if (offsets.front() != 0 || offsets.back() != m) {
    return Malformed(kWhat, context, "offsets do not span the features");
  }
  FeatureVector direct;
  for (uint32_t i = 0; i < n; ++i) {
    if (i > 0 && nodes[i] <= nodes[i - 1]) {
      return Malformed(kWhat, context, "nodes are not strictly increasing");
    }
    if (offsets[i + 1] < offsets[i] || offsets[i + 1] > m) {
      return Malformed(kWhat, context, "offsets are not increasing");
    }
    const std::span<const uint32_t> under(features.data() + offsets[i],
                                          features.data() + offsets[i + 1]);
    for (size_t k = 1; k < under.size(); ++k) {
      if (under[k] <= under[k - 1]) {
        return Malformed(kWhat, context,
                         "features of node " + std::to_string(nodes[i]) + " are not increasing");
      }
    }
    direct.AppendNode(nodes[i], under);
  }
  *out = std::move(direct);
  return Status::Ok();
}

StatusOr<std::string> EncodeFeatures(const std::vector<cv::KeyPoint>& keypoints,
                                     const cv::Mat& descriptors,
                                     const std::vector<cv::Point3f>& points,
                                     const cv::Matx33d& camera) {
  if (descriptors.dims > 2 || descriptors.channels() > 4) {
    return Status::InvalidArgument(
        "descriptors must be a matrix of at most two dimensions and four channels");
  }
  if (!points.empty() && points.size() != keypoints.size()) {
    return Status::InvalidArgument("entry has " + std::to_string(points.size()) +
                                   " 3D points for " + std::to_string(keypoints.size()) +
                                   " keypoints");
  }
  const size_t row_bytes = size_t(descriptors.cols) * descriptors.elemSize();
  // Frames without a camera matrix keep the first layout, object entries (3D points, no camera)
  // the second; frames with a camera matrix use the third.
  const bool has_camera = camera != cv::Matx33d::zeros();
  const uint8_t format = has_camera       ? kFeaturesWithCameraFormat
                         : points.empty() ? kRecordFormat
                                          : kFeaturesWithPointsFormat;
  std::string out(1, char(format));
  out.reserve(1 + 4 + keypoints.size() * kKeyPointBytes + 12 + descriptors.rows * row_bytes + 72 +
              4 + points.size() * 12);
  Put<uint32_t>(&out, uint32_t(keypoints.size()));
  for (const cv::KeyPoint& k : keypoints) {
    Put<float>(&out, k.pt.x);
    Put<float>(&out, k.pt.y);
    Put<float>(&out, k.size);
    Put<float>(&out, k.angle);
    Put<float>(&out, k.response);
    Put<int32_t>(&out, k.octave);
  }
  Put<uint32_t>(&out, uint32_t(descriptors.rows));
  Put<uint32_t>(&out, uint32_t(descriptors.cols));
  Put<int32_t>(&out, descriptors.type());
  for (int r = 0; r < descriptors.rows; ++r) {
    out.append(reinterpret_cast<const char*>(descriptors.ptr(r)), row_bytes);
  }
  if (has_camera) {
    for (int i = 0; i < 9; ++i) Put<double>(&out, camera.val[i]);
  }
  if (has_camera || !points.empty()) {
    Put<uint32_t>(&out, uint32_t(points.size()));
    for (const cv::Point3f& p : points) {
      Put<float>(&out, p.x);
      Put<float>(&out, p.y);
      Put<float>(&out, p.z);
    }
  }
  return out;
}

Status DecodeFeatures(std::string_view bytes, const RecordContext& context,
                      std::vector<cv::KeyPoint>* keypoints, cv::Mat* descriptors,
                      std::vector<cv::Point3f>* points, cv::Matx33d* camera) {
  constexpr std::string_view kWhat = "features";
  Reader reader(bytes);
  uint8_t format = 0;
  if (!reader.Read(&format)) return Malformed(kWhat, context, "empty record");
  if (format != kRecordFormat && format != kFeaturesWithPointsFormat &&
      format != kFeaturesWithCameraFormat) {
    return Malformed(kWhat, context, "unknown record format " + std::to_string(format));
  }
  uint32_t num_keypoints = 0;
  if (!reader.Read(&num_keypoints)) return Truncated(kWhat, context, reader);
  if (!Fits(reader, num_keypoints, kKeyPointBytes)) {
    return Malformed(kWhat, context,
                     std::to_string(num_keypoints) + " keypoints do not fit in the record");
  }
  std::vector<cv::KeyPoint> keys(num_keypoints);
  for (cv::KeyPoint& k : keys) {
    reader.Read(&k.pt.x);
    reader.Read(&k.pt.y);
    reader.Read(&k.size);
    reader.Read(&k.angle);
    reader.Read(&k.response);
    reader.Read(&k.octave);
  }
  uint32_t rows = 0;
  uint32_t cols = 0;
  int32_t type = 0;
  if (!reader.Read(&rows) || !reader.Read(&cols) || !reader.Read(&type)) {
    return Truncated(kWhat, context, reader);
  }
  if (rows > uint32_t(INT_MAX) || cols > uint32_t(INT_MAX)) {
    return Malformed(kWhat, context, "descriptor matrix is too large");
  }
  if (type < 0 || type > CV_MAT_TYPE_MASK || CV_MAT_CN(type) > 4) {
    return Malformed(kWhat, context, "unknown descriptor element type " + std::to_string(type));
  }
  const uint64_t row_bytes = uint64_t(cols) * CV_ELEM_SIZE(type);
  if (!Fits(reader, rows, row_bytes)) {
    return Malformed(kWhat, context,
                     "a " + std::to_string(rows) + "x" + std::to_string(cols) +
                         " descriptor matrix does not match the " + std::to_string(reader.left()) +
                         " bytes left");
  }
  cv::Mat matrix;
  if (rows != 0 || cols != 0) matrix.create(int(rows), int(cols), type);
  const char* data = nullptr;
  reader.Skip(size_t(rows * row_bytes), &data);
  if (rows * row_bytes != 0) std::memcpy(matrix.data, data, size_t(rows * row_bytes));
  cv::Matx33d matrix_of_camera = cv::Matx33d::zeros();
  if (format == kFeaturesWithCameraFormat) {
    for (double& value : matrix_of_camera.val) {
      if (!reader.Read(&value)) return Truncated(kWhat, context, reader);
    }
    if (!(matrix_of_camera(0, 0) > 0.0 && matrix_of_camera(1, 1) > 0.0 &&
          cv::checkRange(matrix_of_camera))) {
      return Malformed(kWhat, context, "camera matrix without finite, positive focal lengths");
    }
  }
  std::vector<cv::Point3f> positions;
  if (format != kRecordFormat) {
    uint32_t num_points = 0;
    if (!reader.Read(&num_points)) return Truncated(kWhat, context, reader);
    const bool points_optional = format == kFeaturesWithCameraFormat;
    if ((num_points != num_keypoints && !(points_optional && num_points == 0)) ||
        uint64_t(num_points) * 12 != reader.left()) {
      return Malformed(kWhat, context,
                       std::to_string(num_points) + " 3D points for " +
                           std::to_string(num_keypoints) + " keypoints in " +
                           std::to_string(reader.left()) + " bytes");
    }
    positions.resize(num_points);
    for (cv::Point3f& p : positions) {
      reader.Read(&p.x);
      reader.Read(&p.y);
      reader.Read(&p.z);
    }
  }
  if (reader.left() != 0) {
    return Malformed(kWhat, context, std::to_string(reader.left()) + " bytes after the features");
  }
  *keypoints = std::move(keys);
  *descriptors = std::move(matrix);
  *points = std::move(positions);
  *camera = matrix_of_camera;
  return Status::Ok();
}

}  // namespace recog::storage
