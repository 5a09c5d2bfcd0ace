#include "client/cpp/frames.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numeric>
#include <sstream>

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

namespace recog::client {
namespace {

// The server's default place features (core/features/feature_extractor.h,
// PlaceFeatureOptions()).
constexpr int kOrbFeatures = 1000;
constexpr float kOrbScaleFactor = 1.2f;
constexpr int kOrbLevels = 8;
constexpr int kOrbEdgeThreshold = 31;
constexpr int kOrbPatchSize = 31;
constexpr int kOrbFastThreshold = 20;
constexpr int kMinShortSide = 352;  // smaller frames are enlarged to it before ORB
constexpr int kDescriptorBytes = 32;

grpc::Status InvalidFrame(const std::string& message) {
  return {grpc::StatusCode::INVALID_ARGUMENT, message};
}

bool IsJpegOrPng(const std::string& bytes) {
  static constexpr char kJpeg[] = "\xff\xd8\xff";
  static constexpr char kPng[] = "\x89PNG\r\n\x1a\n";
  return bytes.starts_with(std::string_view(kJpeg, 3)) ||
         bytes.starts_with(std::string_view(kPng, 8));
}

grpc::Status CheckPixels(const cv::Mat& image) {
  if (image.empty()) return InvalidFrame("the image is empty");
  if (image.dims != 2 || (image.type() != CV_8UC1 && image.type() != CV_8UC3)) {
    return InvalidFrame("the image has pixel type " + cv::typeToString(image.type()) +
                        "; expected 8-bit grey (CV_8UC1) or 8-bit BGR (CV_8UC3)");
  }
  return grpc::Status::OK;
}

// The image's rows one after the other, without padding (little-endian on the usual hosts).
void AppendRows(const cv::Mat& image, std::string* out) {
  const size_t row_bytes = size_t(image.cols) * image.elemSize();
  out->reserve(out->size() + row_bytes * size_t(image.rows));
  for (int y = 0; y < image.rows; ++y) out->append(image.ptr<char>(y), row_bytes);
}

// Core's deterministic order of features: strongest first, then top to bottom, left to right;
// the remaining fields separate keypoints that share a position.
bool StrongerFirst(const cv::KeyPoint& a, const cv::KeyPoint& b) {
  if (a.response != b.response) return a.response > b.response;
  if (a.pt.y != b.pt.y) return a.pt.y < b.pt.y;
  if (a.pt.x != b.pt.x) return a.pt.x < b.pt.x;
  if (a.octave != b.octave) return a.octave < b.octave;
  if (a.size != b.size) return a.size < b.size;
  return a.angle < b.angle;
}

// The pyramid levels that exist for an image of `size` (OpenCV fails on levels that round to
// zero pixels), as the server counts them.
int UsableLevels(cv::Size size) {
  int levels = 0;
  double scale = 1.0;
  while (levels < kOrbLevels && cvRound(size.width / scale) >= 1 &&
         cvRound(size.height / scale) >= 1) {
    ++levels;
    scale *= kOrbScaleFactor;
  }
  return std::max(levels, 1);
}

// A frame whose shorter side is under kMinShortSide is enlarged (bilinear) until it is that long,
// as the server does; MapToOriginal then moves the keypoints back to the frame's own pixels.
cv::Mat EnlargeSmallFrame(const cv::Mat& grey) {
  const int short_side = std::min(grey.rows, grey.cols);
  if (short_side >= kMinShortSide) return grey;
  const double scale = double(kMinShortSide) / short_side;
  cv::Mat enlarged;
  cv::resize(grey, enlarged,
             cv::Size(int(std::lround(grey.cols * scale)), int(std::lround(grey.rows * scale))), 0,
             0, cv::INTER_LINEAR);
  return enlarged;
}

void MapToOriginal(cv::Size enlarged, cv::Size original, std::vector<cv::KeyPoint>* keypoints) {
  const float sx = float(enlarged.width) / float(original.width);
  const float sy = float(enlarged.height) / float(original.height);
  for (cv::KeyPoint& kp : *keypoints) {
    kp.pt.x = std::clamp((kp.pt.x + 0.5f) / sx - 0.5f, 0.f, float(original.width - 1));
    kp.pt.y = std::clamp((kp.pt.y + 0.5f) / sy - 0.5f, 0.f, float(original.height - 1));
    kp.size /= sx;
  }
}

}  // namespace

Result<pb::Frame> FrameFromEncodedFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return grpc::Status(grpc::StatusCode::NOT_FOUND, "cannot open '" + path + "'");
  std::ostringstream bytes;
  bytes << in.rdbuf();
  std::string content = std::move(bytes).str();
  if (content.empty()) return InvalidFrame("'" + path + "' is empty");
  if (!IsJpegOrPng(content)) return InvalidFrame("'" + path + "' is neither a JPEG nor a PNG file");
  pb::Frame frame;
  frame.set_encoded_image(std::move(content));
  return frame;
}

