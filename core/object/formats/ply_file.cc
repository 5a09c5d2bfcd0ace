#include "core/object/formats/ply_file.h"

#include <bit>
#include <cmath>
#include <cstring>
#include <optional>
#include <string_view>
#include <utility>

#include "core/common/file_io.h"
#include "core/common/text_lines.h"

namespace recog {
namespace {

enum class PlyType : uint8_t {
  kInt8,
  kUint8,
  kInt16,
  kUint16,
  kInt32,
  kUint32,
  kFloat32,
  kFloat64
};

std::optional<PlyType> ParsePlyType(std::string_view name) {
  static constexpr std::pair<std::string_view, PlyType> kNames[] = {
      {"char", PlyType::kInt8},      {"int8", PlyType::kInt8},       {"uchar", PlyType::kUint8},
      {"uint8", PlyType::kUint8},    {"short", PlyType::kInt16},     {"int16", PlyType::kInt16},
      {"ushort", PlyType::kUint16},  {"uint16", PlyType::kUint16},   {"int", PlyType::kInt32},
      {"int32", PlyType::kInt32},    {"uint", PlyType::kUint32},     {"uint32", PlyType::kUint32},
      {"float", PlyType::kFloat32},  {"float32", PlyType::kFloat32}, {"double", PlyType::kFloat64},
      {"float64", PlyType::kFloat64}};
  for (const auto& [text, type] : kNames) {
    if (text == name) return type;
  }
  return std::nullopt;
}

size_t PlyTypeSize(PlyType type) {
  static constexpr size_t kSizes[] = {1, 1, 2, 2, 4, 4, 4, 8};
  return kSizes[size_t(type)];
}

// Decodes one little-endian value of `type` at p (PlyTypeSize(type) bytes), on any host.
double DecodeLittleEndian(const char* p, PlyType type) {
  uint64_t bits = 0;
  for (size_t i = PlyTypeSize(type); i-- > 0;) bits = (bits << 8) | uint8_t(p[i]);
  switch (type) {
    case PlyType::kInt8:
      return int8_t(bits);
    case PlyType::kUint8:
      return uint8_t(bits);
    case PlyType::kInt16:
      return int16_t(bits);
    case PlyType::kUint16:
      return uint16_t(bits);
    case PlyType::kInt32:
      return int32_t(bits);
    case PlyType::kUint32:
      return uint32_t(bits);
    case PlyType::kFloat32:
      return std::bit_cast<float>(uint32_t(bits));
    case PlyType::kFloat64:
      return std::bit_cast<double>(bits);
  }
  return 0;
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kFloat32;  // of the value, or of the items of a list
  bool is_list = false;
  PlyType count_type = PlyType::kUint8;  // lists only
};

struct PlyElement {
  std::string name;
  size_t count = 0;
  std::vector<PlyProperty> properties;
};

struct PlyHeader {
  bool binary = false;
  std::vector<PlyElement> elements;
};

// Where the vertex element keeps the fields this reader returns (-1 when absent).
struct VertexLayout {
  size_t element = 0;  // index of the vertex element
  int x = -1, y = -1, z = -1, nx = -1, ny = -1, nz = -1;
  bool has_normals() const { return nx >= 0 && ny >= 0 && nz >= 0; }
};

// Reads and checks the header of a PLY file. On return `lines` is positioned at the body.
StatusOr<PlyHeader> ParsePlyHeader(LineReader* lines, const std::string& where) {
  const auto error = [&](const std::string& message) {
    return Status::DataLoss(where + " line " + std::to_string(lines->line_number()) + ": " +
                            message);
  };
  std::string_view line;
  if (!lines->Next(&line) || line != "ply") {
    return Status::DataLoss(where + " is not a PLY file (no 'ply' line)");
  }
  PlyHeader header;
  bool has_format = false;
  while (lines->Next(&line)) {
    const std::vector<std::string_view> t = Tokens(line);
    if (t.empty() || t[0] == "comment" || t[0] == "obj_info") continue;
    if (t[0] == "end_header") {
      if (!has_format) return error("the header has no 'format' line");
      return header;
    }
    if (t[0] == "format") {
      if (t.size() != 3 || t[2] != "1.0") return error("malformed format line");
      if (t[1] == "binary_big_endian") {
        return Status::InvalidArgument(where + ": binary_big_endian PLY is not supported");
      }
      if (t[1] != "ascii" && t[1] != "binary_little_endian") {
        return error("unknown format " + Quote(t[1]));
      }
      header.binary = t[1] != "ascii";
      has_format = true;
    } else if (t[0] == "element") {
      PlyElement element;
      if (t.size() != 3 || !ParseNumber(t[2], &element.count)) {
        return error("malformed element line");
      }
      element.name = t[1];
      header.elements.push_back(std::move(element));
    } else if (t[0] == "property") {
      if (header.elements.empty()) return error("property before any element");
      PlyProperty property;
      property.is_list = t.size() == 5 && t[1] == "list";
      if (t.size() != 3 && !property.is_list) return error("malformed property line");
      const std::optional<PlyType> type = ParsePlyType(t[property.is_list ? 3 : 1]);
      const std::optional<PlyType> count_type = ParsePlyType(t[property.is_list ? 2 : 1]);
      if (!type || !count_type || (property.is_list && *count_type >= PlyType::kFloat32)) {
        return error("unknown or unusable property type in " + Quote(line));
      }
      property.type = *type;
      property.count_type = *count_type;
      property.name = t.back();
      header.elements.back().properties.push_back(std::move(property));
    } else {
      return error("unknown header line " + Quote(line));
    }
  }
  return Status::DataLoss(where + " is truncated: the header has no 'end_header' line");
}

StatusOr<VertexLayout> FindVertexLayout(const PlyHeader& header, const std::string& where) {
  const auto it = std::find_if(header.elements.begin(), header.elements.end(),
                               [](const PlyElement& e) { return e.name == "vertex"; });
  if (it == header.elements.end()) {
    return Status::InvalidArgument(where + " has no vertex element");
  }
  VertexLayout layout;
  layout.element = size_t(it - header.elements.begin());
  const std::pair<const char*, int*> fields[] = {{"x", &layout.x},   {"y", &layout.y},
                                                 {"z", &layout.z},   {"nx", &layout.nx},
                                                 {"ny", &layout.ny}, {"nz", &layout.nz}};
  for (size_t i = 0; i < it->properties.size(); ++i) {
    for (const auto& [name, index] : fields) {
      if (it->properties[i].name == name && !it->properties[i].is_list) *index = int(i);
    }
  }
  if (layout.x < 0 || layout.y < 0 || layout.z < 0) {
    return Status::InvalidArgument(where + ": the vertex element has no x, y and z properties");
  }
  return layout;
}

// Appends the vertex held in `row` (one value per property) to the cloud; false if not finite.
bool StoreVertex(const std::vector<double>& row, const VertexLayout& layout, PointCloud* cloud) {
  const cv::Point3f p(float(row[layout.x]), float(row[layout.y]), float(row[layout.z]));
  cloud->points.push_back(p);
  bool finite = std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
  if (layout.has_normals()) {
    const cv::Vec3f n(float(row[layout.nx]), float(row[layout.ny]), float(row[layout.nz]));
    cloud->normals.push_back(n);
    finite = finite && std::isfinite(n[0]) && std::isfinite(n[1]) && std::isfinite(n[2]);
  }
  return finite;
}

// Space for `count` instances, bounded by what `bytes` bytes can hold, so that a corrupt count
// cannot make the reader allocate more than the file justifies.
void Reserve(size_t count, size_t bytes, size_t min_instance_bytes, PointCloud* cloud,
             const VertexLayout& layout) {
  const size_t n = std::min(count, bytes / std::max<size_t>(min_instance_bytes, 1) + 1);
  cloud->points.reserve(n);
  if (layout.has_normals()) cloud->normals.reserve(n);
}

// Parses one element instance written on an ASCII line: one value per scalar property into
// `row`; a list is a count followed by that many values, checked and skipped.
Status ParseAsciiInstance(std::string_view line, const PlyElement& element,
                          std::vector<double>* row) {
  for (size_t i = 0; i < element.properties.size(); ++i) {
    const std::string_view token = NextToken(&line);
    if (token.empty()) {
      return Status::DataLoss("expected " + std::to_string(element.properties.size()) +
                              " properties of '" + element.name + "', got " + std::to_string(i));
    }
    double value = 0;
    if (!ParseNumber(token, &value)) return Status::DataLoss("not a number: " + Quote(token));
    (*row)[i] = value;
    size_t list_size = 0;
    if (element.properties[i].is_list && !ParseNumber(token, &list_size)) {
      return Status::DataLoss("bad list size " + Quote(token));
    }
    for (size_t j = 0; j < list_size; ++j) {
      const std::string_view item = NextToken(&line);
      if (!ParseNumber(item, &value)) return Status::DataLoss("bad list item " + Quote(item));
    }
  }
  if (const std::string_view extra = NextToken(&line); !extra.empty()) {
    return Status::DataLoss("unexpected value " + Quote(extra) + " after the properties of '" +
                            element.name + "'");
  }
  return Status::Ok();
}

StatusOr<PointCloud> ReadAsciiPlyBody(LineReader* lines, const PlyHeader& header,
                                      const VertexLayout& layout, const std::string& where) {
  PointCloud cloud;
  for (size_t e = 0; e <= layout.element; ++e) {
    const PlyElement& element = header.elements[e];
    std::vector<double> row(element.properties.size());
    if (e == layout.element) {
      Reserve(element.count, lines->rest().size(), 2 * element.properties.size(), &cloud, layout);
    }
    for (size_t i = 0; i < element.count; ++i) {
      std::string_view line;
      if (!lines->Next(&line)) {
        return Status::DataLoss(where + " is truncated after line " +
                                std::to_string(lines->line_number()) + ": expected " +
                                std::to_string(element.count) + " '" + element.name +
                                "' lines, got " + std::to_string(i));
      }
      Status status = ParseAsciiInstance(line, element, &row);
      if (status.ok() && e == layout.element && !StoreVertex(row, layout, &cloud)) {
        status = Status::DataLoss("the vertex is not finite");
      }
      if (!status.ok()) {
        return status.WithContext(where + " line " + std::to_string(lines->line_number()));
      }
    }
  }
  return cloud;
}

// Reads one binary element instance at *p (advanced past it) into `row`; false when the data
// ends first or a list size is negative.
bool ReadBinaryInstance(const char*& p, const char* end, const PlyElement& element,
                        std::vector<double>* row) {
  for (size_t i = 0; i < element.properties.size(); ++i) {
    const PlyProperty& property = element.properties[i];
    const PlyType type = property.is_list ? property.count_type : property.type;
    if (size_t(end - p) < PlyTypeSize(type)) return false;
    (*row)[i] = DecodeLittleEndian(p, type);
    p += PlyTypeSize(type);
    if (property.is_list) {
      const double size = (*row)[i];
      if (size < 0 || size * double(PlyTypeSize(property.type)) > double(end - p)) return false;
      p += size_t(size) * PlyTypeSize(property.type);
    }
  }
  return true;
}

// The smallest size of an instance (lists count for their size field only).
size_t MinBinaryInstanceBytes(const PlyElement& element) {
  size_t bytes = 0;
  for (const PlyProperty& p : element.properties) {
    bytes += PlyTypeSize(p.is_list ? p.count_type : p.type);
  }
  return bytes;
}

StatusOr<PointCloud> ReadBinaryPlyBody(std::string_view body, const PlyHeader& header,
                                       const VertexLayout& layout, const std::string& where) {
  PointCloud cloud;
  const char* p = body.data();
  const char* const end = body.data() + body.size();
  for (size_t e = 0; e <= layout.element; ++e) {
    const PlyElement& element = header.elements[e];
    std::vector<double> row(element.properties.size());
    if (e == layout.element) {
      Reserve(element.count, size_t(end - p), MinBinaryInstanceBytes(element), &cloud, layout);
    }
    for (size_t i = 0; i < element.count; ++i) {
      if (!ReadBinaryInstance(p, end, element, &row)) {
        return Status::DataLoss(where + " is truncated: its data ends after " + std::to_string(i) +
                                " of " + std::to_string(element.count) + " '" + element.name +
                                "' elements");
      }
      if (e == layout.element && !StoreVertex(row, layout, &cloud)) {
        return Status::DataLoss(where + ": vertex " + std::to_string(i) + " is not finite");
      }
    }
  }
  return cloud;
}

}  // namespace

StatusOr<PointCloud> ReadPly(const std::string& path) {
  const std::string where = "PLY file '" + path + "'";
  RECOG_ASSIGN_OR_RETURN(const std::string content, ReadWholeFile(path, where));
  LineReader lines(content);
  RECOG_ASSIGN_OR_RETURN(const PlyHeader header, ParsePlyHeader(&lines, where));
  RECOG_ASSIGN_OR_RETURN(const VertexLayout layout, FindVertexLayout(header, where));
  if (header.binary) return ReadBinaryPlyBody(lines.rest(), header, layout, where);
  return ReadAsciiPlyBody(&lines, header, layout, where);
}

Status WritePly(const std::string& path, const PointCloud& cloud) {
  const bool normals = !cloud.normals.empty();
  if (normals && cloud.normals.size() != cloud.points.size()) {
    return Status::InvalidArgument("cannot write '" + path +
                                   "': " + std::to_string(cloud.points.size()) + " points but " +
                                   std::to_string(cloud.normals.size()) + " normals");
  }
  std::string text = "ply\nformat ascii 1.0\nelement vertex " +
                     std::to_string(cloud.points.size()) +
                     "\nproperty float x\nproperty float y\nproperty float z\n";
  if (normals) text += "property float nx\nproperty float ny\nproperty float nz\n";
  text += "end_header\n";
  text.reserve(text.size() + cloud.points.size() * (normals ? 72 : 36));
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    const float values[] = {cloud.points[i].x, cloud.points[i].y, cloud.points[i].z};
    for (float v : values) {
      AppendNumber(&text, v);
      text += ' ';
    }
    for (int k = 0; normals && k < 3; ++k) {
      AppendNumber(&text, cloud.normals[i][k]);
      text += ' ';
    }
    text.back() = '\n';
  }
  return WriteFileAtomically(path, {text});
}

}  // namespace recog
