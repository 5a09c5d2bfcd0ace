#include "core/object/formats/roboearth.h"

#include <tinyxml2.h>

#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "core/common/file_io.h"
#include "core/common/text_lines.h"

namespace recog {
namespace {

namespace fs = std::filesystem;

// --- Geometry checks. ---

// OK when R is finite and a rotation: |R^T R - I| < 1e-3 and det(R) > 0.
Status CheckRotation(const cv::Matx33d& R) {
  for (int i = 0; i < 9; ++i) {
    if (!std::isfinite(R.val[i])) return Status::InvalidArgument("R is not finite");
  }
  const double error = cv::norm(R.t() * R - cv::Matx33d::eye(), cv::NORM_INF);
  const double det = cv::determinant(R);
  if (error >= 1e-3 || det <= 0) {
    return Status::InvalidArgument("R is not a rotation (|R^T R - I| = " + FormatNumber(error) +
                                   ", det = " + FormatNumber(det) + ")");
  }
  return Status::Ok();
}

Status CheckTransform(const RigidTransform& transform) {
  RECOG_RETURN_IF_ERROR(CheckRotation(transform.R));
  for (double v : transform.t.val) {
    if (!std::isfinite(v)) return Status::InvalidArgument("t is not finite");
  }
  return Status::Ok();
}

// --- Bundle cameras. ---

constexpr std::string_view kBundleComment =
    "# A contraption file with the bundle.out format in opencv reference system";

// Reads the next line of a bundle file as exactly `n` numbers.
Status ReadNumberLine(LineReader* lines, size_t n, double* values, const std::string& where) {
  std::string_view line;
  if (!lines->Next(&line)) {
    return Status::DataLoss(where + " is truncated: expected 7 lines, got " +
                            std::to_string(lines->line_number()));
  }
  const std::string at = where + " line " + std::to_string(lines->line_number());
  const std::vector<std::string_view> tokens = Tokens(line);
  if (tokens.size() != n) {
    return Status::DataLoss(at + ": expected " + std::to_string(n) + " numbers, got " +
                            std::to_string(tokens.size()));
  }
  for (size_t i = 0; i < n; ++i) {
    if (!ParseNumber(tokens[i], &values[i])) {
      return Status::DataLoss(at + ": not a number: " + Quote(tokens[i]));
    }
    if (!std::isfinite(values[i])) {
      return Status::InvalidArgument(at + ": " + Quote(tokens[i]) + " is not finite");
    }
  }
  return Status::Ok();
}

Status ValidateBundleCamera(const BundleCamera& camera) {
  if (!(camera.focal > 0) || !std::isfinite(camera.focal) || !std::isfinite(camera.k1) ||
      !std::isfinite(camera.k2)) {
    return Status::InvalidArgument("the camera needs a finite focal length > 0 and finite k1, k2");
  }
  return CheckTransform(camera.camera_from_object);
}

// --- meta.xml. ---

using tinyxml2::XMLElement;

std::string_view Trim(std::string_view s) {
  const size_t start = s.find_first_not_of(" \t\r\n");
  if (start == std::string_view::npos) return {};
  return s.substr(start, s.find_last_not_of(" \t\r\n") + 1 - start);
}

// "meta file 'x' line 7: <oTf>", to start a message about `element`.
std::string Describe(const XMLElement* element, const std::string& where) {
  return where + " line " + std::to_string(element->GetLineNum()) + ": <" + element->Name() + ">";
}

std::string_view Text(const XMLElement* element) {
  const char* text = element->GetText();
  return Trim(text == nullptr ? "" : text);
}

// The child element `name` of `parent`; INVALID_ARGUMENT naming both when it is missing.
StatusOr<const XMLElement*> Child(const XMLElement* parent, const char* name,
                                  const std::string& where) {
  const XMLElement* child = parent->FirstChildElement(name);
  if (child == nullptr) {
    return Status::InvalidArgument(Describe(parent, where) + " has no <" + name + ">");
  }
  return child;
}

StatusOr<std::string_view> ChildText(const XMLElement* parent, const char* name,
                                     const std::string& where) {
  RECOG_ASSIGN_OR_RETURN(const XMLElement* child, Child(parent, name, where));
  return Text(child);
}

// The numbers of the child element `name` (blank-separated), exactly `n` of them.
Status ChildNumbers(const XMLElement* parent, const char* name, size_t n, double* values,
                    const std::string& where) {
  RECOG_ASSIGN_OR_RETURN(const XMLElement* child, Child(parent, name, where));
  const std::vector<std::string_view> tokens = Tokens(Text(child));
  const std::string at = Describe(child, where);
  if (tokens.size() != n) {
    return Status::InvalidArgument(at + " needs " + std::to_string(n) + " numbers, got " +
                                   std::to_string(tokens.size()));
  }
  for (size_t i = 0; i < n; ++i) {
    if (!ParseNumber(tokens[i], &values[i]) || !std::isfinite(values[i])) {
      return Status::InvalidArgument(at + " holds " + Quote(tokens[i]) + ", not a finite number");
    }
  }
  return Status::Ok();
}

StatusOr<double> ChildNumber(const XMLElement* parent, const char* name, const std::string& where) {
  double value = 0;
  RECOG_RETURN_IF_ERROR(ChildNumbers(parent, name, 1, &value, where));
  return value;
}

StatusOr<int> ChildInt(const XMLElement* parent, const char* name, const std::string& where) {
  RECOG_ASSIGN_OR_RETURN(const XMLElement* child, Child(parent, name, where));
  int value = 0;
  if (!ParseNumber(Text(child), &value)) {
    return Status::InvalidArgument(Describe(child, where) + " holds " + Quote(Text(child)) +
                                   ", not an integer");
  }
  return value;
}

StatusOr<RigidTransform> ParseOtf(const XMLElement* face, const std::string& where) {
  cv::Matx44d m;
  RECOG_RETURN_IF_ERROR(ChildNumbers(face, "oTf", 16, m.val, where));
  if (cv::norm(m.row(3) - cv::Matx14d(0, 0, 0, 1), cv::NORM_INF) > 1e-9) {
    return Status::InvalidArgument(Describe(face->FirstChildElement("oTf"), where) +
                                   ": the last row is not 0 0 0 1");
  }
  return RigidTransform::FromMatrix(m);
}

StatusOr<RoboEarthFace> ParseFace(const XMLElement* face, const std::string& where) {
  RoboEarthFace out;
  RECOG_ASSIGN_OR_RETURN(out.index, ChildInt(face, "index", where));
  RECOG_ASSIGN_OR_RETURN(out.width, ChildNumber(face, "width", where));
  RECOG_ASSIGN_OR_RETURN(out.height, ChildNumber(face, "height", where));
  RECOG_ASSIGN_OR_RETURN(out.object_from_face, ParseOtf(face, where));
  return out;
}

Status ParsePlanarDimensions(const XMLElement* dimensions, const std::string& where,
                             RoboEarthMeta* meta) {
  RECOG_ASSIGN_OR_RETURN(meta->width, ChildNumber(dimensions, "width", where));
  RECOG_ASSIGN_OR_RETURN(meta->height, ChildNumber(dimensions, "height", where));
  RECOG_ASSIGN_OR_RETURN(meta->depth, ChildNumber(dimensions, "depth", where));
  for (const XMLElement* face = dimensions->FirstChildElement("face"); face != nullptr;
       face = face->NextSiblingElement("face")) {
    RECOG_ASSIGN_OR_RETURN(RoboEarthFace parsed, ParseFace(face, where));
    meta->faces.push_back(std::move(parsed));
  }
  std::sort(meta->faces.begin(), meta->faces.end(),
            [](const RoboEarthFace& a, const RoboEarthFace& b) { return a.index < b.index; });
  return Status::Ok();
}

// Checks the values of a meta (whatever file they come from or go to).
Status ValidateMeta(const RoboEarthMeta& meta) {
  if (meta.name.empty()) return Status::InvalidArgument("the model has no name");
  if (meta.num_faces < 0) return Status::InvalidArgument("the number of faces is negative");
  if (meta.type == ObjectType::k3D) {
    if (!(meta.scale > 0) || !std::isfinite(meta.scale)) {
      return Status::InvalidArgument("the scale must be finite and > 0");
    }
    return Status::Ok();
  }
  if (!(meta.width > 0 && meta.height > 0 && meta.depth >= 0) || !std::isfinite(meta.width) ||
      !std::isfinite(meta.height) || !std::isfinite(meta.depth)) {
    return Status::InvalidArgument("a planar model needs finite width, height > 0 and depth >= 0");
  }
  if (meta.faces.size() != size_t(meta.num_faces)) {
    return Status::InvalidArgument("<faces> says " + std::to_string(meta.num_faces) +
                                   " faces, but " + std::to_string(meta.faces.size()) +
                                   " are described");
  }
  for (size_t i = 0; i < meta.faces.size(); ++i) {
    const RoboEarthFace& face = meta.faces[i];
    const std::string which = "face " + std::to_string(face.index);
    if (face.index < 0 || (i > 0 && face.index <= meta.faces[i - 1].index)) {
      return Status::InvalidArgument(which + ": face indices must be >= 0, unique and sorted");
    }
    if (!(face.width > 0 && face.height > 0) || !std::isfinite(face.width) ||
        !std::isfinite(face.height)) {
      return Status::InvalidArgument(which + " needs a finite width and height > 0");
    }
    RECOG_RETURN_IF_ERROR(CheckTransform(face.object_from_face).WithContext(which + " oTf"));
  }
  return Status::Ok();
}

StatusOr<RoboEarthMeta> ParseMeta(const XMLElement* model, const std::string& where) {
  RoboEarthMeta meta;
  RECOG_ASSIGN_OR_RETURN(const std::string_view name, ChildText(model, "name", where));
  meta.name = name;
  RECOG_ASSIGN_OR_RETURN(const std::string_view type, ChildText(model, "type", where));
  const StatusOr<ObjectType> object_type = ParseObjectType(type);
  if (!object_type.ok()) return object_type.status().WithContext(where + ": <type>");
  meta.type = *object_type;
  RECOG_ASSIGN_OR_RETURN(meta.num_faces, ChildInt(model, "faces", where));
  RECOG_ASSIGN_OR_RETURN(const XMLElement* dimensions, Child(model, "dimensions", where));
  if (meta.type == ObjectType::k3D) {
    RECOG_ASSIGN_OR_RETURN(meta.scale, ChildNumber(dimensions, "scale", where));
  } else {
    RECOG_RETURN_IF_ERROR(ParsePlanarDimensions(dimensions, where, &meta));
  }
  return meta;
}

void AddTextElement(tinyxml2::XMLDocument* doc, XMLElement* parent, const char* name,
                    const std::string& text) {
  parent->InsertEndChild(doc->NewElement(name))->ToElement()->SetText(text.c_str());
}

std::string FormatMatrix(const cv::Matx44d& m) {
  std::string s;
  for (int i = 0; i < 16; ++i) {
    if (i > 0) s += ' ';
    AppendNumber(&s, m.val[i]);
  }
  return s;
}

void AddFace(tinyxml2::XMLDocument* doc, XMLElement* dimensions, const RoboEarthFace& face) {
  XMLElement* element = dimensions->InsertEndChild(doc->NewElement("face"))->ToElement();
  AddTextElement(doc, element, "index", std::to_string(face.index));
  AddTextElement(doc, element, "width", FormatNumber(face.width));
  AddTextElement(doc, element, "height", FormatNumber(face.height));
  AddTextElement(doc, element, "oTf", FormatMatrix(face.object_from_face.Matrix()));
}

// --- Folders. ---

// The index k of a "face_k.png" file name.
std::optional<int> ViewIndex(const std::string& file_name) {
  constexpr std::string_view kPrefix = "face_", kSuffix = ".png";
  const std::string_view name = file_name;
  if (!name.starts_with(kPrefix) || !name.ends_with(kSuffix)) return std::nullopt;
  const std::string_view digits =
      name.substr(kPrefix.size(), name.size() - kPrefix.size() - kSuffix.size());
  int index = 0;
  if (digits.empty() || digits[0] == '-' || !ParseNumber(digits, &index)) return std::nullopt;
  return index;
}

bool IsRegularFile(const fs::path& path) {
  std::error_code ec;
  return fs::is_regular_file(path, ec);
}

// The view of image `png` (face_k.png), or nothing when its face_k.txt is missing.
StatusOr<std::optional<RoboEarthView>> ReadView(const fs::path& png, int index) {
  fs::path txt = png, ply = png;
  txt.replace_extension(".txt");
  ply.replace_extension(".ply");
  if (!IsRegularFile(txt)) return std::optional<RoboEarthView>();
  RoboEarthView view;
  view.index = index;
  view.image_path = png.string();
  RECOG_ASSIGN_OR_RETURN(view.camera, ReadBundleCamera(txt.string()));
  if (IsRegularFile(ply)) view.points_path = ply.string();
  return std::optional<RoboEarthView>(std::move(view));
}

StatusOr<std::vector<RoboEarthView>> ReadViews(const std::string& dir) {
  std::vector<RoboEarthView> views;
  std::error_code ec;
  for (const fs::directory_entry& entry : fs::directory_iterator(dir, ec)) {
    const std::optional<int> index = ViewIndex(entry.path().filename().string());
    if (!index || !IsRegularFile(entry.path())) continue;
    RECOG_ASSIGN_OR_RETURN(std::optional<RoboEarthView> view, ReadView(entry.path(), *index));
    if (view) views.push_back(std::move(*view));
  }
  if (ec) return Status::NotFound("cannot list RoboEarth folder '" + dir + "': " + ec.message());
  std::sort(views.begin(), views.end(),
            [](const RoboEarthView& a, const RoboEarthView& b) { return a.index < b.index; });
  const auto same_index = [](const RoboEarthView& a, const RoboEarthView& b) {
    return a.index == b.index;
  };
  if (const auto dup = std::adjacent_find(views.begin(), views.end(), same_index);
      dup != views.end()) {
    return Status::InvalidArgument("RoboEarth folder '" + dir + "' has two images of view " +
                                   std::to_string(dup->index));
  }
  return views;
}

// --- Export. ---

// "view 3 ('face_003')", to start a message about view `index`.
std::string DescribeView(size_t index, const TrainingView& view) {
  return "view " + std::to_string(index) + (view.name.empty() ? "" : " ('" + view.name + "')");
}

// The size of a view's image, checking that RoboEarth can express its camera: one focal length,
// the principal point at the image centre (the reader puts it there) and no distortion. Half a
// pixel anywhere in the image is tolerated, as keypoints are not located more precisely.
StatusOr<cv::Size> ExportableViewSize(const TrainingView& view, const std::string& which) {
  if (view.image_png.empty()) {
    return Status::FailedPrecondition(which +
                                      " has no image (the model was built without its images)");
  }
  const cv::Mat image = cv::imdecode(view.image_png, cv::IMREAD_UNCHANGED);
  if (image.empty()) return Status::DataLoss(which + ": its image cannot be decoded");
  const CameraIntrinsics& camera = view.camera;
  RECOG_RETURN_IF_ERROR(camera.Validate().WithContext(which));
  if (std::any_of(camera.distortion.begin(), camera.distortion.end(),
                  [](double k) { return k != 0; })) {
    return Status::InvalidArgument(which + " has lens distortion, which RoboEarth cannot express");
  }
  constexpr double kTolerancePx = 0.5;
  // Projecting with fx alone moves a pixel at the top or bottom edge by this much.
  if (std::abs(camera.fx - camera.fy) * image.rows / (2 * camera.fy) > kTolerancePx) {
    return Status::InvalidArgument(which + ": fx = " + FormatNumber(camera.fx) +
                                   " and fy = " + FormatNumber(camera.fy) +
                                   " differ, but a RoboEarth camera has one focal length");
  }
  const double centre_x = image.cols / 2.0, centre_y = image.rows / 2.0;
  if (std::abs(camera.cx - centre_x) > kTolerancePx ||
      std::abs(camera.cy - centre_y) > kTolerancePx) {
    return Status::InvalidArgument(which + ": the principal point (" + FormatNumber(camera.cx) +
                                   ", " + FormatNumber(camera.cy) + ") is not the image centre (" +
                                   FormatNumber(centre_x) + ", " + FormatNumber(centre_y) +
                                   "), where a RoboEarth camera has it");
  }
  return image.size();
}

StatusOr<RoboEarthMeta> ExportMeta(const ObjectModel& model) {
  RoboEarthMeta meta;
  meta.name = model.metadata.name;
  meta.type = model.metadata.type;
  if (meta.type == ObjectType::k3D) {
    meta.num_faces = int(model.views.size());
    meta.scale = 1;
  } else {
    meta.width = model.metadata.dimensions[0];
    meta.height = model.metadata.dimensions[1];
    meta.depth = model.metadata.dimensions[2];
    meta.num_faces = int(model.faces.size());
    for (size_t f = 0; f < model.faces.size(); ++f) {
      const PlanarFace& face = model.faces[f];
      meta.faces.push_back({int(f), face.width, face.height, face.object_from_face});
    }
  }
  RECOG_RETURN_IF_ERROR(ValidateMeta(meta));
  return meta;
}

// The face a camera looks at most directly: the largest cosine between the face's normal (its -z
// axis, towards its viewer) and the direction from the face's centre to the camera; -1 when every
// face turns away.
int MostFrontalFace(const std::vector<PlanarFace>& faces,
                    const RigidTransform& camera_from_object) {
  int best = -1;
  double best_cosine = 0;
  for (size_t f = 0; f < faces.size(); ++f) {
    const RigidTransform camera_from_face = camera_from_object * faces[f].object_from_face;
    const cv::Point3d centre = camera_from_face.Apply({faces[f].width / 2, faces[f].height / 2, 0});
    const cv::Vec3d to_camera(-centre.x, -centre.y, -centre.z);
    const cv::Vec3d normal = camera_from_face.R * cv::Vec3d(0, 0, -1);
    const double cosine = normal.dot(to_camera) / cv::norm(to_camera);
    if (cosine > best_cosine) {
      best_cosine = cosine;
      best = int(f);
    }
  }
  return best;
}

// The model points that project into a view's image in front of its camera. For planar models
// only those of the face the view looks at most directly: the reader takes the bounding box of a
// planar view's points as the face it shows, which other faces' points would enlarge.
PointCloud ViewPoints(const ObjectModel& model, const TrainingView& view, cv::Size size) {
  const bool planar = model.metadata.type == ObjectType::kPlanar;
  const int face = planar ? MostFrontalFace(model.faces, view.camera_from_object) : -1;
  PointCloud cloud;
  if (planar && face < 0) return cloud;
  for (size_t i = 0; i < model.points.size(); ++i) {
    if (planar && model.face_of_point[i] != uint32_t(face)) continue;
    cv::Point2d uv;
    if (ProjectPoint(view.camera, view.camera_from_object, cv::Point3d(model.points[i]), &uv) &&
        uv.x >= 0 && uv.y >= 0 && uv.x < size.width && uv.y < size.height) {
      cloud.points.push_back(model.points[i]);
    }
  }
  return cloud;
}

// Creates `dir` when missing. ALREADY_EXISTS when it holds anything or is not a folder, so that
// an export never mixes its views with those of another model.
Status PrepareEmptyFolder(const std::string& dir) {
  std::error_code ec;
  const fs::file_status st = fs::status(dir, ec);
  if (fs::exists(st)) {
    if (!fs::is_directory(st)) return Status::AlreadyExists("'" + dir + "' is not a folder");
    const bool empty = fs::is_empty(dir, ec);
    if (ec) return Status::NotFound("cannot list folder '" + dir + "': " + ec.message());
    if (!empty) return Status::AlreadyExists("folder '" + dir + "' is not empty");
    return Status::Ok();
  }
  fs::create_directories(dir, ec);
  if (ec) return Status::NotFound("cannot create folder '" + dir + "': " + ec.message());
  return Status::Ok();
}

}  // namespace

StatusOr<BundleCamera> ReadBundleCamera(const std::string& path) {
  const std::string where = "bundle camera file '" + path + "'";
  RECOG_ASSIGN_OR_RETURN(const std::string content, ReadWholeFile(path, where));
  LineReader lines(content);
  std::string_view comment;
  if (!lines.Next(&comment) || !comment.starts_with("#")) {
    return Status::DataLoss(where + " line 1: expected a '#' comment line");
  }
  double counts[2], intrinsics[3], rows[12];
  RECOG_RETURN_IF_ERROR(ReadNumberLine(&lines, 2, counts, where));
  if (counts[0] != 1) {
    return Status::InvalidArgument(where + " line 2: expected one camera, got " +
                                   FormatNumber(counts[0]));
  }
  RECOG_RETURN_IF_ERROR(ReadNumberLine(&lines, 3, intrinsics, where));
  for (int i = 0; i < 4; ++i) RECOG_RETURN_IF_ERROR(ReadNumberLine(&lines, 3, rows + 3 * i, where));
  BundleCamera camera;
  camera.focal = intrinsics[0];
  camera.k1 = intrinsics[1];
  camera.k2 = intrinsics[2];
  std::copy(rows, rows + 9, camera.camera_from_object.R.val);
  std::copy(rows + 9, rows + 12, camera.camera_from_object.t.val);
  RECOG_RETURN_IF_ERROR(ValidateBundleCamera(camera).WithContext(where));
  return camera;
}

Status WriteBundleCamera(const std::string& path, const BundleCamera& camera) {
  RECOG_RETURN_IF_ERROR(ValidateBundleCamera(camera).WithContext("cannot write '" + path + "'"));
  std::string text(kBundleComment);
  text += "\n1 0\n";
  char line[160];
  std::snprintf(line, sizeof(line), "%.6f %.6f %.6f\n", camera.focal, camera.k1, camera.k2);
  text += line;
  const cv::Matx33d& R = camera.camera_from_object.R;
  for (int r = 0; r < 3; ++r) {
    std::snprintf(line, sizeof(line), "%.12f %.12f %.12f \n", R(r, 0), R(r, 1), R(r, 2));
    text += line;
  }
  const cv::Vec3d& t = camera.camera_from_object.t;
  std::snprintf(line, sizeof(line), "%.12f %.12f %.12f \n", t[0], t[1], t[2]);
  text += line;
  return WriteFileAtomically(path, {text});
}

StatusOr<RoboEarthMeta> ReadRoboEarthMeta(const std::string& path) {
  const std::string where = "meta file '" + path + "'";
  RECOG_ASSIGN_OR_RETURN(const std::string content, ReadWholeFile(path, where));
  tinyxml2::XMLDocument doc;
  if (doc.Parse(content.data(), content.size()) != tinyxml2::XML_SUCCESS) {
    return Status::DataLoss(where + " line " + std::to_string(doc.ErrorLineNum()) +
                            ": not well-formed XML (" + doc.ErrorName() + ")");
  }
  const XMLElement* model = doc.RootElement();
  if (model == nullptr || std::string_view(model->Name()) != "model") {
    return Status::InvalidArgument(where + " has no <model> root element");
  }
  RECOG_ASSIGN_OR_RETURN(RoboEarthMeta meta, ParseMeta(model, where));
  RECOG_RETURN_IF_ERROR(ValidateMeta(meta).WithContext(where));
  return meta;
}

Status WriteRoboEarthMeta(const std::string& path, const RoboEarthMeta& meta) {
  RECOG_RETURN_IF_ERROR(ValidateMeta(meta).WithContext("cannot write '" + path + "'"));
  tinyxml2::XMLDocument doc;
  XMLElement* model = doc.InsertEndChild(doc.NewElement("model"))->ToElement();
  AddTextElement(&doc, model, "name", meta.name);
  AddTextElement(&doc, model, "type", std::string(ObjectTypeName(meta.type)));
  AddTextElement(&doc, model, "faces", std::to_string(meta.num_faces));
  XMLElement* dimensions = model->InsertEndChild(doc.NewElement("dimensions"))->ToElement();
  if (meta.type == ObjectType::k3D) {
    AddTextElement(&doc, dimensions, "scale", FormatNumber(meta.scale));
  } else {
    AddTextElement(&doc, dimensions, "width", FormatNumber(meta.width));
    AddTextElement(&doc, dimensions, "height", FormatNumber(meta.height));
    AddTextElement(&doc, dimensions, "depth", FormatNumber(meta.depth));
    for (const RoboEarthFace& face : meta.faces) AddFace(&doc, dimensions, face);
  }
  tinyxml2::XMLPrinter printer;
  doc.Print(&printer);
  return WriteFileAtomically(path, {std::string_view(printer.CStr(), printer.CStrSize() - 1)});
}

StatusOr<RoboEarthFolder> ReadRoboEarthFolder(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    return Status::NotFound("RoboEarth folder '" + dir + "' does not exist");
  }
  RoboEarthFolder folder;
  folder.path = dir;
  RECOG_ASSIGN_OR_RETURN(folder.meta, ReadRoboEarthMeta((fs::path(dir) / "meta.xml").string()));
  RECOG_ASSIGN_OR_RETURN(folder.views, ReadViews(dir));
  if (folder.views.empty()) {
    return Status::InvalidArgument("RoboEarth folder '" + dir +
                                   "' has no view (face_k.png with its face_k.txt)");
  }
  const fs::path dense = fs::path(dir) / "drawing_model.ply";
  if (IsRegularFile(dense)) folder.dense_cloud_path = dense.string();
  return folder;
}

