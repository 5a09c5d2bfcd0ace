#include "tools/evaluation/visp_files.h"

#include <cmath>
#include <fstream>
#include <sstream>

#include <opencv2/calib3d.hpp>

namespace recog::cli {
namespace {

// The numbers of a file, comments ('#' to the end of the line) and ViSP's key=value attributes
// of a face or line (name=floor, useLod=true, ...) removed.
StatusOr<std::vector<std::string>> FileTokens(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Status::NotFound("cannot open '" + path + "'");
  std::vector<std::string> tokens;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream words(line.substr(0, line.find('#')));
    std::string word;
    while (words >> word) {
      if (word.find('=') == std::string::npos) tokens.push_back(word);
    }
  }
  return tokens;
}

// Reads tokens as numbers one at a time, failing with the file name on anything else.
class NumberReader {
 public:
  NumberReader(std::vector<std::string> tokens, std::string path)
      : tokens_(std::move(tokens)), path_(std::move(path)) {}
  Status Next(double* value) {
    if (next_ >= tokens_.size()) return Status::InvalidArgument(path_ + ": ends too early");
    const std::string& token = tokens_[next_++];
    char* end = nullptr;
    *value = std::strtod(token.c_str(), &end);
    if (end != token.c_str() + token.size() || !std::isfinite(*value)) {
      return Status::InvalidArgument(path_ + ": '" + token + "' is not a number");
    }
    return Status::Ok();
  }
  Status NextCount(size_t* count, size_t limit) {
    double value = 0;
    RECOG_RETURN_IF_ERROR(Next(&value));
    if (value < 0 || value > double(limit) || value != std::floor(value)) {
      return Status::InvalidArgument(path_ + ": bad count " + std::to_string(value));
    }
    *count = size_t(value);
    return Status::Ok();
  }
  bool done() const { return next_ >= tokens_.size(); }

 private:
  std::vector<std::string> tokens_;
  std::string path_;
  size_t next_ = 0;
};

}  // namespace

StatusOr<std::vector<FacePolygon>> ReadCaoFaces(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(std::vector<std::string> tokens, FileTokens(path));
  if (tokens.empty() || tokens[0] != "V1") {
    return Status::InvalidArgument(path + ": not a ViSP V1 .cao file");
  }
  tokens.erase(tokens.begin());
  NumberReader reader(std::move(tokens), path);
  constexpr size_t kLimit = 1'000'000;
  size_t num_points = 0;
  RECOG_RETURN_IF_ERROR(reader.NextCount(&num_points, kLimit));
  std::vector<cv::Point3d> points(num_points);
  for (cv::Point3d& p : points) {
    RECOG_RETURN_IF_ERROR(reader.Next(&p.x));
    RECOG_RETURN_IF_ERROR(reader.Next(&p.y));
    RECOG_RETURN_IF_ERROR(reader.Next(&p.z));
  }
  size_t lines = 0, faces_from_lines = 0, faces = 0;
  RECOG_RETURN_IF_ERROR(reader.NextCount(&lines, kLimit));
  RECOG_RETURN_IF_ERROR(reader.NextCount(&faces_from_lines, kLimit));
  if (lines != 0 || faces_from_lines != 0) {
    return Status::InvalidArgument(path + ": lines and faces from lines are not supported");
  }
  RECOG_RETURN_IF_ERROR(reader.NextCount(&faces, kLimit));
  std::vector<FacePolygon> polygons(faces);
  for (FacePolygon& polygon : polygons) {
    size_t corners = 0;
    RECOG_RETURN_IF_ERROR(reader.NextCount(&corners, kLimit));
    if (corners < 3) return Status::InvalidArgument(path + ": a face needs 3 corners");
    for (size_t k = 0; k < corners; ++k) {
      size_t index = 0;
      RECOG_RETURN_IF_ERROR(reader.NextCount(&index, kLimit));
      if (index >= points.size()) {
        return Status::InvalidArgument(path + ": face corner " + std::to_string(index) +
                                       " is not a point");
      }
      polygon.corners.push_back(points[index]);
    }
  }
  // Cylinders and circles (counts only; ViSP writes 0 for none).
  while (!reader.done()) {
    size_t count = 0;
    RECOG_RETURN_IF_ERROR(reader.NextCount(&count, kLimit));
    if (count != 0)
      return Status::InvalidArgument(path + ": cylinders and circles are not supported");
  }
  if (polygons.empty()) return Status::InvalidArgument(path + ": no face");
  return polygons;
}

StatusOr<RigidTransform> ReadVispPose(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(std::vector<std::string> tokens, FileTokens(path));
  if (tokens.size() != 6) {
    return Status::InvalidArgument(path +
                                   ": a pose is 6 numbers (tx ty tz thetaux thetauy thetauz)");
  }
  NumberReader reader(std::move(tokens), path);
  cv::Vec3d t, theta_u;
  for (int k = 0; k < 3; ++k) RECOG_RETURN_IF_ERROR(reader.Next(&t[k]));
  for (int k = 0; k < 3; ++k) RECOG_RETURN_IF_ERROR(reader.Next(&theta_u[k]));
  RigidTransform pose;
  cv::Rodrigues(theta_u, pose.R);
  pose.t = t;
  return pose;
}

}  // namespace recog::cli
