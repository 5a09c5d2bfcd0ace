// Version records. The blob of one version is
//
//   format u8 (1) | header size u32 | header | the model file (the rest)
//   header: name, object_class (u32 length + bytes each), type u8, dimensions 3 x f64, units,
//           source, version u32, tags t u32 + t strings, sha256, size_bytes u64,
//           created_unix_ms i64, num_points u32, num_descriptors u32
//
// little-endian. The decoder checks every length, that the header fills exactly its size, that
// the file has size_bytes bytes and that the name and version agree with the blob's key; any
// mismatch is DATA_LOSS naming the key.
#include "core/object/repository/model_repository.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <chrono>
#include <climits>
#include <cstring>
#include <type_traits>

#include <spdlog/spdlog.h>

#include "core/common/byte_codec.h"
#include "core/common/names.h"
#include "core/common/text.h"
#include "core/object/formats/model_file.h"

namespace recog {
namespace {

static_assert(std::endian::native == std::endian::little,
              "model_repository writes little-endian values with memcpy");

constexpr char kKeyPrefix[] = "model/";
constexpr size_t kVersionDigits = 10;  // UINT32_MAX has 10 digits
constexpr uint8_t kRecordFormat = 1;
constexpr char kPageTokenPrefix[] = "after:";

std::string VersionKey(const std::string& name, uint32_t version) {
  std::string digits = std::to_string(version);
  return kKeyPrefix + name + "/" + std::string(kVersionDigits - digits.size(), '0') + digits;
}

// Splits "model/<name>/<10 digits>"; false when `key` is not such a key.
bool ParseVersionKey(std::string_view key, std::string* name, uint32_t* version) {
  if (!key.starts_with(kKeyPrefix)) return false;
  key.remove_prefix(std::strlen(kKeyPrefix));
  const size_t slash = key.rfind('/');
  if (slash == std::string_view::npos || key.size() - slash - 1 != kVersionDigits) return false;
  *name = std::string(key.substr(0, slash));
  const std::string_view digits = key.substr(slash + 1);
  if (!std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; })) {
    return false;
  }
  const std::from_chars_result parsed =
      std::from_chars(digits.data(), digits.data() + digits.size(), *version);
  return parsed.ec == std::errc() && *version > 0 && ValidateName("object", *name).ok();
}

int64_t NowUnixMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// Checks the tags given at upload, then sorts them and drops duplicates.
Status NormaliseTags(std::vector<std::string>* tags) {
  if (tags->size() > ModelRepository::kMaxTags) {
    return Status::InvalidArgument("a model may have at most " +
                                   std::to_string(ModelRepository::kMaxTags) + " tags, not " +
                                   std::to_string(tags->size()));
  }
  for (const std::string& tag : *tags) {
    if (tag.empty() || tag.size() > ModelRepository::kMaxTagBytes) {
      return Status::InvalidArgument("tags must have 1 to " +
                                     std::to_string(ModelRepository::kMaxTagBytes) +
                                     " bytes, not " + std::to_string(tag.size()));
    }
    for (char c : tag) {
      if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {
        return Status::InvalidArgument("tag '" + EscapeForLog(tag) + "' has a control character");
      }
    }
    if (!IsValidUtf8(tag)) {
      return Status::InvalidArgument("tag '" + EscapeForLog(tag) + "' is not UTF-8 text");
    }
  }
  std::sort(tags->begin(), tags->end());
  tags->erase(std::unique(tags->begin(), tags->end()), tags->end());
  return Status::Ok();
}

bool Matches(const ModelFilter& filter, const ModelVersionInfo& info) {
  return info.metadata.name.starts_with(filter.name_prefix) &&
         (filter.object_class.empty() || info.metadata.object_class == filter.object_class) &&
         (filter.tag.empty() || std::binary_search(info.tags.begin(), info.tags.end(), filter.tag));
}

