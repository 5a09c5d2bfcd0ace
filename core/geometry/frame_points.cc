#include "core/geometry/frame_points.h"

#include <cmath>
#include <limits>
#include <string>

#include <opencv2/imgproc.hpp>

#include "core/common/descriptor.h"

namespace recog {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
// ORB's patch at pyramid level 0: a keypoint's size is this times its level's scale.
constexpr double kOrbPatchSize = 31.0;

Status CheckIntrinsics(const cv::Matx33d& K) {
  if (!(K(0, 0) > 0.0) || !(K(1, 1) > 0.0) || !std::isfinite(K(0, 2)) || !std::isfinite(K(1, 2))) {
    return Status::InvalidArgument("camera matrix needs positive focal lengths fx, fy");
  }
  return Status::Ok();
}

cv::Point3f BackProject(const cv::Matx33d& K, cv::Point2f pixel, double z) {
  return {float((pixel.x - K(0, 2)) * z / K(0, 0)), float((pixel.y - K(1, 2)) * z / K(1, 1)),
          float(z)};
}

// Depth in metres at (x, y), or 0 when there is none.
double DepthAt(const cv::Mat& depth, double scale, int x, int y) {
  if (depth.type() == CV_16U) return depth.at<uint16_t>(y, x) * scale;
  const float z = depth.at<float>(y, x);
  return std::isfinite(z) && z > 0.0f ? double(z) : 0.0;
}

std::string SizeText(cv::Size s) {
  return std::to_string(s.width) + "x" + std::to_string(s.height);
}

cv::Mat Gray(const cv::Mat& image) {
  if (image.channels() == 1) return image;
  cv::Mat gray;
  cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  return gray;
}

// Sum of absolute differences of the window at (xl, y) in `left` and (xr, y) in `right`.
double Sad(const cv::Mat& left, const cv::Mat& right, int xl, int xr, int y, int half) {
  double sum = 0;
  for (int dy = -half; dy <= half; ++dy) {
    const uint8_t* l = left.ptr<uint8_t>(y + dy) + xl;
    const uint8_t* r = right.ptr<uint8_t>(y + dy) + xr;
    for (int dx = -half; dx <= half; ++dx) sum += std::abs(int(l[dx]) - int(r[dx]));
  }
  return sum;
}

// The disparity of the left pixel (x, y) near `disparity`: SAD minimum over ±2 px, parabola
// through it and its neighbours. `disparity` itself when a window leaves an image or the minimum
// lies on the edge of the search.
double RefineDisparity(const cv::Mat& left, const cv::Mat& right, int x, int y, double disparity,
                       int half) {
  constexpr int kRadius = 2;
  const int d0 = int(std::lround(disparity));
  if (y - half < 0 || y + half >= left.rows || x - half < 0 || x + half >= left.cols ||
      x - d0 - kRadius - half < 0 || x - d0 + kRadius + half >= right.cols) {
    return disparity;
  }
  double cost[2 * kRadius + 1];
  int best = 0;
  for (int i = 0; i <= 2 * kRadius; ++i) {
    cost[i] = Sad(left, right, x, x - (d0 - kRadius + i), y, half);
    if (cost[i] < cost[best]) best = i;
  }
  if (best == 0 || best == 2 * kRadius) return disparity;
  const double a = cost[best - 1], b = cost[best], c = cost[best + 1];
  const double denominator = a - 2 * b + c;
  const double offset = denominator > 0 ? 0.5 * (a - c) / denominator : 0.0;
  return d0 - kRadius + best + offset;
}

}  // namespace

Status PointsFromDepth(const std::vector<cv::KeyPoint>& keypoints, cv::Size image_size,
                       const cv::Matx33d& K, const cv::Mat& depth, double depth_scale,
                       std::vector<cv::Point3f>* points) {
  return PointsFromDepth(keypoints, image_size,
                         CameraIntrinsics{K(0, 0), K(1, 1), K(0, 2), K(1, 2), {}}, depth,
                         depth_scale, points);
}

Status PointsFromDepth(const std::vector<cv::KeyPoint>& keypoints, cv::Size image_size,
                       const CameraIntrinsics& camera, const cv::Mat& depth, double depth_scale,
                       std::vector<cv::Point3f>* points) {
  const cv::Matx33d K = camera.K();
  RECOG_RETURN_IF_ERROR(CheckIntrinsics(K));
  const bool pinhole = camera.IsPinhole();
  if (depth.empty()) return Status::InvalidArgument("depth image is empty");
  if (depth.type() != CV_16U && depth.type() != CV_32F) {
    return Status::InvalidArgument(
        "depth image must be CV_16U (depth_scale metres per unit) or CV_32F (metres), one "
        "channel");
  }
  if (depth.size() != image_size) {
    return Status::InvalidArgument("depth image is " + SizeText(depth.size()) +
                                   " but the image is " + SizeText(image_size) +
                                   ": the depth must be aligned with the image");
  }
  if (depth.type() == CV_16U && !(depth_scale > 0.0 && std::isfinite(depth_scale))) {
    return Status::InvalidArgument("depth scale must be > 0 metres per unit");
  }
  points->assign(keypoints.size(), cv::Point3f(kNaN, kNaN, kNaN));
  for (size_t i = 0; i < keypoints.size(); ++i) {
    const cv::Point2f& p = keypoints[i].pt;
    const int x = int(std::lround(p.x)), y = int(std::lround(p.y));
    if (x < 0 || y < 0 || x >= depth.cols || y >= depth.rows) continue;
    double z = DepthAt(depth, depth_scale, x, y);
    for (int dy = -1; z == 0.0 && dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const int nx = x + dx, ny = y + dy;
        if (nx < 0 || ny < 0 || nx >= depth.cols || ny >= depth.rows) continue;
        const double n = DepthAt(depth, depth_scale, nx, ny);
        if (n > 0.0 && (z == 0.0 || n < z)) z = n;
      }
      if (z != 0.0) break;
    }
    if (!(z > 0.0)) continue;
    cv::Vec3d bearing;
    if (pinhole) {
      (*points)[i] = BackProject(K, p, z);
    } else if (UnprojectPixel(camera, p, &bearing) && bearing[2] > 1e-6) {
      const cv::Vec3d point = bearing * (z / bearing[2]);  // z: the depth along the axis
      (*points)[i] = cv::Point3f(float(point[0]), float(point[1]), float(point[2]));
    }
  }
  return Status::Ok();
}

