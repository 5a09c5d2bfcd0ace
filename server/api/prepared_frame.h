// PreparedFrame and PreparedRigFrame: a request's frame made ready for a place map. A frame is
// decoded and validated (DecodeFrame, frame_decoding.h), given its features (the client's, or those
// extracted from its image) and its 3D structure (points from its depth or right image, or only
// the camera matrix). A frame whose camera has a lens distortion has its keypoints moved into the
// pinhole image of the camera's K (ToPinhole, core/geometry/camera_model.h), where the geometry
// of loops works. A rig frame is the same preparation view by view, each view taking its camera's
// intrinsics and image size (PlaceMap's rig calls).
//
// The request is read where it lies: a view is decoded as it is, its camera's intrinsics given
// beside it rather than written into a copy of the view (and of its image bytes). What a prepared
// frame holds it decoded into buffers of its own, so it may outlive the request.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include "core/common/status.h"
#include "core/place/place_map.h"
#include "server/api/frame_decoding.h"
#include "server/api/place_converters.h"

namespace recog::server {

// Extracts the place features of an 8-bit grey image (a worker's extractor, WorkerContext).
using ExtractPlaceFeatures = std::function<Status(const cv::Mat& image, FeatureSet* out)>;

class PreparedFrame {
 public:
  // Decodes `request` for maps of `descriptor`, its images charged to `budget` (the call's), then
  // extracts its features with `extract` and its 3D points, adding the time each step took to
  // `timing` (decode_ms, features_ms, and recognition_ms for the points). `camera`, when given,
  // stands for request.intrinsics (a rig view's camera). Errors of DecodeFrame, of `extract` and
  // of the 3D points (core/geometry/frame_points.h).
  static StatusOr<PreparedFrame> Prepare(const pb::Frame& request,
                                         const DescriptorFormat& descriptor,
                                         const ExtractPlaceFeatures& extract, PixelBudget& budget,
                                         pb::Timing* timing,
                                         const CameraIntrinsics* camera = nullptr);

  const DecodedFrame& frame() const { return frame_; }
  const FeatureSet& features() const { return frame_.has_image() ? extracted_ : frame_.features; }
  const FrameGeometry* geometry() const { return geometry_ ? &*geometry_ : nullptr; }
  // The extras `options` asks for, with the frame's intrinsics (for relative poses).
  PlaceResultOptions Extras(const pb::ResultOptions& options) const {
    return FromProto(options, frame_.intrinsics);
  }

 private:
  PreparedFrame() = default;

  DecodedFrame frame_;
  FeatureSet extracted_;  // when the frame carried an image
  std::optional<FrameGeometry> geometry_;
};

class PreparedRigFrame {
 public:
  // Prepares `request` for the rig map `map`, every camera's view as PreparedFrame does (all their
  // images charged to one budget). INVALID_ARGUMENT naming the camera for a view of an unknown
  // camera, a camera without a view or with two, a view carrying more than its image and
  // structure, or an image of another size than its camera's; and for a frame with content of its
  // own. `budget` is the call's.
  static StatusOr<PreparedRigFrame> Prepare(const pb::Frame& request, const PlaceMap& map,
                                            const ExtractPlaceFeatures& extract,
                                            PixelBudget& budget, pb::Timing* timing);

  const RigFrame& frame() const { return frame_; }
  // The rig frames the client left out (exclude_frame_ids).
  std::vector<uint64_t> excluded() const {
    return {header_.excluded_frames.begin(), header_.excluded_frames.end()};
  }
  // Features over every camera.
  size_t features() const;

 private:
  PreparedRigFrame() = default;

  // Prepares `view` as a frame of `camera` and appends it to the rig frame.
  Status AddCamera(const pb::Frame& view, const RigCamera& camera,
                   const DescriptorFormat& descriptor, const ExtractPlaceFeatures& extract,
                   PixelBudget& budget, pb::Timing* timing);

  DecodedFrame header_;  // the rig frame's timestamp and ids
  RigFrame frame_;
};

}  // namespace recog::server
