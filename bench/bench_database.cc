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
//   Restart_Shipped_k10L5/<entries>  a RocksDB store of that many of the Scale case's entries
//                             (each with 50 placeholder features, to keep the store to a few GB):
//                             the index snapshot's writing time and size, the store's disk per
//                             entry (snapshot apart), and the time from opening the store to the
//                             answer of a first query, loading the snapshot (evicted from the
//                             page cache first, as after a reboot) and rebuilding without it;
//                             both indexes must answer 20 queries as the built one did
//   Query_L1_Shipped_k10L5_Scale/<entries>  the same entries grown to 100K, 300K and 1M (the
//                             first 26,000 are the 26K case's; 1M takes about 8 minutes and 5 GB):
//                             the index's memory, 1,000 timed queries with the default options
//                             (p50 / p99; bounded in large maps, see QueryOptions), 200 exhaustive
//                             ones (p50), how far the two agree (the share of the exhaustive top
//                             10 the default returns; for revisits of stored photos, whether the
//                             best result is a copy of the revisited photo) and the time of each
//                             insertion into the index (p50 / p99; the store keeps nothing)
// The queries of all three are the bags of words of 200 photos held out of the database (the
// first 200 of the seeded shuffle): no entry is made from them.
// The entries are indexed through a store that keeps nothing, so these figures are the in-memory
// index alone; `index_MB_per_million_postings` reports its memory, `process_peak_rss_MB` the
// benchmark process's peak.
// Run: build/bin/bench_database [--benchmark_format=json] [--benchmark_filter=...]
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <fcntl.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <numeric>
#include <random>

#include "bench/bench_support.h"
#include "core/index/database.h"
#include "storage/rocksdb_index_store.h"

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
  Status ScanEntries(MapId, EntryId, uint32_t,
                     const std::function<Status(EntryRecord&)>&) override {
    return Status::Ok();
  }
  StatusOr<std::unique_ptr<SnapshotWriter>> WriteSnapshot(MapId, EntryId) override {
    return Status::FailedPrecondition("a discarding store keeps no snapshot");
  }
  StatusOr<std::unique_ptr<SnapshotReader>> ReadSnapshot(MapId) override {
    return Status::NotFound("discarded");
  }
  Status DropSnapshot(MapId) override { return Status::Ok(); }
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

// `count` words drawn uniformly from the vocabulary, each occurrence weighted by its word's weight
// (as Vocabulary::Transform weighs them), L1-normalised.
BowVector RandomBow(std::mt19937_64& rng, const Vocabulary& vocabulary, int count) {
  std::vector<BowEntry> entries;
  std::uniform_int_distribution<uint32_t> word(0, uint32_t(vocabulary.num_words() - 1));
  for (int i = 0; i < count; ++i) {
    const WordId w = word(rng);
    entries.push_back({w, vocabulary.WordWeight(w)});
  }
  BowVector bow(std::move(entries));
  bow.Normalize(BowNormalization::kL1);
  return bow;
}

void ReportMemory(benchmark::State& state, const Database& db) {
  const DatabaseStats stats = db.Stats();
  state.counters["entries"] = double(stats.entries);
  state.counters["postings"] = double(stats.postings);
  // The postings whose value the index could not code in a byte (see PostingList).
  state.counters["values_stored_aside"] = double(stats.values_stored_aside);
  // Bytes per posting of the index equal its megabytes per million postings.
  state.counters["index_MB_per_million_postings"] =
      double(stats.index_bytes) / double(stats.postings);
  // Bytes per entry, in thousands, equal gigabytes per million entries.
  state.counters["index_GB_per_million_entries"] =
      double(stats.index_bytes) / double(stats.entries) / 1000.0;
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
    AddEntry(*db, RandomBow(rng, *vocabulary, n), n);
  }
  std::vector<BowVector> queries;
  for (int i = 0; i < 50; ++i) queries.push_back(RandomBow(rng, *vocabulary, size(rng)));
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

// The photos entries are made from: all but the first kQueryPhotos.
std::span<const cv::Mat> StoredPhotos() { return std::span(Photos()).subspan(kQueryPhotos); }

