// Images as another lens would have taken them: a pinhole image (camera matrix `source_K`) is
// resampled so that each pixel of the output shows the direction the output camera's lens
// (core/geometry/camera_model.h) maps there. A real sequence passed through a known fisheye or
// radial-tangential distortion this way is the same scene with the same geometry, so the loops
// and metric poses found on it through `--camera LENS:…` can be compared with the original's.
// Output pixels whose direction the source image does not show are black.
#pragma once

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "core/geometry/camera_model.h"

namespace recog {

class LensWarp {
 public:
  // INVALID_ARGUMENT for a source K without positive focal lengths, an invalid `lens`
  // (CameraIntrinsics::Validate) or an empty output size.
  static StatusOr<LensWarp> Create(const cv::Matx33d& source_K, const CameraIntrinsics& lens,
                                   cv::Size output_size);

  // `image` as the lens sees it (bilinear). The image must be as large as source_K assumes; it is
  // not checked: any size works, pixels outside it are black.
  cv::Mat Apply(const cv::Mat& image) const;

 private:
  LensWarp() = default;

  cv::Mat map_x_, map_y_;  // CV_32F: the source pixel of every output pixel
};

}  // namespace recog
