// RocksDbIndexStore: the IndexStore behind OpenRocksDbIndexStore (see rocksdb_index_store.h).
//
// Layout. One column family per kind of record, described by kColumnFamilies below; the key and
// value encodings live in record_codec.h. The catalog (column family `maps`) is small and is read
// into memory when the store opens: MapState holds each map's MapInfo and next entry id, so that
// CreateMap / CommitEntry never read the catalog back from RocksDB.
//
// Locking. catalog_write_mutex_ serialises CreateMap and DeleteMap (including their RocksDB
// write); catalog_mutex_ guards the in-memory catalog and is only held for map lookups and
// inserts. Each map has a write mutex that serialises its CommitEntry / RemoveEntry (so the
// "id already taken" check and the next-id update are exact) and DeleteMap with them; DeleteMap
// marks the MapState deleted under that mutex so that a writer that found the map just before
// cannot write into a deleted map afterwards. Lock order: catalog_write_mutex_ -> map write
// mutex -> catalog_mutex_. Reads only take catalog_mutex_ (shared, for the map lookup), never a
// lock held across a RocksDB write; they read a RocksDB snapshot, so that an entry removed
// concurrently is either read whole or not found, never half. Blobs have a lock of their own,
// blob_write_mutex_, held by PutBlob and DeleteBlob (never with another lock).
#include "storage/rocksdb_index_store.h"

#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <shared_mutex>
#include <thread>
#include <unordered_map>

#include <fcntl.h>
#include <rocksdb/cache.h>
#include <rocksdb/convenience.h>
#include <rocksdb/db.h>
#include <rocksdb/filter_policy.h>
#include <rocksdb/options.h>
#include <rocksdb/snapshot.h>
#include <rocksdb/table.h>
#include <rocksdb/utilities/checkpoint.h>
#include <rocksdb/write_batch.h>
#include <spdlog/spdlog.h>

#include "storage/info_log_file.h"
#include "storage/record_codec.h"
#include "storage/snapshot_file.h"
#include "storage/store_damage.h"

namespace recog {
namespace {

namespace fs = std::filesystem;
using namespace storage;  // NOLINT: the record codec of this store

// --- Column families ---

enum ColumnFamily : size_t {
  kDefaultCf,  // required by RocksDB; holds nothing
  kMapsCf,
  kMetaCf,
  kBowCf,
  kDirectCf,
  kFeaturesCf,
  kBlobsCf,
  kNumColumnFamilies,
};

struct ColumnFamilyConfig {
  ColumnFamily id;
  const char* name;
  uint32_t part;       // the EntryPart it holds; 0 for the others
  bool bloom_filter;   // point lookups of possibly absent keys (the "id taken?" check)
  const char* record;  // what one value is, for messages
};

constexpr std::array<ColumnFamilyConfig, kNumColumnFamilies> kColumnFamilies = {{
    {kDefaultCf, "default", 0, false, "default"},
    {kMapsCf, kCatalogFamily, 0, false, "catalog"},
    {kMetaCf, kEntryMetaFamily, kEntryMetadata, true, "metadata"},
    {kBowCf, "bow", kEntryBow, false, "bow"},
    {kDirectCf, "direct", kEntryDirect, false, "direct index"},
    {kFeaturesCf, "features", kEntryFeatures, false, "features"},
    {kBlobsCf, kBlobFamily, 0, false, "blob"},
}};
constexpr std::array<ColumnFamily, 4> kEntryColumnFamilies = {kMetaCf, kBowCf, kDirectCf,
                                                              kFeaturesCf};

// --- Statuses ---

// Our status for a failed RocksDB call; `what` says what we were doing.
Status FromRocks(const rocksdb::Status& s, const std::string& what) {
  if (s.ok()) return Status::Ok();
  const std::string message = what + ": " + s.ToString();
  if (s.IsNotFound()) return Status::NotFound(message);
  if (s.IsCorruption()) return Status::DataLoss(message);
  if (s.IsIOError()) {
    if (s.IsNoSpace()) return Status::ResourceExhausted(message);
    return Status::Unavailable(message);
  }
  return Status::Internal(message);
}

bool Contains(const std::string& text, std::string_view part) {
  return text.find(part) != std::string::npos;
}

// DB::Open failures get a status that says what is wrong with the directory. RocksDB reports
// the errno of a failed system call only as text (strerror), hence the string matching.
Status OpenFailure(const rocksdb::Status& s, const std::string& dir) {
  const std::string text = s.ToString();
  if (s.IsIOError() && (Contains(text, strerror(EACCES)) || Contains(text, strerror(EROFS)) ||
                        Contains(text, strerror(EPERM)))) {
    return Status::FailedPrecondition("index store directory '" + dir +
                                      "' is not writable: " + text);
  }
  if (s.IsIOError() && (Contains(text, "lock") || Contains(text, "LOCK"))) {
    return Status::Unavailable("index store '" + dir +
                               "' is already open (by another store in this or another "
                               "process): " +
                               text);
  }
  return FromRocks(s, "cannot open index store '" + dir + "'");
}

Status FromErrorCode(const std::error_code& ec, const std::string& what) {
  const std::string message = what + ": " + ec.message();
  if (ec == std::errc::permission_denied || ec == std::errc::read_only_file_system ||
      ec == std::errc::operation_not_permitted) {
    return Status::FailedPrecondition(message);
  }
  if (ec == std::errc::no_space_on_device) return Status::ResourceExhausted(message);
  return Status::Unavailable(message);
}

// Checks `dir` before RocksDB sees it (RocksDB's own messages for these cases are obscure), and
// creates it when allowed.
Status PrepareDirectory(const std::string& dir, bool create_if_missing) {
  std::error_code ec;
  const fs::file_status status = fs::status(dir, ec);
  if (ec && ec != std::errc::no_such_file_or_directory) {
    return FromErrorCode(ec, "cannot inspect index store directory '" + dir + "'");
  }
  if (!fs::exists(status)) {
    if (!create_if_missing) {
      return Status::NotFound("index store directory '" + dir + "' does not exist");
    }
    fs::create_directories(dir, ec);
    if (ec) return FromErrorCode(ec, "cannot create index store directory '" + dir + "'");
    return Status::Ok();
  }
  if (!fs::is_directory(status)) {
    return Status::InvalidArgument("'" + dir + "' is not a directory");
  }
  if (!create_if_missing && !fs::exists(fs::path(dir) / "CURRENT", ec)) {
    return Status::NotFound("there is no index store in '" + dir + "'");
  }
  if (::access(dir.c_str(), W_OK | X_OK) != 0 && (errno == EACCES || errno == EROFS)) {
    return Status::FailedPrecondition("index store directory '" + dir +
                                      "' is not writable: " + strerror(errno));
  }
  return Status::Ok();
}

int64_t NowUnixMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

rocksdb::CompressionType ChooseCompression() {
  const std::vector<rocksdb::CompressionType> supported = rocksdb::GetSupportedCompressions();
  for (rocksdb::CompressionType preferred : {rocksdb::kLZ4Compression, rocksdb::kZSTD}) {
    for (rocksdb::CompressionType s : supported) {
      if (s == preferred) return s;
    }
  }
  return rocksdb::kNoCompression;
}

const char* CompressionName(rocksdb::CompressionType type) {
  switch (type) {
    case rocksdb::kLZ4Compression:
      return "lz4";
    case rocksdb::kZSTD:
      return "zstd";
    default:
      return "none";
  }
}

std::string EntryName(MapId map, EntryId id) {
  return "entry " + std::to_string(id) + " of map " + std::to_string(map);
}

Status UnknownMap(MapId map) {
  return Status::NotFound("map " + std::to_string(map) + " does not exist");
}

// --- The store ---

class RocksDbIndexStore final : public IndexStore {
 public:
  RocksDbIndexStore(std::string dir, const RocksDbStoreOptions& options, StoreRecovery* recovery)
      : dir_(std::move(dir)), options_(options), recovery_(recovery) {
    write_options_.sync = options_.sync == SyncPolicy::kEveryWrite;
  }
  ~RocksDbIndexStore() override;

