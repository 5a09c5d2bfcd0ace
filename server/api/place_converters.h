// The place messages of recognition/v1/place.proto and core's place types: a map's settings
// (through the one settings table, core/place/detector_settings.h) and its rig of cameras, in both
// directions; what a frame did to a map (loop statuses, loop results with their extras, metric
// loops, rig loops); and the extras a request asks for (ResultOptions). What a client sends is
// validated, INVALID_ARGUMENT naming the field.
#pragma once

#include <optional>
#include <vector>

#include "core/common/status.h"
#include "core/geometry/camera_model.h"
#include "core/geometry/camera_rig.h"
#include "core/place/loop_detector.h"
#include "core/place/place_map.h"
#include "core/place/rig_loop_detector.h"
#include "recognition/v1/place.pb.h"

namespace recog::server {

namespace pb = ::recognition::v1;

// Map settings, through the one settings table (core/place/detector_settings.h) by field name:
// ApplyMapSettings applies the detector fields `settings` sets (its preset first) and validates
// the result (INVALID_ARGUMENT naming the setting); ToProto sets every one a map keeps.
Status ApplyMapSettings(const pb::MapSettings& settings, LoopDetectorParams* params);
void ToProto(const LoopDetectorParams& params, pb::MapSettings* out);
// A rig map's cameras (MapSettings.rig; empty for none). INVALID_ARGUMENT naming settings.rig[i]
// for a body pose without 9 + 3 values or a distortion of another length than 0, 4, 5 or 8, and
// naming the camera for what ValidateRig refuses (extrinsics that are not a rigid transform, ...).
StatusOr<std::vector<RigCamera>> RigFromProto(const pb::MapSettings& settings);
void ToProto(const std::vector<RigCamera>& rig, pb::MapSettings* out);

pb::LoopStatus ToProto(LoopStatus status);
// What a frame did to a place map: the loop result with the match's timestamp and the extras
// that came with it.
void ToProto(const PlaceFrameResult& result, pb::LoopResult* out);
// What a rig frame did to a rig map of `rig`'s cameras (LoopResult.rig, cameras by name).
pb::LoopStatus ToProto(RigLoopStatus status);
void ToProto(const RigPlaceResult& result, const std::vector<RigCamera>& rig, pb::LoopResult* out);
void ToProto(const MetricLoop& metric, pb::MetricLoop* out);
// The extras a request asks for; the relative pose uses the frame's intrinsics when it has them.
// PlaceResultOptions::Validate checks the result (top_k).
PlaceResultOptions FromProto(const pb::ResultOptions& options,
                             const std::optional<CameraIntrinsics>& intrinsics);

}  // namespace recog::server
