#include "tools/evaluation/object_evaluation.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/median.h"
#include "core/common/rotation_angle.h"
#include "core/features/feature_extractor.h"
#include "core/index/memory_index_store.h"
#include "core/object/formats/roboearth.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tools/common/cli_support.h"
#include "tools/evaluation/camera_calibration.h"
#include "tools/evaluation/plot.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

constexpr std::pair<std::string_view, ImageTransform> kTransformNames[] = {
    {"none", ImageTransform::kNone},
    {"scale0.5", ImageTransform::kHalfScale},
    {"rot90", ImageTransform::kRotate90},
    {"rot180", ImageTransform::kRotate180}};

constexpr std::pair<std::string_view, ObjectEvaluationMethod> kMethodNames[] = {
    {"merged", ObjectEvaluationMethod::kMerged},
    {"independent-views", ObjectEvaluationMethod::kIndependentViews}};

// The database entry of one training view in the independent-view method.
std::string ViewEntryName(const std::string& object, int view) {
  char suffix[16];
  std::snprintf(suffix, sizeof(suffix), ".face_%03d", view);
  return object + suffix;
}

// The model of one training view alone: the folder's model with every other view left out.
StatusOr<ObjectModel> BuildViewModel(std::shared_ptr<const Vocabulary> vocabulary,
                                     const ModelBuildOptions& build, const RoboEarthFolder& folder,
                                     const RoboEarthView& view) {
  ModelBuildOptions only = build;
  for (const RoboEarthView& other : folder.views) {
    if (other.index != view.index) only.exclude_views.push_back(other.index);
  }
  ModelBuilder builder(std::move(vocabulary), only);
  RECOG_ASSIGN_OR_RETURN(ObjectModel model, builder.FromRoboEarth(folder.path));
  model.metadata.object_class = model.metadata.name;
  model.metadata.name = ViewEntryName(model.metadata.name, view.index);
  return model;
}

ObjectEvaluationSummary Summarise(ImageTransform transform,
                                  const std::vector<ObjectQuery>& queries) {
  ObjectEvaluationSummary s;
  s.transform = transform;
  std::vector<double> rotation, translation, orb, clustering, conversion, query, correspondences,
      ransac, second_pass, total;
  for (const ObjectQuery& q : queries) {
    if (q.transform != transform) continue;
    ++s.queries;
    s.wrong_detections += q.wrong.size();
    if (q.detected) {
      ++s.detections;
      rotation.push_back(q.rotation_error_deg);
      translation.push_back(q.translation_error_ratio);
    }
    orb.push_back(q.timing.orb);
    clustering.push_back(q.timing.clustering);
    conversion.push_back(q.timing.conversion);
    query.push_back(q.timing.query);
    correspondences.push_back(q.timing.correspondences);
    ransac.push_back(q.timing.ransac);
    second_pass.push_back(q.timing.second_pass);
    total.push_back(q.timing.total);
  }
  s.detection_rate = s.queries == 0 ? 0.0 : double(s.detections) / double(s.queries);
  s.median_rotation_error_deg = Median(rotation);
  s.median_translation_error_ratio = Median(translation);
  s.median_timing.orb = Median(orb);
  s.median_timing.clustering = Median(clustering);
  s.median_timing.conversion = Median(conversion);
  s.median_timing.query = Median(query);
  s.median_timing.correspondences = Median(correspondences);
  s.median_timing.ransac = Median(ransac);
  s.median_timing.second_pass = Median(second_pass);
  s.median_timing.total = Median(total);
  return s;
}

}  // namespace

std::string_view ImageTransformName(ImageTransform transform) {
  for (const auto& [name, value] : kTransformNames) {
    if (value == transform) return name;
  }
  return "none";
}

StatusOr<ImageTransform> ParseImageTransform(std::string_view name) {
  for (const auto& [text, value] : kTransformNames) {
    if (name == text) return value;
  }
  return Status::InvalidArgument("unknown image transform '" + std::string(name) +
                                 "' (none, scale0.5, rot90, rot180)");
}

