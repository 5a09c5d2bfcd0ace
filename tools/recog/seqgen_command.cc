// recog seqgen: a long synthetic image sequence with exact loop ground truth, from real photos;
// recog seqgen objects: an RGB-D sequence of one object with exact pose ground truth;
// recog seqgen rig: a front + rear camera rig driven out and back the other way;
// recog seqgen lens: a folder of pinhole images as a given lens would have taken them.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <random>
#include <string>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tools/common/cli_support.h"
#include "tools/evaluation/camera_calibration.h"
#include "tools/evaluation/lens_warp.h"
#include "tools/evaluation/object_sequence_generator.h"
#include "tools/evaluation/rig_file.h"
#include "tools/evaluation/rig_sequence.h"
#include "tools/evaluation/sequence_generator.h"
#include "tools/evaluation/synthetic_images.h"
#include "tools/recog/commands.h"

namespace recog::cli {
namespace {

// --blur, --noise and --illumination, the camera effects both generators share.
void AddCameraEffectOptions(CLI::App* cmd, double* blur_sigma_max, double* noise_sigma,
                            double* illumination_max) {
  cmd->add_option("--blur", *blur_sigma_max, "Largest Gaussian blur sigma")->capture_default_str();
  cmd->add_option("--noise", *noise_sigma, "Gaussian noise sigma (grey levels)")
      ->capture_default_str();
  cmd->add_option("--illumination", *illumination_max, "Relative illumination change")
      ->capture_default_str();
}

struct SeqgenArgs {
  std::string images;
  std::string output;
  SequenceOptions options;
  std::string format = "png";
  bool allow_duplicate_places = false;
  bool sparse_truth = false;
  bool json = false;
  bool quiet = false;
};

int RunSeqgen(const SeqgenArgs& args) {
  if (args.images.empty() || args.output.empty()) {
    return Fail("seqgen", Status::InvalidArgument("--images and --output are required"));
  }
  const auto start = std::chrono::steady_clock::now();
  auto format = ParseSequenceImageFormat(args.format);
  if (!format.ok()) return Fail("seqgen", format.status());
  SequenceOptions options = args.options;
  options.distinct_places = !args.allow_duplicate_places;
  if (Status s = options.Validate(); !s.ok()) return Fail("seqgen", s);
  auto photos = ListImages(args.images);
  if (!photos.ok()) return Fail("seqgen", photos.status());
  const size_t num_photos = photos->size();
  const auto choose_start = std::chrono::steady_clock::now();
  auto generator = SequenceGenerator::Create(std::move(photos).value(), options);
  if (!generator.ok()) return Fail("seqgen", generator.status());
  // Time spent choosing the place photos (the distinct-places check).
  const double choose_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - choose_start).count();

  ProgressBar progress(!args.quiet && !args.json);
  auto written =
      WriteSequence(*generator, args.output, args.sparse_truth, *format,
                    [&](uint64_t done, uint64_t total) { progress.Update("frames", done, total); });
  progress.Finish();
  if (!written.ok()) return Fail("seqgen", written.status());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const int used_photos = int(generator->photos().size());
  const SequenceOptions& o = generator->options();

