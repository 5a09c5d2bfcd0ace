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
// flush or compact; that is fine for those tests because each child writes far less than one
// memtable (64 MB) and the parent, which reopens the store every round, does the flushing; but
// none of their kills lands in a compaction. A fourth test kills during compactions on purpose: its
// writer is a program of its own (storage/testing/compacting_writer.cc, started with fork and exec)
// that has the memtables flushed every few entries, so that level-0 files pile up and RocksDB
// compacts them in the background all the time. The test polls, every millisecond, the bytes
// written by the writer's compaction thread (RocksDB names it "rocksdb:low") in /proc. When the
// thread has written a table file since the last poll, it stops the writer (SIGSTOP) and kills it
// if, no flush running, it has a table file open for writing: the compaction's unfinished output.
// Otherwise (the compaction has finished its output already, or a flush runs) the writer goes on.
// After the kill, a read-only open confirms that no version refers to that file; then the same
// checks as above, for every entry, the ones the compactions were rewriting included.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <optional>
#include <random>
#include <set>
#include <thread>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <rocksdb/db.h>
#include <rocksdb/metadata.h>

#include "core/index/database.h"
#include "core/vocabulary/vocabulary_io.h"
#include "storage/rocksdb_index_store.h"
#include "storage/store_test_util.h"
#include "storage/testing/compacting_writer.h"
#include "tests/testing/synthetic.h"

