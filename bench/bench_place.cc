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
//   Relocalize_Group10x2600_vs_One26K  a relocalisation (core Relocalize, one frame) in a group
//                 of 10 maps of 2,600 frames each against the same 26,000 frames in one map:
//                 median ms of each and their ratio (see RelocalisationFleet).
//   Rig_2Cameras_26K  the rig detector (core RigLoopDetector) per rig frame of a front + rear
//                 rig once its map holds 26,000 camera images (13,000 rig frames), then 200 rig
//                 frames driving back the other way: each camera sees, with its keypoints moved
//                 half a pixel, a subset of what the other camera saw on the way out. Median ms
//                 of the detector per rig frame (conversion of both images, both queries, the
//                 pairs' verification, the check across the rig, insertion); ORB is not in it
//                 (two 640x480 extractions, reported apart). A cost benchmark: the views are
//                 photos, not a 3D scene (accuracy: recog eval place --rig, rig_place_test).
// Needs the shared Caltech photos (falls back to the 4 bundled frames, which gives a degenerate
// tour). Long: about 40 minutes in all on 2 cores (the distinct-place filter of the 4,400-photo
// tour takes most of it). Run: build/bin/bench_place [--benchmark_filter=...]
#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iterator>
#include <numeric>
#include <optional>
#include <random>
#include <span>
#include <thread>

#include "bench/bench_support.h"
#include "core/common/elapsed.h"
#include "core/common/median.h"
#include "core/geometry/frame_points.h"
#include "core/index/memory_index_store.h"
#include "core/place/map_registry.h"
#include "core/place/map_search.h"
#include "core/place/rig_loop_detector.h"
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
      (*feature_ms)[size_t(i - begin)] = MillisecondsSince(start);
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
        points_ms = MillisecondsSince(start);
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
    state.counters["median_ms_" + stage] = Median(values);
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
      state.counters[m.name + "_verify_median_ms"] = Median(verification);
      state.counters[m.name + "_verify_max_ms"] =
          verification.empty() ? 0 : *std::max_element(verification.begin(), verification.end());
    }
  }
  state.counters["frames"] = generator->num_frames();
  state.counters["query_frames_with_truth"] = truth.QueriesWithMatches();
}
BENCHMARK(BM_Table42)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

// A random 60-100 % of `all`'s features (another view of the same place, for a cost benchmark).
FeatureSet FeatureSubset(const FeatureSet& all, std::mt19937_64& rng) {
  std::vector<int> rows(all.size());
  std::iota(rows.begin(), rows.end(), 0);
  std::shuffle(rows.begin(), rows.end(), rng);
  rows.resize(size_t(double(rows.size()) * std::uniform_real_distribution<double>(0.6, 1.0)(rng)));
  FeatureSet subset;
  for (int r : rows) {
    subset.keypoints.push_back(all.keypoints[size_t(r)]);
    subset.descriptors.push_back(all.descriptors.row(r));
  }
  return subset;
}

// The features of the shared Caltech photos with at least 50 keypoints (the 4 bundled frames
// without them), and the median ms of their extraction.
std::vector<FeatureSet> PhotoFeatures(double* extraction_median_ms) {
  cli::SequenceOptions unused;
  auto extractor = std::move(CreateFeatureExtractor(PlaceFeatureOptions())).value();
  std::vector<FeatureSet> photos;
  std::vector<double> ms;
  FeatureSet features;
  for (const std::string& file : TourPhotos(&unused)) {
    auto image = ReadGrayImage(file);
    if (!image.ok()) continue;
    const auto start = std::chrono::steady_clock::now();
    if (!extractor->Extract(*image, &features).ok()) continue;
    ms.push_back(MillisecondsSince(start));
    if (features.size() >= 50) photos.push_back(features);
  }
  std::fprintf(stderr, "bench_place: features of %zu photos\n", photos.size());
  if (extraction_median_ms != nullptr) *extraction_median_ms = Median(ms);
  return photos;
}

// `frame`'s keypoints moved by Gaussian noise of `sigma_px` (another exposure of the same view).
FeatureSet Jittered(FeatureSet frame, double sigma_px, std::mt19937_64& rng) {
  std::normal_distribution<float> noise(0.0f, float(sigma_px));
  for (cv::KeyPoint& k : frame.keypoints) k.pt += cv::Point2f(noise(rng), noise(rng));
  return frame;
}

// A fleet's 26,000 frames twice over: as 10 maps of 2,600 frames (one group: each robot has seen
// its own tenth of the shared Caltech photos, every photo about five times as 60-100 % subsets of
// its features) and as one map of the same 26,000 frames. The queries are 200 fresh subsets of
// photos drawn at random: each place is in exactly one map of the group, and in the one map.
struct RelocalisationFleet {
  MemoryIndexStore store;
  std::unique_ptr<MapRegistry> registry;
  std::vector<std::shared_ptr<PlaceMap>> group, one;
  std::vector<FeatureSet> queries;
  std::vector<size_t> query_map;  // the group's map that has the query's place
};

