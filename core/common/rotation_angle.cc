#include "core/common/rotation_angle.h"

#include <algorithm>
#include <cmath>

namespace recog {

double RotationAngleDeg(const cv::Matx33d& a, const cv::Matx33d& b) {
  // trace(R) = 1 + 2 cos(angle); rounding may take the cosine just outside [-1, 1].
  const double cosine = std::clamp((cv::trace(a * b.t()) - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(cosine) * 180.0 / CV_PI;
}

}  // namespace recog
