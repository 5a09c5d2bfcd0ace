// Crash safety of RocksDbIndexStore: a writer process killed with SIGKILL at a random moment
// never loses an entry whose CommitEntry had returned OK, and never leaves half an entry.
//
// Each round forks a child that opens the store and commits entries with
// ids continuing from NextEntryId, writing each id to a pipe once CommitEntry has returned OK. The
// parent kills the child after a random (seeded) delay, reopens the store and checks that every
// acknowledged id is there with all its parts, that a scan over all parts succeeds (no partial
// entry), and that every entry holds exactly the content derived from its id. The child does
// not use GoogleTest and leaves with _exit; the parent has the store closed whenever it forks.
//
// Both sync policies are run: SyncPolicy::kGrouped promises the same as kEveryWrite against a
// crash of the process (only a crash of the machine can cost it the last interval's writes).
//
// A third test writes as the server does, through a Database (bags of words from the place
// vocabulary), kills the writer mid-stream, reopens through Database::Open (which rebuilds the
// index and checks every entry's parts against each other and the vocabulary) and checks that
// every acknowledged entry is there with its features and that a query with the last one's bag of
// words ranks it first.
//
// A forked child inherits RocksDB's background thread pool without its threads, so it cannot
// flush or compact; that is fine here because each child writes far less than one memtable
// (64 MB) and the parent, which reopens the store every round, does the flushing.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <map>
#include <random>
#include <set>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "core/index/database.h"
#include "core/vocabulary/vocabulary_io.h"
#include "storage/rocksdb_index_store.h"
#include "storage/store_test_util.h"
#include "tests/testing/synthetic.h"