void TransformView(ImageTransform transform, cv::Mat* image, CameraIntrinsics* camera,
                   RigidTransform* camera_from_object) {
  const double w = image->cols, h = image->rows;
  cv::Matx33d turn = cv::Matx33d::eye();  // new camera axes from old ones
  switch (transform) {
    case ImageTransform::kNone:
      return;
    case ImageTransform::kHalfScale:
      cv::resize(*image, *image, cv::Size(), 0.5, 0.5, cv::INTER_AREA);
      // Pixel centres: u' + 0.5 = (u + 0.5) / 2.
      camera->fx *= 0.5;
      camera->fy *= 0.5;
      camera->cx = (camera->cx + 0.5) * 0.5 - 0.5;
      camera->cy = (camera->cy + 0.5) * 0.5 - 0.5;
      return;
    case ImageTransform::kRotate90: {  // clockwise: u' = h - 1 - v, v' = u
      cv::rotate(*image, *image, cv::ROTATE_90_CLOCKWISE);
      const CameraIntrinsics old = *camera;
      camera->fx = old.fy;
      camera->fy = old.fx;
      camera->cx = h - 1 - old.cy;
      camera->cy = old.cx;
      turn = {0, -1, 0, 1, 0, 0, 0, 0, 1};
      break;
    }
    case ImageTransform::kRotate180:
      cv::rotate(*image, *image, cv::ROTATE_180);
      camera->cx = w - 1 - camera->cx;
      camera->cy = h - 1 - camera->cy;
      turn = {-1, 0, 0, 0, -1, 0, 0, 0, 1};
      break;
  }
  camera_from_object->R = turn * camera_from_object->R;
  camera_from_object->t = turn * camera_from_object->t;
}

std::string_view ObjectEvaluationMethodName(ObjectEvaluationMethod method) {
  for (const auto& [name, value] : kMethodNames) {
    if (value == method) return name;
  }
  return "merged";
}

StatusOr<ObjectEvaluationMethod> ParseObjectEvaluationMethod(std::string_view name) {
  for (const auto& [text, value] : kMethodNames) {
    if (name == text) return value;
  }
  return Status::InvalidArgument("unknown evaluation method '" + std::string(name) +
                                 "' (merged, independent-views)");
}

bool IsRotationMatrix(const cv::Matx33d& R) {
  return cv::norm(R.t() * R - cv::Matx33d::eye()) <= 1e-3 && cv::determinant(R) > 0;
}

StatusOr<std::shared_ptr<const Vocabulary>> LoadObjectVocabulary(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(Vocabulary vocabulary,
                         LoadAnyVocabulary(path.empty() ? DefaultObjectVocabularyPath() : path));
  return std::make_shared<const Vocabulary>(std::move(vocabulary));
}

std::vector<ModelSource> FindModelSources(const std::string& path) {
  std::error_code ec;
  const auto is_roboearth = [&ec](const fs::path& p) {
    return fs::is_directory(p, ec) && fs::exists(p / "meta.xml", ec);
  };
  if (!fs::is_directory(path, ec)) return {{path, false}};
  if (is_roboearth(path)) return {{path, true}};
  std::vector<fs::path> entries;
  for (const auto& entry : fs::directory_iterator(path, ec)) entries.push_back(entry.path());
  std::sort(entries.begin(), entries.end());
  std::vector<ModelSource> sources;
  for (const fs::path& entry : entries) {
    if (is_roboearth(entry)) {
      sources.push_back({entry.string(), true});
    } else if (entry.extension() == ".robj") {
      sources.push_back({entry.string(), false});
    }
  }
  return sources;
}

void DrawDetection(const Detection& detection, const CameraIntrinsics& camera,
                   const cv::Scalar& colour, cv::Mat* canvas) {
  std::vector<std::vector<cv::Point>> outline(1);
  for (const cv::Point2f& p : detection.outline) outline[0].emplace_back(cv::Point(p));
  if (outline[0].size() >= 3) cv::polylines(*canvas, outline, true, colour, 2, cv::LINE_AA);
  for (const cv::Point2f& p : detection.inlier_pixels) {
    cv::circle(*canvas, cv::Point(p), 3, colour, 1, cv::LINE_AA);
  }
  // Axes of the object frame, a tenth of the object's distance long.
  const RigidTransform& pose = detection.camera_from_object;
  const double length = 0.1 * cv::norm(pose.t);
  const cv::Vec3d axes[] = {{0, 0, 0}, {length, 0, 0}, {0, length, 0}, {0, 0, length}};
  cv::Point2d pixels[4];
  bool seen[4];
  for (int k = 0; k < 4; ++k) {
    seen[k] = ProjectDirection(camera, pose.R * axes[k] + pose.t, &pixels[k]);  // its lens
  }
  const cv::Scalar axis_colour[] = {{0, 0, 255}, {0, 255, 0}, {255, 0, 0}};
  for (int k = 0; k < 3; ++k) {
    if (!seen[0] || !seen[k + 1]) continue;
    cv::arrowedLine(*canvas, pixels[0], pixels[k + 1], axis_colour[k], 2, cv::LINE_AA);
  }
  cv::putText(*canvas, detection.name + " (" + std::to_string(detection.inliers) + ")",
              outline[0].empty() ? cv::Point(10, 20) : outline[0][0], cv::FONT_HERSHEY_SIMPLEX, 0.6,
              colour, 2, cv::LINE_AA);
}

