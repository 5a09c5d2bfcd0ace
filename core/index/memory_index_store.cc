#include "core/index/memory_index_store.h"

#include <chrono>
#include <cstring>

namespace recog {
namespace {

Status UnknownMap(MapId map) {
  return Status::NotFound("map " + std::to_string(map) + " does not exist");
}

}  // namespace

void CopyEntryParts(const EntryRecord& from, uint32_t parts, EntryRecord* to) {
  to->id = from.id;
  if (parts & kEntryMetadata) to->metadata = from.metadata;
  if (parts & kEntryBow) to->bow = from.bow;
  if (parts & kEntryDirect) to->direct = from.direct;
  if (parts & kEntryFeatures) {
    to->keypoints = from.keypoints;
    to->descriptors = from.descriptors.clone();
    to->points = from.points;
    to->camera = from.camera;
  }
}

MemoryIndexStore::StoredMap* MemoryIndexStore::Find(MapId map) {
  for (auto& [name, stored] : maps_) {
    if (stored.info.id == map) return &stored;
  }
  return nullptr;
}

void MemoryIndexStore::DropStaleSnapshot(StoredMap* stored, bool stale) {
  if (!stale) return;
  stored->snapshot.reset();
  ++stored->snapshot_drops;
}

StatusOr<MapInfo> MemoryIndexStore::CreateMap(const MapConfig& config) {
  RECOG_RETURN_IF_ERROR(config.Validate());
  std::lock_guard lock(mutex_);
  if (maps_.count(config.name) != 0) {
    return Status::AlreadyExists("map '" + config.name + "' already exists");
  }
  StoredMap& stored = maps_[config.name];
  stored.info.id = next_map_id_++;
  stored.info.config = config;
  stored.info.created_unix_ms = std::chrono::duration_cast<std::chrono::milliseconds>(
                                    std::chrono::system_clock::now().time_since_epoch())
                                    .count();
  return stored.info;
}

StatusOr<MapInfo> MemoryIndexStore::GetMap(const std::string& name) {
  std::lock_guard lock(mutex_);
  auto it = maps_.find(name);
  if (it == maps_.end()) return Status::NotFound("map '" + name + "' does not exist");
  return it->second.info;
}

StatusOr<std::vector<MapInfo>> MemoryIndexStore::ListMaps() {
  std::lock_guard lock(mutex_);
  std::vector<MapInfo> out;
  for (const auto& [name, stored] : maps_) out.push_back(stored.info);
  return out;
}

Status MemoryIndexStore::DeleteMap(const std::string& name) {
  std::lock_guard lock(mutex_);
  if (maps_.erase(name) == 0) return Status::NotFound("map '" + name + "' does not exist");
  return Status::Ok();
}

Status MemoryIndexStore::CommitEntry(MapId map, const EntryRecord& entry) {
  std::lock_guard lock(mutex_);
  StoredMap* stored = Find(map);
  if (stored == nullptr) return UnknownMap(map);
  if (entry.id == kInvalidEntryId) return Status::InvalidArgument("entry has no id");
  if (stored->entries.count(entry.id) != 0) {
    return Status::AlreadyExists("entry " + std::to_string(entry.id) + " already exists");
  }
  // An entry below the next id may fall in a snapshot's range (installed or being written).
  DropStaleSnapshot(stored, entry.id < stored->next_id);
  CopyEntryParts(entry, kEntryAllParts, &stored->entries[entry.id]);
  stored->next_id = std::max(stored->next_id, entry.id + 1);
  return Status::Ok();
}

StatusOr<uint64_t> MemoryIndexStore::MapDiskBytes(MapId map) {
  std::lock_guard lock(mutex_);
  if (Find(map) == nullptr) return UnknownMap(map);
  return uint64_t{0};  // nothing is on disk
}

Status MemoryIndexStore::RemoveEntry(MapId map, EntryId id) {
  std::lock_guard lock(mutex_);
  StoredMap* stored = Find(map);
  if (stored == nullptr) return UnknownMap(map);
  if (stored->entries.count(id) == 0) {
    return Status::NotFound("entry " + std::to_string(id) + " does not exist");
  }
  DropStaleSnapshot(stored, true);
  stored->entries.erase(id);
  return Status::Ok();
}

Status MemoryIndexStore::ReadEntry(MapId map, EntryId id, uint32_t parts, EntryRecord* out) {
  std::lock_guard lock(mutex_);
  StoredMap* stored = Find(map);
  if (stored == nullptr) return UnknownMap(map);
  auto it = stored->entries.find(id);
  if (it == stored->entries.end()) {
    return Status::NotFound("entry " + std::to_string(id) + " does not exist");
  }
  CopyEntryParts(it->second, parts, out);
  return Status::Ok();
}

Status MemoryIndexStore::ScanEntries(MapId map, EntryId first, uint32_t parts,
                                     const std::function<Status(EntryRecord&)>& visit) {
  // Copy under the lock, visit outside it, so that `visit` may call the store.
  std::vector<EntryRecord> copies;
  {
    std::lock_guard lock(mutex_);
    StoredMap* stored = Find(map);
    if (stored == nullptr) {
      return UnknownMap(map);
    }
    for (auto it = stored->entries.lower_bound(first); it != stored->entries.end(); ++it) {
      CopyEntryParts(it->second, parts, &copies.emplace_back());
    }
  }
  for (EntryRecord& record : copies) RECOG_RETURN_IF_ERROR(visit(record));
  return Status::Ok();
}

StatusOr<EntryId> MemoryIndexStore::NextEntryId(MapId map) {
  std::lock_guard lock(mutex_);
  StoredMap* stored = Find(map);
  if (stored == nullptr) return UnknownMap(map);
  return stored->next_id;
}

class MemoryIndexStore::MemorySnapshotWriter final : public SnapshotWriter {
 public:
  MemorySnapshotWriter(MemoryIndexStore* store, MapId map, EntryId covers, uint64_t drops)
      : store_(store), map_(map), covers_(covers), drops_(drops) {}
  Status Append(std::string_view bytes) override {
    bytes_.append(bytes);
    return Status::Ok();
  }
  Status Commit() override {
    std::lock_guard lock(store_->mutex_);
    StoredMap* stored = store_->Find(map_);
    if (stored == nullptr) return UnknownMap(map_);
    if (stored->snapshot_drops != drops_) {
      return Status::FailedPrecondition("map " + std::to_string(map_) +
                                        " changed while its snapshot was written");
    }
    stored->snapshot = Snapshot{covers_, std::make_shared<const std::string>(std::move(bytes_))};
    return Status::Ok();
  }