namespace recog {
namespace {

using testing::CrashEntry;
using testing::EntryDifference;
using testing::TempDir;
using testing::TestMapConfig;

constexpr uint32_t kSeed = 20240607;

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
  const double timestamp = e.metadata.timestamp.value_or(-1.0);
  mix(&timestamp, sizeof(timestamp));
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

// Checks a map of a reopened store against what its killed writers acknowledged: the entries
// acknowledged in the last round (`acked_now`) read back with all their parts, a scan over all
// parts succeeds (it fails on a partial entry), every acknowledged entry is among those scanned
// and the map's next id lies past them. An entry seen for the first time is compared with the
// content derived from its id; later rounds compare its fingerprint, kept in *fingerprints.
void CheckReopenedMap(IndexStore& store, MapId map, const std::set<EntryId>& acknowledged,
                      const std::vector<EntryId>& acked_now,
                      std::map<EntryId, uint64_t>* fingerprints) {
  for (EntryId ack : acked_now) {
    EntryRecord got;
    const Status s = store.ReadEntry(map, ack, kEntryAllParts, &got);
    ASSERT_TRUE(s.ok()) << "acknowledged entry " << ack << ": " << s.ToString();
  }
  std::vector<EntryId> present;
  const Status scan = store.ScanEntries(map, 0, kEntryAllParts, [&](EntryRecord& e) {
    if (!present.empty()) {
      EXPECT_GT(e.id, present.back());
    }
    present.push_back(e.id);
    const uint64_t fingerprint = Fingerprint(e);
    auto [known, is_new] = fingerprints->emplace(e.id, fingerprint);
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
    EXPECT_GT(*store.NextEntryId(map), *acknowledged.rbegin());
  }
}

// Written to the pipe by the child once its store is open.
constexpr EntryId kOpenedMarker = kInvalidEntryId;

// How long a round waits for the writer's next acknowledgement (its store open, its first entry)
// before it gives up on that writer. The writers are forked from this process, whose threads
// (RocksDB's background pool above all) may hold a lock at the moment of the fork: the child then
// waits for it for ever (its copy of the lock has no owner left to release it). Such a child is
// killed like any other (a kill while the store opens) and counted; a store that never opens
// fails the parent's own open (not forked) in the same round.
constexpr int kAckTimeoutMs = 60000;

enum class Ack { kReceived, kPipeEnded, kTimedOut };

// Reads the child's next acknowledgement from `fd` into *id: kPipeEnded when the child died,
// kTimedOut when none came within kAckTimeoutMs.
Ack ReadAck(int fd, EntryId* id) {
  pollfd entry{fd, POLLIN, 0};
  if (::poll(&entry, 1, kAckTimeoutMs) == 0) return Ack::kTimedOut;
  return ::read(fd, id, sizeof(*id)) == sizeof(*id) ? Ack::kReceived : Ack::kPipeEnded;
}

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

// Runs `rounds` kill-and-check rounds against a store with the given sync policy. In most rounds
// the delay runs from the moment the child has its store open, so that the kill lands among the
// commits even on a slow (sanitizer) build; every fourth round it runs from the fork, so that
// some kills land while the store is still opening (recovering the previous round's log). A
// child that does not open the store within kAckTimeoutMs (stuck after the fork) is killed then.
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
  int stuck_writers = 0;
  for (int round = 0; round < rounds; ++round) {
    SCOPED_TRACE("round " + std::to_string(round));
    const int delay_ms = std::uniform_int_distribution<int>(5, 80)(rng);
    bool late = round % 4 != 3;
    int acks = -1;
    const pid_t pid = ForkWriter([&](int ack_fd) { RunWriter(path, sync, map, ack_fd); }, &acks);
    ASSERT_GE(pid, 0);
    EntryId id = 0;
    if (late) {
      // Until the child has opened the store (or died: end of file; or is stuck).
      const Ack opened = ReadAck(acks, &id);
      if (opened == Ack::kReceived) {
        EXPECT_EQ(id, kOpenedMarker);
      }
      if (opened == Ack::kTimedOut) {
        late = false;
        ++stuck_writers;
      } else {
        ++late_rounds;
      }
    }
    // The kill's moment, at random: the behaviour under test, not a wait for something.
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
    rounds_with_acks += late && !acked_now.empty();

    auto store = OpenRocksDbIndexStore(path, WithSync(sync));
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    ASSERT_NO_FATAL_FAILURE(CheckReopenedMap(**store, map, acknowledged, acked_now, &fingerprints));
  }
  // The delays are long enough for most late-killed children to get some commits in.
  EXPECT_GE(rounds_with_acks, late_rounds / 2);
  EXPECT_LE(stuck_writers, rounds / 4) << "writers that never opened the store";
  std::printf(
      "%zu acknowledged entries over %d rounds (%d of %d late-kill rounds had some; %d writers "
      "stuck after the fork)\n",
      acknowledged.size(), rounds, rounds_with_acks, late_rounds, stuck_writers);
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
  int stuck_writers = 0;  // a round whose writer is stuck after the fork is run again
  for (int round = 0; round < 6; ++round) {
    SCOPED_TRACE("round " + std::to_string(round));
    int acks = -1;
    const pid_t pid = ForkWriter([&](int ack_fd) { RunDatabaseWriter(path, ack_fd); }, &acks);
    ASSERT_GE(pid, 0);
    EntryId id = 0;
    // Until the child has opened the database (or died: end of file; or is stuck).
    Ack ack = ReadAck(acks, &id);
    if (ack == Ack::kReceived) {
      EXPECT_EQ(id, kOpenedMarker);
    }
    // Then until its first entry is acknowledged, however slow the machine (a sanitizer build
    // once took longer than the wait below to add it), so that the kill comes mid-stream.
    EntryId last = kInvalidEntryId;
    if (ack == Ack::kReceived && (ack = ReadAck(acks, &id)) == Ack::kReceived) {
      acknowledged.insert(id);
      last = id;
    }
    const bool stuck = ack == Ack::kTimedOut;
    // The kill's moment, at random: the behaviour under test, not a wait for something.
    if (!stuck) {
      std::this_thread::sleep_for(
          std::chrono::milliseconds(std::uniform_int_distribution<int>(50, 200)(rng)));
    }
    ::kill(pid, SIGKILL);
    while (::read(acks, &id, sizeof(id)) == sizeof(id)) {
      acknowledged.insert(id);
      last = id;
    }
    ::close(acks);
    int status = 0;
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL)
        << "the writer stopped by itself with exit code " << WEXITSTATUS(status);
    if (stuck) {
      ASSERT_LT(++stuck_writers, 3) << "writers that never acknowledged an entry";
      --round;
      continue;
    }
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

// --- Kills during a compaction ---

namespace fs = std::filesystem;

using testing::CompactingWriterRecord;
using testing::kCompactingWriterMaps;

constexpr int kCompactingWriterMapCount = int(std::size(kCompactingWriterMaps));

// Starts the compacting writer (storage/testing/compacting_writer.h) on the store in `dir` and
// returns its pid, or -1; *records_fd is the non-blocking read end of its pipe.
pid_t StartCompactingWriter(const std::string& dir, int* records_fd) {
  int records[2];
  if (::pipe2(records, O_CLOEXEC) != 0) return -1;
  const std::string fd = std::to_string(records[1]);
  char* const argv[] = {const_cast<char*>(RECOG_COMPACTING_WRITER), const_cast<char*>(dir.c_str()),
                        const_cast<char*>(fd.c_str()), nullptr};
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    // Between fork and exec only async-signal-safe calls: the test process has threads.
    ::fcntl(records[1], F_SETFD, 0);  // the write end, and only it, survives the exec
    ::execv(argv[0], argv);
    ::_exit(127);
  }
  ::close(records[1]);
  if (pid < 0 || ::fcntl(records[0], F_SETFL, O_NONBLOCK) != 0) {
    ::close(records[0]);
    return -1;
  }
  *records_fd = records[0];
  return pid;
}

std::string ProcDir(pid_t pid) { return "/proc/" + std::to_string(pid); }

// The threads of process `pid` named `name`.
std::vector<pid_t> ThreadsNamed(pid_t pid, const std::string& name) {
  std::vector<pid_t> threads;
  std::error_code ec;
  for (auto it = fs::directory_iterator(ProcDir(pid) + "/task", ec);
       !ec && it != fs::directory_iterator(); it.increment(ec)) {
    std::ifstream comm(it->path() / "comm");
    std::string thread_name;
    if (std::getline(comm, thread_name) && thread_name == name) {
      threads.push_back(pid_t(std::stol(it->path().filename().string())));
    }
  }
  return threads;
}

// The bytes thread `tid` of process `pid` has handed to write() and its like so far (`wchar` in
// its /proc io file: per thread and whatever the filesystem, unlike `write_bytes`), or nullopt
// when the thread is gone.
std::optional<uint64_t> BytesWrittenBy(pid_t pid, pid_t tid) {
  std::ifstream io(ProcDir(pid) + "/task/" + std::to_string(tid) + "/io");
  std::string key;
  uint64_t value = 0;
  while (io >> key >> value) {
    if (key == "wchar:") return value;
  }
  return std::nullopt;
}

// The names of the table files (*.sst) process `pid` has open for writing.
std::set<std::string> TableFilesOpenForWriting(pid_t pid) {
  std::set<std::string> names;
  std::error_code ec;
  for (auto it = fs::directory_iterator(ProcDir(pid) + "/fd", ec);
       !ec && it != fs::directory_iterator(); it.increment(ec)) {
    const fs::path file = fs::read_symlink(it->path(), ec);
    if (ec || file.extension() != ".sst") continue;
    std::ifstream info(ProcDir(pid) + "/fdinfo/" + it->path().filename().string());
    std::string key;
    std::string value;
    while (info >> key >> value) {
      if (key == "flags:" && (std::stoi(value, nullptr, 8) & O_ACCMODE) != O_RDONLY) {
        names.insert(file.filename().string());
      }
    }
  }
  return names;
}

// The names of the table files in `dir` that the database does not refer to (read-only, so that
// they stay: a read-write open deletes them), or an error.
StatusOr<std::set<std::string>> UnreferencedTableFiles(const std::string& dir) {
  const rocksdb::DBOptions options;
  std::vector<std::string> families;
  rocksdb::Status s = rocksdb::DB::ListColumnFamilies(options, dir, &families);
  if (!s.ok()) return Status::Internal(s.ToString());
  std::vector<rocksdb::ColumnFamilyDescriptor> descriptors;
  for (const std::string& family : families) {
    descriptors.emplace_back(family, rocksdb::ColumnFamilyOptions());
  }
  std::vector<rocksdb::ColumnFamilyHandle*> handles;
  rocksdb::DB* db = nullptr;
  s = rocksdb::DB::OpenForReadOnly(options, dir, descriptors, &handles, &db);
  if (!s.ok()) return Status::Internal(s.ToString());
  std::vector<rocksdb::LiveFileMetaData> live;
  db->GetLiveFilesMetaData(&live);
  for (rocksdb::ColumnFamilyHandle* handle : handles) db->DestroyColumnFamilyHandle(handle);
  delete db;

  std::set<std::string> unreferenced;
  for (const fs::directory_entry& file : fs::directory_iterator(dir)) {
    if (file.path().extension() == ".sst") unreferenced.insert(file.path().filename().string());
  }
  for (const rocksdb::LiveFileMetaData& file : live) unreferenced.erase(file.relative_filename);
  return unreferenced;
}

// RocksDB names the threads of its compaction pool so (pthread_setname_np).
constexpr char kCompactionThreadName[] = "rocksdb:low";
// A compaction thread that hands at least this much to write() between two polls is writing a
// table file: its other writes (lines of the info log, the MANIFEST record of a finished
// compaction) are a few KiB. RocksDB buffers a table file up to 1 MiB before writing, so small
// outputs may pass unseen; those of the features (the bulk of every entry) do not.
constexpr uint64_t kTableWriteBytes = 64 << 10;
constexpr auto kPollInterval = std::chrono::milliseconds(1);
// A round gives up on seeing a compaction write after this long: the writer flushes every
// kCompactingWriterEntriesPerFlush entries, and every fourth flush starts compactions.
constexpr auto kRoundTimeout = std::chrono::seconds(10);

TEST(RocksDbCrashTest, AKillDuringACompactionLosesNoAcknowledgedEntry) {
  RECOG_SKIP_FORK_UNDER_TSAN();
  TempDir dir("compaction");
  const std::string path = dir.Sub("store");
  MapId maps[kCompactingWriterMapCount];
  {
    auto store = OpenRocksDbIndexStore(path, WithSync(SyncPolicy::kEveryWrite));
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    for (int m = 0; m < kCompactingWriterMapCount; ++m) {
      auto info = (*store)->CreateMap(TestMapConfig(kCompactingWriterMaps[m]));
      ASSERT_TRUE(info.ok());
      maps[m] = info->id;
    }
  }

  constexpr int kRounds = 6;
  std::set<EntryId> acknowledged[kCompactingWriterMapCount];
  std::map<EntryId, uint64_t> fingerprints[kCompactingWriterMapCount];
  int kills_during_compaction_writes = 0;
  int unreferenced_outputs = 0;
  int resumed = 0;  // stops that found the compaction's output finished, or a flush running
  for (int round = 0; round < kRounds; ++round) {
    SCOPED_TRACE("round " + std::to_string(round));
    int records = -1;
    const pid_t pid = StartCompactingWriter(path, &records);
    ASSERT_GE(pid, 0);
    std::vector<EntryId> acked_now[kCompactingWriterMapCount];
    size_t acked_in_round = 0;
    bool flushing = false;
    auto read_records = [&] {
      CompactingWriterRecord record;
      while (::read(records, &record, sizeof(record)) == sizeof(record)) {
        switch (record.kind) {
          case CompactingWriterRecord::kCommitted:
            acknowledged[record.map].insert(record.id);
            acked_now[record.map].push_back(record.id);
            ++acked_in_round;
            break;
          case CompactingWriterRecord::kFlushing:
            flushing = true;
            break;
          case CompactingWriterRecord::kFlushed:
            flushing = false;
            break;
        }
      }
    };

    // Waits for a compaction writing its output (see the top of the file). A stopped process
    // does nothing more: for a crash of the process, the kill lands at the stop. While no flush
    // runs (the writer announces its flushes, the only ones in it), a table file open for writing
    // is the compaction's. Not before the writer has had an entry acknowledged, so that the kill
    // lands among its commits.
    bool compaction_thread_seen = false;
    std::map<pid_t, uint64_t> written;       // by compaction thread
    std::set<std::string> open_for_writing;  // at the kill
    bool exited = false;
    int status = 0;
    const auto deadline = std::chrono::steady_clock::now() + kRoundTimeout;
    while (open_for_writing.empty() && std::chrono::steady_clock::now() < deadline) {
      read_records();
      if (::waitpid(pid, &status, WNOHANG) == pid) {
        exited = true;
        break;
      }
      bool compaction_wrote = false;
      const std::vector<pid_t> compaction_threads = ThreadsNamed(pid, kCompactionThreadName);
      compaction_thread_seen |= !compaction_threads.empty();
      for (pid_t tid : compaction_threads) {
        const std::optional<uint64_t> bytes = BytesWrittenBy(pid, tid);
        if (!bytes) continue;
        auto [last, first_seen] = written.emplace(tid, *bytes);
        compaction_wrote |= !first_seen && *bytes - last->second >= kTableWriteBytes;
        last->second = *bytes;
      }
      if (compaction_wrote && acked_in_round > 0 && !flushing) {
        ::kill(pid, SIGSTOP);
        ASSERT_EQ(::waitpid(pid, &status, WUNTRACED), pid);
        if (!WIFSTOPPED(status)) {
          exited = true;
          break;
        }
        read_records();
        if (!flushing) open_for_writing = TableFilesOpenForWriting(pid);
        if (open_for_writing.empty()) {
          ++resumed;
          ::kill(pid, SIGCONT);
        }
      }
      if (open_for_writing.empty()) std::this_thread::sleep_for(kPollInterval);
    }
    if (!exited) {
      ::kill(pid, SIGKILL);
      ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    }
    read_records();  // the rest, up to the end of the pipe
    ::close(records);
    ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL)
        << "the writer stopped by itself with exit code " << WEXITSTATUS(status);
    ASSERT_TRUE(compaction_thread_seen)
        << "the writer had no thread named '" << kCompactionThreadName
        << "': has RocksDB renamed its compaction threads?";
    ASSERT_FALSE(written.empty())
        << "cannot read the compaction thread's /proc/<pid>/task/<tid>/io";
    if (!open_for_writing.empty()) {
      ++kills_during_compaction_writes;
      // From the directory: the unfinished output is no part of the database.
      const auto unreferenced = UnreferencedTableFiles(path);
      ASSERT_TRUE(unreferenced.ok()) << unreferenced.status().ToString();
      unreferenced_outputs +=
          std::all_of(open_for_writing.begin(), open_for_writing.end(),
                      [&](const std::string& name) { return unreferenced->count(name) > 0; });
    }

    auto store = OpenRocksDbIndexStore(path, WithSync(SyncPolicy::kEveryWrite));
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    for (int m = 0; m < kCompactingWriterMapCount; ++m) {
      SCOPED_TRACE(kCompactingWriterMaps[m]);
      ASSERT_NO_FATAL_FAILURE(
          CheckReopenedMap(**store, maps[m], acknowledged[m], acked_now[m], &fingerprints[m]));
    }
  }
  std::printf(
      "%d rounds: %d kills while a compaction was writing its output (left unreferenced: %d; "
      "writer resumed %d times), %zu entries acknowledged\n",
      kRounds, kills_during_compaction_writes, unreferenced_outputs, resumed,
      acknowledged[0].size() + acknowledged[1].size());
  // A round without such a kill timed out waiting for one.
  EXPECT_GE(kills_during_compaction_writes, kRounds - 1)
      << "no compaction was caught writing its output within " << kRoundTimeout.count() << " s in "
      << kRounds - kills_during_compaction_writes << " of " << kRounds << " rounds";
  EXPECT_EQ(unreferenced_outputs, kills_during_compaction_writes);
}

}  // namespace
}  // namespace recog
