#include "server/api/prepared_frame.h"

#include <algorithm>
#include <chrono>
#include <string>

#include "core/common/elapsed.h"
#include "core/geometry/camera_model.h"
#include "core/geometry/frame_points.h"

namespace recog::server {
namespace {

// The 3D points of `frame`'s `features` from its depth or right image (whose features `extract`
// gives); the frame has one of them, and so pinhole intrinsics.
Status PointsOf(const DecodedFrame& frame, const FeatureSet& features,
                const ExtractPlaceFeatures& extract, FrameGeometry* out) {
  out->K = frame.intrinsics->K();
  if (!frame.depth.empty()) {
    const cv::Size size = frame.has_image() ? frame.image.size() : frame.depth.size();
    return PointsFromDepth(features.keypoints, size, out->K, frame.depth, frame.depth_scale,
                           &out->points);
  }
  FeatureSet right_features;
  RECOG_RETURN_IF_ERROR(extract(frame.right, &right_features));
  return PointsFromStereo(features, frame.image, right_features, frame.right, out->K,
                          frame.baseline_m, StereoOptions{}, &out->points);
}

}  // namespace

StatusOr<PreparedFrame> PreparedFrame::Prepare(const pb::Frame& request,
                                               const DescriptorFormat& descriptor,
                                               const ExtractPlaceFeatures& extract,
                                               PixelBudget& budget, pb::Timing* timing,
                                               const CameraIntrinsics* camera) {
  PreparedFrame prepared;
  RECOG_ASSIGN_OR_RETURN(prepared.frame_, DecodeFrame(request, descriptor, budget, camera));
  const DecodedFrame& frame = prepared.frame_;
  timing->set_decode_ms(timing->decode_ms() + frame.decode_ms);
  if (frame.has_image()) {
    const auto start = std::chrono::steady_clock::now();
    RECOG_RETURN_IF_ERROR(extract(frame.image, &prepared.extracted_));
    timing->set_features_ms(timing->features_ms() + MillisecondsSince(start));
  }
  const auto start = std::chrono::steady_clock::now();
  if (!frame.depth.empty() || !frame.right.empty()) {
    RECOG_RETURN_IF_ERROR(
        PointsOf(frame, prepared.features(), extract, &prepared.geometry_.emplace()));
  } else if (frame.intrinsics.has_value()) {
    // The geometry of loops works in the pinhole image of K: a lens's keypoints move there once.
    FeatureSet& features = frame.has_image() ? prepared.extracted_ : prepared.frame_.features;
    ToPinhole(*frame.intrinsics, features.keypoints);
    prepared.geometry_.emplace().K = frame.intrinsics->K();
  }
  timing->set_recognition_ms(timing->recognition_ms() + MillisecondsSince(start));
  return prepared;
}

StatusOr<PreparedRigFrame> PreparedRigFrame::Prepare(const pb::Frame& request, const PlaceMap& map,
                                                     const ExtractPlaceFeatures& extract,
                                                     PixelBudget& budget, pb::Timing* timing) {
  const std::vector<RigCamera>& rig = map.rig();
  std::string cameras;
  for (const RigCamera& camera : rig) cameras += (cameras.empty() ? "" : ", ") + camera.name;
  if (request.content_case() != pb::Frame::CONTENT_NOT_SET || request.has_depth() ||
      request.has_right() || request.has_intrinsics() || request.views_size() == 0) {
    return Status::InvalidArgument("map '" + map.name() + "' is a rig map: a frame carries " +
                                   "its images in frame.views, one per camera (" + cameras +
                                   "), and nothing of its own but its timestamp and ids");
  }
  PreparedRigFrame prepared;
  RECOG_RETURN_IF_ERROR(DecodeFrameHeader(request, &prepared.header_));
  std::vector<int> view_of(rig.size(), -1);
  for (int i = 0; i < request.views_size(); ++i) {
    const pb::Frame& view = request.views(i);
    const std::string where = "frame.views[" + std::to_string(i) + "]";
    const auto camera = std::find_if(
        rig.begin(), rig.end(), [&](const RigCamera& c) { return c.name == view.camera_id(); });
    if (camera == rig.end()) {
      return Status::InvalidArgument(where + " is for camera '" + view.camera_id() +
                                     "', which the rig of map '" + map.name() +
                                     "' does not have (" + cameras + ")");
    }
    int& slot = view_of[size_t(camera - rig.begin())];
    if (slot >= 0) {
      return Status::InvalidArgument(where + ": camera '" + camera->name + "' has two views");
    }
    if (view.has_timestamp() || !view.client_frame_id().empty() || view.has_intrinsics() ||
        view.exclude_frame_ids_size() > 0 || view.views_size() > 0) {
      return Status::InvalidArgument(
          where + " (camera '" + camera->name + "') holds more than its image and its depth " +
          "or right image: timestamp, client_frame_id and exclude_frame_ids belong to the " +
          "frame, intrinsics to the map's rig");
    }
    slot = i;
  }
  for (size_t c = 0; c < rig.size(); ++c) {
    if (view_of[c] < 0) {
      return Status::InvalidArgument("frame.views has no view for camera '" + rig[c].name +
                                     "'; a rig frame needs one per camera (" + cameras + ")");
    }
  }
  prepared.frame_.timestamp = prepared.header_.timestamp;
  prepared.frame_.client_id = prepared.header_.client_frame_id;
  for (size_t c = 0; c < rig.size(); ++c) {
    const Status status =
        prepared.AddCamera(request.views(view_of[c]), rig[c], map.vocabulary().info().descriptor,
                           extract, budget, timing);
    if (!status.ok()) return status.WithContext("rig camera '" + rig[c].name + "'");
  }
  return prepared;
}

size_t PreparedRigFrame::features() const {
  size_t total = 0;
  for (const FeatureSet& camera : frame_.cameras) total += camera.size();
  return total;
}

Status PreparedRigFrame::AddCamera(const pb::Frame& view, const RigCamera& camera,
                                   const DescriptorFormat& descriptor,
                                   const ExtractPlaceFeatures& extract, PixelBudget& budget,
                                   pb::Timing* timing) {
  const CameraIntrinsics intrinsics{camera.K(0, 0), camera.K(1, 1),    camera.K(0, 2),
                                    camera.K(1, 2), camera.distortion, camera.lens};
  RECOG_ASSIGN_OR_RETURN(
      const PreparedFrame prepared,
      PreparedFrame::Prepare(view, descriptor, extract, budget, timing, &intrinsics));
  const DecodedFrame& decoded = prepared.frame();
  cv::Size size = decoded.image.size();
  if (!decoded.has_image() && view.features().image_width() != 0) {
    size = cv::Size(int(view.features().image_width()), int(view.features().image_height()));
  }
  if ((decoded.has_image() || view.features().image_width() != 0) && size != camera.size) {
    return Status::InvalidArgument("its image is " + std::to_string(size.width) + "x" +
                                   std::to_string(size.height) + "; the camera's are " +
                                   std::to_string(camera.size.width) + "x" +
                                   std::to_string(camera.size.height));
  }
  frame_.cameras.push_back(prepared.features());  // in the camera's pinhole image (Prepare)
  const FrameGeometry* geometry = prepared.geometry();
  frame_.points.push_back(geometry != nullptr ? geometry->points : std::vector<cv::Point3f>());
  return Status::Ok();
}

}  // namespace recog::server
