// Object recognition speed benchmarks (issue "object recognition", thesis Table 5.6):
//   BM_RecognizeRoboEarth            ObjectRecognizer::Recognize with default options, one thread,
//                                    on every 640x480 query image once, with the 11 RoboEarth
//                                    models (every folder of objects/roboearth/models, built with
//                                    the default ModelBuilder options but without training images)
//                                    in an in-memory ObjectDatabase.
//   BM_RecognizeWith1000Distractors  the same with 1,000 synthetic distractor objects added to the
//                                    database.
// Query images: the 640x480 training views of the RoboEarth models (lion, van, box and bio, 54
// photos that show an object, with the camera of their bundle file: f from face_k.txt, principal
// point at the image centre) and the 218 frames of objects/visp-cube (a cube that is in no model:
// the "no object" case, with fx = fy = 600 and the principal point at the centre). The RoboEarth
// views are also in the models, so the detections are easy: this measures speed, not accuracy.
// One benchmark iteration recognises one image (after one untimed warm-up call). The headline
// counters are over the 54 images that show a modelled object: the medians of each stage's
// milliseconds as RecognitionTiming reports them (orb_ms, clustering_ms, conversion_ms, query_ms,
// di_ms, ransac_ms for the first pass, second_pass_ms for all of the second pass; the stage medians
// need not add up to the total's) and of the total, every pass included (total_ms),
// and how many of them gave at least one detection (object_images_detected). The 218 frames
// without a modelled object are reported apart: their median total (no_object_total_ms) and how
// many gave a detection (no_object_images_detected, false positives). The time Google Benchmark
// prints per iteration is the mean over all the images of both kinds.
//   BM_RecognizeRealClutter          the same on real cluttered frames: the 50 colour frames of
//                                    objects/visp-rbt-cube (an 8.5 cm cube among clutter, about 5 %
//                                    of the frame) with its RGB-D model of frames 0, 16, 33 and 49
//                                    (--box 0.085, poses.txt) added to the 11 RoboEarth models;
//                                    the "no object" frames are the 30 of objects/visp-castle (a
//                                    real cluttered desk whose castle is in no model). The same
//                                    counters; object_images_detected counts the frames where the
//                                    cube was found.
//   BM_SolveP3P / BM_OpenCvSolveP3P  one P3P solve of RANSAC PnP's inner loop: SolveP3P
//                                    (core/geometry/p3p.h) against cv::solveP3P (SOLVEPNP_P3P) on
//                                    the same 1,024 random samples (three points in a 20 cm box,
//                                    0.3-2 m in front of the camera, seeded), cycled through.
//                                    Needs no data.
// Distractors: 1,000 planar posters built with ModelBuilder::FromFaceImages, each from one
// Caltech-101 photo of training/caltech101 (of the N photos in natural path order, photo
// floor(i * N / 1000) for distractor i, which spreads them over every category), as a single front
// face of width uniform in [0.1, 0.5) m (a seeded mt19937_64) and height width * rows / cols of the
// photo; named distractor-0000 .. distractor-0999.
// The databases are built once, before the first timed iteration of the benchmark that needs them
// (the distractors take about 20 s; progress goes to stderr). Needs the shared data
// (RECOG_SHARED_DATA, default ../shared/data); the benchmarks are skipped without it.
// Run: build/bin/bench_objects [--benchmark_filter=...]
#include <benchmark/benchmark.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/common/median.h"
#include "core/features/feature_extractor.h"
#include "core/geometry/p3p.h"
#include "core/index/memory_index_store.h"
#include "core/object/builder/model_builder.h"
#include "core/object/formats/roboearth.h"
#include "core/object/recognition/object_database.h"
#include "core/object/recognition/object_recognizer.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tests/testing/data_paths.h"
#include "tools/common/cli_support.h"
#include "tools/evaluation/frame_poses.h"
#include "tools/evaluation/place_evaluation.h"
#include "tools/evaluation/rgbd_recording.h"