namespace recog {
namespace {

using testing::EntryDifference;
using testing::MakeTestEntry;
using testing::TempDir;
using testing::TestMapConfig;

constexpr uint32_t kSeed = 20240607;

// The content of entry `id`, recomputable by the parent. Sizes vary with the id: most entries
// are small (up to 200 features), every eighth one is large (up to 2000 features, ~170 KB).
EntryRecord CrashEntry(EntryId id) {
  return MakeTestEntry(id, 11, DescriptorFormat::Orb(), id % 8 == 0 ? 2000 : 200);
}

RocksDbStoreOptions WithSync(SyncPolicy sync) {
  RocksDbStoreOptions options;
  options.sync = sync;
  return options;
}

// FNV-1a over every part of an entry: the cheap "still the same" check of later rounds.
uint64_t Fingerprint(const EntryRecord& e) {
  uint64_t h = 1469598103934665603ull;
  auto mix = [&h](const void* data, size_t size) {
    const auto* p = static_cast<const uint8_t*>(data);
    for (size_t i = 0; i < size; ++i) h = (h ^ p[i]) * 1099511628211ull;
  };
  mix(&e.metadata.timestamp, sizeof(double));
  mix(&e.metadata.num_features, sizeof(uint32_t));
  mix(e.metadata.user_data.data(), e.metadata.user_data.size());
  mix(e.bow.entries().data(), e.bow.entries().size_bytes());
  for (size_t i = 0; i < e.direct.size(); ++i) {
    const NodeId node = e.direct.node(i);
    mix(&node, sizeof(node));
    mix(e.direct.features(i).data(), e.direct.features(i).size_bytes());
  }
  for (const cv::KeyPoint& k : e.keypoints) {
    const float f[5] = {k.pt.x, k.pt.y, k.size, k.angle, k.response};
    mix(f, sizeof(f));
    mix(&k.octave, sizeof(int));
  }
  for (int r = 0; r < e.descriptors.rows; ++r) {
    mix(e.descriptors.ptr(r), size_t(e.descriptors.cols) * e.descriptors.elemSize());
  }
  return h;
}

// Written to the pipe by the child once its store is open.
constexpr EntryId kOpenedMarker = kInvalidEntryId;

// The child: commits entries until it is killed. Exit codes only on failure.
[[noreturn]] void RunWriter(const std::string& path, SyncPolicy sync, MapId map, int ack_fd) {
  auto store = OpenRocksDbIndexStore(path, WithSync(sync));
  if (!store.ok()) ::_exit(3);
  auto next = (*store)->NextEntryId(map);
  if (!next.ok()) ::_exit(4);
  if (::write(ack_fd, &kOpenedMarker, sizeof(kOpenedMarker)) != sizeof(kOpenedMarker)) ::_exit(6);
  for (EntryId id = *next;; ++id) {
    if (!(*store)->CommitEntry(map, CrashEntry(id)).ok()) ::_exit(5);
    if (::write(ack_fd, &id, sizeof(id)) != sizeof(id)) ::_exit(6);
  }
}

// Runs `rounds` kill-and-check rounds against a store with the given sync policy. In most rounds
// the delay runs from the moment the child has its store open, so that the kill lands among the
// commits even on a slow (sanitizer) build; every fourth round it runs from the fork, so that
// some kills land while the store is still opening (recovering the previous round's log).
// Forks a child that runs `writer` with the write end of a pipe (it never returns) and returns
// the child's pid; *ack_fd is the read end, where the child's acknowledgements arrive.
pid_t ForkWriter(const std::function<void(int)>& writer, int* ack_fd) {
  int acks[2];
  if (::pipe(acks) != 0) return -1;
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::close(acks[0]);
    writer(acks[1]);
  }
  ::close(acks[1]);
  *ack_fd = acks[0];
  return pid;
}

void RunCrashRounds(SyncPolicy sync, int rounds) {
  RECOG_SKIP_FORK_UNDER_TSAN();
  TempDir dir("crash");
  const std::string path = dir.Sub("store");
  MapId map = 0;
  {
    auto store = OpenRocksDbIndexStore(path, WithSync(sync));
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    auto info = (*store)->CreateMap(TestMapConfig("crash"));
    ASSERT_TRUE(info.ok());
    map = info->id;
  }

  std::mt19937 rng(kSeed);
  std::set<EntryId> acknowledged;
  std::map<EntryId, uint64_t> fingerprints;  // of every entry already checked in full
  int rounds_with_acks = 0;
  int late_rounds = 0;
  for (int round = 0; round < rounds; ++round) {
    SCOPED_TRACE("round " + std::to_string(round));
    const int delay_ms = std::uniform_int_distribution<int>(5, 80)(rng);
    const bool early = round % 4 == 3;
    int acks = -1;
    const pid_t pid = ForkWriter([&](int ack_fd) { RunWriter(path, sync, map, ack_fd); }, &acks);
    ASSERT_GE(pid, 0);
    EntryId id = 0;
    if (!early) {
      // Blocks until the child has opened the store (or died: end of file).
      if (::read(acks, &id, sizeof(id)) == sizeof(id)) {
        EXPECT_EQ(id, kOpenedMarker);
      }
      ++late_rounds;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
    ::kill(pid, SIGKILL);
    std::vector<EntryId> acked_now;
    while (::read(acks, &id, sizeof(id)) == sizeof(id)) {
      if (id == kOpenedMarker) continue;
      acknowledged.insert(id);
      acked_now.push_back(id);
    }
    ::close(acks);
    int status = 0;
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL)
        << "the writer stopped by itself with exit code " << WEXITSTATUS(status);
    rounds_with_acks += !early && !acked_now.empty();

    auto store = OpenRocksDbIndexStore(path, WithSync(sync));
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    for (EntryId ack : acked_now) {
      EntryRecord got;
      const Status s = (*store)->ReadEntry(map, ack, kEntryAllParts, &got);
      ASSERT_TRUE(s.ok()) << "acknowledged entry " << ack << ": " << s.ToString();
    }
    // A scan over all parts: fails on a partial entry. An entry seen for the first time is
    // compared with the content derived from its id; later rounds compare its fingerprint.
    std::vector<EntryId> present;
    const Status scan = (*store)->ScanEntries(map, kEntryAllParts, [&](EntryRecord& e) {
      if (!present.empty()) {
        EXPECT_GT(e.id, present.back());
      }
      present.push_back(e.id);
      const uint64_t fingerprint = Fingerprint(e);
      auto [known, is_new] = fingerprints.emplace(e.id, fingerprint);
      if (is_new) {
        EXPECT_EQ(EntryDifference(e, CrashEntry(e.id)), "") << "entry " << e.id;
      } else {
        EXPECT_EQ(known->second, fingerprint) << "entry " << e.id << " changed";
      }
      return Status::Ok();
    });
    ASSERT_TRUE(scan.ok()) << scan.ToString();
    EXPECT_GE(present.size(), acknowledged.size());
    for (EntryId ack : acknowledged) {
      ASSERT_TRUE(std::binary_search(present.begin(), present.end(), ack))
          << "acknowledged entry " << ack << " is gone";
    }
    if (!acknowledged.empty()) {
      EXPECT_GT(*(*store)->NextEntryId(map), *acknowledged.rbegin());
    }
  }
  // The delays are long enough for most late-killed children to get some commits in.
  EXPECT_GE(rounds_with_acks, late_rounds / 2);
  std::printf("%zu acknowledged entries over %d rounds (%d of %d late-kill rounds had some)\n",
              acknowledged.size(), rounds, rounds_with_acks, late_rounds);
}

TEST(RocksDbCrashTest, KilledWritersNeverLoseAcknowledgedEntriesNorLeaveHalfOnes) {
  RunCrashRounds(SyncPolicy::kEveryWrite, 24);
}

TEST(RocksDbCrashTest, GroupedSyncLosesNothingWhenOnlyTheProcessCrashes) {
  RunCrashRounds(SyncPolicy::kGrouped, 12);
}

// The features of Database entry `id`: 100-400 random ORB descriptors (seeded by the id) at
// keypoints along a line.
FeatureSet DatabaseFeatures(EntryId id) {
  const int n = 100 + int(id * 37 % 301);
  FeatureSet features;
  features.descriptors = testing::RandomDescriptors(n, kSeed + id);
  for (int i = 0; i < n; ++i) features.keypoints.emplace_back(float(i), float(i % 480), 31.f);
  return features;
}

std::shared_ptr<const Vocabulary> PlaceVocabulary() {
  auto loaded =
      LoadVocabulary(std::string(RECOG_SOURCE_DIR) + "/vocabularies/place_orb_k10_l5.rvoc");
  if (!loaded.ok()) return nullptr;
  return std::make_shared<const Vocabulary>(std::move(loaded).value());
}

// The child of the Database test: adds entries until it is killed. Exit codes only on failure.
[[noreturn]] void RunDatabaseWriter(const std::string& path, int ack_fd) {
  const auto vocabulary = PlaceVocabulary();
  if (vocabulary == nullptr) ::_exit(2);
  auto store = OpenRocksDbIndexStore(path, WithSync(SyncPolicy::kGrouped));
  if (!store.ok()) ::_exit(3);
  auto db = Database::Open(store->get(), "db", vocabulary);
  if (!db.ok()) ::_exit(4);
  if (::write(ack_fd, &kOpenedMarker, sizeof(kOpenedMarker)) != sizeof(kOpenedMarker)) ::_exit(6);
  for (;;) {
    const auto id = (*db)->Add(DatabaseFeatures((*db)->next_entry_id()));
    if (!id.ok()) ::_exit(5);
    if (::write(ack_fd, &*id, sizeof(*id)) != sizeof(*id)) ::_exit(6);
  }
}

TEST(RocksDbCrashTest, ADatabaseKilledMidStreamReopensWithEveryAcknowledgedEntryFindable) {
  RECOG_SKIP_FORK_UNDER_TSAN();
  const auto vocabulary = PlaceVocabulary();
  ASSERT_NE(vocabulary, nullptr);
  TempDir dir("crash_db");
  const std::string path = dir.Sub("store");
  {
    auto store = OpenRocksDbIndexStore(path, WithSync(SyncPolicy::kGrouped));
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    ASSERT_TRUE(Database::Create(store->get(), "db", vocabulary).ok());
  }
  std::mt19937 rng(kSeed);
  std::set<EntryId> acknowledged;
  for (int round = 0; round < 6; ++round) {
    SCOPED_TRACE("round " + std::to_string(round));
    int acks = -1;
    const pid_t pid = ForkWriter([&](int ack_fd) { RunDatabaseWriter(path, ack_fd); }, &acks);
    ASSERT_GE(pid, 0);
    EntryId id = 0;
    // Blocks until the child has opened the database (or died: end of file).
    if (::read(acks, &id, sizeof(id)) == sizeof(id)) {
      EXPECT_EQ(id, kOpenedMarker);
    }
    std::this_thread::sleep_for(
        std::chrono::milliseconds(std::uniform_int_distribution<int>(50, 200)(rng)));
    ::kill(pid, SIGKILL);
    EntryId last = kInvalidEntryId;
    while (::read(acks, &id, sizeof(id)) == sizeof(id)) {
      acknowledged.insert(id);
      last = id;
    }
    ::close(acks);
    int status = 0;
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL)
        << "the writer stopped by itself with exit code " << WEXITSTATUS(status);
    ASSERT_NE(last, kInvalidEntryId) << "the writer was killed before its first entry";

    auto store = OpenRocksDbIndexStore(path, WithSync(SyncPolicy::kGrouped));
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    auto db = Database::Open(store->get(), "db", vocabulary);  // checks every entry
    ASSERT_TRUE(db.ok()) << db.status().ToString();
    EXPECT_GE((*db)->size(), acknowledged.size());
    EXPECT_GT((*db)->next_entry_id(), last);
    for (EntryId ack : acknowledged) {
      ASSERT_TRUE((*db)->Contains(ack)) << "acknowledged entry " << ack << " is gone";
    }
    auto stored = (*db)->Get(last);
    ASSERT_TRUE(stored.ok()) << stored.status().ToString();
    const FeatureSet expected = DatabaseFeatures(last);
    ASSERT_EQ(stored->descriptors.rows, expected.descriptors.rows);
    EXPECT_EQ(cv::norm(stored->descriptors, expected.descriptors, cv::NORM_HAMMING), 0.0);

    BowVector bow;
    ASSERT_TRUE(vocabulary->Transform(expected.descriptors, &bow).ok());
    bow.Normalize(BowNormalization::kL1);
    std::vector<QueryResult> results;
    ASSERT_TRUE((*db)->Query(bow, {.max_results = 3}, &results).ok());
    ASSERT_FALSE(results.empty());
    EXPECT_EQ(results[0].id, last);
    EXPECT_NEAR(results[0].score, 1.0, 1e-6);
  }
  std::printf("%zu entries acknowledged through the database over 6 rounds\n", acknowledged.size());
}

}  // namespace
}  // namespace recog