Status PointsFromStereo(const FeatureSet& left, const cv::Mat& left_image, const FeatureSet& right,
                        const cv::Mat& right_image, const cv::Matx33d& K, double baseline_m,
                        const StereoOptions& options, std::vector<cv::Point3f>* points) {
  RECOG_RETURN_IF_ERROR(CheckIntrinsics(K));
  if (!(baseline_m > 0.0 && std::isfinite(baseline_m))) {
    return Status::InvalidArgument("stereo needs a baseline > 0 metres");
  }
  if (left_image.empty() || (left_image.type() != CV_8UC1 && left_image.type() != CV_8UC3)) {
    return Status::InvalidArgument("left image must be 8-bit grey or BGR");
  }
  if (right_image.size() != left_image.size() || right_image.type() != left_image.type()) {
    return Status::InvalidArgument("right image is " + SizeText(right_image.size()) + " of type " +
                                   std::to_string(right_image.type()) + " but the left image is " +
                                   SizeText(left_image.size()) + " of type " +
                                   std::to_string(left_image.type()));
  }
  RECOG_RETURN_IF_ERROR(CheckFeatureSet(left, DescriptorFormat::Orb()));
  RECOG_RETURN_IF_ERROR(CheckFeatureSet(right, DescriptorFormat::Orb()));
  if (options.window < 3 || options.window % 2 == 0 || !(options.max_row_offset_px >= 0.0) ||
      !(options.max_disparity_px >= 0.0)) {
    return Status::InvalidArgument(
        "stereo options need an odd window >= 3 and non-negative row offset and disparity");
  }
  const cv::Mat left_gray = Gray(left_image), right_gray = Gray(right_image);
  const std::vector<cv::KeyPoint>& right_keypoints = right.keypoints;

  // Right features by row, for the search along the epipolar line.
  std::vector<std::vector<uint32_t>> rows(size_t(left_image.rows));
  for (size_t j = 0; j < right_keypoints.size(); ++j) {
    const int y = int(std::lround(right_keypoints[j].pt.y));
    if (y >= 0 && y < left_image.rows) rows[size_t(y)].push_back(uint32_t(j));
  }
  const double max_disparity =
      options.max_disparity_px > 0 ? options.max_disparity_px : left_image.cols / 4.0;
  constexpr uint32_t kNone = std::numeric_limits<uint32_t>::max();
  std::vector<uint32_t> match(left.size(), kNone), distance(left.size(), kNone);
  std::vector<uint32_t> claimed_by(right_keypoints.size(), kNone);
  for (size_t i = 0; i < left.size(); ++i) {
    const cv::KeyPoint& l = left.keypoints[i];
    const double tolerance = options.max_row_offset_px * l.size / kOrbPatchSize;
    const int y0 = std::max(0, int(std::floor(l.pt.y - tolerance)));
    const int y1 = std::min(left_image.rows - 1, int(std::ceil(l.pt.y + tolerance)));
    uint32_t best = kNone, best_distance = kNone, second = kNone;
    for (int y = y0; y <= y1; ++y) {
      for (uint32_t j : rows[size_t(y)]) {
        const cv::KeyPoint& r = right_keypoints[j];
        const double d = l.pt.x - r.pt.x;
        if (std::abs(r.pt.y - l.pt.y) > tolerance || !(d > 0.0) || d > max_disparity ||
            std::abs(r.octave - l.octave) > 1) {
          continue;
        }
        const uint32_t h = Hamming256(left.descriptors.ptr<uint8_t>(int(i)),
                                      right.descriptors.ptr<uint8_t>(int(j)));
        if (h < best_distance) {
          second = best_distance;
          best_distance = h;
          best = j;
        } else if (h < second) {
          second = h;
        }
      }
    }
    if (best == kNone || best_distance > options.matching.max_distance ||
        (second != kNone && best_distance >= options.matching.ratio * second)) {
      continue;
    }
    const uint32_t other = claimed_by[best];
    if (other != kNone) {
      if (distance[other] <= best_distance) continue;
      match[other] = kNone;
    }
    claimed_by[best] = uint32_t(i);
    match[i] = best;
    distance[i] = best_distance;
  }

  points->assign(left.size(), cv::Point3f(kNaN, kNaN, kNaN));
  const int half = options.window / 2;
  for (size_t i = 0; i < left.size(); ++i) {
    if (match[i] == kNone) continue;
    const cv::Point2f& p = left.keypoints[i].pt;
    const double orb_disparity = p.x - right_keypoints[match[i]].pt.x;
    const double d = RefineDisparity(left_gray, right_gray, int(std::lround(p.x)),
                                     int(std::lround(p.y)), orb_disparity, half);
    if (!(d > 0.0)) continue;
    (*points)[i] = BackProject(K, p, K(0, 0) * baseline_m / d);
  }
  return Status::Ok();
}

}  // namespace recog
