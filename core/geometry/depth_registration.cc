#include "core/geometry/depth_registration.h"

#include <algorithm>
#include <cmath>

#include <opencv2/calib3d.hpp>

namespace recog {

cv::Mat RegisterDepth(const cv::Mat& depth_m, const DepthCamera& depth_camera,
                      const cv::Matx33d& depth_from_color_R, const cv::Vec3d& depth_from_color_t,
                      const DepthCamera& color_camera, cv::Size color_size) {
  CV_Assert(depth_m.type() == CV_32F);
  cv::Mat registered(color_size, CV_32F, cv::Scalar(0));
  std::vector<cv::Point2f> pixels;
  std::vector<float> depths;
  for (int v = 0; v < depth_m.rows; ++v) {
    const float* row = depth_m.ptr<float>(v);
    for (int u = 0; u < depth_m.cols; ++u) {
      if (row[u] > 0 && std::isfinite(row[u])) {
        pixels.emplace_back(float(u), float(v));
        depths.push_back(row[u]);
      }
    }
  }
  if (pixels.empty()) return registered;
  std::vector<cv::Point2f> normalised;
  cv::undistortPoints(
      pixels, normalised, cv::Mat(depth_camera.K),
      depth_camera.distortion.empty() ? cv::Mat() : cv::Mat(depth_camera.distortion));
  // X_colour = R^T (X_depth - t).
  const cv::Matx33d color_from_depth_R = depth_from_color_R.t();
  const cv::Vec3d color_from_depth_t = -(color_from_depth_R * depth_from_color_t);
  std::vector<cv::Point3f> points(pixels.size());
  for (size_t i = 0; i < pixels.size(); ++i) {
    const cv::Vec3d x_depth(normalised[i].x * depths[i], normalised[i].y * depths[i], depths[i]);
    const cv::Vec3d x_color = color_from_depth_R * x_depth + color_from_depth_t;
    points[i] = cv::Point3f(float(x_color[0]), float(x_color[1]), float(x_color[2]));
  }
  std::vector<cv::Point2f> projected;
  cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(color_camera.K),
                    color_camera.distortion.empty() ? cv::Mat() : cv::Mat(color_camera.distortion),
                    projected);
  // A depth pixel covers about this many colour pixels a side (at equal depths).
  const double footprint = std::max(color_camera.K(0, 0) / depth_camera.K(0, 0),
                                    color_camera.K(1, 1) / depth_camera.K(1, 1));
  const double half = std::max(0.5, footprint / 2);
  for (size_t i = 0; i < points.size(); ++i) {
    const float z = points[i].z;
    if (!(z > 0)) continue;
    const cv::Point2f& p = projected[i];
    const int u0 = std::max(0, int(std::lround(p.x - half + 0.5)));
    const int u1 = std::min(color_size.width - 1, int(std::lround(p.x + half - 0.5)));
    const int v0 = std::max(0, int(std::lround(p.y - half + 0.5)));
    const int v1 = std::min(color_size.height - 1, int(std::lround(p.y + half - 0.5)));
    for (int v = v0; v <= v1; ++v) {
      float* row = registered.ptr<float>(v);
      for (int u = u0; u <= u1; ++u) {
        if (row[u] == 0 || z < row[u]) row[u] = z;
      }
    }
  }
  return registered;
}

}  // namespace recog
