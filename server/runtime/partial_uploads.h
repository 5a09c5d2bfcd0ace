// PartialUploads: what the server remembers of model uploads so that a client whose upload broke
// off can resume it instead of sending the whole file again.
//
// An upload is identified by the SHA-256 and size of its file, as its header announces them, so
// a client that still holds the file can resume it from another connection (or another process).
// Two things are remembered per upload, each for `keep_for` after it happened (and at most
// kMaxEntries uploads, the oldest forgotten first):
//  - the bytes received before the call broke off (the client cancelled, the connection was lost,
//    the deadline passed). A resumed upload takes them out and continues them; at most `max_bytes`
//    of them are kept in all, the oldest dropped first.
//  - that the upload completed and which model version it created, so that a client that lost the
//    answer learns that the file is stored instead of uploading it twice.
// Memory only: a restarted server has forgotten every partial upload (clients start over).
// Thread-safe. Times are passed in (steady clock) so that expiry can be tested.
#pragma once

#include <chrono>
#include <compare>
#include <cstddef>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <string>

namespace recog::server {

class PartialUploads {
 public:
  using Clock = std::chrono::steady_clock;
  static constexpr size_t kMaxEntries = 4096;

  struct Key {
    std::string sha256;  // lowercase hex of the whole file
    uint64_t size_bytes = 0;
    auto operator<=>(const Key&) const = default;
  };
  // The model version a completed upload created.
  struct Stored {
    std::string name;
    uint32_t version = 0;
  };
  // What the server holds of an upload.
  struct Progress {
    uint64_t received_bytes = 0;   // kept bytes of an interrupted upload (0 = none)
    std::optional<Stored> stored;  // set when the upload completed (received_bytes = 0 then)
  };

  PartialUploads(uint64_t max_bytes, Clock::duration keep_for);

  // Keeps `bytes`, the first bytes of the file of upload `key`, after its call broke off
  // (replacing what was kept of it). Ignored when empty, not shorter than the file, or longer
  // than max_bytes.
  void KeepInterrupted(const Key& key, std::string bytes, Clock::time_point now = Clock::now());
  // Takes out the kept bytes of `key`, for a call that continues them; nullopt when none.
  std::optional<std::string> TakeInterrupted(const Key& key, Clock::time_point now = Clock::now());
  // Records that the upload `key` completed and created `stored`.
  void RecordStored(const Key& key, Stored stored, Clock::time_point now = Clock::now());
  Progress ProgressOf(const Key& key, Clock::time_point now = Clock::now());

  // Bytes kept in all (for metrics and tests).
  uint64_t kept_bytes() const;

 private:
  struct Entry {
    std::string bytes;
    std::optional<Stored> stored;
    Clock::time_point at;
  };
  // Forgets the entries older than keep_for_.
  void ExpireLocked(Clock::time_point now);
  // Expires, then forgets the oldest entries until one more entry with `bytes` fits.
  void MakeRoomLocked(Clock::time_point now, uint64_t bytes);

  const uint64_t max_bytes_;
  const Clock::duration keep_for_;
  mutable std::mutex mutex_;
  std::map<Key, Entry> entries_;
  uint64_t kept_bytes_ = 0;
};

}  // namespace recog::server