  // Opens the database and loads the catalog; called once, by OpenRocksDbIndexStore.
  Status Open();

  StatusOr<MapInfo> CreateMap(const MapConfig& config) override;
  StatusOr<MapInfo> GetMap(const std::string& name) override;
  StatusOr<std::vector<MapInfo>> ListMaps() override;
  Status DeleteMap(const std::string& name) override;
  Status CommitEntry(MapId map, const EntryRecord& entry) override;
  Status RemoveEntry(MapId map, EntryId id) override;
  Status ReadEntry(MapId map, EntryId id, uint32_t parts, EntryRecord* out) override;
  Status ScanEntries(MapId map, EntryId first, uint32_t parts,
                     const std::function<Status(EntryRecord&)>& visit) override;
  StatusOr<std::unique_ptr<SnapshotWriter>> WriteSnapshot(MapId map, EntryId covers) override;
  StatusOr<std::unique_ptr<SnapshotReader>> ReadSnapshot(MapId map) override;
  Status DropSnapshot(MapId map) override;
  StatusOr<EntryId> NextEntryId(MapId map) override;
  Status PutBlob(const std::string& key, std::string_view value) override;
  StatusOr<std::string> GetBlob(const std::string& key) override;
  Status DeleteBlob(const std::string& key) override;
  StatusOr<std::vector<std::string>> ListBlobKeys(const std::string& prefix) override;
  Status Flush() override;
  Status Checkpoint(const std::string& dir) override;
  StatusOr<VerifyReport> Verify(uint64_t bytes_per_second) override;
  StatusOr<uint64_t> MapDiskBytes(MapId map) override;

 private:
  struct MapState {
    MapInfo info;
    std::mutex write_mutex;  // serialises the map's writes, and DeleteMap with them
    bool deleted = false;    // guarded by write_mutex
    std::atomic<EntryId> next_entry_id{0};
    // The installed snapshot's entry id bound (kInvalidEntryId: none), and how many writes have
    // dropped it (a writer made before one of them must not install); guarded by write_mutex.
    EntryId snapshot_covers = kInvalidEntryId;
    uint64_t snapshot_drops = 0;
  };

  rocksdb::ColumnFamilyHandle* Cf(ColumnFamily cf) const { return handles_[cf]; }
  std::shared_ptr<MapState> FindMap(MapId map) const;
  Status LoadCatalog();
  // Registers the snapshot files of the known maps and removes every other file of their folder
  // (temporary files, maps deleted meanwhile, damaged headers, bounds beyond a map's entries).
  Status LoadSnapshots();
  // Drops the map's snapshot before a write that makes it stale; requires state.write_mutex.
  Status DropStaleSnapshot(MapState& state);
  // The log is damaged: copies the files, replays the log up to the damage (into db_) and
  // reports what that lost in *recovery_.
  Status RecoverPointInTime(rocksdb::DBOptions db_options,
                            const std::vector<rocksdb::ColumnFamilyDescriptor>& descriptors,
                            std::vector<rocksdb::ColumnFamilyHandle*>* handles,
                            std::vector<std::string> damage);
  Status Write(rocksdb::WriteBatch* batch, const std::string& what);
  // Reads the value of `key` in `cf`; NOT_FOUND when absent.
  Status Get(const rocksdb::ReadOptions& read_options, ColumnFamily cf, const std::string& key,
             rocksdb::PinnableSlice* value, const std::string& what);
  // Decodes a value of the entry part held by `cf` into *record.
  static Status DecodePart(ColumnFamily cf, std::string_view value, const RecordContext& context,
                           EntryRecord* record);
  // Makes every write so far durable: an empty write with sync, for which RocksDB syncs the
  // log. Not DB::FlushWAL(true): it syncs the log file outside RocksDB's write queue, and once a
  // write has failed on that file (a full disk) the Debian build of RocksDB 7.8, compiled with
  // assertions, aborts the process there.
  rocksdb::Status SyncLog();
  void SyncLoop();

  const std::string dir_;
  const RocksDbStoreOptions options_;
  StoreRecovery* const recovery_;  // may be null
  rocksdb::WriteOptions write_options_;
  rocksdb::CompressionType compression_ = rocksdb::kNoCompression;
  rocksdb::DB* db_ = nullptr;  // owned; closed and deleted by the destructor
  std::array<rocksdb::ColumnFamilyHandle*, kNumColumnFamilies> handles_{};
  // Column families this version does not know (written by a newer one): opened, never used.
  std::vector<rocksdb::ColumnFamilyHandle*> unknown_handles_;

  std::mutex catalog_write_mutex_;
  mutable std::shared_mutex catalog_mutex_;
  std::map<std::string, std::shared_ptr<MapState>> maps_by_name_;
  std::unordered_map<MapId, std::shared_ptr<MapState>> maps_by_id_;
  MapId next_map_id_ = 1;  // guarded by catalog_write_mutex_
  // Serialises PutBlob and DeleteBlob, so that DeleteBlob's "absent?" check is exact.
  std::mutex blob_write_mutex_;

