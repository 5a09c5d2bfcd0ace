#include "tools/common/remote_support.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <ctime>

#include "tools/common/server_flags.h"

namespace recog::cli {

void ConnectCommand(CLI::App* command, ServerFlags* flags, int* exit_code,
                    std::function<int(client::RecognitionClient&)> run) {
  flags->AddTo(command);
  const CLI::App* parent = command->get_parent();
  // "stream", "maps list": as the command is typed.
  const std::string name = parent->get_parent() == nullptr
                               ? command->get_name()
                               : parent->get_name() + " " + command->get_name();
  command->callback([exit_code, flags, name, run = std::move(run)] {
    auto client = flags->Connect();
    *exit_code = client.ok() ? run(**client) : Fail(name.c_str(), client.status());
  });
}

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
  out->set_lens(pb::LensModel(camera.lens));  // the same numbers (server/api/frame_decoding.cc)
}

std::string EnumLabel(std::string name, std::string_view prefix) {
  if (name.starts_with(prefix)) name.erase(0, prefix.size());
  std::transform(name.begin(), name.end(), name.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return name;
}

std::string UtcTime(int64_t unix_ms) {
  const std::time_t seconds = std::time_t(unix_ms / 1000);
  std::tm tm{};
  gmtime_r(&seconds, &tm);
  char text[32];
  std::strftime(text, sizeof(text), "%Y-%m-%dT%H:%M:%SZ", &tm);
  return text;
}

Status FromClient(const grpc::Status& status) {
  return status.error_code() == grpc::StatusCode::NOT_FOUND
             ? Status::NotFound(status.error_message())
             : Status::InvalidArgument(status.error_message());
}

Status AttachBagGeometry(const std::optional<CameraIntrinsics>& camera,
                         std::optional<double> baseline, const cv::Mat& depth, const cv::Mat& right,
                         pb::Frame* frame) {
  if (!camera.has_value()) {
    if (depth.empty() && right.empty()) return Status::Ok();
    return Status::InvalidArgument(
        "a depth or right image needs the camera's intrinsics (--camera-info-topic)");
  }
  CameraIntrinsics intrinsics = *camera;
  if (!depth.empty() || !right.empty()) intrinsics.distortion.clear();
  SetIntrinsics(intrinsics, frame);
  grpc::Status attached;
  if (!depth.empty()) {
    attached = client::AttachDepth(depth, 1000.0, frame);  // 16UC1: millimetres (REP 118)
  } else if (!right.empty()) {
    if (!baseline.has_value()) {
      return Status::InvalidArgument(
          "a right image needs the stereo baseline (--right-camera-info-topic)");
    }
    attached = client::AttachStereoRight(right, *baseline, frame);
  }
  if (!attached.ok()) return FromClient(attached);
  return Status::Ok();
}

int Fail(const char* command, const grpc::Status& status) {
  std::fprintf(stderr, "recog %s: %s\n", command, DescribeStatus(status).c_str());
  return 1;
}

}  // namespace recog::cli