namespace recog::bench {
namespace {

constexpr char kModelsDir[] = "objects/roboearth/models";
constexpr char kVispDir[] = "objects/visp-cube/images";
constexpr char kCaltechDir[] = "training/caltech101";
constexpr char kRbtCubeDir[] = "objects/visp-rbt-cube";
constexpr char kCastleDir[] = "objects/visp-castle/images";
constexpr char kRbtCubeName[] = "visp-rbt-cube";
constexpr size_t kDistractors = 1000;
constexpr uint64_t kDistractorSeed = 20130101;

struct QueryImage {
  cv::Mat image;  // 8-bit grey, 640x480
  CameraIntrinsics camera;
  bool shows_object = false;  // shows a modelled object (else none of the database's)
};

const CameraIntrinsics kRbtCubeCamera = {
    607.178466796875, 607.2342529296875, 321.39129638671875, 241.91822814941406, {}};

// The model folders under kModelsDir, by name.
std::vector<std::string> ModelFolders() {
  std::vector<std::string> dirs;
  for (const auto& entry : std::filesystem::directory_iterator(testing::SharedData(kModelsDir))) {
    if (entry.is_directory()) dirs.push_back(entry.path().string());
  }
  std::sort(dirs.begin(), dirs.end());
  return dirs;
}

StatusOr<std::vector<QueryImage>> LoadQueryImages() {
  std::vector<QueryImage> queries;
  for (const std::string& dir : ModelFolders()) {
    RECOG_ASSIGN_OR_RETURN(RoboEarthFolder folder, ReadRoboEarthFolder(dir));
    for (const RoboEarthView& view : folder.views) {
      RECOG_ASSIGN_OR_RETURN(cv::Mat image, ReadGrayImage(view.image_path));
      if (image.cols != 640 || image.rows != 480) continue;
      const double f = view.camera.focal;
      queries.push_back({image, {f, f, 320, 240, {}}, true});
    }
  }
  RECOG_ASSIGN_OR_RETURN(std::vector<std::string> frames,
                         cli::ListImages(testing::SharedData(kVispDir)));
  for (const std::string& path : frames) {
    RECOG_ASSIGN_OR_RETURN(cv::Mat image, ReadGrayImage(path));
    queries.push_back({image, {600, 600, 320, 240, {}}, false});
  }
  return queries;
}

// The query images, loaded on first use (empty when the shared data is missing).
const std::vector<QueryImage>& QueryImages() {
  static const std::vector<QueryImage> queries = [] {
    if (!testing::HasSharedData(kModelsDir) || !testing::HasSharedData(kVispDir)) {
      return std::vector<QueryImage>();
    }
    auto loaded = LoadQueryImages();
    if (!loaded.ok()) {
      std::fprintf(stderr, "bench_objects: %s\n", loaded.status().ToString().c_str());
      return std::vector<QueryImage>();
    }
    return std::move(loaded).value();
  }();
  return queries;
}

// The real cluttered frames of BM_RecognizeRealClutter, loaded on first use (empty when the
// shared data is missing): visp-rbt-cube's in colour, then visp-castle's.
const std::vector<QueryImage>& ClutterImages() {
  static const std::vector<QueryImage> queries = []() -> std::vector<QueryImage> {
    if (!testing::HasSharedData(kRbtCubeDir) || !testing::HasSharedData(kCastleDir)) return {};
    std::vector<QueryImage> loaded;
    auto cube = cli::ListRgbdRecording(testing::SharedData(kRbtCubeDir));
    auto castle = cli::ListImages(testing::SharedData(kCastleDir));
    if (!cube.ok() || !castle.ok()) {
      std::fprintf(stderr, "bench_objects: %s\n",
                   (cube.ok() ? castle.status() : cube.status()).ToString().c_str());
      return {};
    }
    for (const cli::RgbdRecordingFrame& frame : *cube) {
      loaded.push_back({cv::imread(frame.image, cv::IMREAD_COLOR), kRbtCubeCamera, true});
    }
    for (const std::string& path : *castle) {
      loaded.push_back({cv::imread(path, cv::IMREAD_GRAYSCALE),
                        {615.1674804688, 615.1675415039, 312.1889953613, 243.4373779297, {}},
                        false});
    }
    const bool unreadable = std::any_of(loaded.begin(), loaded.end(),
                                        [](const QueryImage& q) { return q.image.empty(); });
    if (unreadable) std::fprintf(stderr, "bench_objects: an image could not be read\n");
    return unreadable ? std::vector<QueryImage>() : loaded;
  }();
  return queries;
}

// An object database in memory; `status` says whether it could be built.
struct ObjectFixture {
  Status status;
  MemoryIndexStore store;
  std::shared_ptr<const ObjectDatabase> database;  // declared after the store it uses
  size_t distractors = 0;
};

// Adds `count` Caltech posters (see the file comment) to `database`.
Status AddDistractors(size_t count, ModelBuilder* builder, ObjectDatabase* database) {
  RECOG_ASSIGN_OR_RETURN(std::vector<std::string> photos,
                         cli::ListImages(testing::SharedData(kCaltechDir)));
  if (photos.size() < count) {
    return Status::FailedPrecondition("only " + std::to_string(photos.size()) +
                                      " Caltech photos for " + std::to_string(count) +
                                      " distractors");
  }
  std::mt19937_64 random(kDistractorSeed);
  for (size_t i = 0; i < count; ++i) {
    RECOG_ASSIGN_OR_RETURN(cv::Mat photo, ReadGrayImage(photos[i * photos.size() / count]));
    // Uniform in [0, 1) from the top 53 bits: the same on every standard library.
    const double unit = double(random() >> 11) * 0x1.0p-53;
    const double width = 0.1 + 0.4 * unit;
    const double height = width * photo.rows / photo.cols;
    char name[32];
    std::snprintf(name, sizeof(name), "distractor-%04zu", i);
    RECOG_ASSIGN_OR_RETURN(ObjectModel model, builder->FromFaceImages(
                                                  name, {{BoxSide::kFront, photo}}, width, height));
    RECOG_RETURN_IF_ERROR(database->Put(model).status());
    if ((i + 1) % 100 == 0) {
      std::fprintf(stderr, "bench_objects: %zu / %zu distractors\n", i + 1, count);
    }
  }
  return Status::Ok();
}

// Adds visp-rbt-cube's RGB-D model of frames 0, 16, 33 and 49 to `database`.
Status AddRbtCube(ModelBuilder* builder, ObjectDatabase* database) {
  const std::string dir = testing::SharedData(kRbtCubeDir);
  RECOG_ASSIGN_OR_RETURN(std::vector<cli::RgbdRecordingFrame> frames, cli::ListRgbdRecording(dir));
  RECOG_ASSIGN_OR_RETURN(auto poses, cli::ReadFramePoses(dir + "/poses.txt"));
  RECOG_ASSIGN_OR_RETURN(std::vector<RgbdView> views,
                         cli::PosedRgbdViews(frames, poses, kRbtCubeCamera, 1000, {0, 16, 33, 49}));
  RECOG_ASSIGN_OR_RETURN(
      ObjectModel model,
      builder->FromRgbd(kRbtCubeName, views, ObjectBox{{0.085, 0.085, 0.085}, {0, 0, 0}}));
  return database->Put(model).status();
}

Status BuildDatabase(size_t distractors, bool rbt_cube, ObjectFixture* fixture) {
  if (!testing::HasSharedData(kModelsDir) ||
      (distractors > 0 && !testing::HasSharedData(kCaltechDir)) ||
      (rbt_cube && !testing::HasSharedData(kRbtCubeDir))) {
    return Status::NotFound("shared data not found under " + testing::SharedDataRoot().string() +
                            " (set RECOG_SHARED_DATA)");
  }
  RECOG_ASSIGN_OR_RETURN(Vocabulary loaded, LoadVocabulary(DefaultObjectVocabularyPath()));
  auto vocabulary = std::make_shared<const Vocabulary>(std::move(loaded));
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<ObjectDatabase> database,
                         ObjectDatabase::Open(&fixture->store, vocabulary));
  ModelBuildOptions options;
  options.keep_images = false;
  ModelBuilder builder(vocabulary, options);
  for (const std::string& dir : ModelFolders()) {
    RECOG_ASSIGN_OR_RETURN(ObjectModel model, builder.FromRoboEarth(dir));  // named by folder
    RECOG_RETURN_IF_ERROR(database->Put(model).status());
    std::fprintf(stderr, "bench_objects: model %s, %zu features\n", model.metadata.name.c_str(),
                 model.num_features());
  }
  RECOG_RETURN_IF_ERROR(AddDistractors(distractors, &builder, database.get()));
  if (rbt_cube) RECOG_RETURN_IF_ERROR(AddRbtCube(&builder, database.get()));
  fixture->database = std::move(database);
  fixture->distractors = distractors;
  return Status::Ok();
}

enum class Databases { kRoboEarth, kWithDistractors, kWithRbtCube };

// The database with the RoboEarth models, and the distractors or the visp-rbt-cube model, built
// on first use.
const ObjectFixture& Fixture(Databases which) {
  auto build = [](size_t distractors, bool rbt_cube) {
    auto fixture = std::make_unique<ObjectFixture>();
    fixture->status = BuildDatabase(distractors, rbt_cube, fixture.get());
    return fixture;
  };
  switch (which) {
    case Databases::kRoboEarth: {
      static const std::unique_ptr<ObjectFixture> plain = build(0, false);
      return *plain;
    }
    case Databases::kWithDistractors: {
      static const std::unique_ptr<ObjectFixture> with_distractors = build(kDistractors, false);
      return *with_distractors;
    }
    case Databases::kWithRbtCube:
      break;
  }
  static const std::unique_ptr<ObjectFixture> with_cube = build(0, true);
  return *with_cube;
}

// Recognises one query image per iteration, cycling through them, and reports the medians.
// An image that shows an object counts as detected when `expect` (any object when empty) is found.
void RunRecognition(benchmark::State& state, const std::vector<QueryImage>& queries,
                    Databases databases, const std::string& expect) {
  if (queries.empty()) {
    state.SkipWithError("shared data not found (set RECOG_SHARED_DATA) or unreadable");
    return;
  }
  const ObjectFixture& fixture = Fixture(databases);
  if (!fixture.status.ok()) {
    state.SkipWithError(fixture.status.ToString().c_str());
    return;
  }
  StatusOr<ObjectRecognizer> created = ObjectRecognizer::Create(fixture.database);
  if (!created.ok()) {
    state.SkipWithError(created.status().ToString().c_str());
    return;
  }
  ObjectRecognizer recognizer = std::move(created).value();
  std::vector<Detection> detections;
  // Warm-up, untimed: creates the ORB extractor and sizes the scratch memory.
  if (Status s = recognizer.Recognize(queries[0].image, queries[0].camera, &detections); !s.ok()) {
    state.SkipWithError(s.ToString().c_str());
    return;
  }
  std::vector<RecognitionTiming> timings;
  std::vector<bool> shows_object;
  size_t detected[2] = {0, 0};  // images with a detection: [0] without an object, [1] with one
  size_t next = 0;
  for (auto _ : state) {
    const QueryImage& query = queries[next];
    next = (next + 1) % queries.size();
    RecognitionTiming timing;
    if (Status s = recognizer.Recognize(query.image, query.camera, &detections, &timing); !s.ok()) {
      state.SkipWithError(s.ToString().c_str());
      return;
    }
    timings.push_back(timing);
    shows_object.push_back(query.shows_object);
    const bool found = expect.empty() || !query.shows_object
                           ? !detections.empty()
                           : std::any_of(detections.begin(), detections.end(),
                                         [&](const Detection& d) { return d.name == expect; });
    detected[query.shows_object ? 1 : 0] += found ? 1 : 0;
  }
  std::vector<RecognitionTiming> object_timings;
  std::vector<double> no_object_totals;
  for (size_t i = 0; i < timings.size(); ++i) {
    if (shows_object[i]) {
      object_timings.push_back(timings[i]);
    } else {
      no_object_totals.push_back(timings[i].total);
    }
  }
  auto median = [&](double RecognitionTiming::*stage) {
    std::vector<double> values;
    for (const RecognitionTiming& t : object_timings) values.push_back(t.*stage);
    return Median(values);
  };
  state.counters["orb_ms"] = median(&RecognitionTiming::orb);
  state.counters["clustering_ms"] = median(&RecognitionTiming::clustering);
  state.counters["conversion_ms"] = median(&RecognitionTiming::conversion);
  state.counters["query_ms"] = median(&RecognitionTiming::query);
  state.counters["di_ms"] = median(&RecognitionTiming::correspondences);
  state.counters["ransac_ms"] = median(&RecognitionTiming::ransac);
  state.counters["second_pass_ms"] = median(&RecognitionTiming::second_pass);
  state.counters["refinement_ms"] = median(&RecognitionTiming::refinement);
  state.counters["total_ms"] = median(&RecognitionTiming::total);
  state.counters["object_images"] = double(object_timings.size());
  state.counters["object_images_detected"] = double(detected[1]);
  state.counters["no_object_total_ms"] = Median(no_object_totals);
  state.counters["no_object_images"] = double(no_object_totals.size());
  state.counters["no_object_images_detected"] = double(detected[0]);
  state.counters["objects"] = double(fixture.database->size());
  if (fixture.distractors > 0) state.counters["distractors"] = double(fixture.distractors);
}

void BM_RecognizeRoboEarth(benchmark::State& state) {
  RunRecognition(state, QueryImages(), Databases::kRoboEarth, "");
}

void BM_RecognizeWith1000Distractors(benchmark::State& state) {
  RunRecognition(state, QueryImages(), Databases::kWithDistractors, "");
}

void BM_RecognizeRealClutter(benchmark::State& state) {
  RunRecognition(state, ClutterImages(), Databases::kWithRbtCube, kRbtCubeName);
}

// Random P3P samples for BM_SolveP3P and BM_OpenCvSolveP3P (see the file comment).
struct P3PSample {
  std::array<cv::Vec3d, 3> object, rays;
  std::vector<cv::Point3f> object_points;
  std::vector<cv::Point2f> pixels;  // the rays as pixels of a camera with K = I
};

const std::vector<P3PSample>& P3PSamples() {
  static const std::vector<P3PSample> samples = [] {
    std::mt19937_64 random(3);
    std::uniform_real_distribution<double> unit(-1, 1);
    std::vector<P3PSample> out(1024);
    for (P3PSample& s : out) {
      cv::Matx33d R;
      cv::Rodrigues(cv::Vec3d(unit(random), unit(random), unit(random)) * 1.5, R);
      const cv::Vec3d t(0.2 * unit(random), 0.2 * unit(random), 1.15 + 0.85 * unit(random));
      for (size_t i = 0; i < 3; ++i) {
        s.object[i] = cv::Vec3d(unit(random), unit(random), unit(random)) * 0.1;
        const cv::Vec3d camera = R * s.object[i] + t;
        s.rays[i] = camera / camera[2];
        s.object_points.emplace_back(cv::Vec3f(s.object[i]));
        s.pixels.emplace_back(float(s.rays[i][0]), float(s.rays[i][1]));
      }
    }
    return out;
  }();
  return samples;
}

void BM_SolveP3P(benchmark::State& state) {
  const std::vector<P3PSample>& samples = P3PSamples();
  std::array<P3PSolution, 4> solutions;
  size_t next = 0, found = 0;
  for (auto _ : state) {
    const P3PSample& s = samples[next++ % samples.size()];
    found += SolveP3P(s.object, s.rays, &solutions);
    benchmark::DoNotOptimize(solutions);
  }
  state.counters["solutions_per_call"] = double(found) / double(state.iterations());
}

void BM_OpenCvSolveP3P(benchmark::State& state) {
  const std::vector<P3PSample>& samples = P3PSamples();
  const cv::Matx33d K = cv::Matx33d::eye();
  std::vector<cv::Mat> rvecs, tvecs;
  size_t next = 0, found = 0;
  for (auto _ : state) {
    const P3PSample& s = samples[next++ % samples.size()];
    found += size_t(
        cv::solveP3P(s.object_points, s.pixels, K, cv::noArray(), rvecs, tvecs, cv::SOLVEPNP_P3P));
    benchmark::DoNotOptimize(rvecs);
  }
  state.counters["solutions_per_call"] = double(found) / double(state.iterations());
}

}  // namespace
}  // namespace recog::bench