  // kGrouped: the WAL sync thread.
  std::atomic<bool> unsynced_writes_{false};
  std::mutex sync_mutex_;
  std::condition_variable sync_cv_;
  bool stopping_ = false;  // guarded by sync_mutex_
  std::thread sync_thread_;
};

RocksDbIndexStore::~RocksDbIndexStore() {
  if (sync_thread_.joinable()) {
    {
      std::lock_guard lock(sync_mutex_);
      stopping_ = true;
    }
    sync_cv_.notify_all();
    sync_thread_.join();
  }
  if (db_ == nullptr) return;
  // DB::Close does not sync the WAL: do it so that a clean close keeps every write.
  if (options_.sync == SyncPolicy::kGrouped) {
    const rocksdb::Status s = SyncLog();
    if (!s.ok()) spdlog::error("index store '{}': final WAL sync failed: {}", dir_, s.ToString());
  }
  // Writes the memtables out, so that the next open has no log to replay: replaying it, and
  // writing its records out again before opening, took 5 s of the open of a store of 300,000
  // entries just written (bench_database's Restart case). A failure only costs that time.
  if (options_.write_memtables_at_close) {
    std::vector<rocksdb::ColumnFamilyHandle*> families;
    for (rocksdb::ColumnFamilyHandle* handle : handles_) {
      if (handle != nullptr) families.push_back(handle);
    }
    const rocksdb::Status flushed = db_->Flush(rocksdb::FlushOptions(), families);
    if (!flushed.ok()) {
      spdlog::warn("index store '{}': memtables not written out at close: {}", dir_,
                   flushed.ToString());
    }
  }
  for (rocksdb::ColumnFamilyHandle* handle : handles_) {
    if (handle != nullptr) db_->DestroyColumnFamilyHandle(handle);
  }
  for (rocksdb::ColumnFamilyHandle* handle : unknown_handles_) {
    db_->DestroyColumnFamilyHandle(handle);
  }
  const rocksdb::Status s = db_->Close();
  if (!s.ok()) spdlog::error("index store '{}': close failed: {}", dir_, s.ToString());
  delete db_;
}

Status RocksDbIndexStore::Open() {
  compression_ = ChooseCompression();

  rocksdb::DBOptions db_options;
  db_options.create_if_missing = options_.create_if_missing;
  db_options.create_missing_column_families = true;
  // Replays the whole WAL, tolerating only a torn last record (a crash of the machine in the
  // middle of a write, never acknowledged); any other damage fails the open (see "Damage").
  db_options.wal_recovery_mode = rocksdb::WALRecoveryMode::kTolerateCorruptedTailRecords;
  // RocksDB's info log: LOG and the 3 previous ones, written so that a full disk cannot abort us.
  auto info_log = InfoLogFile::Open(dir_, 3);
  if (!info_log.ok()) spdlog::warn("index store '{}': {}", dir_, info_log.status().ToString());
  auto recorder = std::make_shared<DamageRecorder>(info_log.ok() ? *info_log : nullptr);
  db_options.info_log = recorder;

  std::shared_ptr<rocksdb::Cache> cache;
  if (options_.block_cache_mb > 0) cache = rocksdb::NewLRUCache(options_.block_cache_mb << 20);
  std::shared_ptr<const rocksdb::FilterPolicy> bloom(rocksdb::NewBloomFilterPolicy(10));

  std::vector<rocksdb::ColumnFamilyDescriptor> descriptors;
  for (const ColumnFamilyConfig& config : kColumnFamilies) {
    rocksdb::BlockBasedTableOptions table;
    if (cache) {
      table.block_cache = cache;
    } else {
      table.no_block_cache = true;
    }
    if (config.bloom_filter) table.filter_policy = bloom;
    rocksdb::ColumnFamilyOptions cf_options;
    cf_options.table_factory.reset(rocksdb::NewBlockBasedTableFactory(table));
    cf_options.compression = compression_;
    cf_options.level_compaction_dynamic_level_bytes = true;
    descriptors.emplace_back(config.name, cf_options);
  }

  // An existing store may have column families of a newer version: RocksDB only opens a
  // database with all of them named.
  std::vector<std::string> existing;
  if (rocksdb::DB::ListColumnFamilies(db_options, dir_, &existing).ok()) {
    bool has_maps = false;
    for (const std::string& name : existing) {
      bool known = false;
      for (const ColumnFamilyConfig& config : kColumnFamilies) known |= name == config.name;
      has_maps |= name == kColumnFamilies[kMapsCf].name;
      if (!known) descriptors.emplace_back(name, rocksdb::ColumnFamilyOptions());
    }
    if (!has_maps && existing.size() > 1) {
      return Status::FailedPrecondition("'" + dir_ +
                                        "' holds a RocksDB database that is not an index store");
    }
  }

  std::vector<rocksdb::ColumnFamilyHandle*> handles;
  const rocksdb::Status s = rocksdb::DB::Open(db_options, dir_, descriptors, &handles, &db_);
  if (!s.ok()) {
    db_ = nullptr;
    std::vector<std::string> damage = recorder->damage();
    if (!s.IsCorruption() || damage.empty()) return OpenFailure(s, dir_);
    if (options_.damaged_log == DamagedLogPolicy::kRefuse) {
      std::string stretches;
      for (const std::string& stretch : damage) {
        if (!stretches.empty()) stretches += "; ";
        stretches += stretch;
      }
      return Status::DataLoss("the write-ahead log of index store '" + dir_ + "' is damaged (" +
                              stretches +
                              "); nothing was changed. Restore a checkpoint, or accept losing "
                              "the writes after the damage with point-in-time recovery "
                              "(recogd --recover point-in-time), which keeps a copy of the files");
    }
    recorder->ClearDamage();
    RECOG_RETURN_IF_ERROR(RecoverPointInTime(db_options, descriptors, &handles, std::move(damage)));
  }
  for (size_t i = 0; i < handles.size(); ++i) {
    if (i < kNumColumnFamilies) {
      handles_[i] = handles[i];
    } else {
      unknown_handles_.push_back(handles[i]);
    }
  }
  RECOG_RETURN_IF_ERROR(LoadCatalog());
  RECOG_RETURN_IF_ERROR(LoadSnapshots());

  if (options_.sync == SyncPolicy::kGrouped) sync_thread_ = std::thread([this] { SyncLoop(); });
  spdlog::info("opened index store '{}': {} maps, sync {}, compression {}", dir_,
               maps_by_name_.size(),
               options_.sync == SyncPolicy::kEveryWrite
                   ? std::string("every write")
                   : "every " + std::to_string(options_.group_sync_interval_ms) + " ms",
               CompressionName(compression_));
  return Status::Ok();
}

Status RocksDbIndexStore::RecoverPointInTime(
    rocksdb::DBOptions db_options, const std::vector<rocksdb::ColumnFamilyDescriptor>& descriptors,
    std::vector<rocksdb::ColumnFamilyHandle*>* handles, std::vector<std::string> damage) {
  StoreRecovery recovery;
  recovery.damage = std::move(damage);
  RECOG_ASSIGN_OR_RETURN(recovery.damaged_copy, KeepDamagedCopy(dir_));

  // What the store held: its table files (opened read-only, applying no log record), and every
  // record of the log that is still readable, read by our own reader.
  StoreInventory before;
  {
    TablesOnly tables;
    rocksdb::DBOptions read_only = db_options;
    read_only.wal_recovery_mode = rocksdb::WALRecoveryMode::kPointInTimeRecovery;
    read_only.wal_filter = &tables;
    std::vector<rocksdb::ColumnFamilyHandle*> read_handles;
    rocksdb::DB* db = nullptr;
    const rocksdb::Status s =
        rocksdb::DB::OpenForReadOnly(read_only, dir_, descriptors, &read_handles, &db);
    if (!s.ok()) return FromRocks(s, "cannot read the damaged index store '" + dir_ + "'");
    StatusOr<StoreInventory> read =
        ReadInventory(db, read_handles[kMapsCf], read_handles[kMetaCf], read_handles[kBlobsCf]);
    for (rocksdb::ColumnFamilyHandle* handle : read_handles) db->DestroyColumnFamilyHandle(handle);
    delete db;
    RECOG_RETURN_IF_ERROR(read.status());
    before = std::move(read).value();
    const size_t skipped = ApplyReadableLog(dir_, tables, &before);
    spdlog::info("index store '{}': {} damaged records of the write-ahead log skipped", dir_,
                 skipped);
  }

  db_options.wal_recovery_mode = rocksdb::WALRecoveryMode::kPointInTimeRecovery;
  const rocksdb::Status s = rocksdb::DB::Open(db_options, dir_, descriptors, handles, &db_);
  if (!s.ok()) {
    db_ = nullptr;
    return OpenFailure(s, dir_);
  }
  RECOG_ASSIGN_OR_RETURN(
      const StoreInventory after,
      ReadInventory(db_, (*handles)[kMapsCf], (*handles)[kMetaCf], (*handles)[kBlobsCf]));
  CompareInventories(before, after, &recovery);
  // The index snapshots may cover entries the recovery lost: the maps are rebuilt on open.
  std::error_code ec;
  std::filesystem::remove_all(storage::SnapshotDirectory(dir_), ec);
  if (ec) return FromErrorCode(ec, "cannot remove the index snapshots of '" + dir_ + "'");
  spdlog::warn(
      "index store '{}' recovered to the damage of its write-ahead log: {} entries of {} "
      "maps and {} blobs lost",
      dir_, recovery.entries_lost(), recovery.maps.size(), recovery.blobs_lost.size());
  for (const std::string& line : recovery.Describe()) spdlog::warn("  {}", line);
  if (recovery_ != nullptr) *recovery_ = std::move(recovery);
  return Status::Ok();
}

Status RocksDbIndexStore::LoadCatalog() {
  bool has_store_record = false;
  StoreRecord store;
  std::map<MapId, EntryId> next_ids;
  {
    std::unique_ptr<rocksdb::Iterator> it(db_->NewIterator(rocksdb::ReadOptions(), Cf(kMapsCf)));
    for (it->SeekToFirst(); it->Valid(); it->Next()) {
      const std::string_view key(it->key().data(), it->key().size());
      const std::string_view value(it->value().data(), it->value().size());
      if (key == kStoreRecordKey) {
        RECOG_RETURN_IF_ERROR(DecodeStoreRecord(value, &store));
        has_store_record = true;
      } else if (key.size() > 1 && key[0] == kMapInfoTag) {
        auto state = std::make_shared<MapState>();
        RECOG_RETURN_IF_ERROR(DecodeMapInfo(key.substr(1), value, &state->info));
        if (!maps_by_id_.emplace(state->info.id, state).second) {
          return Status::DataLoss("the catalog of '" + dir_ + "' has two maps with id " +
                                  std::to_string(state->info.id));
        }
        maps_by_name_.emplace(state->info.config.name, state);
      } else if (MapId id = 0; DecodeNextEntryIdKey(key, &id)) {
        EntryId next = 0;
        RECOG_RETURN_IF_ERROR(DecodeNextEntryId(value, RecordContext{id}, &next));
        next_ids[id] = next;
      } else {
        return Status::DataLoss("the catalog of '" + dir_ + "' has an unknown record");
      }
    }
    RECOG_RETURN_IF_ERROR(FromRocks(it->status(), "cannot read the catalog of '" + dir_ + "'"));
  }

  if (!has_store_record) {
    if (!maps_by_id_.empty() || !next_ids.empty()) {
      return Status::DataLoss("the catalog of '" + dir_ + "' has maps but no store record");
    }
    // A new store.
    rocksdb::WriteBatch batch;
    batch.Put(Cf(kMapsCf), kStoreRecordKey, EncodeStoreRecord(store));
    rocksdb::WriteOptions sync;
    sync.sync = true;
    RECOG_RETURN_IF_ERROR(
        FromRocks(db_->Write(sync, &batch), "cannot initialise index store '" + dir_ + "'"));
  }
  next_map_id_ = store.next_map_id;

  std::unique_ptr<rocksdb::Iterator> meta(db_->NewIterator(rocksdb::ReadOptions(), Cf(kMetaCf)));
  for (auto& [id, state] : maps_by_id_) {
    auto next = next_ids.find(id);
    if (next == next_ids.end()) {
      return Status::DataLoss("the catalog of '" + dir_ + "' has no next entry id for map " +
                              std::to_string(id));
    }
    if (id >= next_map_id_) {
      return Status::DataLoss("the catalog of '" + dir_ + "' has map id " + std::to_string(id) +
                              " beyond the next map id " + std::to_string(next_map_id_));
    }
    // The next-id record is written in the batch of every commit, so it is never behind the
    // entries; check it anyway, it costs one seek per map.
    EntryId next_id = next->second;
    meta->SeekForPrev(MapEntriesEnd(id));
    MapId key_map = 0;
    EntryId key_id = 0;
    if (meta->Valid() &&
        DecodeEntryKey(std::string_view(meta->key().data(), meta->key().size()), &key_map,
                       &key_id) &&
        key_map == id && key_id >= next_id) {
      spdlog::warn("index store '{}': map {} has entry {} but next entry id {}; using {}", dir_, id,
                   key_id, next_id, key_id + 1);
      next_id = key_id + 1;
    }
    RECOG_RETURN_IF_ERROR(FromRocks(meta->status(), "cannot read the entries of '" + dir_ + "'"));
    state->next_entry_id = next_id;
  }
  return Status::Ok();
}

std::shared_ptr<RocksDbIndexStore::MapState> RocksDbIndexStore::FindMap(MapId map) const {
  std::shared_lock lock(catalog_mutex_);
  auto it = maps_by_id_.find(map);
  return it == maps_by_id_.end() ? nullptr : it->second;
}

Status RocksDbIndexStore::Write(rocksdb::WriteBatch* batch, const std::string& what) {
  const rocksdb::Status s = db_->Write(write_options_, batch);
  if (s.ok() && !write_options_.sync) unsynced_writes_.store(true, std::memory_order_release);
  return FromRocks(s, what);
}

Status RocksDbIndexStore::Get(const rocksdb::ReadOptions& read_options, ColumnFamily cf,
                              const std::string& key, rocksdb::PinnableSlice* value,
                              const std::string& what) {
  return FromRocks(db_->Get(read_options, Cf(cf), key, value), what);
}

rocksdb::Status RocksDbIndexStore::SyncLog() {
  rocksdb::WriteOptions synced;
  synced.sync = true;
  rocksdb::WriteBatch nothing;
  return db_->Write(synced, &nothing);
}

void RocksDbIndexStore::SyncLoop() {
  const auto interval = std::chrono::milliseconds(options_.group_sync_interval_ms);
  bool failing = false;
  std::unique_lock lock(sync_mutex_);
  while (!sync_cv_.wait_for(lock, interval, [this] { return stopping_; })) {
    if (!unsynced_writes_.exchange(false, std::memory_order_acq_rel)) continue;
    lock.unlock();
    const rocksdb::Status s = SyncLog();
    lock.lock();
    if (!s.ok()) {
      unsynced_writes_.store(true);  // try again next time
      if (!failing) spdlog::error("index store '{}': WAL sync failed: {}", dir_, s.ToString());
    } else if (failing) {
      spdlog::info("index store '{}': WAL sync works again", dir_);
    }
    failing = !s.ok();
  }
}

// --- Maps ---

StatusOr<MapInfo> RocksDbIndexStore::CreateMap(const MapConfig& config) {
  RECOG_RETURN_IF_ERROR(config.Validate());
  std::lock_guard write_lock(catalog_write_mutex_);
  // The catalog only changes under catalog_write_mutex_, which we hold: no shared lock needed.
  if (maps_by_name_.count(config.name) != 0) {
    return Status::AlreadyExists("map '" + config.name + "' already exists");
  }
  if (next_map_id_ == UINT32_MAX) return Status::ResourceExhausted("no map ids are left");
  auto state = std::make_shared<MapState>();
  state->info.id = next_map_id_;
  state->info.config = config;
  state->info.created_unix_ms = NowUnixMs();
  // The id is used up even if the write fails: a failed write may still reach the disk.
  ++next_map_id_;

  rocksdb::WriteBatch batch;
  batch.Put(Cf(kMapsCf), MapInfoKey(config.name), EncodeMapInfo(state->info));
  batch.Put(Cf(kMapsCf), NextEntryIdKey(state->info.id), EncodeNextEntryId(0));
  batch.Put(Cf(kMapsCf), kStoreRecordKey, EncodeStoreRecord({next_map_id_}));
  RECOG_RETURN_IF_ERROR(Write(&batch, "cannot create map '" + config.name + "'"));

  std::unique_lock lock(catalog_mutex_);
  maps_by_name_.emplace(config.name, state);
  maps_by_id_.emplace(state->info.id, state);
  return state->info;
}

StatusOr<MapInfo> RocksDbIndexStore::GetMap(const std::string& name) {
  std::shared_lock lock(catalog_mutex_);
  auto it = maps_by_name_.find(name);
  if (it == maps_by_name_.end()) return Status::NotFound("map '" + name + "' does not exist");
  return it->second->info;
}

StatusOr<std::vector<MapInfo>> RocksDbIndexStore::ListMaps() {
  std::shared_lock lock(catalog_mutex_);
  std::vector<MapInfo> out;
  out.reserve(maps_by_name_.size());
  for (const auto& [name, state] : maps_by_name_) out.push_back(state->info);
  return out;
}

Status RocksDbIndexStore::DeleteMap(const std::string& name) {
  std::lock_guard write_lock(catalog_write_mutex_);
  auto it = maps_by_name_.find(name);
  if (it == maps_by_name_.end()) return Status::NotFound("map '" + name + "' does not exist");
  const std::shared_ptr<MapState> state = it->second;
  const MapId id = state->info.id;

  std::lock_guard map_lock(state->write_mutex);
  RECOG_RETURN_IF_ERROR(DropStaleSnapshot(*state));
  rocksdb::WriteBatch batch;
  const std::string begin = MapEntriesBegin(id);
  const std::string end = MapEntriesEnd(id);
  for (ColumnFamily cf : kEntryColumnFamilies) batch.DeleteRange(Cf(cf), begin, end);
  batch.Delete(Cf(kMapsCf), MapInfoKey(name));
  batch.Delete(Cf(kMapsCf), NextEntryIdKey(id));
  RECOG_RETURN_IF_ERROR(Write(&batch, "cannot delete map '" + name + "'"));

  state->deleted = true;
  std::unique_lock lock(catalog_mutex_);
  maps_by_name_.erase(name);
  maps_by_id_.erase(id);
  return Status::Ok();
}

// --- Entries ---

Status RocksDbIndexStore::CommitEntry(MapId map, const EntryRecord& entry) {
  if (entry.id == kInvalidEntryId) return Status::InvalidArgument("entry has no id");
  RECOG_RETURN_IF_ERROR(CheckStorable(entry));
  // Encode before taking the map's lock.
  const std::string key = EntryKey(map, entry.id);
  RECOG_ASSIGN_OR_RETURN(
      const std::string features,
      EncodeFeatures(entry.keypoints, entry.descriptors, entry.points, entry.camera));
  rocksdb::WriteBatch batch;
  batch.Put(Cf(kMetaCf), key, EncodeMetadata(entry.metadata));
  batch.Put(Cf(kBowCf), key, EncodeBow(entry.bow));
  batch.Put(Cf(kDirectCf), key, EncodeDirect(entry.direct));
  batch.Put(Cf(kFeaturesCf), key, features);

  const std::shared_ptr<MapState> state = FindMap(map);
  if (state == nullptr) return UnknownMap(map);
  std::lock_guard map_lock(state->write_mutex);
  if (state->deleted) return UnknownMap(map);

  rocksdb::PinnableSlice existing;
  const Status found = Get(rocksdb::ReadOptions(), kMetaCf, key, &existing,
                           "cannot commit " + EntryName(map, entry.id));
  if (found.ok()) {
    return Status::AlreadyExists(EntryName(map, entry.id) + " already exists");
  }
  if (found.code() != StatusCode::kNotFound) return found;

  const EntryId next = state->next_entry_id.load();
  const bool advances = entry.id >= next;
  // An entry below the map's next id may fall in a snapshot's range (installed or being written).
  if (!advances) RECOG_RETURN_IF_ERROR(DropStaleSnapshot(*state));
  if (advances) batch.Put(Cf(kMapsCf), NextEntryIdKey(map), EncodeNextEntryId(entry.id + 1));
  RECOG_RETURN_IF_ERROR(Write(&batch, "cannot commit " + EntryName(map, entry.id)));
  if (advances) state->next_entry_id.store(entry.id + 1);
  return Status::Ok();
}

Status RocksDbIndexStore::RemoveEntry(MapId map, EntryId id) {
  const std::shared_ptr<MapState> state = FindMap(map);
  if (state == nullptr) return UnknownMap(map);
  std::lock_guard map_lock(state->write_mutex);
  if (state->deleted) return UnknownMap(map);

  const std::string key = EntryKey(map, id);
  rocksdb::PinnableSlice existing;
  const Status found =
      Get(rocksdb::ReadOptions(), kMetaCf, key, &existing, "cannot remove " + EntryName(map, id));
  if (found.code() == StatusCode::kNotFound) {
    return Status::NotFound(EntryName(map, id) + " does not exist");
  }
  RECOG_RETURN_IF_ERROR(found);

  RECOG_RETURN_IF_ERROR(DropStaleSnapshot(*state));
  rocksdb::WriteBatch batch;
  for (ColumnFamily cf : kEntryColumnFamilies) batch.Delete(Cf(cf), key);
  return Write(&batch, "cannot remove " + EntryName(map, id));
}

Status RocksDbIndexStore::DecodePart(ColumnFamily cf, std::string_view value,
                                     const RecordContext& context, EntryRecord* record) {
  switch (cf) {
    case kMetaCf:
      return DecodeMetadata(value, context, &record->metadata);
    case kBowCf:
      return DecodeBow(value, context, &record->bow);
    case kDirectCf:
      return DecodeDirect(value, context, &record->direct);
    case kFeaturesCf:
      return DecodeFeatures(value, context, &record->keypoints, &record->descriptors,
                            &record->points, &record->camera);
    default:
      return Status::Internal("column family " + std::to_string(cf) + " holds no entry part");
  }
}

// Moves the requested parts of `from` into *to (the others are left as they are).
void MoveParts(EntryRecord&& from, uint32_t parts, EntryRecord* to) {
  to->id = from.id;
  if (parts & kEntryMetadata) to->metadata = std::move(from.metadata);
  if (parts & kEntryBow) to->bow = std::move(from.bow);
  if (parts & kEntryDirect) to->direct = std::move(from.direct);
  if (parts & kEntryFeatures) {
    to->keypoints = std::move(from.keypoints);
    to->descriptors = std::move(from.descriptors);
    to->points = std::move(from.points);
    to->camera = from.camera;
  }
}

Status RocksDbIndexStore::ReadEntry(MapId map, EntryId id, uint32_t parts, EntryRecord* out) {
  if (FindMap(map) == nullptr) return UnknownMap(map);
  rocksdb::ManagedSnapshot snapshot(db_);
  rocksdb::ReadOptions read_options;
  read_options.snapshot = snapshot.snapshot();
  const std::string key = EntryKey(map, id);
  const RecordContext context{map, id};
  const std::string what = "cannot read " + EntryName(map, id);

  // The metadata record says whether the entry exists.
  EntryRecord record;
  record.id = id;
  rocksdb::PinnableSlice value;
  const Status meta = Get(read_options, kMetaCf, key, &value, what);
  if (meta.code() == StatusCode::kNotFound) {
    return Status::NotFound(EntryName(map, id) + " does not exist");
  }
  RECOG_RETURN_IF_ERROR(meta);
  if (parts & kEntryMetadata) {
    RECOG_RETURN_IF_ERROR(DecodeMetadata(value.ToStringView(), context, &record.metadata));
  }
  for (ColumnFamily cf : {kBowCf, kDirectCf, kFeaturesCf}) {
    if ((parts & kColumnFamilies[cf].part) == 0) continue;
    value.Reset();
    const Status got = Get(read_options, cf, key, &value, what);
    if (got.code() == StatusCode::kNotFound) {
      return Status::DataLoss(EntryName(map, id) + " has no " + kColumnFamilies[cf].record +
                              " record");
    }
    RECOG_RETURN_IF_ERROR(got);
    RECOG_RETURN_IF_ERROR(DecodePart(cf, value.ToStringView(), context, &record));
  }
  MoveParts(std::move(record), parts, out);
  return Status::Ok();
}

Status RocksDbIndexStore::ScanEntries(MapId map, EntryId first, uint32_t parts,
                                      const std::function<Status(EntryRecord&)>& visit) {
  if (FindMap(map) == nullptr) return UnknownMap(map);
  rocksdb::ManagedSnapshot snapshot(db_);
  const std::string begin = EntryKey(map, first);
  const std::string end = MapEntriesEnd(map);
  const rocksdb::Slice upper_bound(end);
  rocksdb::ReadOptions read_options;
  read_options.snapshot = snapshot.snapshot();
  read_options.iterate_upper_bound = &upper_bound;
  read_options.fill_cache = false;  // a full scan would evict the blocks that point reads need

  // The metadata column family defines the entry set; the iterators of the other requested parts
  // walk alongside it and must be at the same key at every step.
  std::vector<ColumnFamily> cfs = {kMetaCf};
  for (ColumnFamily cf : {kBowCf, kDirectCf, kFeaturesCf}) {
    if (parts & kColumnFamilies[cf].part) cfs.push_back(cf);
  }
  std::vector<rocksdb::ColumnFamilyHandle*> handles;
  for (ColumnFamily cf : cfs) handles.push_back(Cf(cf));
  std::vector<rocksdb::Iterator*> raw_iterators;
  const std::string what = "cannot scan map " + std::to_string(map);
  RECOG_RETURN_IF_ERROR(FromRocks(db_->NewIterators(read_options, handles, &raw_iterators), what));
  std::vector<std::unique_ptr<rocksdb::Iterator>> iterators;
  for (rocksdb::Iterator* it : raw_iterators) iterators.emplace_back(it);
  for (auto& it : iterators) it->Seek(begin);

  auto entry_of = [map](const rocksdb::Slice& key) {
    MapId key_map = 0;
    EntryId id = kInvalidEntryId;
    if (!DecodeEntryKey(std::string_view(key.data(), key.size()), &key_map, &id) ||
        key_map != map) {
      id = kInvalidEntryId;
    }
    return id;
  };

  rocksdb::Iterator& meta = *iterators[0];
  for (; meta.Valid(); meta.Next()) {
    const EntryId id = entry_of(meta.key());
    if (id == kInvalidEntryId) {
      return Status::DataLoss("map " + std::to_string(map) + " has a metadata record with a " +
                              std::to_string(meta.key().size()) + "-byte key");
    }
    const RecordContext context{map, id};
    EntryRecord record;
    record.id = id;
    if (parts & kEntryMetadata) {
      RECOG_RETURN_IF_ERROR(DecodeMetadata(meta.value().ToStringView(), context, &record.metadata));
    }
    for (size_t i = 1; i < cfs.size(); ++i) {
      rocksdb::Iterator& part = *iterators[i];
      const char* record_name = kColumnFamilies[cfs[i]].record;
      if (!part.Valid()) {
        RECOG_RETURN_IF_ERROR(FromRocks(part.status(), what));
        return Status::DataLoss(EntryName(map, id) + " has no " + record_name + " record");
      }
      const int order = part.key().compare(meta.key());
      if (order < 0) {
        return Status::DataLoss("map " + std::to_string(map) + " has a " + record_name +
                                " record without metadata (entry " +
                                std::to_string(entry_of(part.key())) + ")");
      }
      if (order > 0) {
        return Status::DataLoss(EntryName(map, id) + " has no " + record_name + " record");
      }
      RECOG_RETURN_IF_ERROR(DecodePart(cfs[i], part.value().ToStringView(), context, &record));
      part.Next();
    }
    EntryRecord out;
    MoveParts(std::move(record), parts, &out);
    RECOG_RETURN_IF_ERROR(visit(out));
  }
  RECOG_RETURN_IF_ERROR(FromRocks(meta.status(), what));
  for (size_t i = 1; i < cfs.size(); ++i) {
    rocksdb::Iterator& part = *iterators[i];
    if (part.Valid()) {
      return Status::DataLoss("map " + std::to_string(map) + " has a " +
                              kColumnFamilies[cfs[i]].record + " record without metadata (entry " +
                              std::to_string(entry_of(part.key())) + ")");
    }
    RECOG_RETURN_IF_ERROR(FromRocks(part.status(), what));
  }
  return Status::Ok();
}

// --- Index snapshots ---

Status RocksDbIndexStore::DropStaleSnapshot(MapState& state) {
  ++state.snapshot_drops;
  if (state.snapshot_covers == kInvalidEntryId) return Status::Ok();
  RECOG_RETURN_IF_ERROR(storage::RemoveSnapshotFile(storage::SnapshotPath(dir_, state.info.id)));
  state.snapshot_covers = kInvalidEntryId;
  return Status::Ok();
}

StatusOr<std::unique_ptr<IndexStore::SnapshotWriter>> RocksDbIndexStore::WriteSnapshot(
    MapId map, EntryId covers) {
  const std::shared_ptr<MapState> state = FindMap(map);
  if (state == nullptr) return UnknownMap(map);
  uint64_t drops = 0;
  {
    std::lock_guard map_lock(state->write_mutex);
    if (covers > state->next_entry_id.load()) {
      return Status::InvalidArgument("a snapshot of map " + std::to_string(map) +
                                     " cannot cover entry ids up to " + std::to_string(covers) +
                                     ", beyond its next id " +
                                     std::to_string(state->next_entry_id.load()));
    }
    drops = state->snapshot_drops;
  }
  const std::string path = storage::SnapshotPath(dir_, map);
  return storage::CreateSnapshotFile(
      path, covers, [this, state, drops, covers, path](const std::string& tmp_path) -> Status {
        // Every entry the snapshot covers must be as durable as the snapshot.
        RECOG_RETURN_IF_ERROR(FromRocks(SyncLog(), "cannot sync the log of '" + dir_ + "'"));
        std::lock_guard map_lock(state->write_mutex);
        if (state->deleted) return UnknownMap(state->info.id);
        if (state->snapshot_drops != drops) {
          return Status::FailedPrecondition("map " + std::to_string(state->info.id) +
                                            " changed while its snapshot was written");
        }
        RECOG_RETURN_IF_ERROR(storage::InstallSnapshotFile(tmp_path, path));
        state->snapshot_covers = covers;
        return Status::Ok();
      });
}

StatusOr<std::unique_ptr<IndexStore::SnapshotReader>> RocksDbIndexStore::ReadSnapshot(MapId map) {
  const std::shared_ptr<MapState> state = FindMap(map);
  if (state == nullptr) return UnknownMap(map);
  std::lock_guard map_lock(state->write_mutex);
  if (state->snapshot_covers == kInvalidEntryId) {
    return Status::NotFound("map " + std::to_string(map) + " has no snapshot");
  }
  // Opened under the lock: a drop that follows unlinks the file, which stays readable.
  return storage::OpenSnapshotFile(storage::SnapshotPath(dir_, map));
}

Status RocksDbIndexStore::DropSnapshot(MapId map) {
  const std::shared_ptr<MapState> state = FindMap(map);
  if (state == nullptr) return UnknownMap(map);
  std::lock_guard map_lock(state->write_mutex);
  return DropStaleSnapshot(*state);
}

Status RocksDbIndexStore::LoadSnapshots() {
  namespace fs = std::filesystem;
  const std::string folder = storage::SnapshotDirectory(dir_);
  std::error_code ec;
  if (!fs::exists(folder, ec)) return Status::Ok();
  std::vector<fs::path> files;
  for (fs::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec)) {
    files.push_back(it->path());
  }
  if (ec) return FromErrorCode(ec, "cannot list " + folder);
  for (const fs::path& file : files) {
    MapId map = 0;
    std::shared_ptr<MapState> state;
    if (storage::ParseSnapshotFileName(file.filename().string(), &map)) state = FindMap(map);
    if (state != nullptr) {
      StatusOr<std::unique_ptr<SnapshotReader>> reader = storage::OpenSnapshotFile(file.string());
      if (reader.ok() && (*reader)->covers() <= state->next_entry_id.load()) {
        state->snapshot_covers = (*reader)->covers();
        continue;
      }
      spdlog::warn(
          "index store '{}': snapshot {} is not used: {}", dir_, file.string(),
          reader.ok() ? "it covers entries the map does not have" : reader.status().ToString());
    }
    RECOG_RETURN_IF_ERROR(storage::RemoveSnapshotFile(file.string()));
  }
  return Status::Ok();
}

StatusOr<EntryId> RocksDbIndexStore::NextEntryId(MapId map) {
  const std::shared_ptr<MapState> state = FindMap(map);
  if (state == nullptr) return UnknownMap(map);
  return state->next_entry_id.load();
}

// --- Blobs ---

Status RocksDbIndexStore::PutBlob(const std::string& key, std::string_view value) {
  RECOG_RETURN_IF_ERROR(ValidateBlob(key, value));
  rocksdb::WriteBatch batch;
  batch.Put(Cf(kBlobsCf), key, rocksdb::Slice(value.data(), value.size()));
  std::lock_guard lock(blob_write_mutex_);
  return Write(&batch, "cannot write blob '" + key + "'");
}

StatusOr<std::string> RocksDbIndexStore::GetBlob(const std::string& key) {
  RECOG_RETURN_IF_ERROR(ValidateBlob(key));
  rocksdb::ReadOptions read_options;
  read_options.fill_cache = false;  // blobs are large and rarely read: keep the cache for entries
  rocksdb::PinnableSlice value;
  const Status got = Get(read_options, kBlobsCf, key, &value, "cannot read blob '" + key + "'");
  if (got.code() == StatusCode::kNotFound) {
    return Status::NotFound("blob '" + key + "' does not exist");
  }
  RECOG_RETURN_IF_ERROR(got);
  return value.ToString();
}

Status RocksDbIndexStore::DeleteBlob(const std::string& key) {
  RECOG_RETURN_IF_ERROR(ValidateBlob(key));
  const std::string what = "cannot delete blob '" + key + "'";
  std::lock_guard lock(blob_write_mutex_);
  rocksdb::ReadOptions read_options;
  read_options.fill_cache = false;
  rocksdb::PinnableSlice existing;
  const Status found = Get(read_options, kBlobsCf, key, &existing, what);
  if (found.code() == StatusCode::kNotFound) {
    return Status::NotFound("blob '" + key + "' does not exist");
  }
  RECOG_RETURN_IF_ERROR(found);
  rocksdb::WriteBatch batch;
  batch.Delete(Cf(kBlobsCf), key);
  return Write(&batch, what);
}

StatusOr<std::vector<std::string>> RocksDbIndexStore::ListBlobKeys(const std::string& prefix) {
  rocksdb::ReadOptions read_options;
  read_options.fill_cache = false;
  std::unique_ptr<rocksdb::Iterator> it(db_->NewIterator(read_options, Cf(kBlobsCf)));
  std::vector<std::string> keys;
  for (it->Seek(prefix); it->Valid() && it->key().starts_with(prefix); it->Next()) {
    keys.push_back(it->key().ToString());
  }
  RECOG_RETURN_IF_ERROR(FromRocks(it->status(), "cannot list the blobs of '" + dir_ + "'"));
  return keys;
}

Status RocksDbIndexStore::Flush() {
  return FromRocks(SyncLog(), "cannot sync index store '" + dir_ + "'");
}

Status RocksDbIndexStore::Checkpoint(const std::string& dir) {
  std::error_code ec;
  const fs::path target = fs::absolute(dir, ec);  // RocksDB wants an absolute path
  if (ec) return FromErrorCode(ec, "bad checkpoint directory '" + dir + "'");
  if (fs::exists(target, ec)) {
    return Status::AlreadyExists("checkpoint directory '" + dir + "' already exists");
  }
  if (!fs::is_directory(target.parent_path(), ec)) {
    return Status::NotFound("the parent directory of checkpoint '" + dir + "' does not exist");
  }
  rocksdb::Checkpoint* raw = nullptr;
  const std::string what = "cannot write checkpoint '" + dir + "'";
  RECOG_RETURN_IF_ERROR(FromRocks(rocksdb::Checkpoint::Create(db_, &raw), what));
  const std::unique_ptr<rocksdb::Checkpoint> checkpoint(raw);
  RECOG_RETURN_IF_ERROR(FromRocks(checkpoint->CreateCheckpoint(target.string()), what));
  spdlog::info("index store '{}': wrote checkpoint '{}'", dir_, target.string());
  return Status::Ok();
}

// Reads every block of the table files `files` (of the store in `dir`) and checks its checksum,
// at most `bytes_per_second` on average (0 = unlimited). DATA_LOSS naming the first damaged file.
StatusOr<IndexStore::VerifyReport> VerifyTableFiles(
    const std::string& dir, const std::vector<rocksdb::LiveFileMetaData>& files,
    uint64_t bytes_per_second) {
  const rocksdb::Options options;  // any block-based table reads with the default factory
  rocksdb::ReadOptions read_options;
  read_options.verify_checksums = true;
  read_options.fill_cache = false;
  IndexStore::VerifyReport report;
  const auto start = std::chrono::steady_clock::now();
  for (const rocksdb::LiveFileMetaData& file : files) {
    const std::string path = file.directory + "/" + file.relative_filename;
    const rocksdb::Status s =
        rocksdb::VerifySstFileChecksum(options, rocksdb::EnvOptions(), read_options, path);
    if (!s.ok()) {
      return Status::DataLoss("index store '" + dir + "': table file " + path +
                              " is damaged: " + s.ToString());
    }
    ++report.files;
    report.bytes += file.size;
    if (bytes_per_second > 0) {
      // Sleep until the average rate is back under the limit.
      const auto due =
          start + std::chrono::duration<double>(double(report.bytes) / double(bytes_per_second));
      std::this_thread::sleep_until(
          std::chrono::time_point_cast<std::chrono::steady_clock::duration>(due));
    }
  }
  return report;
}

StatusOr<uint64_t> RocksDbIndexStore::MapDiskBytes(MapId map) {
  if (FindMap(map) == nullptr) return UnknownMap(map);
  const std::string begin = MapEntriesBegin(map), end = MapEntriesEnd(map);
  const rocksdb::Range range(begin, end);
  rocksdb::SizeApproximationOptions options;
  options.include_memtables = true;
  options.include_files = true;
  uint64_t total = 0;
  for (ColumnFamily cf : kEntryColumnFamilies) {
    uint64_t bytes = 0;
    const rocksdb::Status status = db_->GetApproximateSizes(options, Cf(cf), &range, 1, &bytes);
    if (!status.ok())
      return Status::Internal("cannot size map " + std::to_string(map) + ": " + status.ToString());
    total += bytes;
  }
  std::error_code ec;
  const uintmax_t snapshot = std::filesystem::file_size(storage::SnapshotPath(dir_, map), ec);
  if (!ec) total += snapshot;
  return total;
}

StatusOr<IndexStore::VerifyReport> RocksDbIndexStore::Verify(uint64_t bytes_per_second) {
  // The files being checked stay on disk while compactions replace them.
  RECOG_RETURN_IF_ERROR(
      FromRocks(db_->DisableFileDeletions(), "cannot verify index store '" + dir_ + "'"));
  struct EnableDeletions {
    rocksdb::DB* db;
    ~EnableDeletions() { db->EnableFileDeletions(/*force=*/false); }
  } enable_deletions{db_};
  std::vector<rocksdb::LiveFileMetaData> files;
  db_->GetLiveFilesMetaData(&files);
  return VerifyTableFiles(dir_, files, bytes_per_second);
}

// fsyncs a file or a directory.
Status SyncPath(const fs::path& path, bool directory) {
  const int fd = ::open(path.c_str(), directory ? (O_RDONLY | O_DIRECTORY) : O_RDONLY);
  if (fd < 0 || ::fsync(fd) != 0) {
    const std::error_code ec(errno, std::generic_category());
    if (fd >= 0) ::close(fd);
    return FromErrorCode(ec, "cannot sync '" + path.string() + "'");
  }
  ::close(fd);
  return Status::Ok();
}

}  // namespace

