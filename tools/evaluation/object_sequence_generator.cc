#include "tools/evaluation/object_sequence_generator.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <random>
#include <sstream>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/names.h"
#include "tools/evaluation/synthetic_images.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

// Independent random streams derived from the one seed.
enum ObjectStream : uint64_t { kPhotoStream = 11, kTrajectoryStream = 12, kShotStream = 13 };

constexpr double kDeg = std::numbers::pi / 180;
constexpr double kWallGap = 1.0;                 // metres between the object's back and the wall
constexpr int kTileCols = 400, kTileRows = 300;  // texels of one wall photo
constexpr int kFaceTextureSide = 480;            // long side of a face image, pixels
constexpr double kTrainingFraction = 0.15;
constexpr int kWalls = 2;  // 0: the sequence, 1: the training walk

struct Wall {
  cv::Mat texture;        // 3 x 3 tiles, BGR
  double metres = 0;      // per texel
  double x0 = 0, y0 = 0;  // object-frame (x, y) of texel (0, 0)
};

std::vector<BoxSide> ShapeSides(ObjectShape shape) {
  if (shape == ObjectShape::kPoster) return {BoxSide::kFront};
  return {BoxSide::kFront, BoxSide::kLeft, BoxSide::kRight, BoxSide::kTop};
}

std::string_view SideName(BoxSide side) {
  switch (side) {
    case BoxSide::kFront:
      return "front";
    case BoxSide::kBack:
      return "back";
    case BoxSide::kLeft:
      return "left";
    case BoxSide::kRight:
      return "right";
    case BoxSide::kTop:
      return "top";
    case BoxSide::kBottom:
      return "bottom";
  }
  return "front";
}

double ObjectDepth(const ObjectSequenceOptions& o) {
  return o.shape == ObjectShape::kBox ? o.depth : 0.0;
}

// The object's corners (4 for a poster, 8 for a box), object frame.
std::vector<cv::Vec3d> Corners(const ObjectSequenceOptions& o) {
  const double w = o.width / 2, h = o.height / 2, d = ObjectDepth(o) / 2;
  std::vector<cv::Vec3d> corners;
  for (double z : d > 0 ? std::vector<double>{-d, d} : std::vector<double>{0.0}) {
    for (double y : {-h, h}) {
      for (double x : {-w, w}) corners.push_back({x, y, z});
    }
  }
  return corners;
}

// Area (pixels) of the convex hull of the corners projected with camera_from_object; -1 when a
// corner is closer than 5 cm to the camera plane.
double SilhouetteArea(const std::vector<cv::Vec3d>& corners, const CameraIntrinsics& camera,
                      const RigidTransform& pose) {
  std::vector<cv::Point2f> pixels;
  for (const cv::Vec3d& x : corners) {
    const cv::Vec3d p = pose.R * x + pose.t;
    if (p[2] < 0.05) return -1;
    pixels.emplace_back(float(camera.fx * p[0] / p[2] + camera.cx),
                        float(camera.fy * p[1] / p[2] + camera.cy));
  }
  std::vector<cv::Point2f> hull;
  cv::convexHull(pixels, hull);
  return cv::contourArea(hull);
}

// The camera looking at the object from (azimuth, elevation) (radians; camera on the front side,
// elevation above it), rolled about its axis, with the object's origin at pixel offset (du, dv)
// from the principal point, `distance` metres away.
RigidTransform LookAt(const CameraIntrinsics& camera, double azimuth, double elevation, double roll,
                      double du, double dv, double distance) {
  const cv::Vec3d away(std::sin(azimuth) * std::cos(elevation), -std::sin(elevation),
                       -std::cos(azimuth) * std::cos(elevation));  // object to camera
  const cv::Vec3d z = -away;
  cv::Vec3d x = cv::Vec3d(0, 1, 0).cross(z);
  x /= cv::norm(x);
  const cv::Vec3d y = z.cross(x);
  const cv::Matx33d look(x[0], x[1], x[2], y[0], y[1], y[2], z[0], z[1], z[2]);
  const cv::Matx33d spin(std::cos(roll), -std::sin(roll), 0, std::sin(roll), std::cos(roll), 0, 0,
                         0, 1);
  cv::Vec3d ray(du / camera.fx, dv / camera.fy, 1);
  ray /= cv::norm(ray);
  cv::Matx33d turn = cv::Matx33d::eye();
  const cv::Vec3d axis = cv::Vec3d(0, 0, 1).cross(ray);
  if (cv::norm(axis) > 1e-12) {
    cv::Rodrigues(axis / cv::norm(axis) * std::acos(std::clamp(ray[2], -1.0, 1.0)), turn);
  }
  RigidTransform pose;
  pose.R = turn * spin * look;
  pose.t = distance * ray;  // -R * (distance * away)
  return pose;
}

