// MemoryIndexStore: an IndexStore kept entirely in memory. Nothing survives the process; used by
// tests (the reference implementation of the storage contract) and for throw-away maps.
#pragma once

#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "core/index/index_store.h"

namespace recog {

class MemoryIndexStore : public IndexStore {
 public:
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
  Status Flush() override { return Status::Ok(); }
  Status Checkpoint(const std::string& dir) override;
  StatusOr<VerifyReport> Verify(uint64_t) override { return VerifyReport{}; }
  StatusOr<uint64_t> MapDiskBytes(MapId map) override;

 private:
  struct Snapshot {
    EntryId covers = 0;
    std::shared_ptr<const std::string> bytes;  // shared with the readers
  };
  struct StoredMap {
    MapInfo info;
    std::map<EntryId, EntryRecord> entries;
    EntryId next_id = 0;
    std::optional<Snapshot> snapshot;
    uint64_t snapshot_drops = 0;  // how many times a write dropped the snapshot
  };
  class MemorySnapshotWriter;
  StoredMap* Find(MapId map);  // requires mutex_
  // Drops the map's snapshot (and fails the writers of one) when `stale`; requires mutex_.
  static void DropStaleSnapshot(StoredMap* stored, bool stale);

  std::mutex mutex_;
  std::map<std::string, StoredMap> maps_;
  std::map<std::string, std::string> blobs_;  // key -> value, in byte order of the keys
  MapId next_map_id_ = 1;
};

// Copies the requested parts of `from` into *to (descriptors are deep-copied).
void CopyEntryParts(const EntryRecord& from, uint32_t parts, EntryRecord* to);

}  // namespace recog
