// RocksDbIndexStore beyond the common contract: persistence of entries and blobs across reopen,
// stores written before the blobs column family existed, checkpoints and restore, damaged stored
// values, and the ways opening a directory can fail (not a directory, missing, locked, read-only,
// disk full). The contract suite (index_store_contract_test.cc) covers the IndexStore semantics
// themselves.
//
// Some tests fork: the child process must not use GoogleTest, reports through its exit code or a
// pipe, and leaves with _exit. The parent has every store closed when it forks, so that no
// RocksDB background work is in flight in the copied address space.
#include "storage/rocksdb_index_store.h"

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <thread>

#include <gtest/gtest.h>
#include <rocksdb/db.h>

#include "core/index/memory_index_store.h"
#include "storage/record_codec.h"
#include "storage/snapshot_file.h"
#include "storage/store_test_util.h"
#include "tests/testing/wait.h"

namespace recog {
namespace {

namespace fs = std::filesystem;
using testing::EntryDifference;
using testing::MakeTestEntry;
using testing::TempDir;
using testing::TestMapConfig;
using testing::WaitUntil;

// Exit codes of forked children: kChildStatusBase + StatusCode of what they observed.
constexpr int kChildStatusBase = 10;
constexpr int kChildSkipped = 2;

int ChildExitCode(const Status& s) { return kChildStatusBase + int(s.code()); }

// Runs `child` in a forked process; returns its exit code, or -signal when it was killed.
int RunInChild(const std::function<int()>& child) {
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = ::fork();
  if (pid == 0) ::_exit(child());
  int status = 0;
  ::waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
}

// Opens a store in a raw RocksDB handle, to damage it on purpose.
class RawDb {
 public:
  explicit RawDb(const std::string& path) {
    std::vector<std::string> names;
    EXPECT_TRUE(rocksdb::DB::ListColumnFamilies(rocksdb::DBOptions(), path, &names).ok());
    std::vector<rocksdb::ColumnFamilyDescriptor> descriptors;
    for (const std::string& name : names) descriptors.emplace_back(name, rocksdb::Options());
    std::vector<rocksdb::ColumnFamilyHandle*> handles;
    const rocksdb::Status s =
        rocksdb::DB::Open(rocksdb::DBOptions(), path, descriptors, &handles, &db_);
    EXPECT_TRUE(s.ok()) << s.ToString();
    for (size_t i = 0; i < handles.size(); ++i) handles_[names[i]] = handles[i];
  }
  ~RawDb() {
    for (auto& [name, handle] : handles_) db_->DestroyColumnFamilyHandle(handle);
    delete db_;
  }

  void Put(const std::string& cf, const std::string& key, const std::string& value) {
    ASSERT_TRUE(db_->Put(rocksdb::WriteOptions(), handles_.at(cf), key, value).ok());
  }
  void Delete(const std::string& cf, const std::string& key) {
    ASSERT_TRUE(db_->Delete(rocksdb::WriteOptions(), handles_.at(cf), key).ok());
  }
  // Drops a column family, as if the store had been written by a version without it.
  void DropColumnFamily(const std::string& cf) {
    rocksdb::ColumnFamilyHandle* handle = handles_.at(cf);
    ASSERT_TRUE(db_->DropColumnFamily(handle).ok());
    db_->DestroyColumnFamilyHandle(handle);
    handles_.erase(cf);
  }
  std::string Get(const std::string& cf, const std::string& key) {
    std::string value;
    EXPECT_TRUE(db_->Get(rocksdb::ReadOptions(), handles_.at(cf), key, &value).ok());
    return value;
  }

 private:
  rocksdb::DB* db_ = nullptr;
  std::map<std::string, rocksdb::ColumnFamilyHandle*> handles_;
};

class RocksDbStoreTest : public ::testing::Test {
 protected:
  std::string StorePath() const { return dir_.Sub("store"); }

  std::unique_ptr<IndexStore> Open(SyncPolicy sync = SyncPolicy::kEveryWrite,
                                   const std::string& path = "") {
    RocksDbStoreOptions options;
    options.sync = sync;
    auto store = OpenRocksDbIndexStore(path.empty() ? StorePath() : path, options);
    if (!store.ok()) {
      ADD_FAILURE() << store.status().ToString();
      return nullptr;
    }
    return std::move(store).value();
  }

  // A store with map "m" holding entries 0 .. n-1 (seed 0); returns the map id. Closed again.
  MapId MakeStore(EntryId n) {
    auto store = Open();
    if (store == nullptr) return 0;
    auto map = store->CreateMap(TestMapConfig("m"));
    EXPECT_TRUE(map.ok());
    for (EntryId id = 0; id < n; ++id)
      EXPECT_TRUE(store->CommitEntry(map->id, MakeTestEntry(id)).ok());
    return map->id;
  }

  std::vector<EntryId> ScanIds(IndexStore& store, MapId map, uint32_t parts, Status* status) {
    std::vector<EntryId> ids;
    *status = store.ScanEntries(map, 0, parts, [&](EntryRecord& e) {
      ids.push_back(e.id);
      return Status::Ok();
    });
    return ids;
  }