 private:
  MemoryIndexStore* store_;
  MapId map_;
  EntryId covers_;
  uint64_t drops_;
  std::string bytes_;
};

namespace {

class MemorySnapshotReader final : public IndexStore::SnapshotReader {
 public:
  MemorySnapshotReader(EntryId covers, std::shared_ptr<const std::string> bytes)
      : covers_(covers), bytes_(std::move(bytes)) {}
  EntryId covers() const override { return covers_; }
  uint64_t size() const override { return bytes_->size(); }
  Status Read(void* out, size_t size) override {
    if (size == 0) return Status::Ok();  // `out` may be null then
    if (bytes_->size() - position_ < size) {
      return Status::DataLoss("the snapshot ends " + std::to_string(bytes_->size() - position_) +
                              " bytes before the " + std::to_string(size) + " to read");
    }
    std::memcpy(out, bytes_->data() + position_, size);
    position_ += size;
    return Status::Ok();
  }

 private:
  EntryId covers_;
  std::shared_ptr<const std::string> bytes_;
  size_t position_ = 0;
};

}  // namespace

StatusOr<std::unique_ptr<IndexStore::SnapshotWriter>> MemoryIndexStore::WriteSnapshot(
    MapId map, EntryId covers) {
  std::lock_guard lock(mutex_);
  StoredMap* stored = Find(map);
  if (stored == nullptr) return UnknownMap(map);
  if (covers > stored->next_id) {
    return Status::InvalidArgument("a snapshot of map " + std::to_string(map) +
                                   " cannot cover entry ids up to " + std::to_string(covers) +
                                   ", beyond its next id " + std::to_string(stored->next_id));
  }
  return std::unique_ptr<SnapshotWriter>(
      new MemorySnapshotWriter(this, map, covers, stored->snapshot_drops));
}

StatusOr<std::unique_ptr<IndexStore::SnapshotReader>> MemoryIndexStore::ReadSnapshot(MapId map) {
  std::lock_guard lock(mutex_);
  StoredMap* stored = Find(map);
  if (stored == nullptr) return UnknownMap(map);
  if (!stored->snapshot) return Status::NotFound("map " + std::to_string(map) + " has no snapshot");
  return std::unique_ptr<SnapshotReader>(
      new MemorySnapshotReader(stored->snapshot->covers, stored->snapshot->bytes));
}

Status MemoryIndexStore::DropSnapshot(MapId map) {
  std::lock_guard lock(mutex_);
  StoredMap* stored = Find(map);
  if (stored == nullptr) return UnknownMap(map);
  DropStaleSnapshot(stored, true);
  return Status::Ok();
}

Status MemoryIndexStore::PutBlob(const std::string& key, std::string_view value) {
  RECOG_RETURN_IF_ERROR(ValidateBlob(key, value));
  std::string copy(value);  // allocated, and the old value freed, outside the lock
  std::lock_guard lock(mutex_);
  blobs_[key].swap(copy);
  return Status::Ok();
}

StatusOr<std::string> MemoryIndexStore::GetBlob(const std::string& key) {
  RECOG_RETURN_IF_ERROR(ValidateBlob(key));
  std::lock_guard lock(mutex_);
  auto it = blobs_.find(key);
  if (it == blobs_.end()) return Status::NotFound("blob '" + key + "' does not exist");
  return it->second;
}

Status MemoryIndexStore::DeleteBlob(const std::string& key) {
  RECOG_RETURN_IF_ERROR(ValidateBlob(key));
  std::lock_guard lock(mutex_);
  if (blobs_.erase(key) == 0) return Status::NotFound("blob '" + key + "' does not exist");
  return Status::Ok();
}

StatusOr<std::vector<std::string>> MemoryIndexStore::ListBlobKeys(const std::string& prefix) {
  std::lock_guard lock(mutex_);
  std::vector<std::string> keys;
  for (auto it = blobs_.lower_bound(prefix);
       it != blobs_.end() && it->first.compare(0, prefix.size(), prefix) == 0; ++it) {
    keys.push_back(it->first);
  }
  return keys;
}

Status MemoryIndexStore::Checkpoint(const std::string&) {
  return Status::FailedPrecondition("an in-memory store has nothing to checkpoint");
}

}  // namespace recog
