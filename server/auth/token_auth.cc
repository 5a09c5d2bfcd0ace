#include "server/auth/token_auth.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <utility>

#include "core/common/file_io.h"
#include "core/common/text.h"
#include "wire/sha256.h"

namespace recog::server {
namespace {

constexpr std::string_view kAnonymous = "anonymous";
constexpr size_t kMaxNameBytes = 64;

bool IsVisibleAscii(std::string_view text) {
  return std::all_of(text.begin(), text.end(), [](char c) { return c > ' ' && c < 0x7f; });
}

std::string_view TrimSpaces(std::string_view text) {
  const size_t first = text.find_first_not_of(" \t");
  if (first == std::string_view::npos) return {};
  const size_t last = text.find_last_not_of(" \t");
  return text.substr(first, last - first + 1);
}

bool EqualsIgnoringCase(std::string_view a, std::string_view b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) ==
                  std::tolower(static_cast<unsigned char>(y));
         });
}

// "entry 2 (line 5)": where an entry of the token file is, for errors.
std::string EntryName(size_t index, const YAML::Node& entry) {
  std::string name = "entry " + std::to_string(index + 1);
  if (entry.Mark().line >= 0) name += " (line " + std::to_string(entry.Mark().line + 1) + ")";
  return name;
}

// Reads an entry's `maps` ({read: [...], write: [...]}) into the caller's map scopes: the
// writable maps are those of `write` (none without it), the readable ones those of `read` and
// `write`.
Status ReadMapScopes(const YAML::Node& maps, const std::string& named, Caller* caller) {
  if (!maps.IsMap()) {
    return Status::InvalidArgument(named + ": maps must be a mapping of read and write lists");
  }
  std::vector<std::string> patterns[2];  // read, write
  for (const auto& item : maps) {
    const std::string key = item.first.IsScalar() ? item.first.Scalar() : "";
    const bool write = key == RightName(Right::kWrite);
    if (!write && key != RightName(Right::kRead)) {
      return Status::InvalidArgument(named + ": maps has an unknown key '" + key +
                                     "' (read, write)");
    }
    if (!item.second.IsSequence()) {
      return Status::InvalidArgument(named + ": maps." + key + " must be a list of patterns");
    }
    for (const YAML::Node& pattern : item.second) {
      if (!pattern.IsScalar()) {
        return Status::InvalidArgument(named + ": maps." + key + " holds a non-text pattern");
      }
      patterns[write].push_back(pattern.Scalar());
    }
  }
  if (!patterns[1].empty() && !caller->can_write) {
    return Status::InvalidArgument(named + ": maps.write needs the write right");
  }
  StatusOr<MapScope> readable = MapScope::Of(patterns[0]);
  StatusOr<MapScope> writable = MapScope::Of(patterns[1]);
  if (!readable.ok()) return readable.status().WithContext(named + ": maps.read");
  if (!writable.ok()) return writable.status().WithContext(named + ": maps.write");
  caller->writable_maps = std::move(writable).value();
  caller->readable_maps = std::move(readable).value();
  caller->readable_maps.Include(caller->writable_maps);
  return Status::Ok();
}

// Reads one entry of the `tokens` list into *caller and *token.
Status ReadEntry(const YAML::Node& entry, const std::string& where, Caller* caller,
                 std::string* token) {
  if (!entry.IsMap()) return Status::InvalidArgument(where + " must be a mapping");
  for (const auto& item : entry) {
    const std::string key = item.first.IsScalar() ? item.first.Scalar() : "";
    if (key != "name" && key != "token" && key != "rights" && key != "maps") {
      return Status::InvalidArgument(where + " has an unknown key '" + key +
                                     "' (name, token, rights, maps)");
    }
  }
  const YAML::Node name = entry["name"];
  if (!name.IsDefined() || !name.IsScalar() || name.Scalar().empty()) {
    return Status::InvalidArgument(where + " needs a non-empty name");
  }
  caller->name = name.Scalar();
  if (caller->name.size() > kMaxNameBytes || !IsPrintableAscii(caller->name)) {
    return Status::InvalidArgument(where + ": the name must be 1 to " +
                                   std::to_string(kMaxNameBytes) +
                                   " printable ASCII characters (it is written in the logs)");
  }
  const std::string named = where + " ('" + caller->name + "')";

  const YAML::Node secret = entry["token"];
  if (!secret.IsDefined() || !secret.IsScalar())
    return Status::InvalidArgument(named + " needs a token");
  *token = secret.Scalar();
  if (token->size() < TokenAuthenticator::kMinTokenLength) {
    return Status::InvalidArgument(named + ": the token must be at least " +
                                   std::to_string(TokenAuthenticator::kMinTokenLength) +
                                   " characters long");
  }
  if (!IsVisibleAscii(*token)) {
    return Status::InvalidArgument(named +
                                   ": the token may only hold visible ASCII characters (no "
                                   "spaces)");
  }

  const YAML::Node rights = entry["rights"];
  if (!rights.IsDefined() || !rights.IsSequence() || rights.size() == 0) {
    return Status::InvalidArgument(named + " needs a list of rights, e.g. [read] or [write]");
  }
  for (const YAML::Node& right : rights) {
    const std::string text = right.IsScalar() ? right.Scalar() : "";
    if (text == RightName(Right::kRead)) {
      caller->can_read = true;
    } else if (text == RightName(Right::kWrite)) {
      caller->can_read = true;  // write implies read
      caller->can_write = true;
    } else {
      return Status::InvalidArgument(named + " has an unknown right '" + text +
                                     "' (read or write)");
    }
  }
  const YAML::Node maps = entry["maps"];
  return maps.IsDefined() ? ReadMapScopes(maps, named, caller) : Status::Ok();
}

}  // namespace