Status RocksDbStoreOptions::Validate() const {
  if (sync != SyncPolicy::kEveryWrite && sync != SyncPolicy::kGrouped) {
    return Status::InvalidArgument("unknown sync policy " + std::to_string(int(sync)));
  }
  if (sync == SyncPolicy::kGrouped &&
      (group_sync_interval_ms < 1 || group_sync_interval_ms > 60000)) {
    return Status::InvalidArgument("group_sync_interval_ms must be 1 to 60000, not " +
                                   std::to_string(group_sync_interval_ms));
  }
  if (block_cache_mb > (size_t(1) << 20)) {
    return Status::InvalidArgument("block_cache_mb must be at most 1048576 (1 TiB), not " +
                                   std::to_string(block_cache_mb));
  }
  return Status::Ok();
}

StatusOr<std::unique_ptr<IndexStore>> OpenRocksDbIndexStore(const std::string& dir,
                                                            const RocksDbStoreOptions& options,
                                                            StoreRecovery* recovery) {
  RECOG_RETURN_IF_ERROR(options.Validate());
  RECOG_RETURN_IF_ERROR(PrepareDirectory(dir, options.create_if_missing));
  RECOG_RETURN_IF_ERROR(CheckCurrentFileIsThere(dir));
  if (recovery != nullptr) *recovery = StoreRecovery();
  auto store = std::make_unique<RocksDbIndexStore>(dir, options, recovery);
  RECOG_RETURN_IF_ERROR(store->Open());
  return std::unique_ptr<IndexStore>(std::move(store));
}