// The distance at which the silhouette covers `area` pixels for the other LookAt arguments.
RigidTransform LookAtArea(const ObjectSequenceOptions& o, const CameraIntrinsics& camera,
                          double azimuth, double elevation, double roll, double du, double dv,
                          double area) {
  const std::vector<cv::Vec3d> corners = Corners(o);
  double distance = camera.fx * std::sqrt(o.width * o.height / area);
  for (int k = 0; k < 30; ++k) {
    const double a =
        SilhouetteArea(corners, camera, LookAt(camera, azimuth, elevation, roll, du, dv, distance));
    if (a < 0) {
      distance *= 1.5;
      continue;
    }
    const double step = std::sqrt(a / area);
    distance *= step;
    if (std::abs(step - 1) < 1e-6) break;
  }
  return LookAt(camera, azimuth, elevation, roll, du, dv, distance);
}

cv::Mat CropToAspect(const cv::Mat& photo, double aspect) {  // aspect = width / height
  cv::Rect roi(0, 0, photo.cols, photo.rows);
  if (double(photo.cols) / photo.rows > aspect) {
    roi.width = std::max(1, int(std::lround(photo.rows * aspect)));
    roi.x = (photo.cols - roi.width) / 2;
  } else {
    roi.height = std::max(1, int(std::lround(photo.cols / aspect)));
    roi.y = (photo.rows - roi.height) / 2;
  }
  return photo(roi);
}

cv::Mat ToBgr(const cv::Mat& image) {
  if (image.channels() == 3) return image;
  cv::Mat bgr;
  cv::cvtColor(image, bgr, cv::COLOR_GRAY2BGR);
  return bgr;
}

std::string FrameName(int i) {
  char name[32];
  std::snprintf(name, sizeof(name), "%06d.png", i + 1);
  return name;
}

std::string PoseText(const RigidTransform& pose) {
  std::ostringstream out;
  out.precision(10);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) out << pose.R(r, c) << ' ';
  }
  out << pose.t[0] << ' ' << pose.t[1] << ' ' << pose.t[2];
  return out.str();
}

}  // namespace

struct ObjectSequenceGenerator::Scene {
  std::array<Wall, kWalls> walls;
  double wall_z = 0;  // object-frame z of the wall plane
};

std::string_view ObjectShapeName(ObjectShape shape) {
  return shape == ObjectShape::kBox ? "box" : "poster";
}

StatusOr<ObjectShape> ParseObjectShape(std::string_view name) {
  if (name == "poster") return ObjectShape::kPoster;
  if (name == "box") return ObjectShape::kBox;
  return Status::InvalidArgument("unknown object shape '" + std::string(name) + "' (poster, box)");
}

std::string ObjectSequenceOptions::ObjectName() const {
  return name.empty() ? "synthetic-" + std::string(ObjectShapeName(shape)) : name;
}

Status ObjectSequenceOptions::Validate() const {
  RECOG_RETURN_IF_ERROR(CheckRange("object width (m)", width, 0.01, 10));
  RECOG_RETURN_IF_ERROR(CheckRange("object height (m)", height, 0.01, 10));
  if (shape == ObjectShape::kBox)
    RECOG_RETURN_IF_ERROR(CheckRange("box depth (m)", depth, 0.01, 10));
  if (frames < 2 || frames > 1'000'000) {
    return Status::InvalidArgument("frames = " + std::to_string(frames) +
                                   " is outside [2, 1000000]");
  }
  if (training_views < 1 || training_views > 1000) {
    return Status::InvalidArgument("training views = " + std::to_string(training_views) +
                                   " is outside [1, 1000]");
  }
  if (image_width < 64 || image_width > 8192 || image_height < 64 || image_height > 8192) {
    return Status::InvalidArgument("frame size " + std::to_string(image_width) + "x" +
                                   std::to_string(image_height) + " is outside 64..8192 pixels");
  }
  RECOG_RETURN_IF_ERROR(CheckRange("focal length (px)", focal, 50, 20000));
  RECOG_RETURN_IF_ERROR(CheckRange("largest size fraction", max_fraction, 0.0005, 0.6));
  RECOG_RETURN_IF_ERROR(CheckRange("smallest size fraction", min_fraction, 0.0005, max_fraction));
  RECOG_RETURN_IF_ERROR(CheckRange("blur sigma", blur_sigma_max, 0, 20));
  RECOG_RETURN_IF_ERROR(CheckRange("noise sigma", noise_sigma, 0, 100));
  RECOG_RETURN_IF_ERROR(CheckRange("illumination change", illumination_max, 0, 0.5));
  RECOG_RETURN_IF_ERROR(CheckRange("depth noise (mm)", depth_noise_mm, 0, 100));
  RECOG_RETURN_IF_ERROR(CheckRange("depth holes", depth_holes, 0, 100));
  return ValidateName("object", ObjectName());
}