const std::shared_ptr<const Vocabulary>& ShippedVocabulary() {
  static const auto vocabulary = std::make_shared<const Vocabulary>(LoadBundledPlaceVocabulary());
  return vocabulary;
}

std::unique_ptr<Database> NewShippedDatabase(IndexStore* store) {
  return std::move(Database::Create(store, "m", ShippedVocabulary())).value();
}

// A new database of the shipped vocabulary grown to `entries` (GrowRealDatabase, seed 5).
std::unique_ptr<Database> BuildRealDatabase(IndexStore* store, size_t entries) {
  auto db = NewShippedDatabase(store);
  std::mt19937_64 rng(5);
  GrowRealDatabase(*db, StoredPhotos(), entries, rng);
  return db;
}

// The bags of words of the held-out photos (the shipped vocabulary).
const std::vector<BowVector>& HeldOutQueries() {
  static const std::vector<BowVector> queries = [] {
    std::vector<BowVector> bows;
    for (size_t i = 0; i < kQueryPhotos; ++i) {
      bows.push_back(Transform(*ShippedVocabulary(), Photos()[i]));
    }
    return bows;
  }();
  return queries;
}

// Top-10 query of `db` with held-out photo `i` (modulo their number); returns its word count.
size_t QueryOnce(const Database& db, size_t i) {
  thread_local std::vector<QueryResult> results;
  const BowVector& q = HeldOutQueries()[i % kQueryPhotos];
  if (!db.Query(q, {.max_results = 10}, &results).ok()) std::abort();
  benchmark::DoNotOptimize(results.data());
  return q.size();
}

// Queries `db` with the held-out photos in turn.
void QueryHeldOutPhotos(benchmark::State& state, const Database& db) {
  size_t i = 0;
  double words = 0;
  for (auto _ : state) words += double(QueryOnce(db, i++));
  state.counters["query_words"] = words / double(state.iterations());
  ReportMemory(state, db);
}

void BM_Query_L1_Shipped_k10L5_Photos(benchmark::State& state) {
  static DiscardingStore store;
  static const std::unique_ptr<Database> db = BuildRealDatabase(&store, 0);
  QueryHeldOutPhotos(state, *db);
}
BENCHMARK(BM_Query_L1_Shipped_k10L5_Photos)
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(3)
    ->ReportAggregatesOnly(true);

void BM_Query_L1_Shipped_k10L5_26K(benchmark::State& state) {
  static DiscardingStore store;
  static const std::unique_ptr<Database> db = BuildRealDatabase(&store, 26000);
  QueryHeldOutPhotos(state, *db);
}
BENCHMARK(BM_Query_L1_Shipped_k10L5_26K)
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(3)
    ->ReportAggregatesOnly(true);

// Revisits of stored places: a seeded 60-100 % subset of the features of each of the first
// kQueryPhotos stored photos (as GrowRealDatabase perturbs them), so each has copies in the map.
const std::vector<BowVector>& RevisitQueries() {
  static const std::vector<BowVector> queries = [] {
    std::mt19937_64 rng(17);
    std::vector<int> rows;
    cv::Mat subset;
    std::vector<BowVector> bows;
    for (size_t i = 0; i < kQueryPhotos; ++i) {
      RandomSubset(Photos()[kQueryPhotos + i], rng, &rows, &subset);
      bows.push_back(Transform(*ShippedVocabulary(), subset));
    }
    return bows;
  }();
  return queries;
}