  TempDir dir_{"rocksdb"};
};

TEST_F(RocksDbStoreTest, OptionsAreValidated) {
  RocksDbStoreOptions options;
  EXPECT_TRUE(options.Validate().ok());
  options.group_sync_interval_ms = 0;
  EXPECT_EQ(options.Validate().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(OpenRocksDbIndexStore(StorePath(), options).status().code(),
            StatusCode::kInvalidArgument);
  options.sync = SyncPolicy::kEveryWrite;  // the interval only matters when grouping
  EXPECT_TRUE(options.Validate().ok());
  options.block_cache_mb = size_t(1) << 30;
  EXPECT_EQ(options.Validate().code(), StatusCode::kInvalidArgument);
  options.block_cache_mb = 0;  // no block cache
  auto store = OpenRocksDbIndexStore(StorePath(), options);
  ASSERT_TRUE(store.ok()) << store.status().ToString();
}

TEST_F(RocksDbStoreTest, ReopenKeepsMapsEntriesAndNextIds) {
  for (SyncPolicy sync : {SyncPolicy::kEveryWrite, SyncPolicy::kGrouped}) {
    SCOPED_TRACE(int(sync));
    const std::string path = dir_.Sub("store" + std::to_string(int(sync)));
    std::vector<MapInfo> maps_before;
    MapId deleted_id = 0;
    MapId a = 0;
    MapId b = 0;
    {
      auto store = Open(sync, path);
      ASSERT_NE(store, nullptr);
      a = store->CreateMap(TestMapConfig("a"))->id;
      b = store->CreateMap(TestMapConfig("b", DescriptorFormat::Sift()))->id;
      deleted_id = store->CreateMap(TestMapConfig("c"))->id;
      ASSERT_TRUE(store->CommitEntry(deleted_id, MakeTestEntry(0)).ok());
      ASSERT_TRUE(store->DeleteMap("c").ok());
      for (EntryId id = 0; id < 10; ++id)
        ASSERT_TRUE(store->CommitEntry(a, MakeTestEntry(id)).ok());
      ASSERT_TRUE(store->RemoveEntry(a, 9).ok());
      ASSERT_TRUE(store->RemoveEntry(a, 3).ok());
      for (EntryId id = 0; id < 5; ++id) {
        ASSERT_TRUE(store->CommitEntry(b, MakeTestEntry(id, 1, DescriptorFormat::Sift(), 50)).ok());
      }
      maps_before = *store->ListMaps();
    }
    MapId d = 0;
    {
      auto store = Open(sync, path);
      ASSERT_NE(store, nullptr);
      EXPECT_EQ(*store->ListMaps(), maps_before);
      EXPECT_EQ(*store->NextEntryId(a), 10u);
      EXPECT_EQ(*store->NextEntryId(b), 5u);
      EXPECT_EQ(store->NextEntryId(deleted_id).status().code(), StatusCode::kNotFound);
      Status s;
      EXPECT_EQ(ScanIds(*store, a, kEntryAllParts, &s),
                (std::vector<EntryId>{0, 1, 2, 4, 5, 6, 7, 8}));
      EXPECT_TRUE(s.ok()) << s.ToString();
      for (EntryId id : {0u, 4u, 8u}) {
        EntryRecord got;
        ASSERT_TRUE(store->ReadEntry(a, id, kEntryAllParts, &got).ok());
        EXPECT_EQ(EntryDifference(got, MakeTestEntry(id)), "");
      }
      EntryRecord got;
      ASSERT_TRUE(store->ReadEntry(b, 4, kEntryAllParts, &got).ok());
      EXPECT_EQ(EntryDifference(got, MakeTestEntry(4, 1, DescriptorFormat::Sift(), 50)), "");
      // Map ids are not reused after a reopen either.
      d = store->CreateMap(TestMapConfig("d"))->id;
      EXPECT_GT(d, deleted_id);
    }
    auto store = Open(sync, path);
    ASSERT_NE(store, nullptr);
    EXPECT_EQ(store->GetMap("d")->id, d);
    EXPECT_EQ(store->ListMaps()->size(), 3u);
  }
}

TEST_F(RocksDbStoreTest, BlobsSurviveReopenAndACheckpoint) {
  const std::string model(3 << 20, '\x5a');
  for (SyncPolicy sync : {SyncPolicy::kEveryWrite, SyncPolicy::kGrouped}) {
    SCOPED_TRACE(int(sync));
    const std::string path = dir_.Sub("store" + std::to_string(int(sync)));
    const std::string checkpoint = dir_.Sub("checkpoint" + std::to_string(int(sync)));
    const std::string restored = dir_.Sub("restored" + std::to_string(int(sync)));
    {
      auto store = Open(sync, path);
      ASSERT_NE(store, nullptr);
      ASSERT_TRUE(store->PutBlob("model/box/0000000001", model).ok());
      ASSERT_TRUE(store->PutBlob("model/box/0000000002", "v2").ok());
      ASSERT_TRUE(store->PutBlob("model/cup/0000000001", "first").ok());
      ASSERT_TRUE(store->PutBlob("model/cup/0000000001", "overwritten").ok());
      ASSERT_TRUE(store->PutBlob("doomed", "x").ok());
      ASSERT_TRUE(store->DeleteBlob("doomed").ok());
    }
    const std::vector<std::string> expected_keys = {"model/box/0000000001", "model/box/0000000002",
                                                    "model/cup/0000000001"};
    {
      auto store = Open(sync, path);
      ASSERT_NE(store, nullptr);
      EXPECT_EQ(*store->ListBlobKeys(""), expected_keys);
      EXPECT_TRUE(*store->GetBlob("model/box/0000000001") == model);
      EXPECT_EQ(*store->GetBlob("model/cup/0000000001"), "overwritten");
      EXPECT_EQ(store->GetBlob("doomed").status().code(), StatusCode::kNotFound);
      ASSERT_TRUE(store->Checkpoint(checkpoint).ok());
    }
    ASSERT_TRUE(RestoreRocksDbCheckpoint(checkpoint, restored).ok());
    auto store = Open(sync, restored);
    ASSERT_NE(store, nullptr);
    EXPECT_EQ(*store->ListBlobKeys(""), expected_keys);
    EXPECT_TRUE(*store->GetBlob("model/box/0000000001") == model);
  }
}

TEST_F(RocksDbStoreTest, SnapshotsSurviveReopenAndUnusableSnapshotFilesAreRemoved) {
  namespace fs = std::filesystem;
  const MapId m = MakeStore(3);
  MapId n = 0;
  const auto read_snapshot = [](IndexStore& store, MapId map) -> StatusOr<std::string> {
    RECOG_ASSIGN_OR_RETURN(auto reader, store.ReadSnapshot(map));
    std::string bytes(reader->size(), '\0');
    RECOG_RETURN_IF_ERROR(reader->Read(bytes.data(), bytes.size()));
    return bytes;
  };
  {
    auto store = Open();
    ASSERT_NE(store, nullptr);
    auto map = store->CreateMap(TestMapConfig("n"));
    ASSERT_TRUE(map.ok());
    n = map->id;
    ASSERT_TRUE(store->CommitEntry(n, MakeTestEntry(0)).ok());
    for (const auto& [map_id, covers] : {std::pair{m, 3u}, std::pair{n, 1u}}) {
      auto writer = store->WriteSnapshot(map_id, covers);
      ASSERT_TRUE(writer.ok());
      ASSERT_TRUE((*writer)->Append("index of " + std::to_string(map_id)).ok());
      ASSERT_TRUE((*writer)->Commit().ok());
    }
  }
  {
    auto store = Open();
    ASSERT_NE(store, nullptr);
    const StatusOr<std::string> of_m = read_snapshot(*store, m);
    ASSERT_TRUE(of_m.ok()) << of_m.status().ToString();
    EXPECT_EQ(*of_m, "index of " + std::to_string(m));
    const StatusOr<std::string> of_n = read_snapshot(*store, n);
    ASSERT_TRUE(of_n.ok()) << of_n.status().ToString();
    EXPECT_EQ(*of_n, "index of " + std::to_string(n));
    EXPECT_GT(*store->MapDiskBytes(m), 0u);
  }
  // Damage: m's header, n's bound beyond its entries; add a leftover temporary file and the
  // snapshot of a map that does not exist.
  const std::string folder = storage::SnapshotDirectory(StorePath());
  {
    std::fstream file(storage::SnapshotPath(StorePath(), m), std::ios::in | std::ios::out);
    file.seekp(0);
    file.put('X');
  }
  {
    std::fstream file(storage::SnapshotPath(StorePath(), n), std::ios::in | std::ios::out);
    file.seekp(8);
    file.put(char(50));
  }
  std::ofstream(storage::SnapshotPath(StorePath(), n) + ".tmp") << "half written";
  fs::copy_file(storage::SnapshotPath(StorePath(), n), storage::SnapshotPath(StorePath(), 999));
  auto store = Open();
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->ReadSnapshot(m).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store->ReadSnapshot(n).status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(fs::is_empty(folder));
  Status scanned;
  EXPECT_EQ(ScanIds(*store, m, kEntryAllParts, &scanned).size(), 3u);  // the entries stay
  EXPECT_TRUE(scanned.ok());
}

TEST_F(RocksDbStoreTest, AStoreWrittenBeforeBlobsExistedOpensAndTakesBlobs) {
  const MapId map = MakeStore(3);
  {
    RawDb raw(StorePath());
    raw.DropColumnFamily("blobs");
  }
  std::vector<std::string> families;
  ASSERT_TRUE(rocksdb::DB::ListColumnFamilies(rocksdb::DBOptions(), StorePath(), &families).ok());
  ASSERT_EQ(std::count(families.begin(), families.end(), "blobs"), 0);
  {
    auto store = Open();
    ASSERT_NE(store, nullptr);
    Status s;
    EXPECT_EQ(ScanIds(*store, map, kEntryAllParts, &s), (std::vector<EntryId>{0, 1, 2}));
    EXPECT_TRUE(s.ok()) << s.ToString();
    auto keys = store->ListBlobKeys("");
    ASSERT_TRUE(keys.ok()) << keys.status().ToString();
    EXPECT_TRUE(keys->empty());
    EXPECT_EQ(store->GetBlob("model/box/0000000001").status().code(), StatusCode::kNotFound);
    ASSERT_TRUE(store->PutBlob("model/box/0000000001", "bytes").ok());
  }
  families.clear();
  ASSERT_TRUE(rocksdb::DB::ListColumnFamilies(rocksdb::DBOptions(), StorePath(), &families).ok());
  EXPECT_EQ(std::count(families.begin(), families.end(), "blobs"), 1);
  auto store = Open();
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(*store->GetBlob("model/box/0000000001"), "bytes");
  EXPECT_EQ(store->ListMaps()->size(), 1u);
}

TEST_F(RocksDbStoreTest, GroupedWritesSurviveACleanCloseAndTheSyncThreadStopsPromptly) {
  RocksDbStoreOptions options;
  options.sync = SyncPolicy::kGrouped;
  options.group_sync_interval_ms = 60000;  // the thread never gets to sync on its own
  MapId map = 0;
  {
    auto store = OpenRocksDbIndexStore(StorePath(), options);
    ASSERT_TRUE(store.ok());
    map = (*store)->CreateMap(TestMapConfig("m"))->id;
    for (EntryId id = 0; id < 20; ++id)
      ASSERT_TRUE((*store)->CommitEntry(map, MakeTestEntry(id)).ok());
    const auto start = std::chrono::steady_clock::now();
    store->reset();
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(2));
  }
  auto store = Open();
  ASSERT_NE(store, nullptr);
  Status s;
  EXPECT_EQ(ScanIds(*store, map, kEntryAllParts, &s).size(), 20u);
  EXPECT_TRUE(s.ok());
}

TEST_F(RocksDbStoreTest, CheckpointWhileWritingHoldsEveryEarlierCommit) {
  const std::string checkpoint = dir_.Sub("checkpoint");
  const std::string restored = dir_.Sub("restored");
  MapId map = 0;
  EntryId committed_before = 0;
  {
    auto store = Open(SyncPolicy::kGrouped);
    ASSERT_NE(store, nullptr);
    map = store->CreateMap(TestMapConfig("live"))->id;
    std::atomic<EntryId> acknowledged{0};  // ids 0 .. acknowledged-1 are committed
    std::atomic<bool> stop{false};
    std::atomic<int> failures{0};
    std::thread writer([&] {
      for (EntryId id = 0; !stop; ++id) {
        if (!store->CommitEntry(map, MakeTestEntry(id, 0, DescriptorFormat::Orb(), 100)).ok()) {
          ++failures;
          return;
        }
        acknowledged = id + 1;
      }
    });
    EXPECT_TRUE(WaitUntil([&] { return acknowledged >= 50 || failures > 0; }))
        << "the writer did not commit 50 entries";
    committed_before = acknowledged.load();
    const Status s = store->Checkpoint(checkpoint);
    const EntryId target = acknowledged + 50;
    EXPECT_TRUE(WaitUntil([&] { return acknowledged >= target || failures > 0; }))
        << "the writer did not commit 50 more entries after the checkpoint";
    stop = true;
    writer.join();
    ASSERT_TRUE(s.ok()) << s.ToString();
    EXPECT_EQ(failures.load(), 0);
    EXPECT_EQ(store->Checkpoint(checkpoint).code(), StatusCode::kAlreadyExists);
    EXPECT_EQ(store->Checkpoint(dir_.Sub("no/such/parent")).code(), StatusCode::kNotFound);
  }

  ASSERT_TRUE(RestoreRocksDbCheckpoint(checkpoint, restored).ok());
  auto store = Open(SyncPolicy::kEveryWrite, restored);
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->GetMap("live")->id, map);
  for (EntryId id = 0; id < committed_before; ++id) {
    EntryRecord got;
    const Status s = store->ReadEntry(map, id, kEntryAllParts, &got);
    ASSERT_TRUE(s.ok()) << "entry " << id << ": " << s.ToString();
    EXPECT_EQ(EntryDifference(got, MakeTestEntry(id, 0, DescriptorFormat::Orb(), 100)), "");
  }
  // Whatever else the checkpoint caught is whole.
  Status s;
  const std::vector<EntryId> ids = ScanIds(*store, map, kEntryAllParts, &s);
  EXPECT_TRUE(s.ok()) << s.ToString();
  EXPECT_GE(ids.size(), committed_before);
  EXPECT_GE(*store->NextEntryId(map), committed_before);
  // The restored store is independent and writable.
  EXPECT_TRUE(store->CommitEntry(map, MakeTestEntry(1000000)).ok());
}

TEST_F(RocksDbStoreTest, RestoreRefusesAnExistingTargetAndSomethingThatIsNoCheckpoint) {
  MakeStore(3);
  const std::string checkpoint = dir_.Sub("checkpoint");
  {
    auto store = Open();
    ASSERT_NE(store, nullptr);
    ASSERT_TRUE(store->Checkpoint(checkpoint).ok());
  }
  fs::create_directories(dir_.Sub("taken"));
  EXPECT_EQ(RestoreRocksDbCheckpoint(checkpoint, dir_.Sub("taken")).code(),
            StatusCode::kAlreadyExists);
  EXPECT_EQ(RestoreRocksDbCheckpoint(checkpoint, StorePath()).code(), StatusCode::kAlreadyExists);
  EXPECT_EQ(RestoreRocksDbCheckpoint(dir_.Sub("nothing"), dir_.Sub("new1")).code(),
            StatusCode::kNotFound);
  fs::create_directories(dir_.Sub("empty"));
  EXPECT_EQ(RestoreRocksDbCheckpoint(dir_.Sub("empty"), dir_.Sub("new2")).code(),
            StatusCode::kDataLoss);
  EXPECT_FALSE(fs::exists(dir_.Sub("new1")));
  EXPECT_FALSE(fs::exists(dir_.Sub("new2")));
  // The refused target is untouched.
  EXPECT_TRUE(fs::is_empty(dir_.Sub("taken")));
}

TEST_F(RocksDbStoreTest, MemoryStoreHasNothingToCheckpoint) {
  MemoryIndexStore memory;
  EXPECT_EQ(memory.Checkpoint(dir_.Sub("cp")).code(), StatusCode::kFailedPrecondition);
}

// --- Damaged data ---

TEST_F(RocksDbStoreTest, GarbageFeatureValuesAreDataLossNotACrash) {
  const MapId map = MakeStore(6);
  const std::string valid =
      *storage::EncodeFeatures(MakeTestEntry(1).keypoints, MakeTestEntry(1).descriptors, {});
  const std::vector<std::string> garbage = {
      "",                                                                        // empty
      std::string(1, char(storage::kRecordFormat)),                              // format byte only
      valid.substr(0, valid.size() - 1),                                         // one byte short
      std::string(1, '\x63') + valid.substr(1),                                  // unknown format
      std::string(1, char(storage::kRecordFormat)) + std::string(1000, '\xff'),  // noise
  };
  {
    RawDb raw(StorePath());
    for (size_t i = 0; i < garbage.size(); ++i) {
      raw.Put("features", storage::EntryKey(map, EntryId(i + 1)), garbage[i]);
    }
  }
  auto store = Open();
  ASSERT_NE(store, nullptr);
  for (EntryId id = 1; id <= garbage.size(); ++id) {
    SCOPED_TRACE(id);
    EntryRecord got;
    const Status s = store->ReadEntry(map, id, kEntryAllParts, &got);
    EXPECT_EQ(s.code(), StatusCode::kDataLoss) << s.ToString();
    EXPECT_NE(s.message().find("map " + std::to_string(map) + " entry " + std::to_string(id)),
              std::string::npos)
        << s.message();
    // The undamaged parts still read.
    EXPECT_TRUE(store->ReadEntry(map, id, kEntryMetadata | kEntryBow | kEntryDirect, &got).ok());
  }
  EntryRecord got;
  EXPECT_TRUE(store->ReadEntry(map, 0, kEntryAllParts, &got).ok());

  Status s;
  EXPECT_EQ(ScanIds(*store, map, kEntryAllParts, &s), std::vector<EntryId>{0});
  EXPECT_EQ(s.code(), StatusCode::kDataLoss) << s.ToString();
  EXPECT_EQ(ScanIds(*store, map, kEntryMetadata | kEntryDirect, &s).size(), 6u);
  EXPECT_TRUE(s.ok()) << s.ToString();
}

TEST_F(RocksDbStoreTest, AMissingPartOrAPartWithoutMetadataIsDataLoss) {
  const MapId map = MakeStore(5);
  {
    RawDb raw(StorePath());
    raw.Delete("bow", storage::EntryKey(map, 2));         // entry 2 lacks its bow
    raw.Delete("entry_meta", storage::EntryKey(map, 3));  // entry 3 lost its metadata
    raw.Put("direct", storage::EntryKey(map, 9),          // a direct record of nothing
            storage::EncodeDirect(MakeTestEntry(9).direct));
  }
  auto store = Open();
  ASSERT_NE(store, nullptr);
  EntryRecord got;
  EXPECT_EQ(store->ReadEntry(map, 2, kEntryBow, &got).code(), StatusCode::kDataLoss);
  EXPECT_TRUE(store->ReadEntry(map, 2, kEntryMetadata | kEntryFeatures, &got).ok());
  EXPECT_EQ(store->ReadEntry(map, 3, kEntryAllParts, &got).code(), StatusCode::kNotFound);

  Status s;
  EXPECT_EQ(ScanIds(*store, map, kEntryBow, &s), (std::vector<EntryId>{0, 1}));
  EXPECT_EQ(s.code(), StatusCode::kDataLoss) << s.ToString();
  // Features: entry 3's features record has no metadata.
  EXPECT_EQ(ScanIds(*store, map, kEntryFeatures, &s), (std::vector<EntryId>{0, 1, 2}));
  EXPECT_EQ(s.code(), StatusCode::kDataLoss) << s.ToString();
  EXPECT_NE(s.message().find("without metadata"), std::string::npos) << s.message();
  // Direct: entry 3's and entry 9's records have no metadata.
  ScanIds(*store, map, kEntryDirect, &s);
  EXPECT_EQ(s.code(), StatusCode::kDataLoss) << s.ToString();
  // The metadata alone is consistent.
  EXPECT_EQ(ScanIds(*store, map, kEntryMetadata, &s), (std::vector<EntryId>{0, 1, 2, 4}));
  EXPECT_TRUE(s.ok());
}

TEST_F(RocksDbStoreTest, ADamagedCatalogFailsTheOpen) {
  MakeStore(1);
  {
    RawDb raw(StorePath());
    raw.Put("maps", storage::MapInfoKey("m"), "\x01garbage");
  }
  auto store = OpenRocksDbIndexStore(StorePath(), RocksDbStoreOptions());
  EXPECT_EQ(store.status().code(), StatusCode::kDataLoss) << store.status().ToString();

  // A store written by a newer format is refused, not misread.
  {
    RawDb raw(StorePath());
    raw.Delete("maps", storage::MapInfoKey("m"));
    raw.Delete("maps", storage::NextEntryIdKey(1));
    raw.Put("maps", storage::kStoreRecordKey, std::string("\x09\x05\x00\x00\x00", 5));
  }
  store = OpenRocksDbIndexStore(StorePath(), RocksDbStoreOptions());
  EXPECT_EQ(store.status().code(), StatusCode::kFailedPrecondition) << store.status().ToString();
}

TEST_F(RocksDbStoreTest, ACorruptCurrentFileFailsTheOpen) {
  MakeStore(1);
  std::ofstream(StorePath() + "/CURRENT", std::ios::trunc) << "garbage";
  auto store = OpenRocksDbIndexStore(StorePath(), RocksDbStoreOptions());
  EXPECT_EQ(store.status().code(), StatusCode::kDataLoss) << store.status().ToString();
}

TEST_F(RocksDbStoreTest, AnotherRocksDbDatabaseIsNotAnIndexStore) {
  {
    rocksdb::Options options;
    options.create_if_missing = true;
    rocksdb::DB* db = nullptr;
    ASSERT_TRUE(rocksdb::DB::Open(options, StorePath(), &db).ok());
    rocksdb::ColumnFamilyHandle* cf = nullptr;
    ASSERT_TRUE(db->CreateColumnFamily(rocksdb::ColumnFamilyOptions(), "other", &cf).ok());
    db->DestroyColumnFamilyHandle(cf);
    delete db;
  }
  auto store = OpenRocksDbIndexStore(StorePath(), RocksDbStoreOptions());
  EXPECT_EQ(store.status().code(), StatusCode::kFailedPrecondition) << store.status().ToString();
}

// --- Opening ---

TEST_F(RocksDbStoreTest, ARegularFileIsNotAStoreDirectory) {
  std::ofstream(StorePath()) << "not a directory";
  auto store = OpenRocksDbIndexStore(StorePath(), RocksDbStoreOptions());
  EXPECT_EQ(store.status().code(), StatusCode::kInvalidArgument) << store.status().ToString();
  EXPECT_NE(store.status().message().find(StorePath()), std::string::npos);
}

TEST_F(RocksDbStoreTest, AMissingStoreIsNotFoundWithoutCreateIfMissing) {
  RocksDbStoreOptions options;
  options.create_if_missing = false;
  auto store = OpenRocksDbIndexStore(StorePath(), options);
  EXPECT_EQ(store.status().code(), StatusCode::kNotFound) << store.status().ToString();
  EXPECT_FALSE(fs::exists(StorePath()));
  fs::create_directories(StorePath());  // an empty directory holds no store either
  store = OpenRocksDbIndexStore(StorePath(), options);
  EXPECT_EQ(store.status().code(), StatusCode::kNotFound) << store.status().ToString();
  MakeStore(1);
  store = OpenRocksDbIndexStore(StorePath(), options);
  EXPECT_TRUE(store.ok()) << store.status().ToString();
}

TEST_F(RocksDbStoreTest, ADirectoryOpenInThisProcessIsUnavailable) {
  auto first = Open();
  ASSERT_NE(first, nullptr);
  auto second = OpenRocksDbIndexStore(StorePath(), RocksDbStoreOptions());
  EXPECT_EQ(second.status().code(), StatusCode::kUnavailable) << second.status().ToString();
  EXPECT_NE(second.status().message().find("already open"), std::string::npos);
  first.reset();
  EXPECT_TRUE(OpenRocksDbIndexStore(StorePath(), RocksDbStoreOptions()).ok());
}

TEST_F(RocksDbStoreTest, ADirectoryOpenInAnotherProcessIsUnavailable) {
  RECOG_SKIP_FORK_UNDER_TSAN();
  MakeStore(1);
  // The child holds the store open while the parent tries to open it.
  int ready[2];
  int release[2];
  ASSERT_EQ(::pipe(ready), 0);
  ASSERT_EQ(::pipe(release), 0);
  std::fflush(stdout);
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::close(ready[0]);
    ::close(release[1]);
    RocksDbStoreOptions options;
    options.sync = SyncPolicy::kEveryWrite;
    auto store = OpenRocksDbIndexStore(StorePath(), options);
    const char byte = store.ok() ? 'y' : 'n';
    (void)!::write(ready[1], &byte, 1);
    char unused;
    (void)!::read(release[0], &unused, 1);
    ::_exit(0);  // no clean close needed: the lock dies with the process
  }
  // Only the child keeps these ends: if it dies, the parent's reads see end of file.
  ::close(ready[1]);
  ::close(release[0]);
  char byte = 0;
  const bool child_opened = ::read(ready[0], &byte, 1) == 1 && byte == 'y';
  EXPECT_TRUE(child_opened) << "the child could not open the store";
  if (child_opened) {
    auto store = OpenRocksDbIndexStore(StorePath(), RocksDbStoreOptions());
    EXPECT_EQ(store.status().code(), StatusCode::kUnavailable) << store.status().ToString();
  }
  ::close(release[1]);  // the child's read returns: it exits
  int status = 0;
  ::waitpid(pid, &status, 0);
  ::close(ready[0]);
  // Once the other process is gone, the store opens.
  EXPECT_TRUE(OpenRocksDbIndexStore(StorePath(), RocksDbStoreOptions()).ok());
}

