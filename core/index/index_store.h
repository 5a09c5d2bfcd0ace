// IndexStore: the storage port of the recognition databases.
//
// core/ keeps its indexes in memory and writes every change through this interface, in domain
// types only; storage/ implements it with RocksDB (durable), and MemoryIndexStore implements it
// in memory (tests, throw-away maps). One store holds many maps, each with its own entries, and
// beside them named byte strings ("blobs": object model versions and other files of a few MB).
//
// Contract (checked by the contract test suite that runs against every implementation):
//  - CommitEntry and RemoveEntry are atomic: after a crash an entry is either entirely present
//    (every part) or entirely absent. Once CommitEntry has returned OK, the entry survives a crash
//    of the process (and, with the durable implementation's "sync every write" policy, of the
//    machine).
//  - ScanEntries visits the entries of a map from a given id on, in increasing id order; an entry
//    missing one of the requested parts is DATA_LOSS.
//  - DeleteMap removes every record of the map (its index snapshot included); its name can then be
//    created again.
//  - A map's index snapshot (written by Database::SaveSnapshot) describes the entries with ids
//    below its `covers` id, and the store keeps it only while that holds: it is dropped, before
//    the write, by committing an entry with an id below `covers`, by removing an entry of the map,
//    by deleting the map, and by a recovery that loses writes. A snapshot being written is
//    installed by Commit, atomically (the previous one or the new one, never a mix) and durably
//    along with every entry it covers; FAILED_PRECONDITION when a drop happened since the writer
//    was made.
//  - Blobs are independent of maps. PutBlob (create or overwrite) and DeleteBlob are atomic and
//    as durable as CommitEntry: after a crash a blob holds its old or its new value, never a mix.
//    ListBlobKeys returns keys in increasing byte order.
//  - Errors: NOT_FOUND (unknown map, entry or blob), ALREADY_EXISTS (map name taken),
//    INVALID_ARGUMENT (bad name, record, blob key or blob size), DATA_LOSS (undecodable or
//    inconsistent stored data), RESOURCE_EXHAUSTED (disk full), UNAVAILABLE/INTERNAL (I/O
//    failures).
//
// Thread safety: every method may be called from several threads at once. Ordering between
// concurrent writes to the same map or blob is the caller's business (Database serialises its
// adds).
#pragma once

#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/status.h"
#include "core/index/entry.h"

namespace recog {

class IndexStore {
 public:
  virtual ~IndexStore() = default;

  // Creates a map; its id is unique in this store and never reused.
  virtual StatusOr<MapInfo> CreateMap(const MapConfig& config) = 0;
  virtual StatusOr<MapInfo> GetMap(const std::string& name) = 0;
  // Every map, by name.
  virtual StatusOr<std::vector<MapInfo>> ListMaps() = 0;
  virtual Status DeleteMap(const std::string& name) = 0;

  // Stores every part of `entry` (its id is chosen by the caller) in one atomic write.
  // ALREADY_EXISTS when the id is taken.
  virtual Status CommitEntry(MapId map, const EntryRecord& entry) = 0;
  // Removes every part of an entry in one atomic write.
  virtual Status RemoveEntry(MapId map, EntryId id) = 0;
  // Reads the requested parts (EntryPart flags) of one entry into *out.
  virtual Status ReadEntry(MapId map, EntryId id, uint32_t parts, EntryRecord* out) = 0;
  // Calls `visit` for every entry of the map with an id of at least `first`, in increasing id
  // order, with the requested parts; stops at the first error `visit` returns and returns it.
  virtual Status ScanEntries(MapId map, EntryId first, uint32_t parts,
                             const std::function<Status(EntryRecord&)>& visit) = 0;
  // The largest id ever committed to the map plus one (0 for a new map), so that ids removed
  // from the end are not reused after a reopen.
  virtual StatusOr<EntryId> NextEntryId(MapId map) = 0;