// How far the default (bounded) query agrees with the exhaustive one over `queries`: the share
// of the exhaustive top 10 it returns, averaged, and for revisit queries (`revisits`: query i
// revisits the i-th stored photo) the share whose best result is a copy of the revisited photo,
// for each of the two queries.
struct AgreementWithExhaustive {
  double top10 = 0.0;
  double revisit_found = 0.0;
  double revisit_found_exhaustive = 0.0;
};
AgreementWithExhaustive CompareWithExhaustive(const Database& db,
                                              const std::vector<BowVector>& queries,
                                              const QueryOptions& options, bool revisits) {
  const size_t stored_photos = Photos().size() - kQueryPhotos;  // entry id i copies photo i % it
  AgreementWithExhaustive agreement;
  std::vector<QueryResult> bounded, exhaustive;
  QueryOptions all = options;
  all.full_scan_postings = 0;
  for (size_t i = 0; i < queries.size(); ++i) {
    if (!db.Query(queries[i], options, &bounded).ok() ||
        !db.Query(queries[i], all, &exhaustive).ok()) {
      std::abort();
    }
    size_t found = 0;
    for (const QueryResult& r : exhaustive) {
      found += std::any_of(bounded.begin(), bounded.end(),
                           [&](const QueryResult& b) { return b.id == r.id; });
    }
    agreement.top10 += double(found) / double(std::max<size_t>(1, exhaustive.size()));
    if (revisits) {
      agreement.revisit_found += !bounded.empty() && bounded[0].id % stored_photos == i;
      agreement.revisit_found_exhaustive +=
          !exhaustive.empty() && exhaustive[0].id % stored_photos == i;
    }
  }
  agreement.top10 /= double(queries.size());
  agreement.revisit_found /= double(queries.size());
  agreement.revisit_found_exhaustive /= double(queries.size());
  return agreement;
}

// Times `count` top-10 queries of `db` with the held-out photos in turn; returns them sorted.
std::vector<double> TimeQueries(const Database& db, const QueryOptions& options, size_t count) {
  std::vector<double> ms;
  std::vector<QueryResult> results;
  for (size_t i = 0; i < count; ++i) {
    const auto start = std::chrono::steady_clock::now();
    if (!db.Query(HeldOutQueries()[i % kQueryPhotos], options, &results).ok()) std::abort();
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                     .count());
  }
  std::sort(ms.begin(), ms.end());
  return ms;
}

// Tells the kernel to drop the cached pages of the files under `dir`, so that the next read of
// them comes from the disk.
void EvictFromPageCache(const std::string& dir) {
  for (const auto& f : std::filesystem::recursive_directory_iterator(dir)) {
    if (!f.is_regular_file()) continue;
    const int fd = ::open(f.path().c_str(), O_RDONLY);
    if (fd < 0) continue;
    ::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
    ::close(fd);
  }
}