TEST_F(RocksDbStoreTest, AReadOnlyDirectoryIsRefused) {
  RECOG_SKIP_FORK_UNDER_TSAN();
  MakeStore(1);
  const std::string fresh_parent = dir_.Sub("readonly_parent");
  fs::create_directories(fresh_parent);
  ::chmod(StorePath().c_str(), 0555);
  ::chmod(fresh_parent.c_str(), 0555);
  // Root ignores permissions: the child drops to "nobody" first.
  const int code = RunInChild([&] {
    if (::geteuid() == 0 && (::setgid(65534) != 0 || ::setuid(65534) != 0)) return kChildSkipped;
    // An existing store in a read-only directory.
    Status s = OpenRocksDbIndexStore(StorePath(), RocksDbStoreOptions()).status();
    if (s.code() != StatusCode::kFailedPrecondition) return 20 + int(s.code());
    // A new store under a read-only directory.
    s = OpenRocksDbIndexStore(fresh_parent + "/store", RocksDbStoreOptions()).status();
    if (s.code() != StatusCode::kFailedPrecondition) return 40 + int(s.code());
    return 0;
  });
  ::chmod(StorePath().c_str(), 0755);
  ::chmod(fresh_parent.c_str(), 0755);
  if (code == kChildSkipped) GTEST_SKIP() << "cannot drop root privileges (setuid failed)";
  EXPECT_EQ(code, 0) << "20+code: existing store opened with that status; 40+code: new store; "
                        "20 or 40 means it opened";
  // Writable again: it opens.
  EXPECT_TRUE(OpenRocksDbIndexStore(StorePath(), RocksDbStoreOptions()).ok());
}

