#include "tools/evaluation/camera_trajectory.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tools/evaluation/object_evaluation.h"  // IsRotationMatrix

namespace recog::cli {
namespace {

constexpr double kRadToDeg = 180.0 / CV_PI;

cv::Vec3d OpticalAxis(const CameraPose& pose) {
  return pose.world_from_camera * cv::Vec3d(0, 0, 1);
}

}  // namespace

StatusOr<std::vector<CameraPose>> ReadCameraPoses(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Status::NotFound("pose file '" + path + "' not found");
  std::vector<CameraPose> poses;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream fields(line);
    std::vector<double> values;
    for (double v; fields >> v;) values.push_back(v);
    if (values.empty() && fields.eof()) continue;  // blank or comment
    const std::string where = "pose file '" + path + "' line " + std::to_string(number);
    if (!fields.eof() || values.size() != 12 ||
        !std::all_of(values.begin(), values.end(), [](double v) { return std::isfinite(v); })) {
      return Status::InvalidArgument(where + ": expected 12 numbers (r11 .. r33 cx cy cz)");
    }
    CameraPose pose;
    std::copy(values.begin(), values.begin() + 9, pose.world_from_camera.val);
    pose.center = cv::Vec3d(values[9], values[10], values[11]);
    if (!IsRotationMatrix(pose.world_from_camera)) {
      return Status::InvalidArgument(where + ": the first 9 numbers are not a rotation matrix");
    }
    poses.push_back(pose);
  }
  if (poses.empty()) return Status::InvalidArgument("pose file '" + path + "' has no pose");
  return poses;
}

cv::Matx33d TrueFundamental(const CameraPose& query, const CameraPose& match,
                            const cv::Matx33d& K) {
  // X_query = R X_match + t.
  const cv::Matx33d R = query.world_from_camera.t() * match.world_from_camera;
  const cv::Vec3d t = query.world_from_camera.t() * (match.center - query.center);
  const cv::Matx33d t_cross(0, -t[2], t[1], t[2], 0, -t[0], -t[1], t[0], 0);
  const cv::Matx33d K_inverse = K.inv();
  return K_inverse.t() * (t_cross * R) * K_inverse;
}

LoopGeometryTruth ScoreLoopGeometry(const CameraPose& query, const CameraPose& match,
                                    const cv::Matx33d& K, const FeatureSet& query_features,
                                    const FeatureSet& match_features,
                                    const std::vector<Match>& inliers) {
  LoopGeometryTruth truth;
  truth.distance_m = cv::norm(query.center - match.center);
  const double cosine = OpticalAxis(query).dot(OpticalAxis(match));
  truth.angle_deg = std::acos(std::clamp(cosine, -1.0, 1.0)) * kRadToDeg;
  truth.inliers = uint32_t(inliers.size());
  const cv::Matx33d F = TrueFundamental(query, match, K);
  for (const Match& m : inliers) {
    if (m.a >= query_features.size() || m.b >= match_features.size()) continue;
    const cv::Point2f& q = query_features.keypoints[m.a].pt;
    const cv::Point2f& p = match_features.keypoints[m.b].pt;
    const cv::Vec3d x_query(q.x, q.y, 1), x_match(p.x, p.y, 1);
    const cv::Vec3d line_in_query = F * x_match, line_in_match = F.t() * x_query;
    const double residual = x_query.dot(line_in_query);
    const double norm = line_in_query[0] * line_in_query[0] + line_in_query[1] * line_in_query[1] +
                        line_in_match[0] * line_in_match[0] + line_in_match[1] * line_in_match[1];
    if (norm > 0 && residual * residual / norm < kMaxSampsonPx * kMaxSampsonPx) ++truth.agreeing;
  }
  truth.agrees = truth.agreeing > 0 && truth.agreeing >= kMinAgreeingShare * truth.inliers;
  return truth;
}