Result<pb::Frame> FrameFromImage(const cv::Mat& image) {
  if (grpc::Status status = CheckPixels(image); !status.ok()) return status;
  pb::Frame frame;
  pb::RawImage* raw = frame.mutable_raw_image();
  raw->set_width(uint32_t(image.cols));
  raw->set_height(uint32_t(image.rows));
  raw->set_format(image.channels() == 1 ? pb::PIXEL_FORMAT_GRAY8 : pb::PIXEL_FORMAT_BGR8);
  AppendRows(image, raw->mutable_pixels());
  return frame;
}

grpc::Status AttachDepth(const cv::Mat& depth, double units_per_metre, pb::Frame* frame) {
  if (depth.empty() || depth.dims != 2) return InvalidFrame("the depth image is empty");
  if (depth.type() != CV_16UC1 && depth.type() != CV_32FC1) {
    return InvalidFrame(
        "the depth image has pixel type " + cv::typeToString(depth.type()) +
        "; expected CV_16UC1 (units of 1/units_per_metre metres) or CV_32FC1 (metres)");
  }
  if (!(units_per_metre > 0) || !std::isfinite(units_per_metre)) {
    return InvalidFrame("units_per_metre must be > 0 (1000 for millimetres)");
  }
  pb::DepthImage* out = frame->mutable_depth();
  pb::RawDepth* raw = out->mutable_raw();
  raw->set_width(uint32_t(depth.cols));
  raw->set_height(uint32_t(depth.rows));
  raw->set_format(depth.type() == CV_16UC1 ? pb::DEPTH_FORMAT_U16 : pb::DEPTH_FORMAT_F32);
  raw->clear_data();
  AppendRows(depth, raw->mutable_data());
  out->set_scale(depth.type() == CV_16UC1 ? units_per_metre : 0);
  frame->clear_right();
  return grpc::Status::OK;
}

grpc::Status AttachStereoRight(const cv::Mat& right, double baseline_m, pb::Frame* frame) {
  if (grpc::Status status = CheckPixels(right); !status.ok()) return status;
  if (!(baseline_m > 0) || !std::isfinite(baseline_m)) {
    return InvalidFrame("the stereo baseline must be > 0 metres");
  }
  pb::StereoRight* out = frame->mutable_right();
  pb::RawImage* raw = out->mutable_raw_image();
  raw->set_width(uint32_t(right.cols));
  raw->set_height(uint32_t(right.rows));
  raw->set_format(right.channels() == 1 ? pb::PIXEL_FORMAT_GRAY8 : pb::PIXEL_FORMAT_BGR8);
  raw->clear_pixels();
  AppendRows(right, raw->mutable_pixels());
  out->set_baseline_m(baseline_m);
  frame->clear_depth();
  return grpc::Status::OK;
}

grpc::Status AddRigView(const std::string& camera, pb::Frame view, pb::Frame* rig_frame) {
  if (camera.empty()) return InvalidFrame("a rig view needs its camera's name");
  if (view.content_case() == pb::Frame::CONTENT_NOT_SET) {
    return InvalidFrame("the view of camera '" + camera + "' has no image or features");
  }
  if (view.has_timestamp() || !view.client_frame_id().empty() || view.has_intrinsics() ||
      view.exclude_frame_ids_size() > 0 || view.views_size() > 0) {
    return InvalidFrame(
        "the view of camera '" + camera + "' carries more than its image and its " +
        "depth or right image (set timestamps and ids on the rig frame; the map's " +
        "rig has the intrinsics)");
  }
  for (const pb::Frame& other : rig_frame->views()) {
    if (other.camera_id() == camera)
      return InvalidFrame("camera '" + camera + "' has a view already");
  }
  view.set_camera_id(camera);
  *rig_frame->add_views() = std::move(view);
  return grpc::Status::OK;
}

