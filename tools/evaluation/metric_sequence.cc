#include "tools/evaluation/metric_sequence.h"

#include <cmath>

#include <opencv2/imgproc.hpp>

namespace recog::cli {
namespace {

Status CheckPlane(const TexturedPlane& p) {
  if (p.texture.empty() || p.texture.type() != CV_8UC1) {
    return Status::InvalidArgument("a plane's texture must be a non-empty 8-bit grey image");
  }
  if (!(p.width > 0.0) || !(p.height > 0.0)) {
    return Status::InvalidArgument("a plane needs a width and height > 0 metres");
  }
  constexpr double kTolerance = 1e-6;
  if (std::abs(cv::norm(p.axis_x) - 1.0) > kTolerance ||
      std::abs(cv::norm(p.axis_y) - 1.0) > kTolerance ||
      std::abs(p.axis_x.dot(p.axis_y)) > kTolerance) {
    return Status::InvalidArgument("a plane's axes must be orthogonal unit vectors");
  }
  return Status::Ok();
}

// Renders one camera: the image and the depth (metres, CV_32F, 0 = none).
void Render(const std::vector<TexturedPlane>& planes, const cv::Matx33d& K, cv::Size size,
            const cv::Matx33d& R, const cv::Vec3d& c, cv::Mat* image, cv::Mat* depth) {
  *depth = cv::Mat::zeros(size, CV_32F);
  cv::Mat owner(size, CV_32S, cv::Scalar(-1));
  std::vector<cv::Mat> maps(planes.size());
  for (cv::Mat& m : maps) m = cv::Mat(size, CV_32FC2, cv::Scalar(-1, -1));
  const cv::Matx33d K_inv = K.inv();
  for (size_t p = 0; p < planes.size(); ++p) {
    const TexturedPlane& plane = planes[p];
    const cv::Vec3d normal = plane.axis_x.cross(plane.axis_y);
    const double offset = normal.dot(plane.center - c);
    const double sx = plane.texture.cols / plane.width, sy = plane.texture.rows / plane.height;
    for (int y = 0; y < size.height; ++y) {
      float* z_row = depth->ptr<float>(y);
      int* owner_row = owner.ptr<int>(y);
      cv::Vec2f* map_row = maps[p].ptr<cv::Vec2f>(y);
      for (int x = 0; x < size.width; ++x) {
        const cv::Vec3d ray = R * (K_inv * cv::Vec3d(x, y, 1.0));  // camera z = 1
        const double denominator = normal.dot(ray);
        if (std::abs(denominator) < 1e-12) continue;
        const double s = offset / denominator;  // = depth along the camera's z axis
        if (!(s > 0.0) || (z_row[x] > 0.0f && s >= z_row[x])) continue;
        const cv::Vec3d local = c + s * ray - plane.center;
        const double u = local.dot(plane.axis_x) * sx + 0.5 * plane.texture.cols - 0.5;
        const double v = local.dot(plane.axis_y) * sy + 0.5 * plane.texture.rows - 0.5;
        if (u < 0 || v < 0 || u > plane.texture.cols - 1 || v > plane.texture.rows - 1) continue;
        z_row[x] = float(s);
        owner_row[x] = int(p);
        map_row[x] = cv::Vec2f(float(u), float(v));
      }
    }
  }
  *image = cv::Mat::zeros(size, CV_8U);
  for (size_t p = 0; p < planes.size(); ++p) {
    cv::Mat sampled;
    cv::remap(planes[p].texture, sampled, maps[p], cv::noArray(), cv::INTER_LINEAR,
              cv::BORDER_REPLICATE);
    sampled.copyTo(*image, owner == int(p));
  }
}

}  // namespace

cv::Matx33d Yaw(double degrees) {
  const double a = degrees * CV_PI / 180.0;
  return {std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a)};
}

StatusOr<RenderedFrame> RenderPlanes(const std::vector<TexturedPlane>& planes, const cv::Matx33d& K,
                                     cv::Size size, const CameraPose& pose, double baseline_m) {
  for (const TexturedPlane& p : planes) RECOG_RETURN_IF_ERROR(CheckPlane(p));
  if (!(K(0, 0) > 0.0) || !(K(1, 1) > 0.0)) {
    return Status::InvalidArgument("camera matrix needs positive focal lengths");
  }
  if (size.width <= 0 || size.height <= 0) return Status::InvalidArgument("empty image size");
  if (!(baseline_m >= 0.0)) return Status::InvalidArgument("baseline must be >= 0 metres");
  RenderedFrame frame;
  cv::Mat depth;
  Render(planes, K, size, pose.world_from_camera, pose.center, &frame.image, &depth);
  // Millimetres, rounded; 0 stays 0.
  depth.convertTo(frame.depth_mm, CV_16U, 1000.0);
  if (baseline_m > 0.0) {
    const cv::Vec3d right_center =
        pose.center + pose.world_from_camera * cv::Vec3d(baseline_m, 0, 0);
    cv::Mat right_depth;
    Render(planes, K, size, pose.world_from_camera, right_center, &frame.right, &right_depth);
  }
  return frame;
}

void RelativePose(const CameraPose& query, const CameraPose& match, cv::Matx33d* R, cv::Vec3d* t) {
  // X_world = R_m X_match + c_m and X_query = R_qᵀ (X_world − c_q).
  *R = query.world_from_camera.t() * match.world_from_camera;
  *t = query.world_from_camera.t() * (match.center - query.center);
}

}  // namespace recog::cli