StatusOr<MapScope> MapScope::Of(const std::vector<std::string>& patterns) {
  constexpr std::string_view kGroup = "group:";
  MapScope scope;
  scope.every_map_ = false;
  for (const std::string& pattern : patterns) {
    const size_t star = pattern.find('*');
    if (pattern.empty() || pattern == kGroup ||
        (star != std::string::npos && star + 1 != pattern.size())) {
      return Status::InvalidArgument("bad pattern '" + pattern +
                                     "' (a map name, a name prefix ending in '*', or group:NAME)");
    }
    if (pattern.starts_with(kGroup)) {
      scope.groups_.push_back(pattern.substr(kGroup.size()));
    } else if (star != std::string::npos) {
      scope.prefixes_.push_back(pattern.substr(0, star));
    } else {
      scope.names_.push_back(pattern);
    }
  }
  return scope;
}

bool MapScope::Covers(std::string_view map, std::string_view group) const {
  const auto any = [](const std::vector<std::string>& list, auto matches) {
    return std::any_of(list.begin(), list.end(), matches);
  };
  return every_map_ || any(names_, [&](const std::string& n) { return n == map; }) ||
         any(prefixes_, [&](const std::string& p) { return map.starts_with(p); }) ||
         (!group.empty() && any(groups_, [&](const std::string& g) { return g == group; }));
}

void MapScope::Include(const MapScope& other) {
  every_map_ = every_map_ || other.every_map_;
  names_.insert(names_.end(), other.names_.begin(), other.names_.end());
  prefixes_.insert(prefixes_.end(), other.prefixes_.begin(), other.prefixes_.end());
  groups_.insert(groups_.end(), other.groups_.begin(), other.groups_.end());
}

std::string_view RightName(Right right) {
  switch (right) {
    case Right::kRead:
      return "read";
    case Right::kWrite:
      return "write";
  }
  return "unknown";
}

StatusOr<TokenAuthenticator> TokenAuthenticator::Load(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<const Callers> callers, Read(path));
  TokenAuthenticator authenticator;
  authenticator.shared_ = std::make_shared<Shared>();
  authenticator.shared_->path = path;
  authenticator.shared_->callers = std::move(callers);
  return authenticator;
}

Status TokenAuthenticator::Reload() {
  if (shared_ == nullptr) return Status::Ok();
  RECOG_ASSIGN_OR_RETURN(std::shared_ptr<const Callers> callers, Read(shared_->path));
  std::lock_guard lock(shared_->mutex);
  shared_->callers = std::move(callers);
  return Status::Ok();
}