StatusOr<ObjectEvaluation> EvaluateObjects(const ObjectEvaluationOptions& options) {
  RECOG_ASSIGN_OR_RETURN(Vocabulary loaded, LoadAnyVocabulary(options.vocabulary_path));
  auto vocabulary = std::make_shared<const Vocabulary>(std::move(loaded));
  if (!fs::is_directory(options.roboearth_dir)) {
    return Status::NotFound("RoboEarth folder '" + options.roboearth_dir + "' not found");
  }
  std::vector<fs::path> folders;
  for (const auto& entry : fs::directory_iterator(options.roboearth_dir)) {
    if (entry.is_directory() && fs::exists(entry.path() / "meta.xml")) {
      folders.push_back(entry.path());
    }
  }
  std::sort(folders.begin(), folders.end());
  if (folders.empty()) {
    return Status::InvalidArgument("'" + options.roboearth_dir + "' holds no RoboEarth model");
  }
  ModelBuildOptions build = options.build;
  build.keep_images = false;
  ModelBuilder builder(vocabulary, build);
  MemoryIndexStore store;
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<ObjectDatabase> database,
                         ObjectDatabase::Open(&store, vocabulary));
  const bool merged = options.method == ObjectEvaluationMethod::kMerged;
  ObjectEvaluation evaluation;
  evaluation.method = options.method;
  const auto put = [&](const ObjectModel& model, const std::string& object) -> Status {
    RECOG_RETURN_IF_ERROR(database->Put(model).status());
    evaluation.database.push_back(model.metadata.name);
    evaluation.objects[model.metadata.name] = object;
    return Status::Ok();
  };
  std::vector<RoboEarthFolder> evaluated;
  // What goes back after a held-out view: the full model of each evaluated object (merged), or
  // each evaluated view's own model (independent views), by entry name.
  std::map<std::string, ObjectModel> held_out;
  for (const fs::path& folder : folders) {
    const std::string object = folder.filename().string();
    RECOG_ASSIGN_OR_RETURN(RoboEarthFolder listing, ReadRoboEarthFolder(folder.string()));
    const bool evaluate =
        listing.meta.type == ObjectType::k3D && int(listing.views.size()) >= options.min_views;
    if (merged) {
      RECOG_ASSIGN_OR_RETURN(ObjectModel model, builder.FromRoboEarth(folder.string()));
      RECOG_RETURN_IF_ERROR(put(model, object));
      if (evaluate) held_out.emplace(model.metadata.name, std::move(model));
    } else {
      for (const RoboEarthView& view : listing.views) {
        StatusOr<ObjectModel> model = BuildViewModel(vocabulary, build, listing, view);
        // A view in which no feature sees a 3D point (a small planar crop) cannot be an entry.
        if (model.status().code() == StatusCode::kInvalidArgument) {
          evaluation.skipped_views.push_back(
              {ViewEntryName(object, view.index), model.status().message()});
          continue;
        }
        if (!model.ok()) return model.status();
        RECOG_RETURN_IF_ERROR(put(*model, object));
        if (evaluate) held_out.emplace(model->metadata.name, std::move(*model));
      }
    }
    if (evaluate) evaluated.push_back(std::move(listing));
  }
  size_t total = 0;
  for (const RoboEarthFolder& folder : evaluated) total += folder.views.size();
  total *= options.transforms.size();
  if (!options.draw_dir.empty()) fs::create_directories(options.draw_dir);

  RECOG_ASSIGN_OR_RETURN(ObjectRecognizer recognizer,
                         ObjectRecognizer::Create(database, options.recognition));
  std::vector<Detection> detections;
  for (const RoboEarthFolder& folder : evaluated) {
    const std::string object = fs::path(folder.path).filename().string();
    for (const RoboEarthView& view : folder.views) {
      // Leave v out of its object.
      const std::string entry = merged ? object : ViewEntryName(object, view.index);
      if (merged) {
        ModelBuildOptions without = build;
        without.exclude_views.push_back(view.index);
        ModelBuilder partial_builder(vocabulary, without);
        RECOG_ASSIGN_OR_RETURN(ObjectModel partial, partial_builder.FromRoboEarth(folder.path));
        RECOG_RETURN_IF_ERROR(database->Put(partial).status());
      } else if (held_out.count(entry) != 0) {  // a skipped view has no entry to remove
        RECOG_RETURN_IF_ERROR(database->Remove(entry));
      }
      RECOG_ASSIGN_OR_RETURN(cv::Mat original, ReadGrayImage(view.image_path));
      for (ImageTransform transform : options.transforms) {
        cv::Mat image = original.clone();
        CameraIntrinsics camera;
        camera.fx = camera.fy = view.camera.focal;
        camera.cx = original.cols / 2.0;
        camera.cy = original.rows / 2.0;
        RigidTransform truth = view.camera.camera_from_object;
        TransformView(transform, &image, &camera, &truth);
        ObjectQuery query;
        query.object = object;
        query.view = view.index;
        query.transform = transform;
        RECOG_RETURN_IF_ERROR(recognizer.Recognize(image, camera, &detections, &query.timing));
        for (const Detection& d : detections) {
          const std::string& found = evaluation.objects.at(d.name);
          if (found != query.object) {
            if (std::find(query.wrong.begin(), query.wrong.end(), found) == query.wrong.end()) {
              query.wrong.push_back(found);
            }
          } else if (!query.detected) {
            query.detected = true;
            query.matched = d.name;
            query.inliers = d.inliers;
            query.rotation_error_deg = RotationAngleDeg(d.camera_from_object.R, truth.R);
            query.translation_error_ratio =
                cv::norm(d.camera_from_object.t - truth.t) / cv::norm(truth.t);
          }
        }
        if (!options.draw_dir.empty()) {
          cv::Mat canvas;
          cv::cvtColor(image, canvas, cv::COLOR_GRAY2BGR);
          for (const Detection& d : detections) {
            DrawDetection(d, camera,
                          evaluation.objects.at(d.name) == query.object ? cv::Scalar(0, 200, 0)
                                                                        : cv::Scalar(0, 0, 255),
                          &canvas);
          }
          char name[160];
          std::snprintf(name, sizeof(name), "%s_%03d_%s.png", query.object.c_str(), view.index,
                        std::string(ImageTransformName(transform)).c_str());
          cv::imwrite((fs::path(options.draw_dir) / name).string(), canvas);
        }
        evaluation.queries.push_back(std::move(query));
        if (options.progress) options.progress(evaluation.queries.size(), total);
      }
      // Put v back (merged: the object's full model once all its views have been held out).
      if (!merged && held_out.count(entry) != 0) {
        RECOG_RETURN_IF_ERROR(database->Put(held_out.at(entry)).status());
      }
    }
    if (merged) RECOG_RETURN_IF_ERROR(database->Put(held_out.at(object)).status());
  }
  for (ImageTransform transform : options.transforms) {
    evaluation.summaries.push_back(Summarise(transform, evaluation.queries));
  }
  return evaluation;
}