Status RestoreRocksDbCheckpoint(const std::string& checkpoint_dir, const std::string& data_dir) {
  std::error_code ec;
  if (!fs::exists(checkpoint_dir, ec)) {
    return Status::NotFound("checkpoint directory '" + checkpoint_dir + "' does not exist");
  }
  if (!fs::is_directory(checkpoint_dir, ec)) {
    return Status::InvalidArgument("checkpoint '" + checkpoint_dir + "' is not a directory");
  }
  if (fs::exists(data_dir, ec) || fs::is_symlink(data_dir, ec)) {
    return Status::AlreadyExists("cannot restore into '" + data_dir + "': it already exists");
  }
  // Reading the column family list reads CURRENT and the MANIFEST: a cheap sanity check.
  std::vector<std::string> column_families;
  const rocksdb::Status listed =
      rocksdb::DB::ListColumnFamilies(rocksdb::DBOptions(), checkpoint_dir, &column_families);
  if (!listed.ok()) {
    return Status::DataLoss("'" + checkpoint_dir +
                            "' is not a readable checkpoint: " + listed.ToString());
  }

  const fs::path target = fs::absolute(data_dir, ec);
  if (ec) return FromErrorCode(ec, "bad data directory '" + data_dir + "'");
  const fs::path parent = target.parent_path();
  if (!fs::is_directory(parent, ec)) {
    return Status::NotFound("the parent directory of '" + data_dir + "' does not exist");
  }
  const fs::path temporary =
      parent / (target.filename().string() + ".restoring." + std::to_string(::getpid()));
  fs::remove_all(temporary, ec);
  fs::create_directory(temporary, ec);
  if (ec) return FromErrorCode(ec, "cannot create '" + temporary.string() + "'");

  auto fail = [&](Status status) {
    std::error_code ignored;
    fs::remove_all(temporary, ignored);
    return status;
  };
  for (const fs::directory_entry& file : fs::directory_iterator(checkpoint_dir, ec)) {
    if (!file.is_regular_file()) continue;  // a checkpoint holds files only
    const fs::path to = temporary / file.path().filename();
    fs::copy_file(file.path(), to, ec);
    if (ec) return fail(FromErrorCode(ec, "cannot copy '" + file.path().string() + "'"));
    const Status synced = SyncPath(to, false);
    if (!synced.ok()) return fail(synced);
  }
  if (ec) return fail(FromErrorCode(ec, "cannot list checkpoint '" + checkpoint_dir + "'"));
  const Status synced = SyncPath(temporary, true);
  if (!synced.ok()) return fail(synced);
  fs::rename(temporary, target, ec);
  if (ec) return fail(FromErrorCode(ec, "cannot move the restored store to '" + data_dir + "'"));
  RECOG_RETURN_IF_ERROR(SyncPath(parent, true));
  spdlog::info("restored checkpoint '{}' into '{}'", checkpoint_dir, data_dir);
  return Status::Ok();
}