const RelocalisationFleet& GetRelocalisationFleet() {
  static RelocalisationFleet* fleet = [] {
    constexpr size_t kMaps = 10, kFramesPerMap = 2600, kQueries = 200;
    auto* f = new RelocalisationFleet;
    const std::vector<FeatureSet> photos = PhotoFeatures(nullptr);
    auto vocabulary = std::make_shared<const Vocabulary>(LoadBundledPlaceVocabulary());
    f->registry = std::move(MapRegistry::Open(&f->store, vocabulary)).value();
    f->one.push_back(std::move(f->registry->Create("one", {})).value());
    std::mt19937_64 rng(26);
    const size_t per_map = std::max<size_t>(1, photos.size() / kMaps);
    for (size_t m = 0; m < kMaps; ++m) {
      auto map = std::move(f->registry->Create("robot-" + std::to_string(m), {}, "fleet")).value();
      for (size_t i = 0; i < kFramesPerMap; ++i) {
        const FeatureSet frame =
            FeatureSubset(photos[(m * per_map + i % per_map) % photos.size()], rng);
        if (!map->Add(frame, std::nullopt).ok() || !f->one[0]->Add(frame, std::nullopt).ok()) {
          std::exit(2);
        }
      }
      f->group.push_back(std::move(map));
      std::fprintf(stderr, "bench_place: %zu / %zu maps\n", m + 1, kMaps);
    }
    for (size_t q = 0; q < kQueries; ++q) {
      const size_t m = rng() % kMaps, photo = m * per_map + rng() % per_map;
      f->queries.push_back(FeatureSubset(photos[photo % photos.size()], rng));
      f->query_map.push_back(m);
    }
    return f;
  }();
  return *fleet;
}

void BM_Relocalize_Group10x2600_vs_One26K(benchmark::State& state) {
  const RelocalisationFleet& fleet = GetRelocalisationFleet();
  std::vector<double> group_ms, one_ms;
  int group_found = 0, one_found = 0;
  const auto timed = [](std::span<const std::shared_ptr<PlaceMap>> maps, const FeatureSet& frame,
                        std::vector<double>* ms) {
    const RelocalizationFrame query{&frame, nullptr};
    const auto start = std::chrono::steady_clock::now();
    auto found = Relocalize(maps, std::span(&query, 1));
    ms->push_back(MillisecondsSince(start));
    if (!found.ok()) std::exit(2);
    return std::move(found).value();
  };
  for (auto _ : state) {
    for (size_t q = 0; q < fleet.queries.size(); ++q) {  // alternating, to share the noise
      const auto in_group = timed(fleet.group, fleet.queries[q], &group_ms);
      group_found +=
          !in_group.empty() && in_group.front().map == fleet.group[fleet.query_map[q]]->name();
      one_found += !timed(fleet.one, fleet.queries[q], &one_ms).empty();
    }
  }
  // Where a group query's time goes: SearchMaps' steps, timed one by one.
  std::vector<double> convert_ms, shortlist_ms, one_shortlist_ms, recognise_ms, verified_maps;
  for (const FeatureSet& query : fleet.queries) {
    LoopDetector::ConvertedFrame frame;
    auto start = std::chrono::steady_clock::now();
    if (!fleet.group[0]->ConvertForQuery(query, &frame).ok()) std::exit(2);
    convert_ms.push_back(MillisecondsSince(start));
    start = std::chrono::steady_clock::now();
    std::vector<LoopDetector::Shortlist> shortlists;
    double reference = 0;
    for (const auto& map : fleet.group) {
      shortlists.push_back(std::move(map->Shortlist(frame)).value());
      reference = std::max(reference, shortlists.back().best_score);
    }
    shortlist_ms.push_back(MillisecondsSince(start));
    start = std::chrono::steady_clock::now();
    if (!fleet.one[0]->Shortlist(frame).ok()) std::exit(2);
    one_shortlist_ms.push_back(MillisecondsSince(start));
    start = std::chrono::steady_clock::now();
    int verified = 0;
    for (size_t m = 0; m < fleet.group.size(); ++m) {
      auto r = fleet.group[m]->Recognise(query, frame, shortlists[m], reference);
      verified += r.ok() && r->loop.timings.verification > 0;
    }
    recognise_ms.push_back(MillisecondsSince(start));
    verified_maps.push_back(verified);
  }
  state.counters["group_conversion_median_ms"] = Median(convert_ms);
  state.counters["group_shortlists_median_ms"] = Median(shortlist_ms);
  state.counters["group_recognise_median_ms"] = Median(recognise_ms);
  state.counters["one_map_shortlist_median_ms"] = Median(one_shortlist_ms);
  state.counters["group_verified_maps_median"] = Median(verified_maps);
  state.counters["group_median_ms"] = Median(group_ms);
  state.counters["one_map_median_ms"] = Median(one_ms);
  state.counters["ratio"] = Median(group_ms) / Median(one_ms);
  state.counters["queries"] = double(fleet.queries.size());
  state.counters["group_right_map_first"] = group_found;
  state.counters["one_map_recognised"] = one_found;
}
BENCHMARK(BM_Relocalize_Group10x2600_vs_One26K)
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->UseRealTime();

