// ModelRepository: the shared repository of object models (RoboEarth-style, thesis §5.4.3).
//
// Robots upload model files (.robj, model_file.h); every upload becomes a new, immutable version
// of the model of that name (1, 2, ...), and the latest version of each model is the one the
// ObjectDatabase recognises. Every version stays downloadable until the model is removed.
//
// Storage. Each version is one blob of the IndexStore the ObjectDatabase uses, keyed
// "model/<name>/<version, 10 zero-padded digits>" (names never contain '/'); its value is a small
// header (the ModelVersionInfo) followed by the model file as stored: the upload re-encoded with
// its final name and version, so that a downloaded file's metadata says what it is. `sha256` and
// `size_bytes` describe those stored bytes; the caller checks the checksum of what it received
// before calling Put (core links no cryptography: the hash function is given to Open).
//
// Crash safety. Put writes the version blob first, then the ObjectDatabase; Remove removes the
// object first, then the blobs. Open reconciles the two: it deletes the blobs of versions above
// the database's version of a name, or of names the database does not have (an interrupted Put
// or Remove), and records a version for an object the database has without a blob of its current
// version (one put into the ObjectDatabase directly, e.g. by older code; it gets no tags). Open
// reads every stored version once, to build the in-memory catalog that Versions and List serve.
//
// Thread safety: every method may be called from any thread; Put and Remove are serialised, the
// readers run in parallel with each other and with a writer's store writes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/common/status.h"
#include "core/index/index_store.h"
#include "core/object/model/object_model.h"
#include "core/object/recognition/object_database.h"

namespace recog {

// One stored version of a model.
struct ModelVersionInfo {
  ObjectMetadata metadata;  // of this version; metadata.version is its number (1, 2, ...)
  // Labels given at upload: sorted, distinct, each 1..64 bytes (ModelRepository::kMaxTagBytes)
  // without control characters.
  std::vector<std::string> tags;
  std::string sha256;            // Open's hash function of the stored file (lowercase hex)
  uint64_t size_bytes = 0;       // of the stored file
  int64_t created_unix_ms = 0;   // when this version was stored
  uint32_t num_points = 0;       // 3D points of the model
  uint32_t num_descriptors = 0;  // features (descriptor rows) of the model
  friend bool operator==(const ModelVersionInfo&, const ModelVersionInfo&) = default;
};

// Which models List returns; an empty field matches every model.
struct ModelFilter {
  std::string name_prefix;   // the name starts with it
  std::string object_class;  // metadata.object_class equals it
  std::string tag;           // one of the tags equals it
};

// One page of List: the latest version of each matching model, by name.
struct ModelPage {
  std::vector<ModelVersionInfo> models;
  std::string next_page_token;  // pass to List for the next page; empty on the last page
};

// A change of the repository, as told to the watchers.
struct ModelEvent {
  enum class Kind {
    kPut,     // `info` is the version just stored
    kDelete,  // the model was removed; `info` is what was its latest version
  };
  Kind kind = Kind::kPut;
  ModelVersionInfo info;
  uint64_t sequence = 0;  // 1, 2, ... in the order of the changes since Open
};

class ModelRepository {
 public:
  // Hashes a stored model file: lowercase hex SHA-256 (the server passes an OpenSSL one).
  using HashFunction = std::function<std::string(std::string_view)>;

  static constexpr size_t kMaxTags = 32;
  static constexpr size_t kMaxTagBytes = 64;
  static constexpr size_t kDefaultPageSize = 100;
  static constexpr size_t kMaxPageSize = 1000;

  // Opens the repository kept in `store`, which must be the store `objects` was opened on, and
  // reconciles it with `objects` (see the header comment). INVALID_ARGUMENT when an argument is
  // null; DATA_LOSS when a stored version or its key is damaged (or of an unknown format); the
  // store's errors.
  static StatusOr<std::unique_ptr<ModelRepository>> Open(IndexStore* store,
                                                         std::shared_ptr<ObjectDatabase> objects,
                                                         HashFunction sha256_hex);