  // Index snapshots (see the contract above): opaque bytes the store keeps beside a map's entries.
  class SnapshotWriter {
   public:
    virtual ~SnapshotWriter() = default;  // without Commit: the bytes are discarded
    virtual Status Append(std::string_view bytes) = 0;
    // Installs the snapshot as the map's (after making every write so far durable).
    virtual Status Commit() = 0;
  };
  class SnapshotReader {
   public:
    virtual ~SnapshotReader() = default;
    virtual EntryId covers() const = 0;
    virtual uint64_t size() const = 0;  // the bytes Append wrote
    // Reads the next `size` bytes into `out`; DATA_LOSS when fewer remain.
    virtual Status Read(void* out, size_t size) = 0;
  };
  // Starts a snapshot of map `map` that covers its entries with ids below `covers`.
  virtual StatusOr<std::unique_ptr<SnapshotWriter>> WriteSnapshot(MapId map, EntryId covers) = 0;
  // The map's snapshot; NOT_FOUND when it has none.
  virtual StatusOr<std::unique_ptr<SnapshotReader>> ReadSnapshot(MapId map) = 0;
  // Drops the map's snapshot (OK when it has none).
  virtual Status DropSnapshot(MapId map) = 0;

  // Blobs: named byte strings kept beside the maps (object model versions, ...). Keys are 1 to
  // kMaxBlobKeyBytes arbitrary bytes, values at most kMaxBlobBytes; anything else is
  // INVALID_ARGUMENT (ValidateBlob checks both).
  static constexpr size_t kMaxBlobKeyBytes = 512;
  static constexpr size_t kMaxBlobBytes = size_t(256) << 20;  // 256 MiB
  // Stores `value` under `key`, replacing any previous value, in one atomic write.
  virtual Status PutBlob(const std::string& key, std::string_view value) = 0;
  // NOT_FOUND when there is no blob `key`.
  virtual StatusOr<std::string> GetBlob(const std::string& key) = 0;
  // NOT_FOUND when there is no blob `key`.
  virtual Status DeleteBlob(const std::string& key) = 0;
  // The keys that start with `prefix` (every key for ""), in increasing byte order.
  virtual StatusOr<std::vector<std::string>> ListBlobKeys(const std::string& prefix) = 0;

  // Makes every acknowledged write (entries, maps, blobs) durable (a no-op where every write
  // already is).
  virtual Status Flush() = 0;
  // Writes a consistent copy of the whole store to `dir` (which must not exist) while the store
  // keeps serving. FAILED_PRECONDITION where the implementation has nothing on disk.
  virtual Status Checkpoint(const std::string& dir) = 0;

  // Approximately how many bytes the entries of map `map` take on disk (the files, plus what is
  // still in memory on its way there, plus its index snapshot); 0 where nothing is on disk.
  // NOT_FOUND for an unknown map.
  virtual StatusOr<uint64_t> MapDiskBytes(MapId map) = 0;

  // What Verify read.
  struct VerifyReport {
    size_t files = 0;    // files checked
    uint64_t bytes = 0;  // their bytes
  };
  // Reads every file of the store and checks every block's checksum while the store keeps
  // serving, at most `bytes_per_second` (0: as fast as the disk goes) so that queries keep the
  // disk. DATA_LOSS naming the first damaged file. Where nothing is on disk: an empty report.
  virtual StatusOr<VerifyReport> Verify(uint64_t bytes_per_second) = 0;
};

// INVALID_ARGUMENT when `key` is empty or longer than IndexStore::kMaxBlobKeyBytes, or `value`
// is longer than IndexStore::kMaxBlobBytes; for the implementations of the blob methods.
inline Status ValidateBlob(const std::string& key, std::string_view value = {}) {
  if (key.empty() || key.size() > IndexStore::kMaxBlobKeyBytes) {
    return Status::InvalidArgument("blob keys must have 1 to " +
                                   std::to_string(IndexStore::kMaxBlobKeyBytes) + " bytes, not " +
                                   std::to_string(key.size()));
  }
  if (value.size() > IndexStore::kMaxBlobBytes) {
    return Status::InvalidArgument("blob '" + key + "' has " + std::to_string(value.size()) +
                                   " bytes; at most " + std::to_string(IndexStore::kMaxBlobBytes) +
                                   " are allowed");
  }
  return Status::Ok();
}

}  // namespace recog