StatusOr<ObjectSequenceGenerator> ObjectSequenceGenerator::Create(
    const std::vector<std::string>& object_photos,
    const std::vector<std::string>& background_photos, const ObjectSequenceOptions& options) {
  RECOG_RETURN_IF_ERROR(options.Validate());
  const std::vector<BoxSide> sides = ShapeSides(options.shape);
  if (object_photos.size() < sides.size()) {
    return Status::InvalidArgument("a " + std::string(ObjectShapeName(options.shape)) + " needs " +
                                   std::to_string(sides.size()) + " object photos, got " +
                                   std::to_string(object_photos.size()));
  }
  if (background_photos.empty()) return Status::InvalidArgument("no background photos");
  for (const std::string& photo : object_photos) {
    if (std::find(background_photos.begin(), background_photos.end(), photo) !=
        background_photos.end()) {
      return Status::InvalidArgument("photo '" + photo +
                                     "' is both an object and a background photo");
    }
  }
  ObjectSequenceGenerator g;
  g.options_ = options;
  const ObjectSequenceOptions& o = g.options_;
  g.camera_.fx = g.camera_.fy = o.focal;
  g.camera_.cx = (o.image_width - 1) / 2.0;
  g.camera_.cy = (o.image_height - 1) / 2.0;

  // Seeded choice of the photos: a Fisher-Yates shuffle of each list.
  std::mt19937_64 rng(StreamSeed(o.seed, kPhotoStream, 0));
  const auto shuffled = [&rng](std::vector<std::string> list) {
    for (size_t i = list.size() - 1; i > 0; --i) std::swap(list[i], list[rng() % (i + 1)]);
    return list;
  };
  const std::vector<std::string> objects = shuffled(object_photos);
  const std::vector<std::string> backgrounds = shuffled(background_photos);
  for (size_t k = 0; k < sides.size(); ++k) {
    ObjectFace face;
    face.side = sides[k];
    face.photo = objects[k];
    g.geometry_.push_back(BoxFace(face.side, o.width, o.height, ObjectDepth(o)));
    const PlanarFace& shape = g.geometry_.back();
    RECOG_ASSIGN_OR_RETURN(cv::Mat photo, ReadPhoto(face.photo));
    const cv::Mat crop = CropToAspect(ToBgr(photo), shape.width / shape.height);
    const double scale = double(kFaceTextureSide) / std::max(crop.cols, crop.rows);
    cv::resize(crop, face.image,
               cv::Size(std::max(1, int(std::lround(crop.cols * scale))),
                        std::max(1, int(std::lround(crop.rows * scale)))),
               0, 0, scale < 1 ? cv::INTER_AREA : cv::INTER_LINEAR);
    g.faces_.push_back(std::move(face));
  }

  // The trajectory of the sequence: slow sines with seeded phases.
  std::mt19937_64 path(StreamSeed(o.seed, kTrajectoryStream, 0));
  std::array<double, 7> phase;
  for (double& p : phase) p = Uniform(path, 0, 2 * std::numbers::pi);
  const double exit_1 = Uniform(path, 0.15, 0.3), exit_2 = Uniform(path, 0.55, 0.75);
  const double exit_side_1 = path() % 2 ? 1 : -1, exit_side_2 = path() % 2 ? 1 : -1;
  const bool box = o.shape == ObjectShape::kBox;
  const double max_azimuth = (box ? 50 : 35) * kDeg;
  const double frame_area = double(o.image_width) * o.image_height;
  const auto shot_effects = [&](Shot* shot, int walk, int index, double s) {
    shot->walk = walk;
    shot->effects_seed = StreamSeed(o.seed, kShotStream, uint64_t(walk) << 32 | uint64_t(index));
    shot->gain =
        1 + 0.75 * o.illumination_max * std::sin(2 * std::numbers::pi * 0.9 * s + phase[5]);
    shot->gradient_x =
        0.5 * o.illumination_max * std::sin(2 * std::numbers::pi * 0.6 * s + phase[6]);
    shot->gradient_y =
        0.25 * o.illumination_max * std::cos(2 * std::numbers::pi * 0.4 * s + phase[6]);
  };
  double far = 0;
  for (int i = 0; i < o.frames; ++i) {
    const double s = double(i) / (o.frames - 1);
    const double two_pi_s = 2 * std::numbers::pi * s;
    const double azimuth = max_azimuth * std::sin(0.8 * two_pi_s + phase[0]);
    const double elevation =
        (box ? 20 : 10) * kDeg + 8 * kDeg * std::sin(1.1 * two_pi_s + phase[1]);
    const double roll = 8 * kDeg * std::sin(0.7 * two_pi_s + phase[2]);
    const auto bump = [s](double centre) {
      return std::exp(-((s - centre) / 0.03) * ((s - centre) / 0.03));
    };
    const double du =
        o.image_width * (0.18 * std::sin(1.5 * two_pi_s + phase[3]) +
                         0.75 * (exit_side_1 * bump(exit_1) + exit_side_2 * bump(exit_2)));
    const double dv = o.image_height * 0.12 * std::sin(1.2 * two_pi_s + phase[4]);
    const double fraction = o.max_fraction * std::pow(o.min_fraction / o.max_fraction, s);
    Shot shot;
    shot.camera_from_object =
        LookAtArea(o, g.camera_, azimuth, elevation, roll, du, dv, fraction * frame_area);
    shot_effects(&shot, 0, i, s);
    far = std::max(far, cv::norm(shot.camera_from_object.t));
    g.frames_.push_back(shot);
  }
  // The training walk: the object centred at kTrainingFraction, azimuth evenly spread.
  for (int k = 0; k < o.training_views; ++k) {
    const double s = o.training_views > 1 ? double(k) / (o.training_views - 1) : 0.5;
    Shot shot;
    shot.camera_from_object =
        LookAtArea(o, g.camera_, max_azimuth * (2 * s - 1), (box ? 25 : 10) * kDeg, 0, 0, 0,
                   std::min(kTrainingFraction, o.max_fraction) * frame_area);
    shot_effects(&shot, 1, k, s);
    shot.effects = false;
    far = std::max(far, cv::norm(shot.camera_from_object.t));
    g.training_.push_back(shot);
  }

  // Walls wide enough for the farthest view (mirrored beyond, so any size would do).
  auto scene = std::make_shared<Scene>();
  scene->wall_z = ObjectDepth(o) / 2 + kWallGap;
  const double wall_width = 2.0 * (far + scene->wall_z) * o.image_width / o.focal;
  for (int w = 0; w < kWalls; ++w) {
    Wall& wall = scene->walls[size_t(w)];
    wall.texture.create(3 * kTileRows, 3 * kTileCols, CV_8UC3);
    for (int t = 0; t < 9; ++t) {
      const std::string& path = backgrounds[size_t(w * 9 + t) % backgrounds.size()];
      RECOG_ASSIGN_OR_RETURN(cv::Mat photo, ReadPhoto(path));
      const cv::Mat crop = CropToAspect(ToBgr(photo), double(kTileCols) / kTileRows);
      cv::resize(
          crop,
          wall.texture(cv::Rect((t % 3) * kTileCols, (t / 3) * kTileRows, kTileCols, kTileRows)),
          cv::Size(kTileCols, kTileRows), 0, 0, cv::INTER_AREA);
    }
    wall.metres = wall_width / wall.texture.cols;
    wall.x0 = -wall_width / 2;
    wall.y0 = -wall.metres * wall.texture.rows / 2;
  }
  g.scene_ = std::move(scene);
  return g;
}

