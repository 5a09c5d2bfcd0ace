#include "core/object/formats/model_file.h"

#include "core/common/byte_codec.h"
#include "core/common/file_io.h"

#include <bit>
#include <climits>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <system_error>
#include <type_traits>

#include <xxhash.h>

namespace recog {
namespace {

// Values are written with memcpy in host order; the format says little-endian.
static_assert(std::endian::native == std::endian::little,
              "model_file writes little-endian values with memcpy");

constexpr char kModelMagic[8] = {'R', 'E', 'C', 'O', 'G', 'O', 'B', 'J'};
constexpr uint32_t kModelVersion = 1;
constexpr size_t kModelHeaderSize = 40;
constexpr size_t kModelHeaderChecksumSpan = 32;  // header bytes covered by the header checksum

// A tag is stored as a little-endian u32 whose bytes spell the name, so a hex dump reads "META".
constexpr uint32_t Tag(const char (&name)[5]) {
  return uint32_t(uint8_t(name[0])) | uint32_t(uint8_t(name[1])) << 8 |
         uint32_t(uint8_t(name[2])) << 16 | uint32_t(uint8_t(name[3])) << 24;
}
constexpr uint32_t kMetaTag = Tag("META");
constexpr uint32_t kDescTag = Tag("DESC");
constexpr uint32_t kPntsTag = Tag("PNTS");
constexpr uint32_t kFaceTag = Tag("FACE");
constexpr uint32_t kViewTag = Tag("VIEW");

// Smallest encoded sizes, used to bound counts by the bytes actually present.
constexpr size_t kPointBytes = 3 * sizeof(float);
constexpr size_t kTransformBytes = (9 + 3) * sizeof(double);
constexpr size_t kFaceBytes = 2 * sizeof(double) + kTransformBytes;
constexpr size_t kMinViewBytes = 4 + 4 * sizeof(double) + 4 + kTransformBytes + 4;

std::string TagName(uint32_t tag) {
  std::string name(4, '\0');
  std::memcpy(name.data(), &tag, 4);
  return "'" + name + "'";
}

// The shared encoding plus transforms and sections written in place (the size is patched in
// once the payload is complete).
class Writer : public ByteWriter {
 public:
  void PutTransform(const RigidTransform& transform) {
    for (int i = 0; i < 9; ++i) Put<double>(transform.R.val[i]);
    for (int i = 0; i < 3; ++i) Put<double>(transform.t[i]);
  }
  void BeginSection(uint32_t tag) {
    Put<uint32_t>(tag);
    section_size_at_ = bytes().size();
    Put<uint64_t>(0);
    ++num_sections_;
  }
  void EndSection() {
    const uint64_t size = bytes().size() - section_size_at_ - sizeof(uint64_t);
    std::memcpy(bytes().data() + section_size_at_, &size, sizeof(size));
  }
  uint32_t num_sections() const { return num_sections_; }