StatusOr<std::shared_ptr<const TokenAuthenticator::Callers>> TokenAuthenticator::Read(
    const std::string& path) {
  const std::string what = "token file '" + path + "'";
  RECOG_ASSIGN_OR_RETURN(const std::string text, ReadWholeFile(path, what));
  auto callers = std::make_shared<Callers>();
  // For the errors of duplicates: the entry of each token (by digest) and of each name.
  std::unordered_map<std::string, std::string> entry_of_digest, entry_of_name;
  try {
    const YAML::Node root = YAML::Load(text);
    if (!root.IsMap()) {
      return Status::InvalidArgument(what + " must be a mapping with a 'tokens' list");
    }
    for (const auto& item : root) {
      if (!item.first.IsScalar() || item.first.Scalar() != "tokens") {
        return Status::InvalidArgument(
            what + " has an unknown key '" +
            (item.first.IsScalar() ? item.first.Scalar() : std::string()) + "' (only 'tokens')");
      }
    }
    const YAML::Node tokens = root["tokens"];
    if (!tokens.IsDefined() || !tokens.IsSequence() || tokens.size() == 0) {
      return Status::InvalidArgument(
          what + " has no tokens (to turn authentication off, configure no token file)");
    }
    for (size_t i = 0; i < tokens.size(); ++i) {
      const YAML::Node entry = tokens[i];
      const std::string where = EntryName(i, entry);
      Caller caller;
      std::string token;
      const Status status = ReadEntry(entry, where, &caller, &token);
      if (!status.ok()) return status.WithContext(what, StatusCode::kInvalidArgument);
      std::string digest = Sha256Hex(token);
      const std::string named = where + " ('" + caller.name + "')";
      auto [it, inserted] = entry_of_digest.emplace(digest, named);
      if (!inserted) {
        return Status::InvalidArgument(what + ": " + named + " has the same token as " +
                                       it->second);
      }
      auto [same_name, name_inserted] = entry_of_name.emplace(caller.name, named);
      if (!name_inserted) {
        return Status::InvalidArgument(what + ": " + named + " has the same name as " +
                                       same_name->second + " (names tell tokens apart in logs)");
      }
      caller.identity = digest;
      callers->emplace(std::move(digest), std::move(caller));
    }
  } catch (const YAML::Exception& e) {
    return Status::InvalidArgument(what + " is not valid YAML: " + e.what());
  }
  return std::shared_ptr<const Callers>(std::move(callers));
}

TokenAuthenticator TokenAuthenticator::AllowAll() { return TokenAuthenticator(); }

StatusOr<Caller> TokenAuthenticator::Authenticate(std::string_view authorization_header) const {
  if (shared_ == nullptr)
    return Caller{.name = std::string(kAnonymous),
                  .identity = std::string(kAnonymous),
                  .can_read = true,
                  .can_write = true};
  const std::string_view header = TrimSpaces(authorization_header);
  if (header.empty()) {
    return Status::Unauthenticated("missing authorization header (expected 'Bearer <token>')");
  }
  const size_t space = header.find_first_of(" \t");
  const std::string_view scheme = header.substr(0, space);
  const std::string_view token =
      space == std::string_view::npos ? std::string_view() : TrimSpaces(header.substr(space));
  if (!EqualsIgnoringCase(scheme, "bearer") || token.empty() ||
      token.find_first_of(" \t") != std::string_view::npos) {
    return Status::Unauthenticated("malformed authorization header (expected 'Bearer <token>')");
  }
  const std::string digest = Sha256Hex(token);
  std::shared_ptr<const Callers> callers;
  {
    std::lock_guard lock(shared_->mutex);
    callers = shared_->callers;
  }
  const auto it = callers->find(digest);
  if (it == callers->end()) return Status::Unauthenticated("unknown token");
  return it->second;
}

Status TokenAuthenticator::Check(const Caller& caller, Right right) {
  const bool allowed = right == Right::kRead ? caller.can_read : caller.can_write;
  if (allowed) return Status::Ok();
  return Status::PermissionDenied("'" + caller.name + "' does not have the " +
                                  std::string(RightName(right)) + " right");
}

Status TokenAuthenticator::CheckMap(const Caller& caller, Right right, std::string_view map,
                                    std::string_view group) {
  RECOG_RETURN_IF_ERROR(Check(caller, right));
  const MapScope& scope = right == Right::kRead ? caller.readable_maps : caller.writable_maps;
  if (scope.Covers(map, group)) return Status::Ok();
  return Status::PermissionDenied("'" + caller.name + "' may not " + std::string(RightName(right)) +
                                  " map '" + std::string(map) + "'");
}

Status TokenAuthenticator::CheckEveryMap(const Caller& caller, Right right, std::string_view what) {
  RECOG_RETURN_IF_ERROR(Check(caller, right));
  const bool everywhere = caller.readable_maps.covers_every_map() &&
                          (right == Right::kRead || caller.writable_maps.covers_every_map());
  if (everywhere) return Status::Ok();
  return Status::PermissionDenied("'" + caller.name +
                                  "' reaches only some maps: " + std::string(what) +
                                  " reads every map of the server and needs a token without maps");
}

}  // namespace recog::server
