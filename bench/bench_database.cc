// Recognition database benchmarks (issue "recognition databases"):
//   Query_L1_k10L6/<entries>  top-10 L1 query, 1K..1M entries of 300-1000 words each (word ids
//                             drawn uniformly from a k=10 L=6 vocabulary's 1M words)
//   Query_L1_Shipped_k10L5_Photos  top-10 L1 query over the bags of words (shipped k=10 L=5
//                             vocabulary, ORB) of the shared Caltech photos, one entry per distinct
//                             photo: 4,665 entries with the shared data (the 4,865 of its 4,872
//                             photos that have >= 50 features, minus the 200 query photos)
//   Query_L1_Shipped_k10L5_26K  those 4,665 entries and, to reach 26,000, 21,335 more made from
//                             random 60-100 % subsets of the same photos' features (seeded): not
//                             26,000 distinct photos, of which the shared data has 4,872
// The queries of both are the bags of words of 200 photos held out of the database (the first 200
// of the seeded shuffle): no entry is made from them.
// The entries are indexed through a store that keeps nothing, so these figures are the in-memory
// index alone; `index_MB_per_million_postings` reports its memory, `process_peak_rss_MB` the
// benchmark process's peak.
// Run: build/bin/bench_database [--benchmark_format=json] [--benchmark_filter=...]
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <algorithm>
#include <cstdio>
#include <numeric>
#include <random>

#include "bench/bench_support.h"
#include "core/index/database.h"

namespace recog::bench {
namespace {

// Accepts every write and keeps nothing: the benchmarks measure the in-memory index.
class DiscardingStore : public IndexStore {
 public:
  StatusOr<MapInfo> CreateMap(const MapConfig& config) override {
    info_ = {1, config, 0};
    return info_;
  }
  StatusOr<MapInfo> GetMap(const std::string&) override { return info_; }
  StatusOr<std::vector<MapInfo>> ListMaps() override { return std::vector<MapInfo>{info_}; }
  Status DeleteMap(const std::string&) override { return Status::Ok(); }
  Status CommitEntry(MapId, const EntryRecord&) override { return Status::Ok(); }
  Status RemoveEntry(MapId, EntryId) override { return Status::Ok(); }
  Status ReadEntry(MapId, EntryId, uint32_t, EntryRecord*) override {
    return Status::NotFound("discarded");
  }
  Status ScanEntries(MapId, uint32_t, const std::function<Status(EntryRecord&)>&) override {
    return Status::Ok();
  }
  StatusOr<EntryId> NextEntryId(MapId) override { return EntryId(0); }
  Status PutBlob(const std::string&, std::string_view) override { return Status::Ok(); }
  StatusOr<std::string> GetBlob(const std::string&) override {
    return Status::NotFound("discarded");
  }
  Status DeleteBlob(const std::string&) override { return Status::NotFound("discarded"); }
  StatusOr<std::vector<std::string>> ListBlobKeys(const std::string&) override {
    return std::vector<std::string>{};
  }
  Status Flush() override { return Status::Ok(); }
  Status Checkpoint(const std::string&) override { return Status::FailedPrecondition("none"); }
  StatusOr<VerifyReport> Verify(uint64_t) override { return VerifyReport{}; }
  StatusOr<uint64_t> MapDiskBytes(MapId) override { return uint64_t{0}; }

