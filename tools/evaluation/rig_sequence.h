// Synthetic drives of a multi-camera rig with exactly known geometry (thesis §3.3.2: a robot that
// comes back along its way in the opposite direction sees with its rear camera what its front
// camera saw). The scene is an avenue of textured panels along the world's z axis (the planes of
// metric_sequence.h); a front camera looking along +z and a rear camera looking along -z ride on
// a body that drives out along the avenue, goes round the block (time passes, nothing is
// rendered) and drives back the other way, offset sideways and turned a little.
//
// The scene: a panel every `panel_spacing_m` along the avenue (from three panels before the path
// to three after it) on each side of the road, its
// centre `road_half_width_m` to twice that from the axis and up to 0.3 m above or below the
// cameras, facing along z; each panel is a slab of two photos, one facing +z and one facing -z
// (2 cm apart), so a camera looking along +z never sees what one looking along -z sees. Photos
// are drawn from the given list without repetition (seeded), so the list needs 2 per panel.
//
// The path: `frames_per_leg` body poses step_m apart from z = 0 (out, heading +z), then the same
// number back (heading -z), from the last out position plus step_m / 2 down to step_m / 2, moved
// `return_lateral_offset_m` sideways and turned `return_yaw_deg`. Body frame: x right, y down,
// z forward (the heading). Frame i is at time i * frame_interval_s on the way out and
// round_the_block_s later than that on the way back.
//
// Ground truth: frame i of the way back revisits frame j of the way out when their body
// positions are within `revisit_radius_m` (every way-back frame has such a frame while the
// return offset is under the radius); frames of one leg never revisit each other. Seen by which
// camera: the way back's rear camera looks where the way out's front camera looked.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/status.h"
#include "tools/evaluation/ground_truth.h"
#include "tools/evaluation/metric_sequence.h"
#include "tools/evaluation/rig_file.h"

namespace recog::cli {

struct RigSequenceOptions {
  int frames_per_leg = 40;
  double step_m = 0.25;
  double frame_interval_s = 1.0;
  double round_the_block_s = 60.0;  // between the last frame out and the first frame back
  double return_lateral_offset_m = 0.15;
  double return_yaw_deg = 3.0;
  double revisit_radius_m = 1.0;
  double panel_spacing_m = 1.5;
  double road_half_width_m = 1.0;
  double panel_width_m = 1.6, panel_height_m = 1.2;
  // The rig: empty for the default front + rear pair (DefaultRig), else any cameras without
  // lens distortion (the scene is rendered through pinholes).
  std::vector<RigCamera> cameras;
  cv::Size image_size{640, 480};  // of the default rig's cameras
  double focal_px = 400;          // fx = fy of the default rig; the principal point is the centre
  double camera_offset_m = 0.4;   // the default front camera this far ahead of the body origin,
                                  // its rear camera as far behind
  uint64_t seed = 1;

  // INVALID_ARGUMENT naming the first option out of range.
  Status Validate() const;
};

struct RigSequence {
  std::vector<RigCamera> cameras;                  // options.cameras, or the default front and rear
  std::vector<CameraPose> body_poses;              // world_from_body, one per frame
  std::vector<double> timestamps;                  // seconds, one per frame
  std::vector<std::vector<RenderedFrame>> frames;  // frames[i][c]: frame i seen by camera c
  GroundTruth truth;                               // over the rig frames
};

// How many photos the avenue of `options` needs (valid options).
size_t RigPhotosNeeded(const RigSequenceOptions& options);

// INVALID_ARGUMENT for bad options, a rig that does not validate or has lens distortion, or fewer
// photos than the scene needs (naming how many); photos are 8-bit grey.
// `progress` (may be empty) is told the frames rendered so far and their total.
StatusOr<RigSequence> GenerateRigSequence(
    const std::vector<cv::Mat>& photos, const RigSequenceOptions& options,
    const std::function<void(uint64_t done, uint64_t total)>& progress = {});

// The default rig of `options`: "front" looking along the body's z axis, camera_offset_m ahead
// of its origin, and "rear" looking back, as far behind; image_size, fx = fy = focal_px.
std::vector<RigCamera> DefaultRig(const RigSequenceOptions& options);

// Writes the sequence into `dir` (created; INVALID_ARGUMENT when it exists and is not empty):
//  - rig.yaml: the rig file of its cameras (rig_file.h);
//  - one folder per camera, named after it, in the TUM RGB-D layout (rgb.txt, rgb/NNNNNN.png, and
//    with `depth`, depth.txt and depth/NNNNNN.png in TUM's 1/5000 m), so that each camera's
//    images read as a dataset of their own (`recog eval place --images DIR/front`);
//  - ground_truth.txt (dense, over the rig frames) and body_poses.txt (TUM trajectory format:
//    "timestamp tx ty tz qx qy qz qw", world_from_body).
Status WriteRigSequence(const RigSequence& sequence, bool depth, const std::string& dir);

}  // namespace recog::cli