StatusOr<RenderedObjectFrame> ObjectSequenceGenerator::Frame(int i) const {
  if (i < 0 || i >= num_frames()) {
    return Status::InvalidArgument("frame " + std::to_string(i) + " is outside 0.." +
                                   std::to_string(num_frames() - 1));
  }
  RECOG_ASSIGN_OR_RETURN(RenderedObjectFrame frame, Render(frames_[size_t(i)]));
  frame.truth.image = FrameName(i);
  return frame;
}

StatusOr<RenderedObjectFrame> ObjectSequenceGenerator::TrainingView(int k) const {
  if (k < 0 || k >= int(training_.size())) {
    return Status::InvalidArgument("training view " + std::to_string(k) + " is outside 0.." +
                                   std::to_string(int(training_.size()) - 1));
  }
  return Render(training_[size_t(k)]);
}

StatusOr<RenderedObjectFrame> ObjectSequenceGenerator::Render(const Shot& shot) const {
  const ObjectSequenceOptions& o = options_;
  const cv::Size size(o.image_width, o.image_height);
  const cv::Matx33d K = camera_.K();
  const RigidTransform& pose = shot.camera_from_object;
  RenderedObjectFrame frame;
  frame.truth.camera_from_object = pose;

  // The wall: a textured plane, mirrored beyond its tiles.
  const Wall& wall = scene_->walls[size_t(shot.walk)];
  const auto plane_homography = [&K](const RigidTransform& camera_from_plane) {
    // Plane point (x, y, 0) -> pixel.
    const cv::Matx33d& R = camera_from_plane.R;
    const cv::Vec3d& t = camera_from_plane.t;
    return K * cv::Matx33d(R(0, 0), R(0, 1), t[0], R(1, 0), R(1, 1), t[1], R(2, 0), R(2, 1), t[2]);
  };
  RigidTransform object_from_wall;
  object_from_wall.t = {0, 0, scene_->wall_z};
  const RigidTransform camera_from_wall = pose * object_from_wall;
  const cv::Matx33d wall_texels(wall.metres, 0, wall.x0, 0, wall.metres, wall.y0, 0, 0, 1);
  cv::warpPerspective(wall.texture, frame.image,
                      cv::Mat(plane_homography(camera_from_wall) * wall_texels), size,
                      cv::INTER_LINEAR, cv::BORDER_REFLECT);

  // Depth by ray casting: the wall, then the faces that face the camera (the object is convex,
  // so at most one of those covers a pixel).
  cv::Mat1f depth(size, std::numeric_limits<float>::infinity());
  cv::Mat1b face_of(size, uint8_t(255));
  const auto cast = [&](const RigidTransform& camera_from_plane, double width, double height,
                        uint8_t id) {
    const cv::Vec3d n(camera_from_plane.R(0, 2), camera_from_plane.R(1, 2),
                      camera_from_plane.R(2, 2));
    const double c = n.dot(camera_from_plane.t);
    const cv::Matx33d to_plane = plane_homography(camera_from_plane).inv();
    for (int v = 0; v < size.height; ++v) {
      float* z_row = depth.ptr<float>(v);
      uint8_t* id_row = face_of.ptr<uint8_t>(v);
      const double ry = (v - camera_.cy) / camera_.fy;
      for (int u = 0; u < size.width; ++u) {
        const double rx = (u - camera_.cx) / camera_.fx;
        const double z = c / (n[0] * rx + n[1] * ry + n[2]);
        if (!(z > 0)) continue;
        if (id != 254) {
          const cv::Vec3d q = to_plane * cv::Vec3d(u, v, 1);
          const double x = q[0] / q[2], y = q[1] / q[2];
          if (x < 0 || x > width || y < 0 || y > height || z >= z_row[u]) continue;
        }
        z_row[u] = float(z);
        id_row[u] = id;
      }
    }
  };
  cast(camera_from_wall, 0, 0, 254);
  face_of.setTo(255);
  const cv::Vec3d camera_centre = -(pose.R.t() * pose.t);  // object frame
  for (size_t f = 0; f < faces_.size(); ++f) {
    const PlanarFace& face = geometry_[f];
    const RigidTransform& object_from_face = face.object_from_face;
    const cv::Vec3d outward =
        -cv::Vec3d(object_from_face.R(0, 2), object_from_face.R(1, 2), object_from_face.R(2, 2));
    if ((camera_centre - object_from_face.t).dot(outward) <= 0) continue;
    const RigidTransform camera_from_face = pose * object_from_face;
    cast(camera_from_face, face.width, face.height, uint8_t(f));

    // The face's photo: shrunk first when it has more texels than the face gets pixels.
    const cv::Mat& texture = faces_[f].image;
    const cv::Matx33d to_pixels = plane_homography(camera_from_face);
    std::vector<cv::Point2f> corners;
    for (const cv::Vec3d& c :
         {cv::Vec3d(0, 0, 1), cv::Vec3d(face.width, 0, 1), cv::Vec3d(face.width, face.height, 1),
          cv::Vec3d(0, face.height, 1)}) {
      const cv::Vec3d p = to_pixels * c;
      corners.emplace_back(float(p[0] / p[2]), float(p[1] / p[2]));
    }
    const double texels_per_pixel =
        std::sqrt(double(texture.total()) / std::max(1.0, cv::contourArea(corners)));
    cv::Mat shrunk = texture;
    if (texels_per_pixel > 1.5) {
      cv::resize(texture, shrunk,
                 cv::Size(std::max(2, int(std::lround(texture.cols / texels_per_pixel))),
                          std::max(2, int(std::lround(texture.rows / texels_per_pixel)))),
                 0, 0, cv::INTER_AREA);
    }
    // Original pixel u is face x = u * width / cols; shrunk pixel u' is original (u' + 0.5) k -
    // 0.5.
    const double kx = double(texture.cols) / shrunk.cols, ky = double(texture.rows) / shrunk.rows;
    const double sx = face.width / texture.cols, sy = face.height / texture.rows;
    const cv::Matx33d texels(kx * sx, 0, (0.5 * kx - 0.5) * sx, 0, ky * sy, (0.5 * ky - 0.5) * sy,
                             0, 0, 1);
    cv::Mat warped;
    cv::warpPerspective(shrunk, warped, cv::Mat(to_pixels * texels), size, cv::INTER_LINEAR,
                        cv::BORDER_REPLICATE);
    warped.copyTo(frame.image, face_of == uint8_t(f));
  }
  frame.mask = face_of < 254;
  frame.mask.setTo(255, frame.mask);

  // Depth in millimetres: exact on the object, noisy on the wall, a few holes.
  std::mt19937_64 rng(shot.effects_seed);
  cv::Mat1f noise(size, 0.0f);
  if (o.depth_noise_mm > 0) {
    cv::RNG depth_rng(rng());
    depth_rng.fill(noise, cv::RNG::NORMAL, 0.0, o.depth_noise_mm);
  }
  frame.depth.create(size, CV_16U);
  for (int v = 0; v < size.height; ++v) {
    const float* z = depth.ptr<float>(v);
    const float* n = noise.ptr<float>(v);
    const uint8_t* on_object = frame.mask.ptr<uint8_t>(v);
    uint16_t* out = frame.depth.ptr<uint16_t>(v);
    for (int u = 0; u < size.width; ++u) {
      const double mm = 1000.0 * z[u] + (on_object[u] ? 0.0 : n[u]);  // inf: no wall there
      out[u] = std::isfinite(mm) ? uint16_t(std::lround(std::clamp(mm, 1.0, 65535.0))) : 0;
    }
  }
  for (int h = 0; h < o.depth_holes; ++h) {
    const cv::Point centre(int(Uniform(rng, 0, size.width)), int(Uniform(rng, 0, size.height)));
    cv::circle(frame.depth, centre, int(Uniform(rng, 2, 7)), cv::Scalar(0), cv::FILLED);
  }

  // Camera effects on the colour image.
  if (shot.effects) {
    CameraEffects effects;
    effects.blur_sigma = Uniform(rng, 0, o.blur_sigma_max);
    effects.gain = shot.gain * (1 + Symmetric(rng, 0.25 * o.illumination_max));
    effects.gradient_x = shot.gradient_x;
    effects.gradient_y = shot.gradient_y;
    effects.noise_sigma = o.noise_sigma;
    effects.noise_seed = rng();
    ApplyCameraEffects(effects, &frame.image);
  }

  // Truth: how much of the frame the object covers and how much of it is inside the frame.
  const double pixels = cv::countNonZero(frame.mask);
  const double silhouette = SilhouetteArea(Corners(o), camera_, pose);
  frame.truth.area_fraction = pixels / double(size.area());
  frame.truth.in_view = silhouette > 0 ? std::min(1.0, pixels / silhouette) : 0.0;
  frame.truth.visible = frame.truth.in_view >= 0.5;
  return frame;
}