  // Stores the model file `model_file` as the next version of its model (1 for a new name) and
  // makes it the one recognised. A non-empty `name` renames the model. `tags` are stored sorted
  // and without duplicates. INVALID_ARGUMENT when the bytes are not a valid model file, for a bad
  // name or tag, more than kMaxTags tags, a model without features or with other descriptors than
  // the database's, or a file too large for a blob; FAILED_PRECONDITION for a file of a newer
  // format. Nothing is stored when it fails (what a failing store leaves, Open deletes). The
  // caller checks the checksum of the bytes it received before calling: `sha256` of the result
  // is that of the stored, re-encoded file.
  StatusOr<ModelVersionInfo> Put(std::string_view model_file, const std::string& name,
                                 std::vector<std::string> tags);
  // Stores a version exactly as another repository stored it: `stored_file` is the file that
  // repository's Get returned with `info`. A replica following its primary uses it to keep the
  // primary's names, version numbers, tags, creation times and bytes. The version must be newer
  // than every version held of that model (a replica copies versions oldest first).
  // INVALID_ARGUMENT when the file is not a valid model file for the database, holds another name
  // or version than `info`, or has another size or SHA-256; FAILED_PRECONDITION when the model
  // already has this version or a newer one. Watchers are told as for Put.
  StatusOr<ModelVersionInfo> PutCopy(const ModelVersionInfo& info, std::string_view stored_file);
  // Version `version` of model `name` (0: the latest) and its file bytes exactly as stored.
  // NOT_FOUND for an unknown name or version; DATA_LOSS when the stored version is damaged.
  StatusOr<std::pair<ModelVersionInfo, std::string>> Get(const std::string& name,
                                                         uint32_t version) const;
  // Every version of model `name`, oldest first; empty when there is no such model.
  std::vector<ModelVersionInfo> Versions(const std::string& name) const;
  // The latest versions of the models that match `filter`, by name, `page_size` at a time (0:
  // kDefaultPageSize; larger than kMaxPageSize: kMaxPageSize). `page_token` is "" for the first
  // page, else the next_page_token of the previous page; it stays valid while models change.
  // INVALID_ARGUMENT for a token List did not make.
  StatusOr<ModelPage> List(const ModelFilter& filter, size_t page_size,
                           const std::string& page_token) const;
  // Removes every version of model `name`; the object stops being recognised. NOT_FOUND when
  // there is no such model. When the object is removed but some versions cannot be deleted, the
  // store's error says so (the model is gone; Open deletes what is left).
  Status Remove(const std::string& name);

  // Calls `listener` for every Put, PutCopy and Remove that succeeds, synchronously, once the
  // change is durable, in the order of the changes and never concurrently with itself. Listeners
  // must be quick and must not call the repository. When `existing` is not null it receives every
  // version stored when the listener is registered (by name, oldest first), so that no change
  // falls between the two nor is told twice. Returns the id that Unwatch takes.
  uint64_t Watch(std::function<void(const ModelEvent&)> listener,
                 std::vector<ModelVersionInfo>* existing = nullptr);
  // Stops calling a listener: once Unwatch has returned it is not called again. Unknown ids are
  // ignored.
  void Unwatch(uint64_t id);

 private:
  ModelRepository(IndexStore* store, std::shared_ptr<ObjectDatabase> objects,
                  HashFunction sha256_hex);
  // Brings the blobs in line with the ObjectDatabase and loads the catalog; called by Open.
  Status Reconcile();
  // Decodes a model file given to Put or PutCopy and checks that the database can index it
  // (after renaming it to `name` unless empty).
  StatusOr<ObjectModel> DecodeForDatabase(std::string_view model_file,
                                          const std::string& name) const;
  // The catalog entry of a model file (computes the hash of `file`).
  ModelVersionInfo Describe(const ObjectModel& model, std::string_view file,
                            std::vector<std::string> tags) const;
  // The latest version of model `name`, 0 when there is none.
  uint32_t LatestVersion(const std::string& name) const;
  // Stores `file`, the encoding of `model`, as the version `info` describes: the blob, then the
  // ObjectDatabase, then the catalog and the watchers. Requires write_mutex_.
  Status StoreLocked(const ObjectModel& model, std::string_view file, const ModelVersionInfo& info);
  // Tells every listener about a change; requires write_mutex_.
  void Notify(ModelEvent::Kind kind, const ModelVersionInfo& info);

  IndexStore* const store_;
  const std::shared_ptr<ObjectDatabase> objects_;
  const HashFunction sha256_hex_;

  std::mutex write_mutex_;  // serialises Put and Remove
  mutable std::shared_mutex catalog_mutex_;
  // Every version of every model, by name, oldest first; guarded by catalog_mutex_ and only
  // changed under write_mutex_ too.
  std::map<std::string, std::vector<ModelVersionInfo>> catalog_;
  uint64_t next_sequence_ = 1;  // guarded by write_mutex_

  // Held while listeners run, so that Unwatch waits for a running notification.
  std::mutex listeners_mutex_;
  std::map<uint64_t, std::function<void(const ModelEvent&)>> listeners_;
  uint64_t next_listener_id_ = 1;  // guarded by listeners_mutex_
};

}  // namespace recog