TEST_F(RocksDbStoreTest, ADiskFullIsAnErrorAndAcknowledgedEntriesSurvive) {
  RECOG_SKIP_FORK_UNDER_TSAN();
  const MapId map = MakeStore(0);
  auto big_entry = [](EntryId id) { return MakeTestEntry(id, 3, DescriptorFormat::Orb(), 4000); };
  int acks[2];
  ASSERT_EQ(::pipe(acks), 0);
  const int code = RunInChild([&] {
    ::close(acks[0]);
    RocksDbStoreOptions options;
    options.sync = SyncPolicy::kEveryWrite;
    auto store = OpenRocksDbIndexStore(StorePath(), options);
    if (!store.ok()) return 3;
    // No file may grow past 4 MiB: the write-ahead log hits the limit after a few entries.
    std::signal(SIGXFSZ, SIG_IGN);
    const rlimit limit{4 << 20, RLIM_INFINITY};
    if (::setrlimit(RLIMIT_FSIZE, &limit) != 0) return 4;
    for (EntryId id = 0; id < 1000; ++id) {
      const Status s = (*store)->CommitEntry(map, big_entry(id));
      if (!s.ok()) {
        std::fprintf(stderr, "disk-full child: entry %u: %s\n", id, s.ToString().c_str());
        ::_exit(ChildExitCode(s));  // no clean close: as if it crashed right after the error
      }
      if (::write(acks[1], &id, sizeof(id)) != sizeof(id)) return 5;
    }
    return 1;  // never hit the limit
  });
  ::close(acks[1]);
  std::vector<EntryId> acknowledged;
  EntryId id = 0;
  while (::read(acks[0], &id, sizeof(id)) == sizeof(id)) acknowledged.push_back(id);
  ::close(acks[0]);

  EXPECT_TRUE(code == ChildExitCode(Status::ResourceExhausted("")) ||
              code == ChildExitCode(Status::Unavailable("")))
      << "child exit code " << code << " (10 + status code expected; negative = signal)";
  EXPECT_GT(acknowledged.size(), 0u);

  auto store = Open();
  ASSERT_NE(store, nullptr);
  for (EntryId ack : acknowledged) {
    EntryRecord got;
    const Status s = store->ReadEntry(map, ack, kEntryAllParts, &got);
    ASSERT_TRUE(s.ok()) << "acknowledged entry " << ack << ": " << s.ToString();
    EXPECT_EQ(EntryDifference(got, big_entry(ack)), "");
  }
  Status s;
  EXPECT_GE(ScanIds(*store, map, kEntryAllParts, &s).size(), acknowledged.size());
  EXPECT_TRUE(s.ok()) << s.ToString();
  // With room again, the store takes writes.
  EXPECT_TRUE(store->CommitEntry(map, MakeTestEntry(5000)).ok());
}