Status WriteObjectSequenceTruth(const ObjectSequenceTruth& truth, const std::string& path) {
  std::ofstream out(path);
  if (!out) return Status::Internal("cannot write '" + path + "'");
  out.precision(10);
  out << "# recog object sequence ground truth (recog seqgen objects); pose T_camera<-object, m\n"
      << "object " << truth.object << "\ncamera " << truth.camera.fx << ' ' << truth.camera.fy
      << ' ' << truth.camera.cx << ' ' << truth.camera.cy << "\nimage_size " << truth.width << ' '
      << truth.height << "\n"
      << "# frame IMAGE VISIBLE AREA_FRACTION IN_VIEW r11 r12 r13 r21 r22 r23 r31 r32 r33 t1 t2 "
         "t3\n";
  for (const ObjectTruthFrame& f : truth.frames) {
    out << "frame " << f.image << ' ' << int(f.visible) << ' ' << f.area_fraction << ' '
        << f.in_view << ' ' << PoseText(f.camera_from_object) << '\n';
  }
  out.close();
  if (!out) return Status::Internal("cannot write '" + path + "'");
  return Status::Ok();
}

StatusOr<ObjectSequenceTruth> ReadObjectSequenceTruth(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Status::NotFound("truth file '" + path + "' cannot be read");
  ObjectSequenceTruth truth;
  std::string line;
  int number = 0;
  bool has_camera = false;
  while (std::getline(in, line)) {
    ++number;
    std::istringstream fields(line);
    std::string key;
    if (!(fields >> key) || key[0] == '#') continue;
    const auto bad = [&](const std::string& what) {
      return Status::InvalidArgument(path + ":" + std::to_string(number) + ": " + what);
    };
    if (key == "object") {
      if (!(fields >> truth.object)) return bad("object needs a name");
    } else if (key == "camera") {
      if (!(fields >> truth.camera.fx >> truth.camera.fy >> truth.camera.cx >> truth.camera.cy)) {
        return bad("camera needs fx fy cx cy");
      }
      if (Status s = truth.camera.Validate(); !s.ok()) return bad(s.message());
      has_camera = true;
    } else if (key == "image_size") {
      if (!(fields >> truth.width >> truth.height) || truth.width <= 0 || truth.height <= 0) {
        return bad("image_size needs a positive width and height");
      }
    } else if (key == "frame") {
      ObjectTruthFrame f;
      int visible = 0;
      fields >> f.image >> visible >> f.area_fraction >> f.in_view;
      for (int k = 0; k < 9; ++k) fields >> f.camera_from_object.R.val[k];
      for (int k = 0; k < 3; ++k) fields >> f.camera_from_object.t[k];
      std::string extra;
      if (!fields || (visible != 0 && visible != 1) || (fields >> extra)) {
        return bad("frame needs IMAGE VISIBLE(0/1) AREA_FRACTION IN_VIEW and 12 pose numbers");
      }
      f.visible = visible == 1;
      truth.frames.push_back(std::move(f));
    } else {
      return bad("unknown key '" + key + "'");
    }
  }
  if (truth.object.empty() || !has_camera || truth.frames.empty()) {
    return Status::InvalidArgument("truth file '" + path +
                                   "' needs an object, a camera and at least one frame");
  }
  return truth;
}

