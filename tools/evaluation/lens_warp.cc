#include "tools/evaluation/lens_warp.h"

#include <opencv2/imgproc.hpp>

namespace recog {

StatusOr<LensWarp> LensWarp::Create(const cv::Matx33d& source_K, const CameraIntrinsics& lens,
                                    cv::Size output_size) {
  if (!(source_K(0, 0) > 0) || !(source_K(1, 1) > 0)) {
    return Status::InvalidArgument("the source camera needs fx, fy > 0");
  }
  RECOG_RETURN_IF_ERROR(lens.Validate());
  if (output_size.width <= 0 || output_size.height <= 0) {
    return Status::InvalidArgument("the output size must be positive");
  }
  LensWarp warp;
  warp.map_x_.create(output_size, CV_32F);
  warp.map_y_.create(output_size, CV_32F);
  // A direction the source does not show maps far outside it: black under BORDER_CONSTANT.
  constexpr float kNowhere = -1e6f;
  for (int v = 0; v < output_size.height; ++v) {
    auto* x = warp.map_x_.ptr<float>(v);
    auto* y = warp.map_y_.ptr<float>(v);
    for (int u = 0; u < output_size.width; ++u) {
      cv::Vec3d bearing;
      x[u] = y[u] = kNowhere;
      if (!UnprojectPixel(lens, cv::Point2d(u, v), &bearing) || bearing[2] <= 1e-6) continue;
      const cv::Vec3d source = source_K * (bearing / bearing[2]);
      x[u] = float(source[0]);
      y[u] = float(source[1]);
    }
  }
  return warp;
}

cv::Mat LensWarp::Apply(const cv::Mat& image) const {
  cv::Mat out;
  cv::remap(image, out, map_x_, map_y_, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  return out;
}

}  // namespace recog