void BM_Rig_2Cameras_26K(benchmark::State& state) {
  constexpr size_t kRigFrames = 13000, kQueries = 200;
  double extraction_ms = 0;
  const std::vector<FeatureSet> photos = PhotoFeatures(&extraction_ms);
  const cv::Matx33d K(400, 0, 319.5, 0, 400, 239.5, 0, 0, 1);
  // Images of 640x480, or larger where a photo is (a rig frame's keypoints must be inside).
  cv::Size size(640, 480);
  for (const FeatureSet& photo : photos) {
    for (const cv::KeyPoint& k : photo.keypoints) {
      size.width = std::max(size.width, int(std::ceil(k.pt.x + 1.5f)));
      size.height = std::max(size.height, int(std::ceil(k.pt.y + 1.5f)));
    }
  }
  const std::vector<RigCamera> rig = {
      {.name = "front", .size = size, .K = K, .distortion = {}, .body_t_camera = {0, 0, 0.4}},
      {.name = "rear",
       .size = size,
       .K = K,
       .distortion = {},
       .body_R_camera = cv::Matx33d(-1, 0, 0, 0, 1, 0, 0, 0, -1),
       .body_t_camera = {0, 0, -0.4}}};
  auto vocabulary = std::make_shared<const Vocabulary>(LoadBundledPlaceVocabulary());
  std::mt19937_64 rng(13);
  std::map<std::string, std::vector<double>> times;
  std::map<std::string, int> statuses;
  for (auto _ : state) {
    MemoryIndexStore store;
    auto db = std::move(Database::Create(&store, "rig", vocabulary)).value();
    auto detector = std::move(RigLoopDetector::Create(db.get(), rig, {})).value();
    // One rig frame a second; the way out's front and rear cameras see photos 2f and 2f + 1.
    std::vector<RigFrame> out(kRigFrames);
    for (size_t f = 0; f < kRigFrames; ++f) {
      out[f].cameras = {FeatureSubset(photos[(2 * f) % photos.size()], rng),
                        FeatureSubset(photos[(2 * f + 1) % photos.size()], rng)};
      out[f].timestamp = double(f);
      if (auto added = detector.Add(out[f]); !added.ok()) {
        std::fprintf(stderr, "bench_place: %s\n", added.status().ToString().c_str());
        std::exit(2);
      }
      if ((f + 1) % 1000 == 0) {
        std::fprintf(stderr, "bench_place: rig map %zu / %zu frames\n", f + 1, kRigFrames);
      }
    }
    for (size_t q = 0; q < kQueries; ++q) {
      const RigFrame& seen = out[rng() % kRigFrames];
      RigFrame back;  // driving the other way: front sees the rear's view, rear the front's
      back.cameras = {Jittered(seen.cameras[1], 0.5, rng), Jittered(seen.cameras[0], 0.5, rng)};
      back.timestamp = double(kRigFrames + 60 + q);
      auto r = detector.Process(back);
      if (!r.ok()) {
        std::fprintf(stderr, "bench_place: %s\n", r.status().ToString().c_str());
        std::exit(2);
      }
      const RigLoopTimings& t = r->timings;
      times["conversion"].push_back(t.conversion);
      times["query"].push_back(t.query);
      times["verification"].push_back(t.verification);
      times["insertion"].push_back(t.insertion);
      times["detector"].push_back(t.conversion + t.query + t.verification + t.insertion);
      ++statuses[std::string(RigLoopStatusName(r->status))];
    }
    state.counters["map_camera_images"] = double(2 * kRigFrames);
  }
  for (const auto& [stage, values] : times) {
    state.counters["median_ms_" + stage] = Median(values);
  }
  state.counters["median_ms_features_one_image"] = extraction_ms;
  state.counters["rig_frames_measured"] = double(times["detector"].size());
  for (const auto& [status, count] : statuses) state.counters["status_" + status] = count;
}
BENCHMARK(BM_Rig_2Cameras_26K)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

}  // namespace
}  // namespace recog::bench

BENCHMARK_MAIN();
