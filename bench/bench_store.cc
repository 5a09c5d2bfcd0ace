// Durable database benchmarks over the RocksDB store (issue "recognition databases"):
//   AddEntry/grouped      add one entry (1000 real ORB features of a corridor frame, its BoW and
//                         direct index) including its RocksDB write, WAL synced every 50 ms
//   AddEntry/every_write  the same with an fsync in every write
//   Reopen_100K           open a store of 100,000 entries (300-1000 features each, k=10 L=6
//                         vocabulary shape), rebuild and check the index, answer the first query
//   Verify_100K           read that store's table files and check every block's checksum
// The store lives in the system temp folder and is removed at the end.
// Run: build/bin/bench_store [--benchmark_format=json]
#include <benchmark/benchmark.h>

#include <chrono>
#include <filesystem>
#include <random>

#include "bench/bench_support.h"
#include "core/index/database.h"
#include "storage/rocksdb_index_store.h"

namespace recog::bench {
namespace {

namespace fs = std::filesystem;

void Check(const Status& s) {
  if (!s.ok()) {
    std::fprintf(stderr, "bench_store: %s\n", s.ToString().c_str());
    std::exit(2);
  }
}

struct ConvertedFrame {
  FeatureSet features;
  BowVector bow;
  FeatureVector direct;
};

// Real corridor frames with 1000 features, converted once with the bundled place vocabulary.
std::vector<ConvertedFrame> CorridorFrames(const Vocabulary& vocabulary) {
  std::vector<ConvertedFrame> frames;
  for (const cv::Mat& descriptors : CorridorDescriptorSets(1000)) {
    ConvertedFrame f;
    f.features.descriptors = descriptors;
    for (int i = 0; i < descriptors.rows; ++i) {
      f.features.keypoints.emplace_back(float(i % 640), float(i % 480), 31.f, 0.f, 1.f, 0);
    }
    Check(vocabulary.Transform(descriptors, &f.bow, &f.direct, 2));
    frames.push_back(std::move(f));
  }
  return frames;
}

void AddEntryBenchmark(benchmark::State& state, SyncPolicy sync) {
  static const auto vocabulary = std::make_shared<const Vocabulary>(LoadBundledPlaceVocabulary());
  static const std::vector<ConvertedFrame> frames = CorridorFrames(*vocabulary);
  const std::string dir = TempPath(sync == SyncPolicy::kGrouped ? "add_grouped" : "add_sync");
  fs::remove_all(dir);
  {
    RocksDbStoreOptions options;
    options.sync = sync;
    auto store = OpenRocksDbIndexStore(dir, options);
    Check(store.status());
    auto db = Database::Create(store->get(), "bench", vocabulary);
    Check(db.status());
    size_t i = 0;
    for (auto _ : state) {
      const ConvertedFrame& f = frames[i++ % frames.size()];
      auto id = (*db)->AddConverted(f.bow, f.direct, f.features);
      if (!id.ok()) state.SkipWithError(id.status().ToString().c_str());
    }
    state.counters["entries"] = double((*db)->size());
  }
  fs::remove_all(dir);
}

void BM_AddEntry_Grouped(benchmark::State& state) {
  AddEntryBenchmark(state, SyncPolicy::kGrouped);
}
BENCHMARK(BM_AddEntry_Grouped)
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(5)
    ->ReportAggregatesOnly(true);

void BM_AddEntry_EveryWrite(benchmark::State& state) {
  AddEntryBenchmark(state, SyncPolicy::kEveryWrite);
}
BENCHMARK(BM_AddEntry_EveryWrite)
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(5)
    ->ReportAggregatesOnly(true);

// Builds (once) a store of 100,000 synthetic entries, closed when this returns.
struct HundredThousandStore {
  static constexpr size_t kEntries = 100000;
  std::string dir = TempPath("reopen_100k");
  std::shared_ptr<const Vocabulary> vocabulary =
      std::make_shared<const Vocabulary>(RandomFullTreeVocabulary(10, 6, 4));
  BowVector first_query;