pb::RigCameraSettings MakeRigCamera(const std::string& name, cv::Size size, const cv::Matx33d& K,
                                    const std::vector<double>& distortion,
                                    const cv::Matx33d& body_R_camera,
                                    const cv::Vec3d& body_t_camera) {
  pb::RigCameraSettings camera;
  camera.set_name(name);
  camera.set_width(uint32_t(std::max(size.width, 0)));
  camera.set_height(uint32_t(std::max(size.height, 0)));
  pb::CameraIntrinsics* k = camera.mutable_intrinsics();
  k->set_fx(K(0, 0));
  k->set_fy(K(1, 1));
  k->set_cx(K(0, 2));
  k->set_cy(K(1, 2));
  k->mutable_distortion()->Assign(distortion.begin(), distortion.end());
  pb::Pose* pose = camera.mutable_body_pose();
  pose->mutable_rotation()->Assign(body_R_camera.val, body_R_camera.val + 9);
  pose->mutable_translation()->Assign(body_t_camera.val, body_t_camera.val + 3);
  return camera;
}

Result<OrbFeatures> ExtractOrbFeatures(const cv::Mat& image) {
  if (grpc::Status status = CheckPixels(image); !status.ok()) return status;
  cv::Mat grey = image;
  if (image.type() == CV_8UC3) cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  try {
    const cv::Mat described = EnlargeSmallFrame(grey);
    cv::Ptr<cv::ORB> orb = cv::ORB::create(
        kOrbFeatures, kOrbScaleFactor, UsableLevels(described.size()), kOrbEdgeThreshold,
        /*firstLevel=*/0, /*WTA_K=*/2, cv::ORB::HARRIS_SCORE, kOrbPatchSize, kOrbFastThreshold);
    orb->detectAndCompute(described, cv::noArray(), keypoints, descriptors);
    if (described.size() != grey.size()) MapToOriginal(described.size(), grey.size(), &keypoints);
  } catch (const cv::Exception& e) {
    return grpc::Status(grpc::StatusCode::INTERNAL, std::string("ORB failed: ") + e.what());
  }
  OrbFeatures out;
  out.descriptors.create(0, kDescriptorBytes, CV_8UC1);
  if (keypoints.empty()) return out;
  std::vector<size_t> order(keypoints.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return StrongerFirst(keypoints[a], keypoints[b]); });
  order.resize(std::min(order.size(), size_t(kOrbFeatures)));
  out.keypoints.reserve(order.size());
  out.descriptors.create(int(order.size()), kDescriptorBytes, CV_8UC1);
  for (size_t i = 0; i < order.size(); ++i) {
    out.keypoints.push_back(keypoints[order[i]]);
    descriptors.row(int(order[i])).copyTo(out.descriptors.row(int(i)));
  }
  return out;
}

Result<pb::Frame> FrameFromFeatures(const std::vector<cv::KeyPoint>& keypoints,
                                    const cv::Mat& descriptors, cv::Size image_size) {
  if (descriptors.rows != int(keypoints.size())) {
    return InvalidFrame(std::to_string(descriptors.rows) + " descriptor rows for " +
                        std::to_string(keypoints.size()) + " keypoints");
  }
  if (!keypoints.empty() &&
      (descriptors.type() != CV_8UC1 || descriptors.cols != kDescriptorBytes)) {
    return InvalidFrame("descriptors must be 32-byte binary rows (CV_8UC1, 32 columns), got " +
                        cv::typeToString(descriptors.type()) + " with " +
                        std::to_string(descriptors.cols) + " columns");
  }
  pb::Frame frame;
  pb::Features* out = frame.mutable_features();
  pb::Keypoints* k = out->mutable_keypoints();
  const int n = int(keypoints.size());
  for (auto* array : {k->mutable_x(), k->mutable_y(), k->mutable_size(), k->mutable_angle(),
                      k->mutable_response()}) {
    array->Reserve(n);
  }
  k->mutable_octave()->Reserve(n);
  for (const cv::KeyPoint& p : keypoints) {
    k->add_x(p.pt.x);
    k->add_y(p.pt.y);
    k->add_size(p.size);
    k->add_angle(p.angle);
    k->add_response(p.response);
    k->add_octave(p.octave);
  }
  std::string* bytes = out->mutable_descriptors();
  bytes->reserve(keypoints.size() * kDescriptorBytes);
  for (int r = 0; r < descriptors.rows; ++r)
    bytes->append(descriptors.ptr<char>(r), kDescriptorBytes);
  out->set_descriptor_bytes(kDescriptorBytes);
  out->set_image_width(uint32_t(std::max(image_size.width, 0)));
  out->set_image_height(uint32_t(std::max(image_size.height, 0)));
  return frame;
}

}  // namespace recog::client
