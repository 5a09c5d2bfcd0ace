#include "tools/evaluation/rig_sequence.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <random>

#include <Eigen/Geometry>

#include "tools/evaluation/synthetic_images.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

// Panel sides, in the order photos are drawn.
constexpr double kSides[2] = {-1.0, 1.0};
constexpr double kSlabThickness = 0.02;  // metres between a panel's two photos

// A photo across the avenue, upright and unmirrored for the cameras looking along `facing` z
// (+1 or -1): their x axis is facing * world x.
TexturedPlane Facing(const cv::Mat& photo, const cv::Vec3d& center, double facing, double width,
                     double height) {
  return {photo, center, cv::Vec3d(facing, 0, 0), cv::Vec3d(0, 1, 0), width, height};
}

// The way back's positions reach half a step beyond the way out's.
double PathEnd(const RigSequenceOptions& o) {
  return o.step_m * (o.frames_per_leg - 1) + o.step_m / 2;
}

// The avenue goes on this many panels beyond both ends of the path, so that the cameras at the
// ends still look at panels.
constexpr int kPanelsBeyondTheEnds = 3;

int PanelsPerSide(const RigSequenceOptions& o) {
  return int(std::floor(PathEnd(o) / o.panel_spacing_m + 1e-9)) + 1 + 2 * kPanelsBeyondTheEnds;
}

std::vector<TexturedPlane> Avenue(const std::vector<cv::Mat>& photos, const RigSequenceOptions& o) {
  std::mt19937_64 rng(o.seed);
  std::vector<size_t> order(photos.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::shuffle(order.begin(), order.end(), rng);
  size_t next = 0;
  auto photo = [&]() -> const cv::Mat& { return photos[order[next++]]; };
  std::uniform_real_distribution<double> out(o.road_half_width_m, 2.0 * o.road_half_width_m);
  std::uniform_real_distribution<double> height(-0.3, 0.3);
  std::vector<TexturedPlane> planes;
  for (int k = 0; k < PanelsPerSide(o); ++k) {
    const double z = o.panel_spacing_m * double(k - kPanelsBeyondTheEnds);
    for (const double side : kSides) {
      const cv::Vec3d center(side * out(rng), height(rng), z);
      // Cameras looking along +z come from smaller z: they see the face at the smaller z.
      planes.push_back(Facing(photo(), center, +1, o.panel_width_m, o.panel_height_m));
      planes.push_back(Facing(photo(), center + cv::Vec3d(0, 0, kSlabThickness), -1,
                              o.panel_width_m, o.panel_height_m));
    }
  }
  return planes;
}

Status WriteLines(const fs::path& path, const std::string& text) {
  std::ofstream file(path);
  file << text;
  file.close();
  if (!file) return Status::Internal("cannot write '" + path.string() + "'");
  return Status::Ok();
}

}  // namespace

Status RigSequenceOptions::Validate() const {
  auto positive = [](double v) { return v > 0.0 && std::isfinite(v); };
  if (frames_per_leg < 2) return Status::InvalidArgument("frames_per_leg must be at least 2");
  if (!positive(step_m)) return Status::InvalidArgument("step_m must be > 0");
  if (!positive(frame_interval_s)) return Status::InvalidArgument("frame_interval_s must be > 0");
  if (!(round_the_block_s >= 0.0)) {
    return Status::InvalidArgument("round_the_block_s must be >= 0");
  }
  if (!(std::abs(return_lateral_offset_m) < road_half_width_m)) {
    return Status::InvalidArgument("return_lateral_offset_m must stay on the road");
  }
  if (!(std::abs(return_yaw_deg) <= 30.0)) {
    return Status::InvalidArgument("return_yaw_deg must be within 30 degrees");
  }
  if (!positive(revisit_radius_m)) return Status::InvalidArgument("revisit_radius_m must be > 0");
  if (!positive(panel_spacing_m) || !positive(road_half_width_m) || !positive(panel_width_m) ||
      !positive(panel_height_m)) {
    return Status::InvalidArgument("panel spacing, road half width and panel size must be > 0");
  }
  if (image_size.width < 16 || image_size.height < 16) {
    return Status::InvalidArgument("image_size must be at least 16 x 16");
  }
  if (!positive(focal_px)) return Status::InvalidArgument("focal_px must be > 0");
  if (!(camera_offset_m >= 0.0)) return Status::InvalidArgument("camera_offset_m must be >= 0");
  return Status::Ok();
}

size_t RigPhotosNeeded(const RigSequenceOptions& o) {
  return size_t(PanelsPerSide(o)) * 2 * 2;  // two sides, two photos a panel
}

std::vector<RigCamera> DefaultRig(const RigSequenceOptions& o) {
  const cv::Matx33d K(o.focal_px, 0, 0.5 * (o.image_size.width - 1), 0, o.focal_px,
                      0.5 * (o.image_size.height - 1), 0, 0, 1);
  return {{.name = "front",
           .size = o.image_size,
           .K = K,
           .distortion = {},
           .body_t_camera = {0, 0, o.camera_offset_m}},
          {.name = "rear",
           .size = o.image_size,
           .K = K,
           .distortion = {},
           .body_R_camera = Yaw(180),
           .body_t_camera = {0, 0, -o.camera_offset_m}}};
}