std::string EncodeVersionRecord(const ModelVersionInfo& info, std::string_view file) {
  ByteWriter header;
  const ObjectMetadata& meta = info.metadata;
  header.PutString(meta.name);
  header.PutString(meta.object_class);
  header.Put<uint8_t>(uint8_t(meta.type));
  for (int i = 0; i < 3; ++i) header.Put<double>(meta.dimensions[i]);
  header.PutString(meta.units);
  header.PutString(meta.source);
  header.Put<uint32_t>(meta.version);
  header.Put<uint32_t>(uint32_t(info.tags.size()));
  for (const std::string& tag : info.tags) header.PutString(tag);
  header.PutString(info.sha256);
  header.Put<uint64_t>(info.size_bytes);
  header.Put<int64_t>(info.created_unix_ms);
  header.Put<uint32_t>(info.num_points);
  header.Put<uint32_t>(info.num_descriptors);

  ByteWriter record;
  record.Put<uint8_t>(kRecordFormat);
  record.Put<uint32_t>(uint32_t(header.bytes().size()));
  record.bytes().reserve(record.bytes().size() + header.bytes().size() + file.size());
  record.bytes() += header.bytes();
  record.bytes() += file;
  return std::move(record.bytes());
}

// Decodes the record stored under `key` (model `name`, version `version`) into *info and, when
// `file` is not null, the model file into *file.
Status DecodeVersionRecord(std::string_view value, const std::string& key, const std::string& name,
                           uint32_t version, ModelVersionInfo* info, std::string* file) {
  const std::string where = "stored model version '" + key + "'";
  ByteReader record(value);
  const uint8_t format = record.Get<uint8_t>();
  if (record.ok() && format != kRecordFormat) {
    return Status::DataLoss(where + " has unknown format " + std::to_string(format));
  }
  ByteReader header(record.GetBytes(record.Get<uint32_t>()));
  if (!record.ok()) return Status::DataLoss(where + " is truncated");

  ModelVersionInfo decoded;
  ObjectMetadata& meta = decoded.metadata;
  meta.name = header.GetString();
  meta.object_class = header.GetString();
  const uint8_t type = header.Get<uint8_t>();
  for (int i = 0; i < 3; ++i) meta.dimensions[i] = header.Get<double>();
  meta.units = header.GetString();
  meta.source = header.GetString();
  meta.version = header.Get<uint32_t>();
  const uint32_t num_tags = header.Get<uint32_t>();
  if (num_tags > ModelRepository::kMaxTags) {
    return Status::DataLoss(where + " has " + std::to_string(num_tags) + " tags");
  }
  for (uint32_t i = 0; i < num_tags && header.ok(); ++i) decoded.tags.push_back(header.GetString());
  decoded.sha256 = header.GetString();
  decoded.size_bytes = header.Get<uint64_t>();
  decoded.created_unix_ms = header.Get<int64_t>();
  decoded.num_points = header.Get<uint32_t>();
  decoded.num_descriptors = header.Get<uint32_t>();
  if (!header.ok()) return Status::DataLoss(where + " has a truncated header");
  if (header.left() != 0) {
    return Status::DataLoss(where + " has " + std::to_string(header.left()) +
                            " unexpected bytes after its header");
  }
  if (type > uint8_t(ObjectType::k3D)) {
    return Status::DataLoss(where + " has unknown object type " + std::to_string(type));
  }
  meta.type = ObjectType(type);
  if (meta.name != name || meta.version != version) {
    return Status::DataLoss(where + " holds version " + std::to_string(meta.version) +
                            " of model '" + meta.name + "'");
  }
  if (decoded.size_bytes != record.left()) {
    return Status::DataLoss(where + " should hold a " + std::to_string(decoded.size_bytes) +
                            "-byte model file, not " + std::to_string(record.left()) + " bytes");
  }
  if (file != nullptr) *file = std::string(record.GetBytes(record.left()));
  *info = std::move(decoded);
  return Status::Ok();
}

}  // namespace

ModelRepository::ModelRepository(IndexStore* store, std::shared_ptr<ObjectDatabase> objects,
                                 HashFunction sha256_hex)
    : store_(store), objects_(std::move(objects)), sha256_hex_(std::move(sha256_hex)) {}

StatusOr<std::unique_ptr<ModelRepository>> ModelRepository::Open(
    IndexStore* store, std::shared_ptr<ObjectDatabase> objects, HashFunction sha256_hex) {
  if (store == nullptr || objects == nullptr || !sha256_hex) {
    return Status::InvalidArgument(
        "a model repository needs a store, an object database and a hash function");
  }
  std::unique_ptr<ModelRepository> repository(
      new ModelRepository(store, std::move(objects), std::move(sha256_hex)));
  RECOG_RETURN_IF_ERROR(repository->Reconcile());
  return repository;
}