// A real full filesystem (a small tmpfs), both sync policies: the write that finds no room is
// RESOURCE_EXHAUSTED, every write acknowledged before it reads back whole, writes keep failing
// while the disk is full, and once space returns the same open store takes writes again (no
// restart) and a reopen finds everything acknowledged.
TEST_F(RocksDbStoreTest, AFullDiskRefusesWritesLosesNothingAcknowledgedAndResumesWhenSpaceReturns) {
  for (SyncPolicy sync : {SyncPolicy::kEveryWrite, SyncPolicy::kGrouped}) {
    SCOPED_TRACE(sync == SyncPolicy::kEveryWrite ? "every write" : "grouped");
    testing::SmallFilesystem disk("diskfull", size_t(256) << 20);
    if (!disk.error().empty()) GTEST_SKIP() << disk.error();
    disk.Fill(4 << 20);
    const std::string path = disk.Sub("store");
    auto store = Open(sync, path);
    ASSERT_NE(store, nullptr);
    auto map = store->CreateMap(TestMapConfig("m"));
    ASSERT_TRUE(map.ok());
    auto entry = [](EntryId id) { return MakeTestEntry(id, 5, DescriptorFormat::Orb(), 2000); };
    std::vector<EntryId> acknowledged;
    Status refused;
    for (EntryId id = 0; id < 5000 && refused.ok(); ++id) {
      refused = store->CommitEntry(map->id, entry(id));
      if (refused.ok()) acknowledged.push_back(id);
    }
    ASSERT_EQ(refused.code(), StatusCode::kResourceExhausted) << refused.ToString();
    EXPECT_GT(acknowledged.size(), 0u);
    const EntryId next = acknowledged.back() + 1;
    EXPECT_EQ(store->CommitEntry(map->id, entry(next)).code(), StatusCode::kResourceExhausted);
    for (EntryId ack : acknowledged) {
      EntryRecord got;
      ASSERT_TRUE(store->ReadEntry(map->id, ack, kEntryAllParts, &got).ok()) << ack;
      EXPECT_EQ(EntryDifference(got, entry(ack)), "") << ack;
    }

    disk.FreeSpace();
    // RocksDB looks for free space every 5 s and then recovers by itself.
    Status resumed = Status::ResourceExhausted("not tried yet");
    ASSERT_TRUE(WaitUntil(
        [&] {
          resumed = store->CommitEntry(map->id, entry(next));
          return resumed.code() != StatusCode::kResourceExhausted;
        },
        testing::kEventTimeout, std::chrono::milliseconds(100)))
        << "the store took no write again after the disk was freed";
    ASSERT_TRUE(resumed.ok()) << resumed.ToString();
    acknowledged.push_back(next);
    EXPECT_TRUE(store->CommitEntry(map->id, entry(next + 1)).ok());
    acknowledged.push_back(next + 1);

    store.reset();
    store = Open(sync, path);
    ASSERT_NE(store, nullptr);
    Status scan;
    const std::vector<EntryId> present = ScanIds(*store, map->id, kEntryAllParts, &scan);
    EXPECT_TRUE(scan.ok()) << scan.ToString();
    for (EntryId ack : acknowledged) {
      EXPECT_TRUE(std::binary_search(present.begin(), present.end(), ack)) << ack << " is gone";
    }
  }
}

}  // namespace
}  // namespace recog
