// Damage to the files of a RocksDbIndexStore: found, named and accounted for. Used by the store's
// Open only (see rocksdb_index_store.h, "Damage"); nothing here is part of the public API.
//
// DamageRecorder is the info log of the store's RocksDB. It forwards every line to RocksDB's own
// LOG file and keeps the lines in which replaying the write-ahead log reports damaged bytes
// ("/data/store/000004.log: dropping 25027 bytes; Corruption: checksum mismatch"): RocksDB's
// status says only "Corruption: checksum mismatch", these lines name the file and the amount.
//
// StoreInventory is what a store holds: its maps (id and name), each map's entry ids and the blob
// keys. A point-in-time recovery takes one of what the damaged store held, the table files plus
// every readable record of the log (TablesOnly and ApplyReadableLog read those), and one of the
// recovered state; their difference is what the recovery lost.
#pragma once

#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include <rocksdb/db.h>
#include <rocksdb/env.h>
#include <rocksdb/wal_filter.h>

#include "core/common/status.h"
#include "storage/rocksdb_index_store.h"

namespace recog::storage {

class DamageRecorder final : public rocksdb::Logger {
 public:
  // Forwards to `log` (RocksDB's LOG file of the store), which may be null.
  explicit DamageRecorder(std::shared_ptr<rocksdb::Logger> log);

  // The damage lines seen so far, without RocksDB's source location prefix.
  std::vector<std::string> damage() const;
  void ClearDamage();

  using rocksdb::Logger::Logv;
  void Logv(const char* format, va_list ap) override;
  void Logv(rocksdb::InfoLogLevel level, const char* format, va_list ap) override;
  void Flush() override;

 private:
  std::shared_ptr<rocksdb::Logger> log_;
  mutable std::mutex mutex_;
  std::vector<std::string> damage_;
};

// DATA_LOSS when `dir` holds RocksDB files (MANIFEST-*, *.sst, *.log) but no CURRENT file:
// RocksDB would take it for an empty directory and create a new store over the old one's files.
Status CheckCurrentFileIsThere(const std::string& dir);

// Copies every file of the store in `dir` into a new directory beside it,
// "<dir>.damaged-<UTC time>", and returns that directory. Table files (*.sst, never modified)
// are hard-linked when the filesystem allows it.
StatusOr<std::string> KeepDamagedCopy(const std::string& dir);

struct StoreInventory {
  std::map<MapId, std::string> map_names;      // the maps of the catalog
  std::map<MapId, std::set<EntryId>> entries;  // entry ids by map (a map may lack its name)
  std::set<std::string> blob_keys;

  // The name of map `id`, or "<map id N, its name was in the damaged bytes>" when its catalog
  // record is missing.
  std::string NameOf(MapId id) const;
};

// The column families the inventory reads, by name.
inline constexpr char kCatalogFamily[] = "maps";
inline constexpr char kEntryMetaFamily[] = "entry_meta";
inline constexpr char kBlobFamily[] = "blobs";

// Reads the inventory of an open store from its catalog, entry metadata and blob column families.
StatusOr<StoreInventory> ReadInventory(rocksdb::DB* db, rocksdb::ColumnFamilyHandle* maps,
                                       rocksdb::ColumnFamilyHandle* entry_meta,
                                       rocksdb::ColumnFamilyHandle* blobs);

// A WalFilter that applies no record of the write-ahead log and learns the column families' ids
// and log numbers: a read-only open with it reads the table files only, whatever the log holds.
class TablesOnly final : public rocksdb::WalFilter {
 public:
  void ColumnFamilyLogNumberMap(const std::map<uint32_t, uint64_t>& log_numbers,
                                const std::map<std::string, uint32_t>& ids_by_name) override;
  WalProcessingOption LogRecordFound(unsigned long long log_number,
                                     const std::string& log_file_name,
                                     const rocksdb::WriteBatch& batch,
                                     rocksdb::WriteBatch* new_batch, bool* batch_changed) override;
  const char* Name() const override { return "recog.TablesOnly"; }

  // The id of column family `name`; UINT32_MAX when unknown.
  uint32_t IdOf(const std::string& name) const;
  // True when the tables of column family `id` do not hold the records of log `log_number`.
  bool NeedsLog(uint32_t id, uint64_t log_number) const;

 private:
  std::map<std::string, uint32_t> ids_by_name_;
  std::map<uint32_t, uint64_t> log_numbers_;
};

// Reads every write-ahead log file (*.log) of the store in `dir`, oldest first, with this
// project's own reader of RocksDB's log format (documented in RocksDB's wiki, "Write Ahead Log
// File Format"): a record that fails its checksum costs the rest of its 32 KiB block, not the
// rest of the file. Applies the changes of every record that passes its checksum and decodes to
// `inventory` (the tables' inventory, read with TablesOnly), in log order, and returns how many
// records it skipped.
size_t ApplyReadableLog(const std::string& dir, const TablesOnly& tables,
                        StoreInventory* inventory);

// Fills recovery->maps and recovery->blobs_lost with what is in `before` and not in `after`.
void CompareInventories(const StoreInventory& before, const StoreInventory& after,
                        StoreRecovery* recovery);

}  // namespace recog::storage