StatusOr<ObjectTruthFrame> FindTruthFrame(const ObjectSequenceTruth& truth,
                                          const std::string& image_path) {
  const std::string name = fs::path(image_path).filename().string();
  for (const ObjectTruthFrame& frame : truth.frames) {
    if (frame.image == name) return frame;
  }
  return Status::NotFound("the truth has no frame '" + name + "'");
}

TruthFrameScore ScoreTruthFrame(const ObjectTruthFrame& truth, const std::string& expect,
                                const std::vector<Detection>& detections,
                                const SizeRecallOptions& options) {
  TruthFrameScore score;
  score.image = truth.image;
  score.visible = truth.visible;
  score.area_fraction = truth.area_fraction;
  for (const Detection& d : detections) {
    if (d.name != expect) {
      ++score.other_objects;
      continue;
    }
    if (score.found) continue;  // the first (best) detection of the object counts
    score.found = true;
    score.rotation_error_deg = RotationAngleDeg(d.camera_from_object.R, truth.camera_from_object.R);
    score.translation_error_m = cv::norm(d.camera_from_object.t - truth.camera_from_object.t);
    score.correct_pose = score.rotation_error_deg <= options.max_rotation_error_deg &&
                         score.translation_error_m <=
                             options.max_translation_error * cv::norm(truth.camera_from_object.t);
  }
  return score;
}

