// Damage to the files of a RocksDbIndexStore (see store_damage.h).
#include "storage/store_damage.h"

#include <array>
#include <cstdarg>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <system_error>

#include <rocksdb/write_batch.h>

#include "storage/record_codec.h"

namespace recog {

size_t StoreRecovery::entries_lost() const {
  size_t lost = 0;
  for (const MapLoss& map : maps) lost += map.missing.size();
  return lost;
}

size_t StoreRecovery::maps_lost() const {
  size_t lost = 0;
  for (const MapLoss& map : maps) lost += map.map_lost ? 1 : 0;
  return lost;
}

std::vector<std::string> StoreRecovery::Describe() const {
  std::vector<std::string> lines;
  for (const std::string& stretch : damage) lines.push_back("damaged write-ahead log: " + stretch);
  if (!damage.empty()) {
    lines.push_back(
        "writes whose records lay in the damaged bytes are lost too and cannot be listed");
  }
  for (const MapLoss& map : maps) {
    std::string ids;
    for (EntryId id : map.missing) {
      if (!ids.empty()) ids += ',';
      ids += std::to_string(id);
    }
    lines.push_back("map '" + map.name + "'" + (map.map_lost ? " lost whole" : "") + ": " +
                    std::to_string(map.entries_before) + " -> " +
                    std::to_string(map.entries_after) + " entries, missing ids " +
                    (ids.empty() ? "(none)" : ids));
  }
  if (!blobs_lost.empty()) {
    std::string keys;
    for (const std::string& key : blobs_lost) {
      if (!keys.empty()) keys += ", ";
      keys += key;
    }
    lines.push_back(std::to_string(blobs_lost.size()) + " blobs lost: " + keys);
  }
  if (!damaged_copy.empty()) lines.push_back("the damaged files are kept in " + damaged_copy);
  return lines;
}

namespace storage {
namespace {

namespace fs = std::filesystem;

constexpr std::string_view kDroppingMarker = ": dropping ";
constexpr std::string_view kIgnoringPrefix = "(ignoring error) ";

Status FileError(const std::error_code& ec, const std::string& what) {
  return Status::Unavailable(what + ": " + ec.message());
}

bool IsStoreFile(const std::string& name) {
  return name.starts_with("MANIFEST-") || name.ends_with(".sst") || name.ends_with(".log");
}

}  // namespace

DamageRecorder::DamageRecorder(std::shared_ptr<rocksdb::Logger> log)
    : rocksdb::Logger(log != nullptr ? log->GetInfoLogLevel() : rocksdb::InfoLogLevel::INFO_LEVEL),
      log_(std::move(log)) {}

std::vector<std::string> DamageRecorder::damage() const {
  std::lock_guard lock(mutex_);
  return damage_;
}

void DamageRecorder::ClearDamage() {
  std::lock_guard lock(mutex_);
  damage_.clear();
}

void DamageRecorder::Logv(const char* format, va_list ap) {
  Logv(rocksdb::InfoLogLevel::INFO_LEVEL, format, ap);
}

void DamageRecorder::Logv(rocksdb::InfoLogLevel level, const char* format, va_list ap) {
  if (level >= rocksdb::InfoLogLevel::WARN_LEVEL) {
    va_list copy;
    va_copy(copy, ap);
    char line[1024];
    std::vsnprintf(line, sizeof(line), format, copy);
    va_end(copy);
    std::string_view text(line);
    if (text.find(kDroppingMarker) != std::string_view::npos) {
      // "[db/db_impl/db_impl_open.cc:982] (ignoring error) /dir/000004.log: dropping ..."
      if (text.starts_with('[')) {
        const size_t end = text.find("] ");
        if (end != std::string_view::npos) text.remove_prefix(end + 2);
      }
      if (text.starts_with(kIgnoringPrefix)) text.remove_prefix(kIgnoringPrefix.size());
      std::lock_guard lock(mutex_);
      damage_.emplace_back(text);
    }
  }
  if (log_ != nullptr) log_->Logv(level, format, ap);
}

void DamageRecorder::Flush() {
  if (log_ != nullptr) log_->Flush();
}

Status CheckCurrentFileIsThere(const std::string& dir) {
  std::error_code ec;
  if (fs::exists(fs::path(dir) / "CURRENT", ec)) return Status::Ok();
  std::vector<std::string> found;
  for (const fs::directory_entry& file : fs::directory_iterator(dir, ec)) {
    const std::string name = file.path().filename().string();
    if (IsStoreFile(name)) found.push_back(name);
  }
  if (ec) return FileError(ec, "cannot list index store directory '" + dir + "'");
  if (found.empty()) return Status::Ok();
  return Status::DataLoss("index store '" + dir + "' has " + std::to_string(found.size()) +
                          " store files (" + found.front() +
                          ", ...) but no CURRENT file: refusing to create a new store over them; "
                          "restore the store from a checkpoint");
}

StatusOr<std::string> KeepDamagedCopy(const std::string& dir) {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char stamp[32];
  std::strftime(stamp, sizeof(stamp), "%Y%m%dT%H%M%SZ", &utc);
  std::string copy = fs::path(dir).lexically_normal().string();
  while (copy.size() > 1 && copy.back() == '/') copy.pop_back();
  copy += ".damaged-";
  copy += stamp;
  std::error_code ec;
  const std::string first_choice = copy;
  for (int suffix = 1; fs::exists(copy, ec); ++suffix) {
    copy = first_choice + '.' + std::to_string(suffix);
  }
  fs::create_directory(copy, ec);
  if (ec) return FileError(ec, "cannot create '" + copy + "' for the damaged store's files");
  for (const fs::directory_entry& file : fs::directory_iterator(dir, ec)) {
    if (!file.is_regular_file()) continue;
    const fs::path to = fs::path(copy) / file.path().filename();
    if (file.path().extension() == ".sst") {
      fs::create_hard_link(file.path(), to, ec);
      if (!ec) continue;
    }
    fs::copy_file(file.path(), to, ec);
    if (ec) return FileError(ec, "cannot copy '" + file.path().string() + "' to '" + copy + "'");
  }
  if (ec) return FileError(ec, "cannot list index store directory '" + dir + "'");
  return copy;
}

std::string StoreInventory::NameOf(MapId id) const {
  const auto name = map_names.find(id);
  if (name != map_names.end()) return name->second;
  return "<map id " + std::to_string(id) + ", its name was in the damaged bytes>";
}

StatusOr<StoreInventory> ReadInventory(rocksdb::DB* db, rocksdb::ColumnFamilyHandle* maps,
                                       rocksdb::ColumnFamilyHandle* entry_meta,
                                       rocksdb::ColumnFamilyHandle* blobs) {
  const auto read_error = [](const rocksdb::Status& s, const std::string& what) {
    return Status::DataLoss("cannot read the " + what + " of the store: " + s.ToString());
  };
  StoreInventory inventory;
  std::unique_ptr<rocksdb::Iterator> it(db->NewIterator(rocksdb::ReadOptions(), maps));
  for (it->SeekToFirst(); it->Valid(); it->Next()) {
    const std::string_view key(it->key().data(), it->key().size());
    if (key.size() < 2 || key[0] != kMapInfoTag) continue;
    MapInfo info;
    RECOG_RETURN_IF_ERROR(DecodeMapInfo(
        key.substr(1), std::string_view(it->value().data(), it->value().size()), &info));
    inventory.map_names[info.id] = info.config.name;
    inventory.entries[info.id];
  }
  if (!it->status().ok()) return read_error(it->status(), "catalog");

  it.reset(db->NewIterator(rocksdb::ReadOptions(), entry_meta));
  for (it->SeekToFirst(); it->Valid(); it->Next()) {
    MapId map = 0;
    EntryId id = 0;
    if (DecodeEntryKey(std::string_view(it->key().data(), it->key().size()), &map, &id)) {
      inventory.entries[map].insert(id);
    }
  }
  if (!it->status().ok()) return read_error(it->status(), "entries");

  it.reset(db->NewIterator(rocksdb::ReadOptions(), blobs));
  for (it->SeekToFirst(); it->Valid(); it->Next()) inventory.blob_keys.insert(it->key().ToString());
  if (!it->status().ok()) return read_error(it->status(), "blobs");
  return inventory;
}

// --- Reading the write-ahead log ---

namespace {

// RocksDB's log format: 32 KiB blocks of physical records, each with a header of a masked CRC32C
// (4 bytes, little-endian), the payload length (2) and a type (1); the recyclable types add the
// log number (4). A logical record (one write batch) is one kFull record or kFirst, kMiddle...,
// kLast; a block's tail shorter than a header is zero padding.
constexpr size_t kBlockSize = 32768;
constexpr size_t kHeaderSize = 7;
constexpr size_t kRecyclableHeaderSize = 11;
enum RecordType : uint8_t {
  kFull = 1,
  kFirst = 2,
  kMiddle = 3,
  kLast = 4,
  kRecyclableFull = 5,
  kRecyclableFirst = 6,
  kRecyclableMiddle = 7,
  kRecyclableLast = 8,
};

uint32_t Crc32c(uint32_t crc, std::string_view bytes) {
  static const std::array<uint32_t, 256> table = [] {
    std::array<uint32_t, 256> t{};
    for (uint32_t i = 0; i < 256; ++i) {
      uint32_t c = i;
      for (int bit = 0; bit < 8; ++bit) c = (c & 1) ? (c >> 1) ^ 0x82F63B78u : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  crc = ~crc;
  for (unsigned char byte : bytes) crc = table[(crc ^ byte) & 0xff] ^ (crc >> 8);
  return ~crc;
}

uint32_t Unmask(uint32_t masked) {
  const uint32_t rotated = masked - 0xa282ead8u;
  return (rotated >> 17) | (rotated << 15);
}

uint32_t Fixed32(const char* p) {
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | uint8_t(p[i]);
  return v;
}

// Calls visit(record) for every logical record of `bytes` whose physical records pass their
// checksums; returns the number of damaged or incomplete records skipped.
size_t ReadLogRecords(std::string_view bytes,
                      const std::function<void(const std::string&)>& visit) {
  size_t skipped = 0;
  std::string record;
  bool in_record = false;
  size_t pos = 0;
  while (pos < bytes.size()) {
    const size_t block_left = kBlockSize - pos % kBlockSize;
    if (block_left < kHeaderSize || bytes.size() - pos < kHeaderSize) {
      pos += block_left;  // padding
      continue;
    }
    const char* header = bytes.data() + pos;
    const size_t length = uint8_t(header[4]) | size_t(uint8_t(header[5])) << 8;
    const uint8_t type = uint8_t(header[6]);
    const bool recyclable = type >= kRecyclableFull && type <= kRecyclableLast;
    const size_t header_size = recyclable ? kRecyclableHeaderSize : kHeaderSize;
    if (type == 0 && length == 0) {  // preallocated zeros: the end of what was written
      pos += block_left;
      continue;
    }
    const bool fits =
        header_size + length <= block_left && pos + header_size + length <= bytes.size();
    if (!fits || Unmask(Fixed32(header)) !=
                     Crc32c(0, std::string_view(header + 6, header_size - 6 + length))) {
      // Damaged: the rest of the block cannot be trusted, and neither can a record in progress.
      skipped += in_record ? 1 : 0;
      in_record = false;
      ++skipped;
      pos += block_left;
      continue;
    }
    const std::string_view payload(header + header_size, length);
    pos += header_size + length;
    switch (recyclable ? type - (kRecyclableFull - kFull) : type) {
      case kFull:
        skipped += in_record ? 1 : 0;
        in_record = false;
        visit(std::string(payload));
        break;
      case kFirst:
        skipped += in_record ? 1 : 0;
        record.assign(payload);
        in_record = true;
        break;
      case kMiddle:
        if (in_record) record.append(payload);
        break;
      case kLast:
        if (in_record) {
          record.append(payload);
          visit(record);
        } else {
          ++skipped;  // its start was in damaged bytes
        }
        in_record = false;
        break;
      default:
        break;  // metadata records (compression type, timestamp sizes): no writes
    }
  }
  return skipped + (in_record ? 1 : 0);
}

// The changes one write batch makes to an inventory, collected before any is applied so that a
// batch that does not decode changes nothing. The store writes nothing else into the column
// families watched here.
class BatchChanges final : public rocksdb::WriteBatch::Handler {
 public:
  BatchChanges(const TablesOnly& tables, uint64_t log_number)
      : tables_(tables),
        log_number_(log_number),
        catalog_(tables.IdOf(kCatalogFamily)),
        entry_meta_(tables.IdOf(kEntryMetaFamily)),
        blobs_(tables.IdOf(kBlobFamily)) {}

  rocksdb::Status PutCF(uint32_t family, const rocksdb::Slice& key,
                        const rocksdb::Slice& value) override {
    if (!tables_.NeedsLog(family, log_number_)) return rocksdb::Status::OK();
    const std::string_view k(key.data(), key.size());
    if (family == catalog_ && k.size() > 1 && k[0] == kMapInfoTag) {
      MapInfo info;
      if (DecodeMapInfo(k.substr(1), std::string_view(value.data(), value.size()), &info).ok()) {
        changes_.push_back([id = info.id, name = info.config.name](StoreInventory* inventory) {
          inventory->map_names[id] = name;
          inventory->entries[id];
        });
      }
    } else if (MapId map = 0, id = 0; family == entry_meta_ && DecodeEntryKey(k, &map, &id)) {
      changes_.push_back(
          [map, id](StoreInventory* inventory) { inventory->entries[map].insert(id); });
    } else if (family == blobs_) {
      changes_.push_back(
          [key = std::string(k)](StoreInventory* inventory) { inventory->blob_keys.insert(key); });
    }
    return rocksdb::Status::OK();
  }
  rocksdb::Status DeleteCF(uint32_t family, const rocksdb::Slice& key) override {
    if (!tables_.NeedsLog(family, log_number_)) return rocksdb::Status::OK();
    const std::string_view k(key.data(), key.size());
    if (family == catalog_ && k.size() > 1 && k[0] == kMapInfoTag) {
      changes_.push_back([name = std::string(k.substr(1))](StoreInventory* inventory) {
        std::erase_if(inventory->map_names, [&](const auto& map) {
          if (map.second != name) return false;
          inventory->entries.erase(map.first);
          return true;
        });
      });
    } else if (MapId map = 0, id = 0; family == entry_meta_ && DecodeEntryKey(k, &map, &id)) {
      changes_.push_back(
          [map, id](StoreInventory* inventory) { inventory->entries[map].erase(id); });
    } else if (family == blobs_) {
      changes_.push_back(
          [key = std::string(k)](StoreInventory* inventory) { inventory->blob_keys.erase(key); });
    }
    return rocksdb::Status::OK();
  }
  rocksdb::Status DeleteRangeCF(uint32_t family, const rocksdb::Slice& begin,
                                const rocksdb::Slice& /*end*/) override {
    // DeleteMap's range: every entry of one map.
    MapId map = 0;
    EntryId first = 0;
    if (tables_.NeedsLog(family, log_number_) && family == entry_meta_ &&
        DecodeEntryKey(std::string_view(begin.data(), begin.size()), &map, &first)) {
      changes_.push_back([map](StoreInventory* inventory) { inventory->entries[map].clear(); });
    }
    return rocksdb::Status::OK();
  }

  void ApplyTo(StoreInventory* inventory) const {
    for (const auto& change : changes_) change(inventory);
  }

 private:
  const TablesOnly& tables_;
  const uint64_t log_number_;
  const uint32_t catalog_, entry_meta_, blobs_;
  std::vector<std::function<void(StoreInventory*)>> changes_;
};

}  // namespace

void TablesOnly::ColumnFamilyLogNumberMap(const std::map<uint32_t, uint64_t>& log_numbers,
                                          const std::map<std::string, uint32_t>& ids_by_name) {
  log_numbers_ = log_numbers;
  ids_by_name_ = ids_by_name;
}

rocksdb::WalFilter::WalProcessingOption TablesOnly::LogRecordFound(
    unsigned long long /*log_number*/, const std::string& /*log_file_name*/,
    const rocksdb::WriteBatch& /*batch*/, rocksdb::WriteBatch* /*new_batch*/,
    bool* /*batch_changed*/) {
  return WalProcessingOption::kIgnoreCurrentRecord;
}

uint32_t TablesOnly::IdOf(const std::string& name) const {
  const auto found = ids_by_name_.find(name);
  return found != ids_by_name_.end() ? found->second : UINT32_MAX;
}

bool TablesOnly::NeedsLog(uint32_t id, uint64_t log_number) const {
  const auto found = log_numbers_.find(id);
  return found == log_numbers_.end() || log_number >= found->second;
}

size_t ApplyReadableLog(const std::string& dir, const TablesOnly& tables,
                        StoreInventory* inventory) {
  std::map<uint64_t, fs::path> logs;  // by log number: the order they were written in
  std::error_code ec;
  for (const fs::directory_entry& file : fs::directory_iterator(dir, ec)) {
    const std::string name = file.path().filename().string();
    if (file.path().extension() != ".log" || name.size() <= 4) continue;
    const std::string digits = name.substr(0, name.size() - 4);
    if (digits.find_first_not_of("0123456789") == std::string::npos) {
      logs[std::stoull(digits)] = file.path();
    }
  }
  size_t skipped = 0;
  for (const auto& [log_number, path] : logs) {
    std::ifstream in(path, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    skipped += ReadLogRecords(bytes, [&, number = log_number](const std::string& record) {
      BatchChanges changes(tables, number);
      if (rocksdb::WriteBatch(record).Iterate(&changes).ok()) {
        changes.ApplyTo(inventory);
      } else {
        ++skipped;
      }
    });
  }
  return skipped;
}

void CompareInventories(const StoreInventory& before, const StoreInventory& after,
                        StoreRecovery* recovery) {
  static const std::set<EntryId> kNone;
  for (const auto& [map, ids] : before.entries) {
    const auto kept = after.entries.find(map);
    const bool map_lost = !after.map_names.contains(map);
    const std::set<EntryId>& now = kept != after.entries.end() ? kept->second : kNone;
    StoreRecovery::MapLoss loss;
    loss.name = before.NameOf(map);
    loss.entries_before = ids.size();
    loss.entries_after = map_lost ? 0 : now.size();
    loss.map_lost = map_lost;
    for (EntryId id : ids) {
      if (map_lost || !now.contains(id)) loss.missing.push_back(id);
    }
    if (loss.map_lost || !loss.missing.empty()) recovery->maps.push_back(std::move(loss));
  }
  for (const std::string& key : before.blob_keys) {
    if (!after.blob_keys.contains(key)) recovery->blobs_lost.push_back(key);
  }
}

}  // namespace storage
}  // namespace recog
