// Frame helpers: the three forms of pb::Frame (proto/recognition/v1/common.proto) built from
// what a robot has at hand — an image file, decoded pixels, or features it extracted itself.
//
// Client-side features move the extraction onto the robot and cost about 60 KB a frame (1000
// keypoints and 32-byte descriptors) whatever the camera's resolution. ExtractOrbFeatures computes
// exactly what the server computes for a frame sent as an image with its default place settings
// (core's PlaceFeatureOptions(): ORB, 1000 features, scale factor 1.2, 8 levels, FAST threshold 20,
// edge threshold 31, Harris score, 31-pixel patches, no grid bucketing; a frame whose shorter side
// is under 352 pixels enlarged to 352 first and its keypoints mapped back to its own pixels;
// features sorted strongest first), so a map built from either form answers the same. Equal
// features need equal grey pixels: the server decodes images with cv::IMREAD_GRAYSCALE, so read
// files that way (cv::imread(path, cv::IMREAD_GRAYSCALE)); converting a colour image yourself
// rounds differently.
//
// Timestamps, camera ids, intrinsics and client frame ids are left for the caller to set on the
// returned frame. None of these functions throws; they are thread-safe.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "client/cpp/result.h"
#include "recognition/v1/common.pb.h"
#include "recognition/v1/place.pb.h"

namespace recog::client {

namespace pb = ::recognition::v1;

// The bytes of a JPEG or PNG file, sent as they are (the server decodes them). NOT_FOUND when
// the file cannot be read, INVALID_ARGUMENT when it is empty or neither JPEG nor PNG.
Result<pb::Frame> FrameFromEncodedFile(const std::string& path);

// Raw pixels: an 8-bit grey (CV_8UC1, sent as GRAY8) or 8-bit BGR (CV_8UC3, sent as BGR8)
// image, any stride. INVALID_ARGUMENT for an empty image or another pixel type.
Result<pb::Frame> FrameFromImage(const cv::Mat& image);

// ORB keypoints with their 32-byte descriptors.
struct OrbFeatures {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;  // CV_8UC1, one 32-byte row per keypoint
};

// The server's default place features of an 8-bit grey or BGR image (BGR is converted to grey
// first, as the server does with raw BGR frames). An image too small for any feature gives none.
// INVALID_ARGUMENT for an empty image or another pixel type.
Result<OrbFeatures> ExtractOrbFeatures(const cv::Mat& image);

// A frame carrying features: one keypoint per descriptor row, 32-byte (CV_8UC1, 32 columns)
// descriptors as the server's vocabularies use. `image_size` (optional) is recorded for drawing.
// INVALID_ARGUMENT when the descriptors do not match the keypoints or are not 32-byte binary.
Result<pb::Frame> FrameFromFeatures(const std::vector<cv::KeyPoint>& keypoints,
                                    const cv::Mat& descriptors, cv::Size image_size = {});

// Metric loops (place maps): the frame's 3D structure, for a frame that also carries its
// intrinsics without distortion (the server refuses either without). Attaching one replaces the
// other.
//
// An aligned depth image (registered to the frame's image, same size): CV_16UC1 in units of
// 1/units_per_metre metres (1000: millimetres; 5000: TUM RGB-D) or CV_32FC1 in metres
// (units_per_metre is then ignored); 0 or NaN = no depth. Sent raw. INVALID_ARGUMENT for an empty
// image, another type or units_per_metre <= 0.
grpc::Status AttachDepth(const cv::Mat& depth, double units_per_metre, pb::Frame* frame);
// The right image of a rectified stereo pair whose left image is the frame's (same size, 8-bit
// grey or BGR, sent raw), the camera moved by baseline_m metres (> 0) along its x axis.
// INVALID_ARGUMENT for an empty image, another pixel type or a non-positive baseline.
grpc::Status AttachStereoRight(const cv::Mat& right, double baseline_m, pb::Frame* frame);

// Rig maps (MapSettings.rig): a frame of a multi-camera rig carries one view per camera in
// Frame.views, and only its timestamp, client_frame_id and exclude_frame_ids itself. A view is a
// frame built as above (with AttachDepth or AttachStereoRight for metric loops) without
// intrinsics: the map's rig has them. AddRigView names `view` after `camera` and appends it to
// `rig_frame`. INVALID_ARGUMENT for an empty camera name, a view without content, a view
// carrying a timestamp, ids, intrinsics or views of its own, or a camera the frame has a view of
// already.
grpc::Status AddRigView(const std::string& camera, pb::Frame view, pb::Frame* rig_frame);

// One camera of a rig map: its name, the size of its images, its pinhole matrix K with OpenCV's
// distortion coefficients (none, or 4, 5 or 8), and its pose in the body frame
// (X_body = body_R_camera * X_camera + body_t_camera, metres). The server checks the rest.
pb::RigCameraSettings MakeRigCamera(const std::string& name, cv::Size size, const cv::Matx33d& K,
                                    const std::vector<double>& distortion,
                                    const cv::Matx33d& body_R_camera,
                                    const cv::Vec3d& body_t_camera);

}  // namespace recog::client