 private:
  MapInfo info_;
};

// Adds an entry with the given bag of words and `features` placeholder features.
void AddEntry(Database& db, const BowVector& bow, int features) {
  static const cv::Mat descriptors(1000, 32, CV_8U, cv::Scalar(0));
  static const std::vector<uint32_t> all = [] {
    std::vector<uint32_t> v(1000);
    std::iota(v.begin(), v.end(), 0u);
    return v;
  }();
  FeatureSet f;
  f.descriptors = descriptors.rowRange(0, features);
  f.keypoints.resize(size_t(features));
  FeatureVector direct;
  direct.AppendNode(0, std::span(all.data(), size_t(features)));
  if (!db.AddConverted(bow, direct, f).ok()) std::abort();
}

BowVector RandomBow(std::mt19937_64& rng, uint32_t words, int count) {
  std::vector<BowEntry> entries;
  std::uniform_int_distribution<uint32_t> word(0, words - 1);
  std::uniform_real_distribution<float> value(0.1f, 1.f);
  for (int i = 0; i < count; ++i) entries.push_back({word(rng), value(rng)});
  BowVector bow(std::move(entries));
  bow.Normalize(BowNormalization::kL1);
  return bow;
}

void ReportMemory(benchmark::State& state, const Database& db) {
  const DatabaseStats stats = db.Stats();
  state.counters["entries"] = double(stats.entries);
  state.counters["postings"] = double(stats.postings);
  // Bytes per posting of the index equal its megabytes per million postings.
  state.counters["index_MB_per_million_postings"] =
      double(stats.index_bytes) / double(stats.postings);
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  state.counters["process_peak_rss_MB"] = double(usage.ru_maxrss) / 1024.0;
}

void BM_Query_L1_k10L6(benchmark::State& state) {
  static DiscardingStore store;
  static const auto vocabulary =
      std::make_shared<const Vocabulary>(RandomFullTreeVocabulary(10, 6, 3));
  static std::unique_ptr<Database> db =
      std::move(Database::Create(&store, "m", vocabulary)).value();
  static std::mt19937_64 rng(11);
  const size_t target = size_t(state.range(0));
  std::uniform_int_distribution<int> size(300, 1000);
  while (db->size() < target) {  // grows across the arguments 1K .. 1M
    const int n = size(rng);
    AddEntry(*db, RandomBow(rng, uint32_t(vocabulary->num_words()), n), n);
  }
  std::vector<BowVector> queries;
  for (int i = 0; i < 50; ++i)
    queries.push_back(RandomBow(rng, uint32_t(vocabulary->num_words()), size(rng)));
  std::vector<QueryResult> results;
  size_t i = 0;
  for (auto _ : state) {
    if (!db->Query(queries[i++ % queries.size()], {.max_results = 10}, &results).ok()) std::abort();
    benchmark::DoNotOptimize(results.data());
  }
  ReportMemory(state, *db);
}
BENCHMARK(BM_Query_L1_k10L6)
    ->Arg(1000)
    ->Arg(10000)
    ->Arg(26000)
    ->Arg(100000)
    ->Arg(1000000)
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(3)
    ->ReportAggregatesOnly(true);

constexpr size_t kQueryPhotos = 200;

// ORB descriptors of the real photos, one set per photo; the first kQueryPhotos are the queries.
const std::vector<cv::Mat>& Photos() {
  static const std::vector<cv::Mat> photos = RealImageDescriptors(5);
  if (photos.size() <= kQueryPhotos) {
    std::fprintf(stderr, "bench_database: only %zu photos\n", photos.size());
    std::exit(2);
  }
  return photos;
}

BowVector Transform(const Vocabulary& vocabulary, const cv::Mat& descriptors) {
  BowVector bow;
  if (!vocabulary.Transform(descriptors, &bow).ok()) std::abort();
  return bow;
}

// A database of every non-query photo once and, up to `entries` in all, random 60-100 % subsets of
// their features (none when `entries` is at most the number of those photos).
std::unique_ptr<Database> BuildRealDatabase(IndexStore* store,
                                            const std::shared_ptr<const Vocabulary>& vocabulary,
                                            size_t entries) {
  auto db = std::move(Database::Create(store, "m", vocabulary)).value();
  const std::vector<cv::Mat>& photos = Photos();
  for (size_t i = kQueryPhotos; i < photos.size(); ++i) {
    AddEntry(*db, Transform(*vocabulary, photos[i]), 1000);
  }
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> keep(0.6, 1.0);
  for (size_t i = 0; db->size() < entries; ++i) {
    const cv::Mat& all = photos[kQueryPhotos + i % (photos.size() - kQueryPhotos)];
    std::vector<int> rows(size_t(all.rows));
    std::iota(rows.begin(), rows.end(), 0);
    std::shuffle(rows.begin(), rows.end(), rng);
    rows.resize(size_t(all.rows * keep(rng)));
    cv::Mat subset;
    for (int r : rows) subset.push_back(all.row(r));
    AddEntry(*db, Transform(*vocabulary, subset), 1000);
  }
  return db;
}

// Queries `db` with the held-out photos in turn.
void QueryHeldOutPhotos(benchmark::State& state, const Vocabulary& vocabulary, const Database& db) {
  static const std::vector<BowVector> queries = [&] {
    std::vector<BowVector> bows;
    for (size_t i = 0; i < kQueryPhotos; ++i) bows.push_back(Transform(vocabulary, Photos()[i]));
    return bows;
  }();
  std::vector<QueryResult> results;
  size_t i = 0;
  double words = 0;
  for (auto _ : state) {
    const BowVector& q = queries[i++ % queries.size()];
    words += double(q.size());
    if (!db.Query(q, {.max_results = 10}, &results).ok()) std::abort();
    benchmark::DoNotOptimize(results.data());
  }
  state.counters["query_words"] = words / double(state.iterations());
  ReportMemory(state, db);
}

const std::shared_ptr<const Vocabulary>& ShippedVocabulary() {
  static const auto vocabulary = std::make_shared<const Vocabulary>(LoadBundledPlaceVocabulary());
  return vocabulary;
}

void BM_Query_L1_Shipped_k10L5_Photos(benchmark::State& state) {
  static DiscardingStore store;
  static const std::unique_ptr<Database> db = BuildRealDatabase(&store, ShippedVocabulary(), 0);
  QueryHeldOutPhotos(state, *ShippedVocabulary(), *db);
}
BENCHMARK(BM_Query_L1_Shipped_k10L5_Photos)
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(3)
    ->ReportAggregatesOnly(true);

void BM_Query_L1_Shipped_k10L5_26K(benchmark::State& state) {
  static DiscardingStore store;
  static const std::unique_ptr<Database> db = BuildRealDatabase(&store, ShippedVocabulary(), 26000);
  QueryHeldOutPhotos(state, *ShippedVocabulary(), *db);
}
BENCHMARK(BM_Query_L1_Shipped_k10L5_26K)
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(3)
    ->ReportAggregatesOnly(true);

}  // namespace
}  // namespace recog::bench

BENCHMARK_MAIN();