  if (args.json) {
    nlohmann::json skipped = nlohmann::json::array();
    for (const SkippedPhoto& p : generator->skipped()) {
      skipped.push_back({{"photo", p.photo},
                         {"same_as_place", p.same_as_place},
                         {"same_as_photo", generator->PlacePhoto(p.same_as_place)},
                         {"inliers", p.inliers}});
    }
    nlohmann::json j = {
        {"frames", written->frames},
        {"places", generator->num_places()},
        {"revisits", generator->num_revisits()},
        {"frames_per_place", o.frames_per_place},
        {"photos_found", num_photos},
        {"photos_used", used_photos},
        {"distinct_places", o.distinct_places},
        {"skipped_duplicates", generator->skipped_duplicates()},
        {"skipped_photos", skipped},
        {"choose_seconds", choose_seconds},
        {"queries_with_matches", written->queries_with_matches},
        {"width", o.width},
        {"height", o.height},
        {"seed", o.seed},
        {"image_format", *format == SequenceImageFormat::kJpeg ? "jpg" : "png"},
        {"images", written->images_dir},
        {"ground_truth", written->ground_truth_path},
        {"ground_truth_format", written->sparse_truth ? "sparse" : "dense"},
        {"seconds", seconds},
        {"frames_per_second", seconds > 0 ? written->frames / seconds : 0.0},
    };
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf(
      "wrote %d frames (%dx%d): %d places x %d frames + %d revisits x %d frames, seed %llu\n"
      "query frames with a true match: %d\n"
      "images:       %s\nground truth: %s (%s)\n"
      "time: %.1f s (%.1f frames/s)\n",
      written->frames, o.width, o.height, generator->num_places(), o.frames_per_place,
      generator->num_revisits(), o.frames_per_place, static_cast<unsigned long long>(o.seed),
      written->queries_with_matches, written->images_dir.c_str(),
      written->ground_truth_path.c_str(), written->sparse_truth ? "sparse" : "dense", seconds,
      seconds > 0 ? written->frames / seconds : 0.0);
  if (o.distinct_places) {
    std::printf(
        "distinct places: skipped %d photos showing the scene of an earlier place (%.1f s)\n",
        generator->skipped_duplicates(), choose_seconds);
    constexpr int kListed = 10;
    const std::vector<SkippedPhoto>& skipped = generator->skipped();
    for (size_t k = 0; k < skipped.size() && k < size_t(kListed); ++k) {
      std::printf("  %s ~ %s (%d inliers)\n", skipped[k].photo.c_str(),
                  generator->PlacePhoto(skipped[k].same_as_place).c_str(), skipped[k].inliers);
    }
    if (skipped.size() > size_t(kListed)) {
      std::printf("  ... and %zu more (--json lists them all)\n", skipped.size() - kListed);
    }
  }
  if (used_photos < generator->num_places()) {
    std::printf(
        "note: %d photos for %d places; photos are reused (mirrored on odd cycles), and the ground "
        "truth still treats those places as different\n",
        used_photos, generator->num_places());
  }
  return 0;
}

struct ObjectSeqgenArgs {
  std::string object_photos, background_photos, output, shape = "poster";
  ObjectSequenceOptions options;
  bool json = false, quiet = false;
};

int RunObjectSeqgen(ObjectSeqgenArgs args) {
  const auto fail = [](const Status& status) {
    std::fprintf(stderr, "recog seqgen objects: %s\n", status.ToString().c_str());
    return 1;
  };
  auto shape = ParseObjectShape(args.shape);
  if (!shape.ok()) return fail(shape.status());
  args.options.shape = *shape;
  if (Status s = args.options.Validate(); !s.ok()) return fail(s);
  auto objects = ListImages(args.object_photos);
  if (!objects.ok()) return fail(objects.status().WithContext("--object-photos"));
  auto backgrounds = ListImages(args.background_photos);
  if (!backgrounds.ok()) return fail(backgrounds.status().WithContext("--background-photos"));
  const auto start = std::chrono::steady_clock::now();
  auto generator = ObjectSequenceGenerator::Create(*objects, *backgrounds, args.options);
  if (!generator.ok()) return fail(generator.status());
  ProgressBar progress(!args.quiet && !args.json);
  auto written = WriteObjectSequence(*generator, args.output, [&](uint64_t done, uint64_t total) {
    progress.Update("images", done, total);
  });
  progress.Finish();
  if (!written.ok()) return fail(written.status());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const ObjectSequenceOptions& o = generator->options();
  const CameraIntrinsics& camera = generator->camera();
  nlohmann::json faces = nlohmann::json::array();
  for (const ObjectFace& face : generator->faces()) faces.push_back(face.photo);
  if (args.json) {
    const nlohmann::json j = {
        {"frames", written->frames},
        {"visible_frames", written->visible_frames},
        {"training_views", o.training_views},
        {"object", o.ObjectName()},
        {"shape", std::string(ObjectShapeName(o.shape))},
        {"size_m", {o.width, o.height, o.shape == ObjectShape::kBox ? o.depth : 0.0}},
        {"camera", {camera.fx, camera.fy, camera.cx, camera.cy}},
        {"width", o.image_width},
        {"height", o.image_height},
        {"area_fraction_min", written->min_fraction},
        {"area_fraction_max", written->max_fraction},
        {"face_photos", faces},
        {"seed", o.seed},
        {"truth", written->truth_path},
        {"views", written->views_path},
        {"readme", written->readme_path},
        {"seconds", seconds}};
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf(
      "wrote %d frames (%dx%d, fx = fy = %g, cx = %g, cy = %g) and %d training views of %s '%s', "
      "seed %llu\n"
      "object in view (at least half) in %d frames, covering %.2f %% .. %.2f %% of the frame\n"
      "truth: %s\nviews: %s\ncommands: %s\ntime: %.1f s\n",
      written->frames, o.image_width, o.image_height, camera.fx, camera.cx, camera.cy,
      o.training_views, std::string(ObjectShapeName(o.shape)).c_str(), o.ObjectName().c_str(),
      static_cast<unsigned long long>(o.seed), written->visible_frames, 100 * written->min_fraction,
      100 * written->max_fraction, written->truth_path.c_str(), written->views_path.c_str(),
      written->readme_path.c_str(), seconds);
  return 0;
}

void AddObjectSeqgenCommand(CLI::App& seqgen, int* exit_code) {
  auto args = std::make_shared<ObjectSeqgenArgs>();
  ObjectSequenceOptions& o = args->options;
  CLI::App* cmd = seqgen.add_subcommand(
      "objects",
      "Generate an RGB-D sequence of one object (a poster or a box made of photos) in front of "
      "background photos, with exact poses, masks, training views and a README");
  cmd->add_option("--object-photos", args->object_photos, "Folder of photos for the object's faces")
      ->required();
  cmd->add_option("--background-photos", args->background_photos,
                  "Folder of other photos for the walls behind it")
      ->required();
  cmd->add_option("-o,--output", args->output, "Output folder (must not exist or be empty)")
      ->required();
  cmd->add_option("--shape", args->shape, "poster or box")->capture_default_str();
  cmd->add_option("--name", o.name, "Object name (default: the shape)");
  cmd->add_option("--object-width", o.width, "Object width, metres")->capture_default_str();
  cmd->add_option("--object-height", o.height, "Object height, metres")->capture_default_str();
  cmd->add_option("--object-depth", o.depth, "Box depth, metres")->capture_default_str();
  cmd->add_option("--frames", o.frames, "Frames of the sequence")->capture_default_str();
  cmd->add_option("--training-views", o.training_views, "Views of the training walk")
      ->capture_default_str();
  cmd->add_option("--width", o.image_width, "Frame width")->capture_default_str();
  cmd->add_option("--height", o.image_height, "Frame height")->capture_default_str();
  cmd->add_option("--focal", o.focal, "Focal length fx = fy, pixels")->capture_default_str();
  cmd->add_option("--max-fraction", o.max_fraction, "Object area at the start, fraction of frame")
      ->capture_default_str();
  cmd->add_option("--min-fraction", o.min_fraction, "Object area at the end, fraction of frame")
      ->capture_default_str();
  AddCameraEffectOptions(cmd, &o.blur_sigma_max, &o.noise_sigma, &o.illumination_max);
  cmd->add_option("--depth-noise", o.depth_noise_mm, "Depth noise on the background, mm")
      ->capture_default_str();
  cmd->add_option("--depth-holes", o.depth_holes, "Zero-depth holes per frame")
      ->capture_default_str();
  cmd->add_option("--seed", o.seed, "Random seed")->capture_default_str();
  cmd->add_flag("--json", args->json, "Print the summary as JSON");
  cmd->add_flag("-q,--quiet", args->quiet, "No progress output");
  cmd->callback([args, exit_code] { *exit_code = RunObjectSeqgen(*args); });
}

struct RigSeqgenArgs {
  std::string images, output, rig;
  RigSequenceOptions options;
  bool depth = false, json = false, quiet = false;
};

int RunRigSeqgen(const RigSeqgenArgs& args) {
  const auto fail = [](const Status& status) {
    std::fprintf(stderr, "recog seqgen rig: %s\n", status.ToString().c_str());
    return 1;
  };
  RigSequenceOptions o = args.options;
  if (!args.rig.empty()) {
    auto cameras = ReadRigFile(args.rig);
    if (!cameras.ok()) return fail(cameras.status());
    o.cameras = std::move(cameras).value();
  }
  if (Status s = o.Validate(); !s.ok()) return fail(s);
  const auto start = std::chrono::steady_clock::now();
  auto paths = ListImages(args.images);
  if (!paths.ok()) return fail(paths.status().WithContext("--images"));
  // Only the photos the avenue needs are read: a seeded draw from the folder.
  const size_t needed = RigPhotosNeeded(o);
  if (paths->size() < needed) {
    return fail(Status::InvalidArgument("the avenue needs " + std::to_string(needed) +
                                        " photos, '" + args.images + "' has " +
                                        std::to_string(paths->size())));
  }
  std::mt19937_64 rng(o.seed);
  std::shuffle(paths->begin(), paths->end(), rng);
  std::vector<cv::Mat> photos;
  for (size_t i = 0; i < needed; ++i) {
    auto photo = ReadPhoto((*paths)[i]);
    if (!photo.ok()) return fail(photo.status());
    if (photo->channels() == 3) cv::cvtColor(*photo, *photo, cv::COLOR_BGR2GRAY);
    photos.push_back(std::move(photo).value());
  }
  ProgressBar progress(!args.quiet && !args.json);
  auto sequence = GenerateRigSequence(photos, o, [&](uint64_t done, uint64_t total) {
    progress.Update("rig frames", done, total);
  });
  progress.Finish();
  if (!sequence.ok()) return fail(sequence.status());
  if (Status s = WriteRigSequence(*sequence, args.depth, args.output); !s.ok()) return fail(s);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const int revisits = sequence->truth.QueriesWithMatches();
  nlohmann::json cameras = nlohmann::json::array();
  std::string folders;
  for (const RigCamera& c : sequence->cameras) {
    cameras.push_back(c.name);
    folders += (folders.empty() ? "" : ", ") + args.output + "/" + c.name;
  }
  if (args.json) {
    const nlohmann::json j = {{"frames", sequence->frames.size()},
                              {"frames_per_leg", o.frames_per_leg},
                              {"cameras", cameras},
                              {"revisiting_frames", revisits},
                              {"depth", args.depth},
                              {"seed", o.seed},
                              {"output", args.output},
                              {"seconds", seconds}};
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf(
      "wrote %zu rig frames (%zu cameras): %d out, %d back the other way, seed %llu\n"
      "way-back frames revisiting the way out: %d\n"
      "rig: %s/rig.yaml; cameras: %s (TUM layout%s); ground truth: %s/ground_truth.txt; body "
      "poses: %s/body_poses.txt\ntime: %.1f s\n",
      sequence->frames.size(), sequence->cameras.size(), o.frames_per_leg, o.frames_per_leg,
      static_cast<unsigned long long>(o.seed), revisits, args.output.c_str(), folders.c_str(),
      args.depth ? ", with depth" : "", args.output.c_str(), args.output.c_str(), seconds);
  return 0;
}

void AddRigSeqgenCommand(CLI::App& seqgen, int* exit_code) {
  auto args = std::make_shared<RigSeqgenArgs>();
  RigSequenceOptions& o = args->options;
  CLI::App* cmd = seqgen.add_subcommand(
      "rig",
      "Generate a drive of a camera rig (by default a front and a rear camera) along an avenue of "
      "photo panels, out and back the other way, with exact geometry: the way back's rear camera "
      "sees the way out's front views");
  cmd->add_option("--images", args->images, "Folder of photos for the panels")->required();
  cmd->add_option("-o,--output", args->output, "Output folder (must not exist or be empty)")
      ->required();
  cmd->add_option("--frames-per-leg", o.frames_per_leg, "Rig frames out, and as many back")
      ->capture_default_str();
  cmd->add_option("--step", o.step_m, "Metres between frames")->capture_default_str();
  cmd->add_option("--return-offset", o.return_lateral_offset_m,
                  "Sideways offset of the way back, metres")
      ->capture_default_str();
  cmd->add_option("--return-yaw", o.return_yaw_deg, "Turn of the way back, degrees")
      ->capture_default_str();
  cmd->add_option("--revisit-radius", o.revisit_radius_m,
                  "Body positions this close (metres) are a revisit in the ground truth")
      ->capture_default_str();
  CLI::Option* rig =
      cmd->add_option("--rig", args->rig,
                      "Rig file of the cameras (without lens distortion); default: a front and a "
                      "rear camera of --width x --height, fx = fy = --focal, 0.4 m before and "
                      "behind the body");
  cmd->add_option("--width", o.image_size.width, "Frame width")
      ->capture_default_str()
      ->excludes(rig);
  cmd->add_option("--height", o.image_size.height, "Frame height")
      ->capture_default_str()
      ->excludes(rig);
  cmd->add_option("--focal", o.focal_px, "Focal length fx = fy, pixels")
      ->capture_default_str()
      ->excludes(rig);
  cmd->add_flag("--depth", args->depth, "Also write each camera's depth images (TUM, 1/5000 m)");
  cmd->add_option("--seed", o.seed, "Random seed")->capture_default_str();
  cmd->add_flag("--json", args->json, "Print the summary as JSON");
  cmd->add_flag("-q,--quiet", args->quiet, "No progress output");
  cmd->callback([args, exit_code] { *exit_code = RunRigSeqgen(*args); });
}

struct LensSeqgenArgs {
  std::string images, output, source_camera, camera, size;
  bool quiet = false;
};

int RunLensSeqgen(const LensSeqgenArgs& args) {
  const auto fail = [](const Status& status) {
    std::fprintf(stderr, "recog seqgen lens: %s\n", status.ToString().c_str());
    return 1;
  };
  auto source = ParseNumbers("--source-camera", args.source_camera);
  if (!source.ok()) return fail(source.status());
  if (source->size() != 4) {
    return fail(Status::InvalidArgument("--source-camera takes fx,fy,cx,cy of the pinhole images"));
  }
  const cv::Matx33d source_K((*source)[0], 0, (*source)[2], 0, (*source)[1], (*source)[3], 0, 0, 1);
  auto lens = ParseCameraFlag("--camera", args.camera);
  if (!lens.ok()) return fail(lens.status());
  auto paths = ListImages(args.images);
  if (!paths.ok()) return fail(paths.status().WithContext("--images"));
  if (Status s = PrepareOutputFolder(args.output); !s.ok()) return fail(s);
  ProgressBar progress(!args.quiet);
  std::optional<LensWarp> warp;  // made for the first image's size (or --size)
  cv::Size size;
  for (size_t i = 0; i < paths->size(); ++i) {
    const std::string& path = (*paths)[i];
    const cv::Mat image = cv::imread(path, cv::IMREAD_UNCHANGED);
    if (image.empty()) return fail(Status::InvalidArgument("cannot read image '" + path + "'"));
    if (!warp.has_value()) {
      size = image.size();
      if (!args.size.empty()) {
        auto wh = ParseNumbers("--size", args.size);
        if (!wh.ok() || wh->size() != 2) {
          return fail(Status::InvalidArgument("--size takes width,height"));
        }
        size = cv::Size(int((*wh)[0]), int((*wh)[1]));
      }
      auto made = LensWarp::Create(source_K, *lens, size);
      if (!made.ok()) return fail(made.status());
      warp.emplace(std::move(made).value());
    }
    // PNG: a second JPEG compression would change the features more than the lens does.
    std::filesystem::path out =
        std::filesystem::path(args.output) / std::filesystem::relative(path, args.images);
    out.replace_extension(".png");
    std::filesystem::create_directories(out.parent_path());
    if (!cv::imwrite(out.string(), warp->Apply(image))) {
      return fail(Status::Internal("cannot write '" + out.string() + "'"));
    }
    progress.Update("images", i + 1, paths->size());
  }
  progress.Finish();
  std::printf("wrote %zu images of %dx%d through %s to %s\n", paths->size(), size.width,
              size.height, lens->Describe().c_str(), args.output.c_str());
  return 0;
}

void AddLensSeqgenCommand(CLI::App& seqgen, int* exit_code) {
  auto args = std::make_shared<LensSeqgenArgs>();
  CLI::App* cmd = seqgen.add_subcommand(
      "lens",
      "Write a folder of pinhole images as a given lens would have taken them (same file names, "
      "as PNG): a real sequence through a known distortion, to compare the loops and poses found "
      "through --camera LENS:... with the original's");
  cmd->add_option("--images", args->images, "Folder of pinhole images (recursive)")->required();
  cmd->add_option("-o,--output", args->output, "Output folder (must not exist or be empty)")
      ->required();
  cmd->add_option("--source-camera", args->source_camera, "fx,fy,cx,cy of the images")->required();
  cmd->add_option("--camera", args->camera,
                  "The lens to simulate, in --camera syntax (docs/cli.md, \"Cameras\"), e.g. "
                  "equidistant:fx,fy,cx,cy,k1,k2,k3,k4")
      ->required();
  cmd->add_option("--size", args->size, "width,height of the output (default: the input's)");
  cmd->add_flag("-q,--quiet", args->quiet, "No progress output");
  cmd->callback([args, exit_code] { *exit_code = RunLensSeqgen(*args); });
}

}  // namespace

void AddSeqgenCommand(CLI::App& app, int* exit_code) {
  auto args = std::make_shared<SeqgenArgs>();
  SequenceOptions& o = args->options;
  CLI::App* cmd = app.add_subcommand(
      "seqgen",
      "Generate an image sequence with exact loop ground truth from photos (one photo per place)");
  cmd->add_option("--images", args->images,
                  "Folder of photos (recursive, natural order); required without a mode");
  cmd->add_option("-o,--output", args->output,
                  "Output folder (must not exist or be empty); required without a mode");
  cmd->add_option("--places", o.places,
                  "Places, one photo each (photos of the same scene as an earlier one are skipped)")
      ->capture_default_str();
  cmd->add_option("--frames-per-place", o.frames_per_place, "Consecutive frames per visit")
      ->capture_default_str();
  cmd->add_option("--revisit-fraction", o.revisit_fraction,
                  "Fraction of places visited again later (0 = no loops)")
      ->capture_default_str();
  cmd->add_option("--width", o.width, "Frame width")->capture_default_str();
  cmd->add_option("--height", o.height, "Frame height")->capture_default_str();
  cmd->add_option("--max-shift", o.max_shift_px, "Per-frame camera shift (pixels)")
      ->capture_default_str();
  cmd->add_option("--max-rotation", o.max_rotation_deg, "Per-frame camera rotation (degrees)")
      ->capture_default_str();
  cmd->add_option("--max-scale", o.max_scale, "Per-frame relative scale change")
      ->capture_default_str();
  AddCameraEffectOptions(cmd, &o.blur_sigma_max, &o.noise_sigma, &o.illumination_max);
  cmd->add_option("--seed", o.seed, "Random seed")->capture_default_str();
  cmd->add_flag("--allow-duplicate-places", args->allow_duplicate_places,
                "Use the first photos as they are, even if two show the same scene (cycled and "
                "mirrored if fewer than --places)");
  cmd->add_option("--format", args->format, "Image format: png or jpg (quality 95)")
      ->capture_default_str();
  cmd->add_flag("--sparse-truth", args->sparse_truth,
                "Sparse ground truth (forced above 5000 frames)");
  cmd->add_flag("--json", args->json, "Print the summary as JSON");
  cmd->add_flag("-q,--quiet", args->quiet, "No progress output");
  AddObjectSeqgenCommand(*cmd, exit_code);
  AddRigSeqgenCommand(*cmd, exit_code);
  AddLensSeqgenCommand(*cmd, exit_code);
  cmd->require_subcommand(0, 1);
  cmd->callback([cmd, args, exit_code] {
    if (!cmd->get_subcommands().empty()) return;  // a mode ran its own
    *exit_code = RunSeqgen(*args);
  });
}

}  // namespace recog::cli
