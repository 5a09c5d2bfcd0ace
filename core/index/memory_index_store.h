// MemoryIndexStore: an IndexStore kept entirely in memory. Nothing survives the process; used by
// tests (the reference implementation of the storage contract) and for throw-away maps.
#pragma once

#include <map>
#include <mutex>
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
  Status ScanEntries(MapId map, uint32_t parts,
                     const std::function<Status(EntryRecord&)>& visit) override;
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
  struct StoredMap {
    MapInfo info;
    std::map<EntryId, EntryRecord> entries;
    EntryId next_id = 0;
  };
  StoredMap* Find(MapId map);  // requires mutex_

  std::mutex mutex_;
  std::map<std::string, StoredMap> maps_;
  std::map<std::string, std::string> blobs_;  // key -> value, in byte order of the keys
  MapId next_map_id_ = 1;
};

// Copies the requested parts of `from` into *to (descriptors are deep-copied).
void CopyEntryParts(const EntryRecord& from, uint32_t parts, EntryRecord* to);

}  // namespace recog