// Opens the store and the map and answers a first query; returns the seconds that took (in
// *store_seconds those of opening the store alone), and the database (its store in *store).
double TimedRestart(const std::string& dir, std::unique_ptr<IndexStore>* store,
                    std::unique_ptr<Database>* db, double* store_seconds) {
  const auto start = std::chrono::steady_clock::now();
  auto opened = OpenRocksDbIndexStore(dir, RocksDbStoreOptions{});
  if (!opened.ok()) std::abort();
  *store = std::move(opened).value();
  *store_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  auto database = Database::Open(store->get(), "m", ShippedVocabulary());
  if (!database.ok()) {
    std::fprintf(stderr, "bench_database: %s\n", database.status().ToString().c_str());
    std::exit(2);
  }
  *db = std::move(database).value();
  QueryOnce(**db, 0);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

std::vector<std::vector<QueryResult>> FirstAnswers(const Database& db) {
  std::vector<std::vector<QueryResult>> answers(20);
  for (size_t i = 0; i < answers.size(); ++i) {
    if (!db.Query(HeldOutQueries()[i], {.max_results = 10}, &answers[i]).ok()) std::abort();
  }
  return answers;
}

void BM_Restart_Shipped_k10L5(benchmark::State& state) {
  const size_t entries = size_t(state.range(0));
  const std::string dir = TempPath("restart_" + std::to_string(entries));
  const std::string snapshots = dir + "/index-snapshots";
  std::filesystem::remove_all(dir);
  std::vector<std::vector<QueryResult>> expected;
  {
    auto store = OpenRocksDbIndexStore(dir, RocksDbStoreOptions{});
    if (!store.ok()) std::abort();
    auto db = NewShippedDatabase(store->get());
    std::mt19937_64 rng(5);
    for (size_t size = 100000; db->size() < entries; size += 100000) {
      GrowRealDatabase(*db, StoredPhotos(), std::min(size, entries), rng, nullptr, 50);
      std::fprintf(stderr, "bench_database: %zu entries stored\n", db->size());
    }
    expected = FirstAnswers(*db);
    ReportMemory(state, *db);
    const auto start = std::chrono::steady_clock::now();
    const StatusOr<uint64_t> written = db->SaveSnapshot();
    if (!written.ok()) std::abort();
    state.counters["snapshot_write_s"] =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    state.counters["snapshot_MB"] = double(*written) / 1e6;
  }
  const uint64_t store_bytes = DirectoryBytes(dir) - DirectoryBytes(dir, snapshots);
  state.counters["store_MB"] = double(store_bytes) / 1e6;
  state.counters["store_KB_per_entry"] = double(store_bytes) / double(entries) / 1e3;
  for (auto _ : state) {
    EvictFromPageCache(snapshots);
    std::unique_ptr<IndexStore> store;
    std::unique_ptr<Database> db;
    double store_s = 0.0;
    state.counters["restart_s"] = TimedRestart(dir, &store, &db, &store_s);
    state.counters["restart_store_open_s"] = store_s;
    if (!db->open_report().from_snapshot || FirstAnswers(*db) != expected) {
      state.SkipWithError("the index loaded from the snapshot differs");
    }
    if (!store->DropSnapshot(db->info().id).ok()) std::abort();
  }
  {
    std::unique_ptr<IndexStore> store;
    std::unique_ptr<Database> db;
    double store_s = 0.0;
    state.counters["restart_rebuild_s"] = TimedRestart(dir, &store, &db, &store_s);
    state.counters["restart_rebuild_store_open_s"] = store_s;
    if (db->open_report().from_snapshot || FirstAnswers(*db) != expected) {
      state.SkipWithError("the rebuilt index differs");
    }
  }
  std::filesystem::remove_all(dir);
}
BENCHMARK(BM_Restart_Shipped_k10L5)
    ->Arg(100000)
    ->Arg(300000)
    ->Arg(1000000)
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->UseRealTime();

// The map a fleet fills over months: one database grown across the arguments. Each size reports
// the insertion of the entries that brought it there, 1,000 timed queries with the default
// options (the 200 held-out photos five times), 200 exhaustive ones, and how far the default
// (bounded, see QueryOptions) query's top 10 agree with the exhaustive query's, for the held-out
// photos (no stored copy: a top 10 of near ties) and for revisits of stored photos.
void BM_Query_L1_Shipped_k10L5_Scale(benchmark::State& state) {
  static DiscardingStore store;
  static const std::unique_ptr<Database> db = NewShippedDatabase(&store);
  static std::mt19937_64 rng(5);
  std::vector<double> insert_ms;
  GrowRealDatabase(*db, StoredPhotos(), size_t(state.range(0)), rng, &insert_ms);
  std::sort(insert_ms.begin(), insert_ms.end());
  const QueryOptions options{.max_results = 10};
  std::vector<double> query_ms;
  for (auto _ : state) query_ms = TimeQueries(*db, options, 1000);
  QueryOptions exhaustive = options;
  exhaustive.full_scan_postings = 0;
  const std::vector<double> exhaustive_ms = TimeQueries(*db, exhaustive, kQueryPhotos);
  const AgreementWithExhaustive held_out =
      CompareWithExhaustive(*db, HeldOutQueries(), options, false);
  const AgreementWithExhaustive revisits =
      CompareWithExhaustive(*db, RevisitQueries(), options, true);
  state.counters["query_p50_ms"] = Percentile(query_ms, 50);
  state.counters["query_p99_ms"] = Percentile(query_ms, 99);
  state.counters["exhaustive_query_p50_ms"] = Percentile(exhaustive_ms, 50);
  state.counters["held_out_top10_in_exhaustive"] = held_out.top10;
  state.counters["revisit_top10_in_exhaustive"] = revisits.top10;
  state.counters["revisit_found"] = revisits.revisit_found;
  state.counters["revisit_found_exhaustive"] = revisits.revisit_found_exhaustive;
  state.counters["insert_p50_ms"] = Percentile(insert_ms, 50);
  state.counters["insert_p99_ms"] = Percentile(insert_ms, 99);
  ReportMemory(state, *db);
}
BENCHMARK(BM_Query_L1_Shipped_k10L5_Scale)
    ->Arg(100000)
    ->Arg(300000)
    ->Arg(1000000)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1);

}  // namespace
}  // namespace recog::bench

BENCHMARK_MAIN();