// The iteration count is the number of query images (each is recognised once), known only once
// they are listed, so the benchmarks are registered here rather than with BENCHMARK().
int main(int argc, char** argv) {
  cv::setNumThreads(0);  // no OpenCV worker threads: everything runs on this one
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  const auto iterations =
      benchmark::IterationCount(std::max<size_t>(1, recog::bench::QueryImages().size()));
  benchmark::RegisterBenchmark("BM_RecognizeRoboEarth", recog::bench::BM_RecognizeRoboEarth)
      ->Unit(benchmark::kMillisecond)
      ->Iterations(iterations);
  benchmark::RegisterBenchmark("BM_RecognizeWith1000Distractors",
                               recog::bench::BM_RecognizeWith1000Distractors)
      ->Unit(benchmark::kMillisecond)
      ->Iterations(iterations);
  benchmark::RegisterBenchmark("BM_RecognizeRealClutter", recog::bench::BM_RecognizeRealClutter)
      ->Unit(benchmark::kMillisecond)
      ->Iterations(
          benchmark::IterationCount(std::max<size_t>(1, recog::bench::ClutterImages().size())));
  benchmark::RegisterBenchmark("BM_SolveP3P", recog::bench::BM_SolveP3P)
      ->Unit(benchmark::kMicrosecond);
  benchmark::RegisterBenchmark("BM_OpenCvSolveP3P", recog::bench::BM_OpenCvSolveP3P)
      ->Unit(benchmark::kMicrosecond);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