SizeRecall SummariseSizeRecall(const std::vector<TruthFrameScore>& frames,
                               const SizeRecallOptions& options) {
  SizeRecall out;
  std::vector<double> edges = {0.0};
  edges.insert(edges.end(), options.bin_edges.begin(), options.bin_edges.end());
  edges.push_back(1.0);
  for (size_t b = 0; b + 1 < edges.size(); ++b) {
    SizeBin bin;
    bin.lo = edges[b];
    bin.hi = edges[b + 1];
    std::vector<double> areas, rotation, translation;
    for (const TruthFrameScore& f : frames) {
      const bool last = b + 2 == edges.size();
      if (!f.visible || f.area_fraction < bin.lo || (f.area_fraction >= bin.hi && !last)) continue;
      ++bin.frames;
      areas.push_back(f.area_fraction);
      if (f.found) {
        ++bin.found;
        rotation.push_back(f.rotation_error_deg);
        translation.push_back(f.translation_error_m);
      }
      bin.correct += f.correct_pose;
    }
    if (bin.frames > 0) {
      bin.recall = double(bin.correct) / double(bin.frames);
      bin.found_rate = double(bin.found) / double(bin.frames);
    }
    bin.median_area = Median(areas);
    bin.median_rotation_error_deg = Median(rotation);
    bin.median_translation_error_m = Median(translation);
    out.bins.push_back(bin);
  }
  for (const TruthFrameScore& f : frames) {
    out.other_objects += f.other_objects;
    if (!f.visible) {
      out.found_not_visible += f.found;
      continue;
    }
    ++out.visible_frames;
    out.found += f.found;
    out.correct += f.correct_pose;
  }
  out.recall = out.visible_frames == 0 ? 0.0 : double(out.correct) / double(out.visible_frames);
  return out;
}

Status WriteSizeRecallCsv(const SizeRecall& recall, const std::string& path) {
  std::ofstream out(path);
  out << "area_lo,area_hi,median_area,frames,found,correct,recall,found_rate,median_rotation_deg,"
         "median_translation_m\n";
  for (const SizeBin& b : recall.bins) {
    out << b.lo << ',' << b.hi << ',' << b.median_area << ',' << b.frames << ',' << b.found << ','
        << b.correct << ',' << b.recall << ',' << b.found_rate << ',' << b.median_rotation_error_deg
        << ',' << b.median_translation_error_m << '\n';
  }
  out.close();
  if (!out) return Status::Internal("cannot write '" + path + "'");
  return Status::Ok();
}

Status WriteSizeRecallPlot(const SizeRecall& recall, const std::string& title,
                           const std::string& path) {
  PlotSeries correct{"recall (right pose)", {}, cv::Scalar(200, 80, 20), {}};
  PlotSeries found{"found (any pose)", {}, cv::Scalar(40, 160, 40), {}};
  for (const SizeBin& b : recall.bins) {
    if (b.frames == 0) continue;
    const double x = std::log10(100 * std::max(b.median_area, 1e-4));
    correct.points.push_back({x, b.recall});
    correct.point_labels.push_back(std::to_string(b.frames));
    found.points.push_back({x, b.found_rate});
  }
  PlotOptions plot;
  plot.title = title;
  plot.x_label = "area, log10(% of frame); labels: frames";
  plot.y_label = "fraction of frames";
  plot.x_min = -1;
  plot.x_max = 2;
  plot.write_csv = false;  // WriteSizeRecallCsv writes the bins, with more columns
  return WritePlot(path, plot, {correct, found});
}

}  // namespace recog::cli