Status WriteTrajectoryPlot(const std::vector<CameraPose>& poses,
                           const std::vector<DrawnLoop>& loops, const std::string& title,
                           const std::string& path, int size) {
  if (poses.empty()) return Status::InvalidArgument("no camera pose to draw");
  // The plane of the centres' two main directions.
  cv::Mat centres(int(poses.size()), 3, CV_64F);
  for (size_t i = 0; i < poses.size(); ++i) {
    for (int k = 0; k < 3; ++k) centres.at<double>(int(i), k) = poses[i].center[k];
  }
  const cv::PCA pca(centres, cv::Mat(), cv::PCA::DATA_AS_ROW, 2);
  const auto plane = [&](const cv::Vec3d& v, bool direction) {
    cv::Vec3d x = direction ? v : v - cv::Vec3d(pca.mean.ptr<double>());
    return cv::Point2d(x.dot(cv::Vec3d(pca.eigenvectors.ptr<double>(0))),
                       x.dot(cv::Vec3d(pca.eigenvectors.ptr<double>(1))));
  };
  std::vector<cv::Point2d> points;
  double extent = 1e-9;
  for (const CameraPose& pose : poses) {
    points.push_back(plane(pose.center, false));
    extent = std::max({extent, std::abs(points.back().x), std::abs(points.back().y)});
  }
  const int margin = 70;
  const double scale = (size / 2.0 - margin) / extent;  // pixels per metre
  const auto pixel = [&](const cv::Point2d& p) {
    return cv::Point(int(std::lround(size / 2.0 + p.x * scale)),
                     int(std::lround(size / 2.0 - p.y * scale)));
  };
  cv::Mat image(size, size, CV_8UC3, cv::Scalar(255, 255, 255));
  const cv::Scalar grey(150, 150, 150), green(40, 160, 40), red(40, 40, 220), orange(0, 150, 250);
  for (size_t i = 1; i < points.size(); ++i) {
    cv::line(image, pixel(points[i - 1]), pixel(points[i]), grey, 1, cv::LINE_AA);
  }
  for (const DrawnLoop& loop : loops) {
    if (loop.query < 0 || loop.match < 0 || size_t(loop.query) >= points.size() ||
        size_t(loop.match) >= points.size()) {
      continue;
    }
    const cv::Scalar colour = loop.verdict == DrawnLoop::Verdict::kCorrect ? green
                              : loop.verdict == DrawnLoop::Verdict::kFalse ? red
                                                                           : orange;
    cv::line(image, pixel(points[size_t(loop.query)]), pixel(points[size_t(loop.match)]), colour, 2,
             cv::LINE_AA);
  }
  for (size_t i = 0; i < points.size(); ++i) {
    const cv::Point at = pixel(points[i]);
    cv::Point2d axis = plane(OpticalAxis(poses[i]), true);
    const double length = std::hypot(axis.x, axis.y);
    if (length > 1e-6) axis *= 25.0 / length;
    cv::arrowedLine(image, at, at + cv::Point(int(axis.x), int(-axis.y)), cv::Scalar(120, 60, 0), 1,
                    cv::LINE_AA, 0, 0.3);
    cv::circle(image, at, 4, cv::Scalar(0, 0, 0), cv::FILLED, cv::LINE_AA);
    cv::putText(image, std::to_string(i + 1), at + cv::Point(6, -6), cv::FONT_HERSHEY_SIMPLEX, 0.4,
                cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }
  cv::putText(image, title, cv::Point(15, 28), cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(0, 0, 0),
              1, cv::LINE_AA);
  int y = size - 60;
  for (const auto& [label, colour] : {std::pair<const char*, cv::Scalar>{"correct loop", green},
                                      {"false loop", red},
                                      {"ambiguous pair", orange}}) {
    cv::line(image, cv::Point(15, y), cv::Point(45, y), colour, 2, cv::LINE_AA);
    cv::putText(image, label, cv::Point(52, y + 4), cv::FONT_HERSHEY_SIMPLEX, 0.45,
                cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    y += 18;
  }
  // A scale bar of a round number of metres, about a fifth of the width.
  const double metres = std::pow(10.0, std::floor(std::log10(size / 5.0 / scale)));
  const int bar = int(std::lround(metres * scale));
  cv::line(image, cv::Point(size - 30 - bar, size - 30), cv::Point(size - 30, size - 30),
           cv::Scalar(0, 0, 0), 2);
  std::ostringstream label;
  label << metres << " m";
  cv::putText(image, label.str(), cv::Point(size - 30 - bar, size - 38), cv::FONT_HERSHEY_SIMPLEX,
              0.45, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  if (!cv::imwrite(path, image)) return Status::Internal("cannot write '" + path + "'");
  return Status::Ok();
}

}  // namespace recog::cli