  HundredThousandStore() {
    fs::remove_all(dir);
    auto store = OpenRocksDbIndexStore(dir, RocksDbStoreOptions{});
    Check(store.status());
    auto db = Database::Create(store->get(), "bench", vocabulary);
    Check(db.status());
    std::mt19937_64 rng(21);
    std::uniform_int_distribution<int> size(300, 1000);
    std::uniform_int_distribution<uint32_t> word(0, uint32_t(vocabulary->num_words()) - 1);
    cv::Mat descriptors(1000, 32, CV_8U);
    cv::randu(descriptors, 0, 256);
    std::vector<uint32_t> all(1000);
    std::iota(all.begin(), all.end(), 0u);
    for (size_t e = 0; e < kEntries; ++e) {
      const int n = size(rng);
      std::vector<BowEntry> words;
      for (int i = 0; i < n; ++i) words.push_back({word(rng), 1.f});
      BowVector bow(std::move(words));
      bow.Normalize(BowNormalization::kL1);
      FeatureSet f;
      f.descriptors = descriptors.rowRange(0, n);
      f.keypoints.resize(size_t(n));
      FeatureVector direct;
      direct.AppendNode(NodeId(1 + e % 10), std::span(all.data(), size_t(n)));
      Check((*db)->AddConverted(bow, direct, f).status());
      if (e == 0) first_query = bow;
      if (e % 10000 == 9999) std::fprintf(stderr, "bench_store: built %zu entries\n", e + 1);
    }
    Check((*store)->Flush());
  }
  ~HundredThousandStore() { fs::remove_all(dir); }
};

// The store both benchmarks below read, built on first use.
const HundredThousandStore& Store100K() {
  static const HundredThousandStore built;
  return built;
}

void BM_Reopen_100K(benchmark::State& state) {
  const HundredThousandStore& built = Store100K();
  for (auto _ : state) {
    auto store = OpenRocksDbIndexStore(built.dir, RocksDbStoreOptions{});
    Check(store.status());
    auto db = Database::Open(store->get(), "bench", built.vocabulary);
    Check(db.status());
    std::vector<QueryResult> results;
    Check((*db)->Query(built.first_query, {.max_results = 10}, &results));
    if (results.empty() || results[0].id != 0)
      state.SkipWithError("first query did not find entry 0");
    state.counters["entries"] = double((*db)->size());
    state.counters["postings"] = double((*db)->Stats().postings);
  }
  uintmax_t bytes = 0;
  for (const auto& f : fs::recursive_directory_iterator(built.dir)) {
    if (f.is_regular_file()) bytes += f.file_size();
  }
  state.counters["store_MB"] = double(bytes) / 1e6;
}
BENCHMARK(BM_Reopen_100K)->Unit(benchmark::kSecond)->Iterations(1)->Repetitions(3)->UseRealTime();

// IndexStore::Verify over the 100,000-entry store: every table file read and every block's
// checksum checked, as fast as the disk goes (what `recogd --verify` does offline; the background
// check and `recog admin verify` cap the rate at store.verify_mb_per_s).
void BM_Verify_100K(benchmark::State& state) {
  const HundredThousandStore& built = Store100K();
  auto store = OpenRocksDbIndexStore(built.dir, RocksDbStoreOptions{});
  Check(store.status());
  uint64_t bytes = 0;
  for (auto _ : state) {
    auto report = (*store)->Verify(0);
    Check(report.status());
    bytes = report->bytes;
    state.counters["files"] = double(report->files);
  }
  state.counters["verified_MB"] = double(bytes) / 1e6;
  state.SetBytesProcessed(int64_t(bytes) * int64_t(state.iterations()));
}
BENCHMARK(BM_Verify_100K)->Unit(benchmark::kSecond)->Iterations(1)->Repetitions(3)->UseRealTime();

}  // namespace
}  // namespace recog::bench

BENCHMARK_MAIN();