Status ExportRoboEarthFolder(const ObjectModel& model, const std::string& dir) {
  RECOG_RETURN_IF_ERROR(model.Validate());
  const std::string what =
      "cannot export model '" + model.metadata.name + "' as RoboEarth folder '" + dir + "'";
  if (model.points.empty()) return Status::FailedPrecondition(what + ": it has no 3D point");
  if (model.views.empty()) {
    return Status::FailedPrecondition(what + ": it has no training view");
  }
  std::vector<cv::Size> sizes;
  for (size_t k = 0; k < model.views.size(); ++k) {
    const StatusOr<cv::Size> size =
        ExportableViewSize(model.views[k], DescribeView(k, model.views[k]));
    if (!size.ok()) return size.status().WithContext(what);
    sizes.push_back(*size);
  }
  const StatusOr<RoboEarthMeta> meta = ExportMeta(model);
  if (!meta.ok()) return meta.status().WithContext(what);
  RECOG_RETURN_IF_ERROR(PrepareEmptyFolder(dir).WithContext(what));

  const fs::path root(dir);
  RECOG_RETURN_IF_ERROR(WriteRoboEarthMeta((root / "meta.xml").string(), *meta));
  RECOG_RETURN_IF_ERROR(WritePly((root / "drawing_model.ply").string(), {model.points, {}}));
  for (size_t k = 0; k < model.views.size(); ++k) {
    const TrainingView& view = model.views[k];
    char stem[32];
    std::snprintf(stem, sizeof(stem), "face_%03zu", k);
    const std::string base = (root / stem).string();
    // The bytes are already PNG: written as they are, the image is exactly the one trained on.
    RECOG_RETURN_IF_ERROR(WriteFileAtomically(
        base + ".png", {std::string_view(reinterpret_cast<const char*>(view.image_png.data()),
                                         view.image_png.size())}));
    BundleCamera camera;
    camera.focal = view.camera.fx;
    camera.camera_from_object = view.camera_from_object;
    RECOG_RETURN_IF_ERROR(WriteBundleCamera(base + ".txt", camera));
    RECOG_RETURN_IF_ERROR(WritePly(base + ".ply", ViewPoints(model, view, sizes[k])));
  }
  return Status::Ok();
}

}  // namespace recog
