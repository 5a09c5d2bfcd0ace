// TokenAuthenticator: bearer-token authentication with per-token rights.
//
// Each client (a robot, an operator's tool) sends `authorization: Bearer <token>` with every call.
// The tokens, each with a name for the logs and its rights, come from a YAML file:
//
//   tokens:
//     - name: robot-7          # shown in logs, never the secret
//       token: "s3cret..."     # at least 16 visible ASCII characters, unique in the file
//       rights: [read]         # read and/or write
//
// `read` allows queries, recognition, listing and downloading; `write` allows all of that and
// also creating and deleting maps, adding and streaming frames, uploading and deleting models
// (write implies read). Names are unique in the file (they are what the logs show: rotate a
// robot's token as `robot-7` and `robot-7-next`), and so are tokens.
//
// An entry may scope its rights on place maps (a fleet: each robot writes its own maps and reads
// its group's; an operator's entry has no `maps` and reaches every map):
//
//     - name: robot-7
//       token: "..."
//       rights: [write]
//       maps:
//         write: ["robot-7*"]       # map names, name prefixes ending in '*', or group:NAME
//         read: ["group:fleet"]     # read also holds where write does
//
// With `maps`, the token reaches only the maps its patterns cover (MapScope); the server checks
// every map a call names, the maps a query searches included (CheckMap: PERMISSION_DENIED naming
// the map), and ListMaps lists only the readable ones. Its rights on the object repository are its
// `rights`, unscoped. The admin calls (Checkpoint, Verify, StoreStatus) read or copy every map at
// once, so they need a token without `maps` besides the right (CheckEveryMap).
//
// Only the SHA-256 digests of the tokens are kept, and a presented token is found by looking up
// its digest, so the time Authenticate takes says nothing useful about the secrets. Error
// messages and Caller never contain a token.
//
// Reload() re-reads the file (recogd: SIGHUP): calls authenticated after it use the new tokens, so
// an added token works and a removed one is refused from then on; a file that does not load
// leaves the tokens in use. Copies of an authenticator share their tokens, so a reload through
// one copy is seen by all (the server keeps one to reload while the RPC handlers authenticate
// through theirs). Every method is safe to call from any number of threads.
#pragma once

#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "core/common/status.h"

namespace recog::server {

// What a caller may do.
enum class Right {
  kRead,   // queries, recognition, listing and downloading
  kWrite,  // creating/deleting maps, adding/streaming frames, uploading/deleting models
};
std::string_view RightName(Right right);  // "read", "write"

// The place maps a right holds for: every map, or those a list of patterns covers. A pattern is
// a map name ("robot-7"), a name prefix ending in '*' ("robot-7*"), or "group:NAME" (every map
// created in that group).
class MapScope {
 public:
  // Every map (the default).
  MapScope() = default;
  // The maps `patterns` cover (none for an empty list). INVALID_ARGUMENT naming a pattern that is
  // empty, has a '*' elsewhere than at its end, or is "group:" without a name.
  static StatusOr<MapScope> Of(const std::vector<std::string>& patterns);

  bool Covers(std::string_view map, std::string_view group) const;
  // True for the default scope (every map, present and future).
  bool covers_every_map() const { return every_map_; }
  // Also covers what `other` covers.
  void Include(const MapScope& other);

 private:
  bool every_map_ = true;
  std::vector<std::string> names_, prefixes_, groups_;
};

// An authenticated caller.
struct Caller {
  std::string name;  // the token's name from the file, or "anonymous" with AllowAll
  // Who the caller is for what must not be shared between tokens (the request log's answers):
  // the SHA-256 digest of its token, or "anonymous" with AllowAll.
  std::string identity = {};
  bool can_read = false;        // holds Right::kRead
  bool can_write = false;       // holds Right::kWrite
  MapScope readable_maps = {};  // where can_read holds for place maps (every map by default)
  MapScope writable_maps = {};  // where can_write holds for place maps
};

class TokenAuthenticator {
 public:
  // Reads the token file at `path`. NOT_FOUND when it is missing; INVALID_ARGUMENT naming the
  // entry (its number and line) for a missing or empty name, a name used twice or holding other
  // than printable ASCII, a token shorter than
  // kMinTokenLength or with characters other than visible ASCII, a token used twice, an unknown
  // or missing right, an unknown key, a bad `maps` (not read/write lists of valid patterns, or
  // write patterns without the write right), a file without tokens, or malformed YAML.
  static StatusOr<TokenAuthenticator> Load(const std::string& path);

  // No authentication: every call, with or without a header, is made by "anonymous" with both
  // rights. For servers configured without a token file.
  static TokenAuthenticator AllowAll();

  // The caller that `authorization_header` (the value of the `authorization` metadata, e.g.
  // "Bearer s3cret...", empty when absent) proves to be. UNAUTHENTICATED when the header is
  // missing, is not a bearer token, or the token is unknown.
  StatusOr<Caller> Authenticate(std::string_view authorization_header) const;

  // Re-reads the file given to Load, with Load's errors; on error the tokens in use are kept. OK
  // and nothing done for AllowAll().
  Status Reload();

  // OK when `caller` holds `right`, else PERMISSION_DENIED naming the caller and the right.
  static Status Check(const Caller& caller, Right right);
  // Check, then that the right holds for the place map `map` of group `group` ("" for none):
  // else PERMISSION_DENIED naming the caller, the right and the map.
  static Status CheckMap(const Caller& caller, Right right, std::string_view map,
                         std::string_view group);
  // Check, then that the caller reads (and, for kWrite, writes) every map, as a token without
  // `maps` does: what the admin calls need. Else PERMISSION_DENIED naming the caller and `what`
  // ("Checkpoint").
  static Status CheckEveryMap(const Caller& caller, Right right, std::string_view what);

  // True for AllowAll().
  bool allows_all() const { return shared_ == nullptr; }

  static constexpr size_t kMinTokenLength = 16;

 private:
  using Callers = std::unordered_map<std::string, Caller>;  // by the SHA-256 digest of the token
  // The token file and its tokens, shared by the copies of an authenticator.
  struct Shared {
    std::string path;
    mutable std::mutex mutex;
    std::shared_ptr<const Callers> callers;  // replaced whole by Reload, under `mutex`
  };

  TokenAuthenticator() = default;
  static StatusOr<std::shared_ptr<const Callers>> Read(const std::string& path);

  std::shared_ptr<Shared> shared_;  // null for AllowAll()
};

}  // namespace recog::server
