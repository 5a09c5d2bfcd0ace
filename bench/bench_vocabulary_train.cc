// Training benchmark: the default place vocabulary (k=10, L=5, ORB, 1000 features per image) from
// every photo of the shared Caltech-101 set, with 2 threads, once. Reports the time of each stage
// and the peak resident memory of the process. Needs the shared data (skips otherwise).
// Run: build/bin/bench_vocabulary_train [--benchmark_format=json]
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <chrono>
#include <filesystem>

#include "core/features/training_images.h"
#include "core/vocabulary/vocabulary_trainer.h"
#include "tests/testing/data_paths.h"
#include "tools/common/cli_support.h"

namespace recog::bench {
namespace {

// The shared Caltech photos, or nothing when the shared data is absent.
std::vector<std::string> CaltechImages() {
  auto files = cli::ListImages(testing::SharedData("training/caltech101"));
  return files.ok() ? std::move(files).value() : std::vector<std::string>{};
}

void BM_TrainPlaceVocabulary_Caltech(benchmark::State& state) {
  const std::vector<std::string> files = CaltechImages();
  if (files.empty()) {
    state.SkipWithError("shared Caltech photos not found (set RECOG_SHARED_DATA)");
    return;
  }
  using Clock = std::chrono::steady_clock;
  double extraction_s = 0, clustering_s = 0;
  size_t descriptors = 0, words = 0;
  for (auto _ : state) {
    const auto t0 = Clock::now();
    FeatureOptions features;
    features.orb.max_features = 1000;
    auto set = ExtractTrainingSet(files, features, 2, nullptr, nullptr);
    if (!set.ok()) {
      state.SkipWithError(set.status().ToString().c_str());
      return;
    }
    descriptors = set->num_descriptors();
    const auto t1 = Clock::now();
    TrainingOptions options;  // defaults: k=10, L=5, tf-idf, seed 42
    options.threads = 2;
    auto vocabulary = TrainVocabulary(std::move(set).value(), options);
    if (!vocabulary.ok()) {
      state.SkipWithError(vocabulary.status().ToString().c_str());
      return;
    }
    words = vocabulary->num_words();
    const auto t2 = Clock::now();
    extraction_s = std::chrono::duration<double>(t1 - t0).count();
    clustering_s = std::chrono::duration<double>(t2 - t1).count();
  }
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  state.counters["images"] = double(files.size());
  state.counters["descriptors"] = double(descriptors);
  state.counters["words"] = double(words);
  state.counters["features_s"] = extraction_s;
  state.counters["clustering_weighting_s"] = clustering_s;
  state.counters["peak_rss_MiB"] = double(usage.ru_maxrss) / 1024.0;
}
BENCHMARK(BM_TrainPlaceVocabulary_Caltech)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

}  // namespace
}  // namespace recog::bench

BENCHMARK_MAIN();
