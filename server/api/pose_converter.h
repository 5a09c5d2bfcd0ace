// A rigid transform to the wire's Pose (recognition/v1/common.proto): the one converter places
// (loop poses, a rig's body poses) and objects (a detection's pose) share.
#pragma once

#include <opencv2/core.hpp>

#include "recognition/v1/common.pb.h"

namespace recog::server {

namespace pb = ::recognition::v1;

// Pose.rotation holds R row by row, Pose.translation t.
inline void ToProto(const cv::Matx33d& R, const cv::Vec3d& t, pb::Pose* out) {
  out->clear_rotation();
  out->clear_translation();
  for (int i = 0; i < 9; ++i) out->add_rotation(R.val[i]);
  for (int i = 0; i < 3; ++i) out->add_translation(t[i]);
}

}  // namespace recog::server