 private:
  size_t section_size_at_ = 0;
  uint32_t num_sections_ = 0;
};

class Reader : public ByteReader {
 public:
  using ByteReader::ByteReader;
  RigidTransform GetTransform() {
    RigidTransform transform;
    for (int i = 0; i < 9; ++i) transform.R.val[i] = Get<double>();
    for (int i = 0; i < 3; ++i) transform.t[i] = Get<double>();
    return transform;
  }
};

void WriteSections(const ObjectModel& model, Writer* w) {
  const ObjectMetadata& meta = model.metadata;
  w->BeginSection(kMetaTag);
  w->PutString(meta.name);
  w->PutString(meta.object_class);
  w->Put<uint8_t>(uint8_t(meta.type));
  for (int i = 0; i < 3; ++i) w->Put<double>(meta.dimensions[i]);
  w->PutString(meta.units);
  w->PutString(meta.source);
  w->Put<uint32_t>(meta.version);
  w->EndSection();

  w->BeginSection(kDescTag);
  w->Put<uint8_t>(uint8_t(model.descriptor.type));
  w->Put<uint32_t>(model.descriptor.size_bytes);
  w->Put<uint32_t>(uint32_t(model.num_features()));
  // Row by row: the matrix may be a non-continuous view into a larger one. Validate() has checked
  // that every row holds exactly size_bytes bytes.
  for (size_t i = 0; i < model.num_features(); ++i) {
    w->PutBytes(model.descriptors.ptr<uint8_t>(int(i)), model.descriptor.size_bytes);
  }
  for (uint32_t p : model.point_of_feature) w->Put<uint32_t>(p);
  w->EndSection();

  w->BeginSection(kPntsTag);
  w->Put<uint32_t>(uint32_t(model.points.size()));
  for (const cv::Point3f& p : model.points) {
    w->Put<float>(p.x);
    w->Put<float>(p.y);
    w->Put<float>(p.z);
  }
  w->EndSection();

  if (!model.faces.empty() || !model.face_of_point.empty()) {
    w->BeginSection(kFaceTag);
    w->Put<uint32_t>(uint32_t(model.faces.size()));
    for (const PlanarFace& face : model.faces) {
      w->Put<double>(face.width);
      w->Put<double>(face.height);
      w->PutTransform(face.object_from_face);
    }
    // No count: Validate() has made this one per point for planar models and none for 3D ones.
    for (uint32_t f : model.face_of_point) w->Put<uint32_t>(f);
    w->EndSection();
  }

  if (!model.views.empty()) {
    w->BeginSection(kViewTag);
    w->Put<uint32_t>(uint32_t(model.views.size()));
    for (const TrainingView& view : model.views) {
      const CameraIntrinsics& c = view.camera;
      w->PutString(view.name);
      w->Put<double>(c.fx);
      w->Put<double>(c.fy);
      w->Put<double>(c.cx);
      w->Put<double>(c.cy);
      w->Put<uint32_t>(uint32_t(c.distortion.size()));
      for (double d : c.distortion) w->Put<double>(d);
      w->PutTransform(view.camera_from_object);
      w->Put<uint32_t>(uint32_t(view.image_png.size()));
      w->PutBytes(view.image_png.data(), view.image_png.size());
    }
    w->EndSection();
  }
}

// Parsing. Each section parser reads its whole payload and reports why it is unusable, or "".

std::string EndOfSection(const Reader& r) {
  if (!r.ok()) return "a length runs past its end";
  if (r.left() != 0) return std::to_string(r.left()) + " unexpected trailing bytes";
  return "";
}

std::string ParseMetaRecord(std::string_view payload, ObjectMetadata* meta) {
  Reader r(payload);
  meta->name = r.GetString();
  meta->object_class = r.GetString();
  const uint8_t type = r.Get<uint8_t>();
  for (int i = 0; i < 3; ++i) meta->dimensions[i] = r.Get<double>();
  meta->units = r.GetString();
  meta->source = r.GetString();
  meta->version = r.Get<uint32_t>();
  if (std::string why = EndOfSection(r); !why.empty()) return why;
  if (type != uint8_t(ObjectType::kPlanar) && type != uint8_t(ObjectType::k3D)) {
    return "unknown object type " + std::to_string(type);
  }
  meta->type = ObjectType(type);
  return "";
}

std::string ParseDesc(std::string_view payload, ObjectModel* model) {
  Reader r(payload);
  model->descriptor.type = DescriptorType(r.Get<uint8_t>());
  model->descriptor.size_bytes = r.Get<uint32_t>();
  if (!r.ok()) return EndOfSection(r);
  // A valid format has a known type and a row length of 4..4096 bytes: never 0 (the count check
  // below divides by it) and well within the int OpenCV takes.
  if (Status s = model->descriptor.Validate(); !s.ok()) return s.message();
  const size_t row_bytes = model->descriptor.size_bytes;
  const uint32_t n = r.GetCount(row_bytes + sizeof(uint32_t));
  if (n > uint32_t(INT_MAX)) return "too many features";
  const std::string_view rows = r.GetBytes(uint64_t(n) * row_bytes);
  if (n > 0) {
    model->descriptors.create(int(n), int(row_bytes), CV_8U);
    std::memcpy(model->descriptors.data, rows.data(), rows.size());
  }
  model->point_of_feature.resize(n);
  for (uint32_t& p : model->point_of_feature) p = r.Get<uint32_t>();
  return EndOfSection(r);
}

std::string ParsePnts(std::string_view payload, std::vector<cv::Point3f>* points) {
  Reader r(payload);
  points->resize(r.GetCount(kPointBytes));
  for (cv::Point3f& p : *points) {
    p.x = r.Get<float>();
    p.y = r.Get<float>();
    p.z = r.Get<float>();
  }
  return EndOfSection(r);
}

// The face indices carry no count of their own: there is one per point (num_indices) for planar
// models and none for 3D ones.
std::string ParseFaceRecord(std::string_view payload, size_t num_indices, ObjectModel* model) {
  Reader r(payload);
  model->faces.resize(r.GetCount(kFaceBytes));
  for (PlanarFace& face : model->faces) {
    face.width = r.Get<double>();
    face.height = r.Get<double>();
    face.object_from_face = r.GetTransform();
  }
  if (!r.ok()) return EndOfSection(r);
  if (num_indices > r.left() / sizeof(uint32_t)) {
    return "expected " + std::to_string(num_indices) + " face indices, one per point";
  }
  model->face_of_point.resize(num_indices);
  for (uint32_t& f : model->face_of_point) f = r.Get<uint32_t>();
  return EndOfSection(r);
}

std::string ParseView(std::string_view payload, std::vector<TrainingView>* views) {
  Reader r(payload);
  views->resize(r.GetCount(kMinViewBytes));
  for (TrainingView& view : *views) {
    CameraIntrinsics& c = view.camera;
    view.name = r.GetString();
    c.fx = r.Get<double>();
    c.fy = r.Get<double>();
    c.cx = r.Get<double>();
    c.cy = r.Get<double>();
    c.distortion.resize(r.GetCount(sizeof(double)));
    for (double& d : c.distortion) d = r.Get<double>();
    view.camera_from_object = r.GetTransform();
    const std::string_view png = r.GetBytes(r.Get<uint32_t>());
    view.image_png.assign(png.begin(), png.end());
    if (!r.ok()) break;  // the remaining views would only be zeros
  }
  return EndOfSection(r);
}

Status Corrupt(const std::string& where, const std::string& why) {
  return Status::DataLoss(where + " is corrupt (" + why + ")");
}

}  // namespace

StatusOr<std::string> EncodeObjectModel(const ObjectModel& model) {
  RECOG_RETURN_IF_ERROR(model.Validate());
  // Validate() lets a model without features carry any format; the reader insists on a usable
  // one, so check it here rather than write a file that cannot be read back.
  RECOG_RETURN_IF_ERROR(model.descriptor.Validate());
  Writer w;
  w.bytes().resize(kModelHeaderSize);
  WriteSections(model, &w);

  std::string& out = w.bytes();
  const uint64_t body_size = out.size() - kModelHeaderSize;
  const uint64_t body_checksum = XXH3_64bits(out.data() + kModelHeaderSize, body_size);
  const uint32_t num_sections = w.num_sections();
  std::memcpy(out.data(), kModelMagic, sizeof(kModelMagic));
  std::memcpy(out.data() + 8, &kModelVersion, 4);
  std::memcpy(out.data() + 12, &num_sections, 4);
  std::memcpy(out.data() + 16, &body_size, 8);
  std::memcpy(out.data() + 24, &body_checksum, 8);
  const uint64_t header_checksum = XXH3_64bits(out.data(), kModelHeaderChecksumSpan);
  std::memcpy(out.data() + 32, &header_checksum, 8);
  return std::move(out);
}

StatusOr<ObjectModel> DecodeObjectModel(std::string_view bytes, const std::string& where) {
  if (bytes.size() >= sizeof(kModelMagic) &&
      std::memcmp(bytes.data(), kModelMagic, sizeof(kModelMagic)) != 0) {
    return Status::DataLoss(where + " is not an object model file (bad magic)");
  }
  if (bytes.size() < kModelHeaderSize) {
    return Corrupt(where, "truncated: " + std::to_string(bytes.size()) +
                              " bytes, shorter than the " + std::to_string(kModelHeaderSize) +
                              "-byte header");
  }
  Reader header(bytes.substr(0, kModelHeaderSize));
  header.Take(sizeof(kModelMagic));
  const uint32_t version = header.Get<uint32_t>();
  const uint32_t num_sections = header.Get<uint32_t>();
  const uint64_t body_size = header.Get<uint64_t>();
  const uint64_t body_checksum = header.Get<uint64_t>();
  const uint64_t header_checksum = header.Get<uint64_t>();
  // The checksum comes before the version so that a damaged version field reads as corruption,
  // not as a file from the future.
  if (header_checksum != XXH3_64bits(bytes.data(), kModelHeaderChecksumSpan)) {
    return Corrupt(where, "header checksum mismatch");
  }
  if (version > kModelVersion) {
    return Status::FailedPrecondition(where + " was written by a newer version (format version " +
                                      std::to_string(version) + "; this build reads up to " +
                                      std::to_string(kModelVersion) + ")");
  }
  if (version == 0) return Corrupt(where, "format version 0");
  const std::string_view body = bytes.substr(kModelHeaderSize);
  if (body_size != body.size()) {
    return Corrupt(where, "the header announces " + std::to_string(body_size) +
                              " body bytes, the file has " + std::to_string(body.size()) +
                              " (truncated or padded)");
  }
  if (body_checksum != XXH3_64bits(body.data(), body.size())) {
    return Corrupt(where, "body checksum mismatch");
  }

  // Split the body into sections first: FACE can only be read once META and PNTS are known, and
  // sections may come in any order.
  struct Known {
    uint32_t tag;
    bool required;
    std::string_view payload;
    bool seen = false;
  };
  Known known[] = {{kMetaTag, true, {}},
                   {kDescTag, true, {}},
                   {kPntsTag, true, {}},
                   {kFaceTag, false, {}},
                   {kViewTag, false, {}}};
  Reader r(body);
  for (uint32_t i = 0; i < num_sections; ++i) {
    const uint32_t tag = r.Get<uint32_t>();
    const std::string_view payload = r.GetBytes(r.Get<uint64_t>());
    if (!r.ok()) {
      return Corrupt(where, "section " + std::to_string(i) + " of " + std::to_string(num_sections) +
                                " runs past the end of the body");
    }
    for (Known& k : known) {
      if (k.tag != tag) continue;
      if (k.seen) return Corrupt(where, "duplicate " + TagName(tag) + " section");
      k.seen = true;
      k.payload = payload;
    }
    // A tag that matched nothing is a later addition this build does not know: skipped.
  }
  if (r.left() != 0) {
    return Corrupt(where, std::to_string(r.left()) + " bytes after the last of " +
                              std::to_string(num_sections) + " sections");
  }
  for (const Known& k : known) {
    if (k.required && !k.seen) return Corrupt(where, "missing " + TagName(k.tag) + " section");
  }

  ObjectModel model;
  const auto check = [&](uint32_t tag, const std::string& why) {
    return why.empty() ? Status::Ok() : Corrupt(where, TagName(tag) + " section: " + why);
  };
  const auto& [meta, desc, pnts, face, view] = known;
  RECOG_RETURN_IF_ERROR(check(kMetaTag, ParseMetaRecord(meta.payload, &model.metadata)));
  RECOG_RETURN_IF_ERROR(check(kDescTag, ParseDesc(desc.payload, &model)));
  RECOG_RETURN_IF_ERROR(check(kPntsTag, ParsePnts(pnts.payload, &model.points)));
  if (face.seen) {
    const size_t num_indices = model.metadata.type == ObjectType::kPlanar ? model.points.size() : 0;
    RECOG_RETURN_IF_ERROR(check(kFaceTag, ParseFaceRecord(face.payload, num_indices, &model)));
  }
  if (view.seen) {
    RECOG_RETURN_IF_ERROR(check(kViewTag, ParseView(view.payload, &model.views)));
  }
  if (Status s = model.Validate(); !s.ok()) return Corrupt(where, s.message());
  return model;
}

Status SaveObjectModel(const ObjectModel& model, const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(const std::string bytes, EncodeObjectModel(model));
  return WriteFileAtomically(path, {bytes});
}

StatusOr<ObjectModel> LoadObjectModel(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    return Status::NotFound("object model file '" + path + "' does not exist");
  }
  if (std::filesystem::is_directory(path, ec)) {
    return Status::InvalidArgument("'" + path + "' is a directory, not an object model file");
  }
  RECOG_ASSIGN_OR_RETURN(const std::string bytes,
                         ReadWholeFile(path, "object model file '" + path + "'"));
  return DecodeObjectModel(bytes, "object model file '" + path + "'");
}

}  // namespace recog
