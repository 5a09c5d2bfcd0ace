// The durable IndexStore: every map and entry of a recognition server in one RocksDB database.
//
// Callers get an IndexStore (core/index/index_store.h) from OpenRocksDbIndexStore and never see
// a RocksDB type. Inside, each kind of record has its own column family: `maps` (the map catalog:
// name -> MapInfo, each map's next entry id, the store-wide next map id), `entry_meta`
// (EntryMetadata), `bow` (BowVector), `direct` (FeatureVector), `features` (keypoints and
// descriptors) and `blobs` (the IndexStore blobs: the raw key bytes -> the value as given). Entry
// records are keyed by big-endian `map id | entry id`, so a map's entries are contiguous and in id
// order; the value encodings are in storage/record_codec.h. Opening a store creates the column
// families it lacks, so a store written before `blobs` existed opens (with no blobs). Reading or
// listing blobs bypasses the block cache, which stays for the entries; listing reads the blocks
// that hold the values too (RocksDB keeps them with the keys), so it costs about a full read.
//
// Durability. Every CommitEntry / RemoveEntry / CreateMap / DeleteMap / PutBlob / DeleteBlob is one
// RocksDB WriteBatch written through the write-ahead log, so a crash never leaves half an entry,
// half a map or half a blob.
// When a write has returned OK:
//  - SyncPolicy::kEveryWrite: the WAL was fsync'ed before returning; the write survives a crash of
//    the process and of the machine (power loss, kernel panic).
//  - SyncPolicy::kGrouped: the WAL record was handed to the operating system before returning, and
//    a background thread fsyncs the WAL every `group_sync_interval_ms`. The write survives a crash
//    of the process (kill -9, abort), but a crash of the machine may lose the writes of the last
//    interval. Flush() forces the sync. Much higher write throughput: many writes share one fsync.
//
// Damage. A store never loses acknowledged writes without saying so. The write-ahead log is
// replayed tolerating only a torn last write (the record being written when the machine lost
// power). Damage anywhere else in the log (a flipped byte, a lost block) fails the open with
// DATA_LOSS naming the log file and the damaged bytes, and nothing is rewritten. An operator who
// accepts the loss opens with DamagedLogPolicy::kPointInTime: the store's files are first copied
// beside it ("<dir>.damaged-<UTC time>"), the log is replayed up to its damage (a consistent
// prefix of the writes), and StoreRecovery lists what that lost: per map the entries that the
// log's readable records held and the recovered store does not, maps lost whole, blob keys lost.
// Entries whose records lay in the damaged bytes themselves cannot be listed.
// Damage to a table file (*.sst) is found when its block is read (DATA_LOSS naming the file);
// a missing CURRENT file beside the store's other files is DATA_LOSS, not a new empty store.
//
// Index snapshots (IndexStore::WriteSnapshot) are files in "<dir>/index-snapshots", one per map
// (storage/snapshot_file.h), outside RocksDB. Installing one first syncs the write-ahead log, so
// that every entry it covers is durable. Opening the store keeps the files of known maps whose
// bound does not exceed the map's entries and removes the rest; a point-in-time recovery removes
// them all. Checkpoints do not copy them: a store restored from one rebuilds its indexes once.
//
// Checkpoints. IndexStore::Checkpoint(dir) writes a consistent, openable copy of the whole store
// (SST files hard-linked when on the same filesystem) while the store keeps serving; it holds
// every write that returned before the call. RestoreRocksDbCheckpoint copies one back into place,
// offline.
//
// Thread safety: the store may be used from any number of threads at once (see IndexStore).
// Writes to different maps proceed in parallel; writes to one map are serialised by a per-map
// lock; reads never wait for writes. Only one store (in this or another process) can have a
// directory open at a time.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/index/index_store.h"

