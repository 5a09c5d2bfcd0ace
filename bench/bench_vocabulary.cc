// Vocabulary benchmarks (issue "bags-of-binary-words core"):
//   Transform/*      1000 real ORB descriptors -> BoW vector + direct-index entry (levels_up 2)
//   LoadProject/1M   load a 1M-word vocabulary in the project format (file in the page cache)
//   ImportDbow2Text/1M  import the same vocabulary from DBoW2 text (ORBvoc.txt layout)
//   ImportDbow2Yaml/brief  import the shared 24,830-word BRIEF YAML (skipped without shared data)
// Run: build/bin/bench_vocabulary [--benchmark_format=json]
#include <benchmark/benchmark.h>

#include <cstdio>
#include <filesystem>

#include "bench/bench_support.h"
#include "core/vocabulary/dbow2_format.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tests/testing/data_paths.h"

namespace recog::bench {
namespace {

constexpr int kFeatures = 1000;
constexpr int kLevelsUp = 2;

void TransformBenchmark(benchmark::State& state, const Vocabulary& vocabulary) {
  static const std::vector<cv::Mat> sets = CorridorDescriptorSets(kFeatures);
  BowVector bow;
  FeatureVector direct;
  size_t i = 0;
  for (auto _ : state) {
    const Status s = vocabulary.Transform(sets[i++ % sets.size()], &bow, &direct, kLevelsUp);
    benchmark::DoNotOptimize(s);
    benchmark::DoNotOptimize(bow.entries().data());
  }
  state.counters["words"] = double(vocabulary.num_words());
  state.counters["descriptor_sets"] = double(sets.size());
  state.counters["bow_entries"] = double(bow.size());
  state.SetItemsProcessed(int64_t(state.iterations()) * kFeatures);
}

void BM_Transform_Place_k10_L5(benchmark::State& state) {
  static const Vocabulary vocabulary = LoadBundledPlaceVocabulary();
  TransformBenchmark(state, vocabulary);
}
BENCHMARK(BM_Transform_Place_k10_L5)
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(5)
    ->ReportAggregatesOnly(true);

void BM_Transform_Random_k10_L6(benchmark::State& state) {
  static const Vocabulary vocabulary = RandomFullTreeVocabulary(10, 6, 1);
  TransformBenchmark(state, vocabulary);
}
BENCHMARK(BM_Transform_Random_k10_L6)
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(5)
    ->ReportAggregatesOnly(true);

// Writes the 1M-word vocabulary once in both formats, shared by the load benchmarks.
struct MillionWordFiles {
  std::string project = TempPath("1m.rvoc");
  std::string dbow2 = TempPath("1m.txt");
  size_t memory_bytes = 0;
  MillionWordFiles() {
    const Vocabulary v = RandomFullTreeVocabulary(10, 6, 2);
    memory_bytes = v.MemoryBytes();
    if (!SaveVocabulary(v, project).ok() || !ExportDbow2Text(v, dbow2).ok()) {
      std::fprintf(stderr, "bench: cannot write temporary vocabularies\n");
      std::exit(2);
    }
  }
  ~MillionWordFiles() {
    std::filesystem::remove(project);
    std::filesystem::remove(dbow2);
  }
};
const MillionWordFiles& Files() {
  static const MillionWordFiles files;
  return files;
}

void BM_LoadProject_1M(benchmark::State& state) {
  const MillionWordFiles& files = Files();
  size_t words = 0, memory = 0;
  for (auto _ : state) {
    auto v = LoadVocabulary(files.project);
    if (!v.ok()) state.SkipWithError(v.status().ToString().c_str());
    words = v->num_words();
    memory = v->MemoryBytes();
  }
  state.counters["words"] = double(words);
  state.counters["memory_MB"] = double(memory) / 1e6;
  state.counters["file_MB"] = double(std::filesystem::file_size(files.project)) / 1e6;
}
BENCHMARK(BM_LoadProject_1M)
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(5)
    ->ReportAggregatesOnly(true);

void BM_ImportDbow2Text_1M(benchmark::State& state) {
  const MillionWordFiles& files = Files();
  size_t words = 0;
  for (auto _ : state) {
    auto v = ImportDbow2Text(files.dbow2);
    if (!v.ok()) state.SkipWithError(v.status().ToString().c_str());
    words = v->num_words();
  }
  state.counters["words"] = double(words);
  state.counters["file_MB"] = double(std::filesystem::file_size(files.dbow2)) / 1e6;
}
BENCHMARK(BM_ImportDbow2Text_1M)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->Repetitions(3)
    ->ReportAggregatesOnly(true);

void BM_ImportDbow2Yaml_Brief(benchmark::State& state) {
  const std::string path = testing::SharedData("vocabularies/brief_k10_l6_dbow2.yml.gz");
  if (!std::filesystem::exists(path)) {
    state.SkipWithError("shared data not found (set RECOG_SHARED_DATA)");
    return;
  }
  size_t words = 0;
  for (auto _ : state) {
    auto v = ImportDbow2Yaml(path);
    if (!v.ok()) state.SkipWithError(v.status().ToString().c_str());
    words = v->num_words();
  }
  state.counters["words"] = double(words);
}
BENCHMARK(BM_ImportDbow2Yaml_Brief)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->Repetitions(3)
    ->ReportAggregatesOnly(true);

}  // namespace
}  // namespace recog::bench

BENCHMARK_MAIN();