Status ModelRepository::Reconcile() {
  // The stored versions of each name, oldest first (the zero-padded versions sort numerically).
  RECOG_ASSIGN_OR_RETURN(const std::vector<std::string> keys, store_->ListBlobKeys(kKeyPrefix));
  std::map<std::string, std::vector<std::pair<uint32_t, std::string>>> stored;
  for (const std::string& key : keys) {
    std::string name;
    uint32_t version = 0;
    if (!ParseVersionKey(key, &name, &version)) {
      return Status::DataLoss("the model repository has a blob with a malformed key '" + key + "'");
    }
    stored[name].emplace_back(version, key);
  }
  std::map<std::string, uint32_t> current;  // the database's version of each object
  for (const ObjectMetadata& metadata : objects_->List()) current[metadata.name] = metadata.version;

  std::unique_lock lock(catalog_mutex_);
  for (const auto& [name, versions] : stored) {
    const auto object = current.find(name);
    const uint32_t latest = object == current.end() ? 0 : object->second;
    for (const auto& [version, key] : versions) {
      if (version > latest) {
        // An interrupted Put (the database never got this version) or Remove.
        spdlog::warn(
            "model repository: deleting version {} of '{}', absent from the object database",
            version, name);
        RECOG_RETURN_IF_ERROR(store_->DeleteBlob(key));
        continue;
      }
      RECOG_ASSIGN_OR_RETURN(const std::string value, store_->GetBlob(key));
      ModelVersionInfo info;
      RECOG_RETURN_IF_ERROR(DecodeVersionRecord(value, key, name, version, &info, nullptr));
      catalog_[name].push_back(std::move(info));
    }
  }
  for (const auto& [name, version] : current) {
    const auto known = catalog_.find(name);
    if (known != catalog_.end() && known->second.back().metadata.version == version) continue;
    // Put into the object database without the repository: record its current version.
    spdlog::info("model repository: recording version {} of model '{}' from the object database",
                 version, name);
    RECOG_ASSIGN_OR_RETURN(const ObjectModel model, objects_->Get(name));
    RECOG_ASSIGN_OR_RETURN(const std::string file, EncodeObjectModel(model));
    ModelVersionInfo info = Describe(model, file, {});
    RECOG_RETURN_IF_ERROR(
        store_->PutBlob(VersionKey(name, version), EncodeVersionRecord(info, file)));
    catalog_[name].push_back(std::move(info));
  }
  return Status::Ok();
}

ModelVersionInfo ModelRepository::Describe(const ObjectModel& model, std::string_view file,
                                           std::vector<std::string> tags) const {
  ModelVersionInfo info;
  info.metadata = model.metadata;
  info.tags = std::move(tags);
  info.sha256 = sha256_hex_(file);
  info.size_bytes = file.size();
  info.created_unix_ms = NowUnixMs();
  info.num_points = uint32_t(model.points.size());
  info.num_descriptors = uint32_t(model.num_features());
  return info;
}

StatusOr<ObjectModel> ModelRepository::DecodeForDatabase(std::string_view model_file,
                                                         const std::string& name) const {
  StatusOr<ObjectModel> decoded = DecodeObjectModel(model_file, "uploaded model file");
  if (decoded.status().code() == StatusCode::kDataLoss) {
    // Damaged input, not damaged storage.
    return Status::InvalidArgument(decoded.status().message());
  }
  RECOG_RETURN_IF_ERROR(decoded.status());
  ObjectModel model = std::move(*decoded);
  if (!name.empty()) {
    RECOG_RETURN_IF_ERROR(ValidateName("object", name));
    model.metadata.name = name;
  }
  const DescriptorFormat& format = objects_->index().info().config.descriptor;
  if (!(model.descriptor == format)) {
    return Status::InvalidArgument("model '" + model.metadata.name + "' has " +
                                   model.descriptor.ToString() +
                                   " descriptors, the object database " + format.ToString());
  }
  if (model.num_features() == 0) {
    return Status::InvalidArgument("model '" + model.metadata.name + "' has no features");
  }
  return model;
}

uint32_t ModelRepository::LatestVersion(const std::string& name) const {
  std::shared_lock lock(catalog_mutex_);
  const auto known = catalog_.find(name);
  return known == catalog_.end() ? 0 : known->second.back().metadata.version;
}