namespace recog {

enum class SyncPolicy {
  kEveryWrite,  // fsync the WAL in every write: durable against machine crashes
  kGrouped,     // fsync the WAL from a background thread every group_sync_interval_ms
};

// What opening a store does with a write-ahead log damaged anywhere but in its torn last write.
enum class DamagedLogPolicy {
  kRefuse,       // DATA_LOSS naming the log file and the damage; no file is changed
  kPointInTime,  // keep a copy of the files, replay up to the damage, report the loss
};

// What a point-in-time recovery lost (see "Damage" above). Empty when the log was whole.
struct StoreRecovery {
  struct MapLoss {
    std::string name;
    size_t entries_before = 0;     // entries held by the log's readable records
    size_t entries_after = 0;      // entries in the recovered store
    std::vector<EntryId> missing;  // the ids of the difference, increasing
    bool map_lost = false;         // the map itself is gone
  };
  std::vector<std::string> damage;      // per damaged stretch: "<file>: dropping N bytes; <why>"
  std::string damaged_copy;             // the directory holding the files as they were
  std::vector<MapLoss> maps;            // the maps that lost something, by name
  std::vector<std::string> blobs_lost;  // blob keys (object model versions: model/<name>/<v>)

  bool recovered() const { return !damage.empty(); }
  size_t entries_lost() const;  // the missing ids of every map
  size_t maps_lost() const;     // the maps lost whole
  // One line per damaged stretch, per map that lost something, and for the blobs lost.
  std::vector<std::string> Describe() const;
};

struct RocksDbStoreOptions {
  // When an acknowledged write is fsync'ed; see the header comment.
  SyncPolicy sync = SyncPolicy::kGrouped;
  // kGrouped: the background thread syncs the WAL this often, 1 to 60000 ms. The window in which
  // a machine crash may lose acknowledged writes. Ignored by kEveryWrite.
  uint32_t group_sync_interval_ms = 50;
  // Create the directory and an empty store when there is none; otherwise NOT_FOUND.
  bool create_if_missing = true;
  // Memory for cached uncompressed blocks, shared by all column families, at most 1 TiB. 0 turns
  // the cache off (every read goes to the files / the OS page cache).
  size_t block_cache_mb = 64;
  // A write-ahead log damaged anywhere but in its torn last write: refuse, or recover to the
  // damage and report the loss (see "Damage" above).
  DamagedLogPolicy damaged_log = DamagedLogPolicy::kRefuse;
  // Closing writes the memtables out to table files, so that the next open has no log to replay
  // (seconds for a large store). false leaves the writes in the log, as a crash does (tests of
  // damaged logs).
  bool write_memtables_at_close = true;

  // INVALID_ARGUMENT naming the bad field.
  Status Validate() const;
};

// Opens (or creates) the store in `dir`. Fails with
//  - INVALID_ARGUMENT for bad options or when `dir` exists but is not a directory;
//  - NOT_FOUND when there is no store in `dir` and !create_if_missing;
//  - FAILED_PRECONDITION when `dir` is not writable (read-only directory or filesystem), or the
//    store was written by a newer, incompatible version;
//  - UNAVAILABLE when another store (in this or another process) has `dir` open, or on other I/O
//    errors; DATA_LOSS when the store is corrupt (a damaged log under DamagedLogPolicy::kRefuse).
// The message names the directory and includes RocksDB's own description. When the log was damaged
// and options.damaged_log is kPointInTime, *recovery (if given) says what the recovery lost.
StatusOr<std::unique_ptr<IndexStore>> OpenRocksDbIndexStore(const std::string& dir,
                                                            const RocksDbStoreOptions& options,
                                                            StoreRecovery* recovery = nullptr);

// Offline restore: copies a checkpoint directory (written by IndexStore::Checkpoint) to
// `data_dir`, which must not exist (ALREADY_EXISTS otherwise) and is then opened with
// OpenRocksDbIndexStore. The copy is made under a temporary name, fsync'ed and renamed, so an
// interrupted restore never leaves a half-copied store at `data_dir`. NOT_FOUND when
// `checkpoint_dir` does not exist, DATA_LOSS when it is not a readable store.
Status RestoreRocksDbCheckpoint(const std::string& checkpoint_dir, const std::string& data_dir);

// Checks a checkpoint directory (written by IndexStore::Checkpoint, or downloaded by `recog admin
// checkpoint`) without changing it: it must open read-only as a store (CURRENT, MANIFEST and the
// log readable) and every block of every table file it lists must match its checksum. DATA_LOSS
// naming what is damaged, NOT_FOUND when `checkpoint_dir` is no directory.
StatusOr<IndexStore::VerifyReport> VerifyRocksDbCheckpoint(const std::string& checkpoint_dir);

}  // namespace recog