StatusOr<RigSequence> GenerateRigSequence(
    const std::vector<cv::Mat>& photos, const RigSequenceOptions& o,
    const std::function<void(uint64_t done, uint64_t total)>& progress) {
  RECOG_RETURN_IF_ERROR(o.Validate());
  const size_t needed = RigPhotosNeeded(o);
  if (photos.size() < needed) {
    return Status::InvalidArgument("the avenue needs " + std::to_string(needed) + " photos, got " +
                                   std::to_string(photos.size()));
  }
  for (const cv::Mat& p : photos) {
    if (p.empty() || p.type() != CV_8UC1) {
      return Status::InvalidArgument("photos must be 8-bit grey");
    }
  }
  const std::vector<TexturedPlane> scene = Avenue(photos, o);

  RigSequence sequence;
  sequence.cameras = o.cameras.empty() ? DefaultRig(o) : o.cameras;
  RECOG_RETURN_IF_ERROR(ValidateRig(sequence.cameras));
  for (const RigCamera& camera : sequence.cameras) {
    if (!camera.distortion.empty()) {
      return Status::InvalidArgument("rig camera '" + camera.name +
                                     "' has lens distortion: the generator renders pinhole "
                                     "cameras only");
    }
  }
  const int n = o.frames_per_leg;
  for (int i = 0; i < n; ++i) {  // out, heading +z
    sequence.body_poses.push_back({cv::Matx33d::eye(), {0, 0, o.step_m * i}});
    sequence.timestamps.push_back(o.frame_interval_s * i);
  }
  for (int i = 0; i < n; ++i) {  // back, heading -z, offset and turned
    const double z = o.step_m * (n - 1 - i) + o.step_m / 2;
    sequence.body_poses.push_back({Yaw(180 + o.return_yaw_deg), {o.return_lateral_offset_m, 0, z}});
    sequence.timestamps.push_back(o.frame_interval_s * (n - 1 + i) + o.round_the_block_s);
  }

  sequence.truth.frames = 2 * n;
  sequence.truth.matches.resize(size_t(2 * n));
  for (int i = n; i < 2 * n; ++i) {
    for (int j = 0; j < n; ++j) {
      if (cv::norm(sequence.body_poses[size_t(i)].center - sequence.body_poses[size_t(j)].center) <=
          o.revisit_radius_m) {
        sequence.truth.matches[size_t(i)].push_back(j);
      }
    }
  }

  for (const CameraPose& body : sequence.body_poses) {
    std::vector<RenderedFrame> views;
    for (const RigCamera& camera : sequence.cameras) {
      RECOG_ASSIGN_OR_RETURN(RenderedFrame view, RenderPlanes(scene, camera.K, camera.size,
                                                              CameraInWorld(body, camera), 0.0));
      views.push_back(std::move(view));
    }
    sequence.frames.push_back(std::move(views));
    if (progress) progress(sequence.frames.size(), sequence.body_poses.size());
  }
  return sequence;
}

Status WriteRigSequence(const RigSequence& sequence, bool depth, const std::string& dir) {
  RECOG_RETURN_IF_ERROR(PrepareOutputFolder(dir));
  const fs::path root(dir);
  std::error_code ec;
  for (size_t c = 0; c < sequence.cameras.size(); ++c) {
    const fs::path folder = root / sequence.cameras[c].name;
    fs::create_directories(folder / "rgb", ec);
    if (depth && !ec) fs::create_directories(folder / "depth", ec);
    if (ec) return Status::Internal("cannot create '" + folder.string() + "': " + ec.message());
    std::string rgb_list = "# timestamp filename\n", depth_list = "# timestamp filename\n";
    for (size_t i = 0; i < sequence.frames.size(); ++i) {
      char name[32], stamp[32];
      std::snprintf(name, sizeof(name), "%06zu.png", i);
      std::snprintf(stamp, sizeof(stamp), "%.6f", sequence.timestamps[i]);
      const RenderedFrame& view = sequence.frames[i][c];
      RECOG_RETURN_IF_ERROR(WriteImage((folder / "rgb" / name).string(), view.image));
      rgb_list += std::string(stamp) + " rgb/" + name + "\n";
      if (depth) {
        cv::Mat tum_depth;
        view.depth_mm.convertTo(tum_depth, CV_16U, 5.0);  // TUM: 5000 units per metre
        RECOG_RETURN_IF_ERROR(WriteImage((folder / "depth" / name).string(), tum_depth));
        depth_list += std::string(stamp) + " depth/" + name + "\n";
      }
    }
    RECOG_RETURN_IF_ERROR(WriteLines(folder / "rgb.txt", rgb_list));
    if (depth) RECOG_RETURN_IF_ERROR(WriteLines(folder / "depth.txt", depth_list));
  }
  std::string poses = "# timestamp tx ty tz qx qy qz qw (world_from_body)\n";
  for (size_t i = 0; i < sequence.body_poses.size(); ++i) {
    const CameraPose& body = sequence.body_poses[i];
    Eigen::Matrix3d R;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) R(r, c) = body.world_from_camera(r, c);
    }
    const Eigen::Quaterniond q(R);
    char line[256];
    std::snprintf(line, sizeof(line), "%.6f %.6f %.6f %.6f %.9f %.9f %.9f %.9f\n",
                  sequence.timestamps[i], body.center[0], body.center[1], body.center[2], q.x(),
                  q.y(), q.z(), q.w());
    poses += line;
  }
  RECOG_RETURN_IF_ERROR(WriteLines(root / "body_poses.txt", poses));
  RECOG_RETURN_IF_ERROR(
      WriteDenseGroundTruth(sequence.truth, (root / "ground_truth.txt").string()));
  return WriteRigFile(sequence.cameras, (root / "rig.yaml").string());
}

}  // namespace recog::cli
