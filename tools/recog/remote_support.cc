#include "tools/recog/remote_support.h"

#include <cstdio>

#include "tools/recog/server_flags.h"

namespace recog::cli {

client::Result<pb::Frame> FrameFromImageFile(const std::string& path, const cv::Mat& gray) {
  client::Result<pb::Frame> encoded = client::FrameFromEncodedFile(path);
  if (encoded.ok() || encoded.status().error_code() != grpc::StatusCode::INVALID_ARGUMENT) {
    return encoded;
  }
  return client::FrameFromImage(gray);  // neither JPEG nor PNG
}

void SetIntrinsics(const CameraIntrinsics& camera, pb::Frame* frame) {
  pb::CameraIntrinsics* out = frame->mutable_intrinsics();
  out->set_fx(camera.fx);
  out->set_fy(camera.fy);
  out->set_cx(camera.cx);
  out->set_cy(camera.cy);
  out->mutable_distortion()->Assign(camera.distortion.begin(), camera.distortion.end());
}

int Fail(const char* command, const Status& status) {
  std::fprintf(stderr, "recog %s: %s\n", command, status.ToString().c_str());
  return 1;
}

int Fail(const char* command, const grpc::Status& status) {
  std::fprintf(stderr, "recog %s: %s\n", command, DescribeStatus(status).c_str());
  return 1;
}

}  // namespace recog::cli
