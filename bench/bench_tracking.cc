// Object tracking speed (issue 16, "tracking across a stream"):
//   BM_TrackVispCube  ObjectTracker::Track with default options, one thread, on the 218 frames of
//                     objects/visp-cube in order (640x480, an 8.4 cm cube moved by hand), one frame
//                     per iteration. The model is built as docs/objects.md builds it: the CAD faces
//                     (cube.cao), the frame-0 pose (cube.0.pos) and frame 0, with ViSP's
//                     intrinsics (547, 547, 338, 234); it is the only object in the database.
// Counters: tracking_ms_per_object, the headline, is the median over the frames that followed at
// least one tracked object of TrackingTiming::tracking / (objects tracked + objects lost): feature
// extraction in the predicted box, window matching and PnP for one object. tracked_frame_ms and
// recognized_frame_ms are the medians of the whole frame's time on frames that were only tracked
// and on frames where the full recognition ran; frames_tracked, frames_recognized and
// frames_found count them (frames_found: the cube was reported). One untimed warm-up frame first
// (creates the extractors and sizes the scratch memory), then the tracker is reset.
// Needs the shared data (RECOG_SHARED_DATA, default ../shared/data); skipped without it.
// Run: build/bin/bench_tracking
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/utility.hpp>

#include "core/common/median.h"
#include "core/index/memory_index_store.h"
#include "core/object/builder/model_builder.h"
#include "core/object/tracking/object_tracker.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tests/testing/data_paths.h"
#include "tools/common/cli_support.h"
#include "tools/evaluation/place_evaluation.h"
#include "tools/evaluation/visp_files.h"

namespace recog::bench {
namespace {

constexpr char kVispDir[] = "objects/visp-cube";

struct TrackingFixture {
  Status status = Status::Ok();
  CameraIntrinsics camera = {547, 547, 338, 234, {}};
  std::vector<cv::Mat> frames;
  MemoryIndexStore store;
  std::shared_ptr<ObjectDatabase> database;
};

Status Build(TrackingFixture* f) {
  const std::string dir = testing::SharedData(kVispDir);
  RECOG_ASSIGN_OR_RETURN(std::vector<std::string> paths, cli::ListImages(dir + "/images"));
  for (const std::string& path : paths) {
    RECOG_ASSIGN_OR_RETURN(cv::Mat image, ReadGrayImage(path));
    f->frames.push_back(std::move(image));
  }
  if (f->frames.empty()) return Status::NotFound("no frames in " + dir + "/images");
  RECOG_ASSIGN_OR_RETURN(Vocabulary loaded, LoadVocabulary(DefaultObjectVocabularyPath()));
  auto vocabulary = std::make_shared<const Vocabulary>(std::move(loaded));
  RECOG_ASSIGN_OR_RETURN(std::vector<FacePolygon> faces, cli::ReadCaoFaces(dir + "/cube.cao"));
  PosedImage view;
  view.name = "image0000";
  view.image = f->frames[0];
  view.camera = f->camera;
  RECOG_ASSIGN_OR_RETURN(view.camera_from_object, cli::ReadVispPose(dir + "/cube.0.pos"));
  ModelBuildOptions build;
  build.keep_images = false;
  ModelBuilder builder(vocabulary, build);
  RECOG_ASSIGN_OR_RETURN(ObjectModel model, builder.FromPosedPolygons("visp-cube", faces, {view}));
  RECOG_ASSIGN_OR_RETURN(f->database, ObjectDatabase::Open(&f->store, vocabulary));
  RECOG_RETURN_IF_ERROR(f->database->Put(model).status());
  return Status::Ok();
}

const TrackingFixture& Fixture() {
  static TrackingFixture* fixture = [] {
    auto* f = new TrackingFixture;
    f->status = Build(f);
    return f;
  }();
  return *fixture;
}

void BM_TrackVispCube(benchmark::State& state) {
  const TrackingFixture& fixture = Fixture();
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
  ObjectTracker tracker(fixture.database);
  std::vector<Detection> detections;
  if (Status s = tracker.Track(recognizer, fixture.frames[0], fixture.camera, &detections);
      !s.ok()) {
    state.SkipWithError(s.ToString().c_str());
    return;
  }
  tracker.Reset();
  std::vector<double> per_object, tracked_frames, recognized_frames;
  size_t found = 0, next = 0;
  for (auto _ : state) {
    if (next == 0) tracker.Reset();
    TrackingTiming timing;
    if (Status s =
            tracker.Track(recognizer, fixture.frames[next], fixture.camera, &detections, &timing);
        !s.ok()) {
      state.SkipWithError(s.ToString().c_str());
      return;
    }
    next = (next + 1) % fixture.frames.size();
    found += detections.empty() ? 0 : 1;
    (timing.recognized ? recognized_frames : tracked_frames).push_back(timing.total);
    if (timing.tracked + timing.lost > 0) {
      per_object.push_back(timing.tracking / double(timing.tracked + timing.lost));
    }
  }
  state.counters["tracking_ms_per_object"] = Median(per_object);
  state.counters["tracked_frame_ms"] = Median(tracked_frames);
  state.counters["recognized_frame_ms"] = Median(recognized_frames);
  state.counters["frames_tracked"] = double(tracked_frames.size());
  state.counters["frames_recognized"] = double(recognized_frames.size());
  state.counters["frames_found"] = double(found);
}

}  // namespace
}  // namespace recog::bench

// One iteration per frame of the sequence, known only once the frames are read, so the benchmark
// is registered here rather than with BENCHMARK().
int main(int argc, char** argv) {
  cv::setNumThreads(0);  // no OpenCV worker threads: everything runs on this one
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  const size_t frames = recog::bench::Fixture().frames.size();
  benchmark::RegisterBenchmark("BM_TrackVispCube", recog::bench::BM_TrackVispCube)
      ->Unit(benchmark::kMillisecond)
      ->Iterations(benchmark::IterationCount(std::max<size_t>(1, frames)));
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