StatusOr<IndexStore::VerifyReport> VerifyRocksDbCheckpoint(const std::string& checkpoint_dir) {
  const std::string what = "checkpoint '" + checkpoint_dir + "'";
  std::error_code ec;
  if (!fs::is_directory(checkpoint_dir, ec)) return Status::NotFound(what + " is no directory");
  rocksdb::DBOptions db_options;
  db_options.create_if_missing = false;
  db_options.wal_recovery_mode = rocksdb::WALRecoveryMode::kTolerateCorruptedTailRecords;
  // No LOG file is written into the checkpoint.
  db_options.info_log = std::make_shared<DamageRecorder>(nullptr);
  std::vector<std::string> names;
  rocksdb::Status s = rocksdb::DB::ListColumnFamilies(db_options, checkpoint_dir, &names);
  if (!s.ok()) return Status::DataLoss(what + " is not a readable store: " + s.ToString());
  std::vector<rocksdb::ColumnFamilyDescriptor> descriptors;
  for (const std::string& name : names) descriptors.emplace_back(name, rocksdb::Options());
  std::vector<rocksdb::ColumnFamilyHandle*> handles;
  rocksdb::DB* db = nullptr;
  s = rocksdb::DB::OpenForReadOnly(db_options, checkpoint_dir, descriptors, &handles, &db);
  if (!s.ok()) return Status::DataLoss(what + " is not a readable store: " + s.ToString());
  std::vector<rocksdb::LiveFileMetaData> files;
  db->GetLiveFilesMetaData(&files);
  for (rocksdb::ColumnFamilyHandle* handle : handles) db->DestroyColumnFamilyHandle(handle);
  delete db;
  return VerifyTableFiles(checkpoint_dir, files, 0);
}

}  // namespace recog
