// Place recognition benchmarks (issue "place recognition"):
//   Pipeline_26K  the whole loop-detection pipeline per 640x480 frame (1000 ORB features, one
//                 thread) once the map holds 26,000 frames: a recog seqgen tour of 4,400 distinct
//                 Caltech photos (6 frames each) followed by revisits; the timings of the frames
//                 processed after the 26,000th are reported as medians, stage by stage (thesis
//                 Table 4.3), with the precision of the detections among them.
//   Pipeline_26K_Depth  the same with a depth image per frame (a plane 2 m away): the 3D points
//                 (PointsFromDepth), entries that keep them and the 3D check of loops included.
//                 Both share one tour, generated and extracted once.
//   Table42       correspondences through the direct index at levels 0-3 against exhaustive
//                 matching (thesis Table 4.2): recall and verification time on a seqgen tour of
//                 200 distinct places, 10 frames a visit, 50 % revisits.
// Needs the shared Caltech photos (falls back to the 4 bundled frames, which gives a degenerate
// tour). Long: about 40 minutes in all on 2 cores (the distinct-place filter of the 4,400-photo
// tour takes most of it). Run: build/bin/bench_place [--benchmark_filter=...]
#include <benchmark/benchmark.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <iterator>
#include <optional>
#include <thread>

#include "bench/bench_support.h"
#include "core/geometry/frame_points.h"
#include "core/index/memory_index_store.h"
#include "tests/testing/data_paths.h"
#include "tools/common/cli_support.h"
#include "tools/evaluation/place_evaluation.h"
#include "tools/evaluation/sequence_generator.h"

