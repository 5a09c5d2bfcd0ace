// PlacementTable: which shard owns each place map, when maps are sharded across several recogd
// servers behind nginx (deploy/nginx/, docs/scaling.md).
//
// The table is one text file that nginx and the servers both read: it is the body of an nginx
// `map` block (nginx includes it to route a call by its `x-recog-map` header to the shard's
// upstream), one entry per line, `<map name> <shard name>;`, with `#` comments and blank lines:
//
//   # map            shard
//   hall-robot-1     shard_a;
//   yard-robot-2     shard_b;
//
// A line `group:<group> <shard>;` places a map group (MapSettings.group): every map of the group
// must be created on that shard (the servers refuse it elsewhere), so a query that searches the
// group finds all of its maps on the one server it reaches; nginx routes a call naming only a
// group (the clients send `x-recog-map: group:<group>`) to that shard.
//
// Map and group names follow recogd's name rule; shard names are nginx upstream names
// ([A-Za-z0-9_], 1 to 64 characters). nginx's special map keys (default, hostnames, include,
// volatile) and regular expressions are refused: every map is listed explicitly, and a map that
// is not listed has no owner (nginx and the servers refuse it). A server started with a shard
// name serves only the maps the table gives it (recogd: shard.name, shard.placement_file; SIGHUP
// reloads the file).
#pragma once

#include <map>
#include <optional>
#include <string>

#include "core/common/status.h"

namespace recog::server {

class PlacementTable {
 public:
  // NOT_FOUND when the file is missing or cannot be opened, DATA_LOSS when it cannot be read in
  // full; INVALID_ARGUMENT naming the line of the first bad entry (syntax, name, duplicate map).
  static StatusOr<PlacementTable> Load(const std::string& path);
  static StatusOr<PlacementTable> Parse(const std::string& text, const std::string& source);

  // The shard that owns `map`; nullopt when the table does not list it.
  std::optional<std::string> OwnerOf(const std::string& map) const;
  // The shard that holds every map of `group`; nullopt when the table does not place it.
  std::optional<std::string> OwnerOfGroup(const std::string& group) const;
  size_t size() const { return owners_.size(); }  // maps listed
  size_t groups() const { return group_owners_.size(); }

  static constexpr char kGroupPrefix[] = "group:";

  // Whether `name` may name a shard.
  static bool IsShardName(const std::string& name);

 private:
  std::map<std::string, std::string> owners_;        // map -> shard
  std::map<std::string, std::string> group_owners_;  // group -> shard
};

}  // namespace recog::server