StatusOr<ModelVersionInfo> ModelRepository::Put(std::string_view model_file,
                                                const std::string& name,
                                                std::vector<std::string> tags) {
  RECOG_RETURN_IF_ERROR(NormaliseTags(&tags));
  RECOG_ASSIGN_OR_RETURN(ObjectModel model, DecodeForDatabase(model_file, name));

  std::lock_guard write_lock(write_mutex_);
  const uint32_t latest = LatestVersion(model.metadata.name);
  if (latest == UINT32_MAX) {
    return Status::ResourceExhausted("model '" + model.metadata.name + "' has no versions left");
  }
  model.metadata.version = latest + 1;
  RECOG_ASSIGN_OR_RETURN(const std::string file, EncodeObjectModel(model));
  const ModelVersionInfo info = Describe(model, file, std::move(tags));
  RECOG_RETURN_IF_ERROR(StoreLocked(model, file, info));
  return info;
}

StatusOr<ModelVersionInfo> ModelRepository::PutCopy(const ModelVersionInfo& info,
                                                    std::string_view stored_file) {
  const std::string& name = info.metadata.name;
  const uint32_t version = info.metadata.version;
  std::vector<std::string> tags = info.tags;
  RECOG_RETURN_IF_ERROR(NormaliseTags(&tags));
  RECOG_ASSIGN_OR_RETURN(const ObjectModel model, DecodeForDatabase(stored_file, ""));
  if (model.metadata.name != name || model.metadata.version != version) {
    return Status::InvalidArgument(
        "the file holds version " + std::to_string(model.metadata.version) + " of model '" +
        model.metadata.name + "', not version " + std::to_string(version) + " of '" + name + "'");
  }
  ModelVersionInfo copy = Describe(model, stored_file, std::move(tags));
  if (copy.size_bytes != info.size_bytes || copy.sha256 != info.sha256) {
    return Status::InvalidArgument("the file of version " + std::to_string(version) +
                                   " of model '" + name +
                                   "' differs from its description (size or SHA-256)");
  }
  copy.created_unix_ms = info.created_unix_ms;

  std::lock_guard write_lock(write_mutex_);
  const uint32_t latest = LatestVersion(name);
  if (latest >= version) {
    return Status::FailedPrecondition("model '" + name + "' already has version " +
                                      std::to_string(latest) + "; a copy of version " +
                                      std::to_string(version) + " must be newer");
  }
  RECOG_RETURN_IF_ERROR(StoreLocked(model, stored_file, copy));
  return copy;
}

Status ModelRepository::StoreLocked(const ObjectModel& model, std::string_view file,
                                    const ModelVersionInfo& info) {
  const std::string key = VersionKey(info.metadata.name, info.metadata.version);
  RECOG_RETURN_IF_ERROR(store_->PutBlob(key, EncodeVersionRecord(info, file)));

  const StatusOr<ObjectMetadata> indexed = objects_->Put(model);
  if (!indexed.ok()) {
    const Status deleted = store_->DeleteBlob(key);
    if (!deleted.ok()) {
      spdlog::warn("model repository: cannot delete '{}' after a failed put ({}); Open will", key,
                   deleted.ToString());
    }
    return indexed.status();
  }
  if (indexed->version != info.metadata.version) {
    return Status::Internal("the object database gave model '" + info.metadata.name + "' version " +
                            std::to_string(indexed->version) + " instead of " +
                            std::to_string(info.metadata.version) +
                            ": is something else writing it?");
  }
  {
    std::unique_lock lock(catalog_mutex_);
    catalog_[info.metadata.name].push_back(info);
  }
  Notify(ModelEvent::Kind::kPut, info);
  return Status::Ok();
}

StatusOr<std::pair<ModelVersionInfo, std::string>> ModelRepository::Get(const std::string& name,
                                                                        uint32_t version) const {
  {
    std::shared_lock lock(catalog_mutex_);
    const auto known = catalog_.find(name);
    if (known == catalog_.end()) return Status::NotFound("there is no model '" + name + "'");
    const std::vector<ModelVersionInfo>& versions = known->second;
    if (version == 0) version = versions.back().metadata.version;
    const bool found = std::any_of(versions.begin(), versions.end(), [version](const auto& info) {
      return info.metadata.version == version;
    });
    if (!found) {
      return Status::NotFound("model '" + name + "' has no version " + std::to_string(version));
    }
  }
  // Read outside the lock: a Remove meanwhile makes the blob NOT_FOUND.
  const std::string key = VersionKey(name, version);
  StatusOr<std::string> value = store_->GetBlob(key);
  if (value.status().code() == StatusCode::kNotFound) {
    return Status::NotFound("model '" + name + "' has no version " + std::to_string(version));
  }
  RECOG_RETURN_IF_ERROR(value.status());
  std::pair<ModelVersionInfo, std::string> out;
  RECOG_RETURN_IF_ERROR(DecodeVersionRecord(*value, key, name, version, &out.first, &out.second));
  return out;
}