StatusOr<ObjectSequenceWriteResult> WriteObjectSequence(
    const ObjectSequenceGenerator& generator, const std::string& out_dir,
    const std::function<void(uint64_t, uint64_t)>& progress) {
  RECOG_RETURN_IF_ERROR(PrepareOutputFolder(out_dir));
  const fs::path root(out_dir);
  for (const char* dir : {"images", "depth", "masks", "faces", "train"}) {
    std::error_code ec;
    fs::create_directories(root / dir, ec);
    if (ec) return Status::Internal("cannot create '" + (root / dir).string() + "'");
  }
  const ObjectSequenceOptions& o = generator.options();
  const CameraIntrinsics& camera = generator.camera();
  const uint64_t total = uint64_t(o.frames + o.training_views);
  uint64_t done = 0;
  ObjectSequenceWriteResult result;
  result.min_fraction = 1;

  // The faces, and the commands that build a model from them.
  std::ostringstream face_args;
  face_args.precision(6);
  for (const ObjectFace& face : generator.faces()) {
    const std::string name = "faces/" + std::string(SideName(face.side)) + ".png";
    RECOG_RETURN_IF_ERROR(WriteImage((root / name).string(), face.image));
    face_args << (o.shape == ObjectShape::kPoster
                      ? " --planar "
                      : " --face " + std::string(SideName(face.side)) + "=")
              << name;
  }
  face_args << " --width " << o.width << " --height " << o.height;
  if (o.shape == ObjectShape::kBox) face_args << " --depth " << o.depth;

  // The training walk and views.txt.
  result.views_path = (root / "views.txt").string();
  std::ofstream views(result.views_path);
  views.precision(10);
  views
      << "# rgb depth fx fy cx cy depth_scale r11..r33 t1 t2 t3 mask (recog model build --rgbd)\n";
  for (int k = 0; k < o.training_views; ++k) {
    RECOG_ASSIGN_OR_RETURN(const RenderedObjectFrame view, generator.TrainingView(k));
    char stem[16];
    std::snprintf(stem, sizeof(stem), "%02d.png", k + 1);
    const std::string rgb = "train/rgb_" + std::string(stem),
                      depth = "train/depth_" + std::string(stem),
                      mask = "train/mask_" + std::string(stem);
    RECOG_RETURN_IF_ERROR(WriteImage((root / rgb).string(), view.image));
    RECOG_RETURN_IF_ERROR(WriteImage((root / depth).string(), view.depth));
    RECOG_RETURN_IF_ERROR(WriteImage((root / mask).string(), view.mask));
    views << rgb << ' ' << depth << ' ' << camera.fx << ' ' << camera.fy << ' ' << camera.cx << ' '
          << camera.cy << " 1000 " << PoseText(view.truth.camera_from_object) << ' ' << mask
          << '\n';
    if (progress) progress(++done, total);
  }
  views.close();
  if (!views) return Status::Internal("cannot write '" + result.views_path + "'");

  // The sequence.
  ObjectSequenceTruth truth;
  truth.object = o.ObjectName();
  truth.camera = camera;
  truth.width = o.image_width;
  truth.height = o.image_height;
  for (int i = 0; i < o.frames; ++i) {
    RECOG_ASSIGN_OR_RETURN(const RenderedObjectFrame frame, generator.Frame(i));
    const std::string name = frame.truth.image;
    RECOG_RETURN_IF_ERROR(WriteImage((root / "images" / name).string(), frame.image));
    RECOG_RETURN_IF_ERROR(WriteImage((root / "depth" / name).string(), frame.depth));
    RECOG_RETURN_IF_ERROR(WriteImage((root / "masks" / name).string(), frame.mask));
    if (frame.truth.visible) {
      ++result.visible_frames;
      result.min_fraction = std::min(result.min_fraction, frame.truth.area_fraction);
      result.max_fraction = std::max(result.max_fraction, frame.truth.area_fraction);
    }
    truth.frames.push_back(frame.truth);
    if (progress) progress(++done, total);
  }
  result.frames = o.frames;
  result.truth_path = (root / "truth.txt").string();
  RECOG_RETURN_IF_ERROR(WriteObjectSequenceTruth(truth, result.truth_path));

  // README.txt: every file and the commands.
  result.readme_path = (root / "README.txt").string();
  std::ofstream readme(result.readme_path);
  readme.precision(10);
  const std::string name = o.ObjectName();
  char camera_arg[128];
  std::snprintf(camera_arg, sizeof(camera_arg), "%.6g,%.6g,%.6g,%.6g", camera.fx, camera.fy,
                camera.cx, camera.cy);
  readme << "Synthetic object sequence (recog seqgen objects), seed " << o.seed << ".\n\n"
         << "Object '" << name << "': a " << ObjectShapeName(o.shape) << " of " << o.width << " x "
         << o.height;
  if (o.shape == ObjectShape::kBox) readme << " x " << o.depth;
  readme
      << " m (object frame at its centre, x right, y down, z away from the viewer of the front).\n"
      << "Camera: pinhole, no distortion, " << o.image_width << "x" << o.image_height
      << ", fx = fy = " << camera.fx << ", cx = " << camera.cx << ", cy = " << camera.cy
      << " (pixel centres at integer coordinates).\n"
      << o.frames << " frames, object area from " << o.max_fraction * 100 << " % to "
      << o.min_fraction * 100 << " % of the frame (whole silhouette), " << result.visible_frames
      << " frames with at least half of it in view.\n\n"
      << "Files:\n"
      << "  images/NNNNNN.png  colour frames (8-bit BGR)\n"
      << "  depth/NNNNNN.png   registered depth, 16-bit millimetres, 0 = no depth\n"
      << "  masks/NNNNNN.png   the object's mask (255 on the object)\n"
      << "  truth.txt          per frame: visible, area fraction, in-view fraction, "
         "T_camera<-object (R row-major, t in metres)\n"
      << "  faces/SIDE.png     the object's face images (for recog model build)\n"
      << "  train/{rgb,depth,mask}_NN.png  a separate walk around the object\n"
      << "  views.txt          those training views for recog model build --rgbd\n\n"
      << "Commands (run in this folder):\n"
      << "  recog model build" << face_args.str() << " --name " << name << " -o " << name
      << ".robj\n"
      << "  recog model build --rgbd views.txt --name " << name << " -o " << name << "_rgbd.robj\n"
      << "  recog eval sequence --models " << name << ".robj --images images --camera "
      << camera_arg << " --expect " << name
      << " --truth truth.txt --size-recall size_recall   # writes size_recall.csv and .png\n";
  readme.close();
  if (!readme) return Status::Internal("cannot write '" + result.readme_path + "'");
  return result;
}

}  // namespace recog::cli
