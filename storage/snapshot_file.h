// Snapshot files: how the RocksDB store keeps its maps' index snapshots (IndexStore::WriteSnapshot)
// beside its database, one file per map: "<store>/index-snapshots/map-<id>.snapshot".
//
// A file is a 16-byte header (the magic "RCGSNAPS" and the entry id bound the snapshot covers,
// little-endian) followed by the bytes the snapshot's writer appended; those carry their own
// checksum (Database checks it). A snapshot is written to "<file>.tmp", synced, and renamed into
// place by the store's install step, after which the directory is synced: a crash leaves the old
// file or the new one, never a mix, and at worst a ".tmp" file that the next open removes.
// Removing a file syncs the directory as well, so that a removal the store relies on (a snapshot
// dropped before an entry is removed) survives a crash of the machine.
//
// The files are plain POSIX I/O (no RocksDB): the snapshot of a million-entry map is gigabytes
// written and read once, sequentially, which RocksDB's log and compactions would only copy.
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "core/common/status.h"
#include "core/index/index_store.h"

namespace recog::storage {

// The folder of a store's snapshot files, and the file of one map.
std::string SnapshotDirectory(const std::string& store_dir);
std::string SnapshotPath(const std::string& store_dir, MapId map);

// The map a file name of the snapshot folder belongs to ("map-<id>.snapshot"); false for any
// other name (".tmp" files included).
bool ParseSnapshotFileName(const std::string& file_name, MapId* map);

// Writes `path` + ".tmp" (the folder is created when missing). Commit syncs it, then calls
// `install(tmp_path)`, which decides under the store's locks whether to rename it into place
// (InstallSnapshotFile); the temporary file is removed whenever it was not installed.
StatusOr<std::unique_ptr<IndexStore::SnapshotWriter>> CreateSnapshotFile(
    const std::string& path, EntryId covers,
    std::function<Status(const std::string& tmp_path)> install);

// Renames the synced `tmp_path` to `path` and syncs their folder.
Status InstallSnapshotFile(const std::string& tmp_path, const std::string& path);

// Opens a snapshot file for reading; DATA_LOSS when its header is damaged, NOT_FOUND when absent.
StatusOr<std::unique_ptr<IndexStore::SnapshotReader>> OpenSnapshotFile(const std::string& path);

// Removes `path` (OK when absent) and syncs its folder.
Status RemoveSnapshotFile(const std::string& path);

}  // namespace recog::storage