std::vector<ModelVersionInfo> ModelRepository::Versions(const std::string& name) const {
  std::shared_lock lock(catalog_mutex_);
  const auto known = catalog_.find(name);
  return known == catalog_.end() ? std::vector<ModelVersionInfo>() : known->second;
}

StatusOr<ModelPage> ModelRepository::List(const ModelFilter& filter, size_t page_size,
                                          const std::string& page_token) const {
  if (page_size == 0) page_size = kDefaultPageSize;
  page_size = std::min(page_size, kMaxPageSize);
  std::string after;  // the last name of the previous page
  if (!page_token.empty()) {
    after = page_token.substr(std::min(page_token.size(), std::strlen(kPageTokenPrefix)));
    if (!page_token.starts_with(kPageTokenPrefix) || !ValidateName("object", after).ok()) {
      return Status::InvalidArgument("'" + page_token + "' is not a page token of this listing");
    }
  }
  ModelPage page;
  std::shared_lock lock(catalog_mutex_);
  // The names with the prefix are contiguous: start at the first of them after `after`.
  auto it = catalog_.lower_bound(std::max(filter.name_prefix, after));
  if (it != catalog_.end() && !after.empty() && it->first == after) ++it;
  for (; it != catalog_.end() && it->first.starts_with(filter.name_prefix); ++it) {
    const ModelVersionInfo& latest = it->second.back();
    if (!Matches(filter, latest)) continue;
    if (page.models.size() == page_size) {
      page.next_page_token = kPageTokenPrefix + page.models.back().metadata.name;
      break;
    }
    page.models.push_back(latest);
  }
  return page;
}

Status ModelRepository::Remove(const std::string& name) {
  std::lock_guard write_lock(write_mutex_);
  std::vector<ModelVersionInfo> versions;
  {
    std::shared_lock lock(catalog_mutex_);
    const auto known = catalog_.find(name);
    if (known == catalog_.end()) return Status::NotFound("there is no model '" + name + "'");
    versions = known->second;
  }
  const Status removed = objects_->Remove(name);
  // NOT_FOUND: something removed the object from the database directly; its versions still go.
  if (!removed.ok() && removed.code() != StatusCode::kNotFound) return removed;
  {
    std::unique_lock lock(catalog_mutex_);
    catalog_.erase(name);
  }
  Status deleted;
  for (const ModelVersionInfo& info : versions) {
    const Status s = store_->DeleteBlob(VersionKey(name, info.metadata.version));
    if (!s.ok() && s.code() != StatusCode::kNotFound && deleted.ok()) deleted = s;
  }
  Notify(ModelEvent::Kind::kDelete, versions.back());
  if (!deleted.ok()) {
    return deleted.WithContext("model '" + name +
                               "' is removed, but some of its stored versions stay until the "
                               "next open");
  }
  return Status::Ok();
}

void ModelRepository::Notify(ModelEvent::Kind kind, const ModelVersionInfo& info) {
  ModelEvent event;
  event.kind = kind;
  event.info = info;
  event.sequence = next_sequence_++;
  std::lock_guard lock(listeners_mutex_);
  for (const auto& [id, listener] : listeners_) listener(event);
}

uint64_t ModelRepository::Watch(std::function<void(const ModelEvent&)> listener,
                                std::vector<ModelVersionInfo>* existing) {
  // Put, PutCopy and Remove notify under write_mutex_: holding it keeps the catalog and the
  // registration together.
  std::unique_lock<std::mutex> write_lock;
  if (existing != nullptr) {
    write_lock = std::unique_lock(write_mutex_);
    existing->clear();
    std::shared_lock catalog_lock(catalog_mutex_);
    for (const auto& [name, versions] : catalog_) {
      existing->insert(existing->end(), versions.begin(), versions.end());
    }
  }
  std::lock_guard lock(listeners_mutex_);
  const uint64_t id = next_listener_id_++;
  listeners_.emplace(id, std::move(listener));
  return id;
}

void ModelRepository::Unwatch(uint64_t id) {
  std::lock_guard lock(listeners_mutex_);
  listeners_.erase(id);
}

}  // namespace recog