namespace recog::bench {
namespace {

// The shared Caltech photos; without them the 4 bundled frames, which show one corridor and so
// cannot give distinct places (the tour then reuses them, and precision means little).
std::vector<std::string> TourPhotos(cli::SequenceOptions* options) {
  const std::string caltech = testing::SharedData("training/caltech101");
  const bool shared = std::filesystem::exists(caltech);
  options->distinct_places = shared;
  auto files = cli::ListImages(shared ? caltech : testing::ProjectTestData("corridor"));
  if (!files.ok()) std::exit(2);
  return *files;
}

// Generates and extracts frames [begin, end) with two threads, in order.
std::vector<FeatureSet> ExtractFrames(const cli::SequenceGenerator& generator, int begin, int end,
                                      std::vector<double>* feature_ms) {
  std::vector<FeatureSet> features(size_t(end - begin));
  feature_ms->assign(size_t(end - begin), 0.0);
  std::atomic<int> next{begin};
  auto work = [&] {
    auto extractor = std::move(CreateFeatureExtractor(PlaceFeatureOptions())).value();
    for (int i = next++; i < end; i = next++) {
      auto frame = generator.Frame(i);
      if (!frame.ok()) std::exit(2);
      const auto start = std::chrono::steady_clock::now();
      if (!extractor->Extract(frame->image, &features[size_t(i - begin)]).ok()) std::exit(2);
      (*feature_ms)[size_t(i - begin)] =
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
              .count();
    }
  };
  std::thread helper(work);
  work();
  helper.join();
  return features;
}

// The Pipeline tour, generated and extracted once for both Pipeline benchmarks (its photos go
// through seqgen's distinct-place filter, which takes most of the setup).
struct PipelineTour {
  std::optional<cli::SequenceGenerator> generator;
  std::vector<FeatureSet> features;
  std::vector<double> feature_ms;
};

const PipelineTour& GetPipelineTour() {
  static const PipelineTour tour = [] {
    PipelineTour t;
    cli::SequenceOptions options;
    options.places = 4400;
    options.frames_per_place = 6;
    options.revisit_fraction = 0.03;  // 132 revisits, 792 frames after the first 26,400
    const std::vector<std::string> photos = TourPhotos(&options);
    auto generator = cli::SequenceGenerator::Create(photos, options);
    if (!generator.ok()) {
      std::fprintf(stderr, "bench_place: %s\n", generator.status().ToString().c_str());
      std::exit(2);
    }
    t.generator.emplace(std::move(generator).value());
    const int frames = t.generator->num_frames();
    for (int begin = 0; begin < frames; begin += 1000) {
      const int end = std::min(frames, begin + 1000);
      std::vector<double> feature_ms;
      std::vector<FeatureSet> batch = ExtractFrames(*t.generator, begin, end, &feature_ms);
      std::move(batch.begin(), batch.end(), std::back_inserter(t.features));
      t.feature_ms.insert(t.feature_ms.end(), feature_ms.begin(), feature_ms.end());
      std::fprintf(stderr, "bench_place: features of %d / %d frames\n", end, frames);
    }
    return t;
  }();
  return tour;
}

// The whole pipeline over the tour with the detector `params`; with_depth: every frame comes
// with a depth image (a plane 2 m in front of the camera: seqgen's frames are warps of flat
// photos) whose 3D points the entries keep and the loops are checked with (PnP,
// LoopResult::metric).
void RunPipeline(benchmark::State& state, const LoopDetectorParams& params, bool with_depth) {
  const PipelineTour& tour = GetPipelineTour();
  auto vocabulary = std::make_shared<const Vocabulary>(LoadBundledPlaceVocabulary());
  MemoryIndexStore store;
  auto db = std::move(Database::Create(&store, "tour", vocabulary)).value();
  auto detector = std::move(LoopDetector::Create(db.get(), params)).value();
  const cv::Size size(640, 480);
  const cv::Mat depth(size, CV_16U, cv::Scalar(2000));
  FrameGeometry geometry{cv::Matx33d(525, 0, 319.5, 0, 525, 239.5, 0, 0, 1), {}};
  std::map<std::string, std::vector<double>> times;
  int detections = 0, correct = 0, metric_verified = 0;
  for (auto _ : state) {
    for (int i = 0; i < int(tour.features.size()); ++i) {
      const FeatureSet& features = tour.features[size_t(i)];
      double points_ms = 0;
      if (with_depth) {
        const auto start = std::chrono::steady_clock::now();
        if (!PointsFromDepth(features.keypoints, size, geometry.K, depth, 0.001, &geometry.points)
                 .ok()) {
          std::exit(2);
        }
        points_ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                .count();
      }
      auto r = detector.Process(features, std::nullopt, {}, with_depth ? &geometry : nullptr);
      if (!r.ok()) std::exit(2);
      if (db->size() <= 26000) continue;  // measure once the map holds 26,000 frames
      const LoopTimings& t = r->timings;
      const double extraction = tour.feature_ms[size_t(i)];
      times["features"].push_back(extraction);
      times["conversion"].push_back(t.conversion);
      times["query"].push_back(t.query);
      times["islands"].push_back(t.islands);
      times["insertion"].push_back(t.insertion);
      times["bow_stages"].push_back(t.conversion + t.query + t.islands + t.insertion);
      if (t.verification > 0) times["verification_when_run"].push_back(t.verification);
      if (with_depth) {
        times["points"].push_back(points_ms);
        if (r->metric.checked)
          times["metric_verification_when_run"].push_back(t.metric_verification);
      }
      times["total"].push_back(extraction + points_ms + t.conversion + t.query + t.islands +
                               t.insertion + t.verification + t.metric_verification);
      if (r->status == LoopStatus::kLoopDetected) {
        ++detections;
        correct += tour.generator->SamePlace(i, int(r->match));
        metric_verified += r->metric.verified;
      }
    }
  }
  for (const auto& [stage, values] : times) {
    state.counters["median_ms_" + stage] = cli::Median(values);
  }
  state.counters["measured_frames"] = double(times["total"].size());
  state.counters["verifications"] = double(times["verification_when_run"].size());
  state.counters["map_entries"] = double(db->size());
  state.counters["detections"] = detections;
  state.counters["correct"] = correct;
  if (with_depth) state.counters["metric_verified"] = metric_verified;
}

void BM_Pipeline_26K(benchmark::State& state) { RunPipeline(state, {}, false); }
void BM_Pipeline_26K_Depth(benchmark::State& state) { RunPipeline(state, {}, true); }
// The keyframes preset: every frame is queried (no gate on the score with the previous frame).
void BM_Pipeline_26K_Keyframes(benchmark::State& state) {
  RunPipeline(state, LoopDetectorParams::Keyframes(), false);
}
BENCHMARK(BM_Pipeline_26K)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK(BM_Pipeline_26K_Depth)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK(BM_Pipeline_26K_Keyframes)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

void BM_Table42(benchmark::State& state) {
  cli::SequenceOptions options;
  options.places = 200;
  options.frames_per_place = 10;
  options.revisit_fraction = 0.5;
  const std::vector<std::string> photos = TourPhotos(&options);
  auto generator = cli::SequenceGenerator::Create(photos, options);
  if (!generator.ok()) {
    state.SkipWithError(generator.status().ToString().c_str());
    return;
  }
  cli::SequenceFeatures sequence;
  sequence.features = ExtractFrames(*generator, 0, generator->num_frames(), &sequence.feature_ms);
  for (int i = 0; i < generator->num_frames(); ++i) sequence.names.push_back(std::to_string(i + 1));
  const cli::GroundTruth truth = generator->BuildGroundTruth();
  auto vocabulary = std::make_shared<const Vocabulary>(LoadBundledPlaceVocabulary());
  struct Method {
    std::string name;
    GeometryCheck check;
    uint32_t levels_up;
  };
  const std::vector<Method> methods = {{"DI0", GeometryCheck::kDirectIndex, 0},
                                       {"DI1", GeometryCheck::kDirectIndex, 1},
                                       {"DI2", GeometryCheck::kDirectIndex, 2},
                                       {"DI3", GeometryCheck::kDirectIndex, 3},
                                       {"Exhaustive", GeometryCheck::kExhaustive, 2}};
  for (auto _ : state) {
    for (const Method& m : methods) {
      cli::PlaceEvaluationOptions o;
      o.detector.geometry = m.check;
      o.direct_index_levels_up = m.levels_up;
      std::vector<LoopResult> results;
      auto e = cli::EvaluatePlace(sequence, truth, vocabulary, o, &results);
      if (!e.ok()) std::exit(2);
      std::vector<double> verification;
      for (const LoopResult& r : results) {
        if (r.timings.verification > 0) verification.push_back(r.timings.verification);
      }
      state.counters[m.name + "_recall"] = e->recall;
      state.counters[m.name + "_precision"] = e->precision;
      state.counters[m.name + "_verify_median_ms"] = cli::Median(verification);
      state.counters[m.name + "_verify_max_ms"] =
          verification.empty() ? 0 : *std::max_element(verification.begin(), verification.end());
    }
  }
  state.counters["frames"] = generator->num_frames();
  state.counters["query_frames_with_truth"] = truth.QueriesWithMatches();
}
BENCHMARK(BM_Table42)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

}  // namespace
}  // namespace recog::bench

BENCHMARK_MAIN();
