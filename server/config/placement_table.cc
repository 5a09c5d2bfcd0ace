#include "server/config/placement_table.h"

#include <sstream>
#include <vector>

#include "core/common/file_io.h"
#include "core/common/names.h"
#include "core/index/entry.h"

namespace recog::server {

bool PlacementTable::IsShardName(const std::string& name) {
  if (name.empty() || name.size() > 64) return false;
  for (char c : name) {
    const bool ok =
        (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_';
    if (!ok) return false;
  }
  return true;
}

StatusOr<PlacementTable> PlacementTable::Load(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(const std::string text,
                         ReadWholeFile(path, "the placement table '" + path + "'"));
  return Parse(text, path);
}

StatusOr<PlacementTable> PlacementTable::Parse(const std::string& text, const std::string& source) {
  PlacementTable table;
  std::istringstream lines(text);
  std::string line;
  for (int number = 1; std::getline(lines, line); ++number) {
    const auto bad = [&](const std::string& why) {
      return Status::InvalidArgument(source + ":" + std::to_string(number) + ": " + why);
    };
    if (const size_t hash = line.find('#'); hash != std::string::npos) line.erase(hash);
    std::istringstream words(line);
    std::vector<std::string> tokens;
    for (std::string token; words >> token;) tokens.push_back(token);
    if (tokens.empty()) continue;
    // "map shard;" or "map shard ;"
    if (tokens.size() == 3 && tokens[2] == ";") {
      tokens.pop_back();
      tokens.back() += ';';
    }
    if (tokens.size() != 2 || tokens[1].size() < 2 || tokens[1].back() != ';') {
      return bad("expected '<map> <shard>;'");
    }
    const std::string& key = tokens[0];
    const std::string shard = tokens[1].substr(0, tokens[1].size() - 1);
    if (key == "default" || key == "hostnames" || key == "include" || key == "volatile") {
      return bad("'" + key + "' is an nginx map keyword: list every map explicitly");
    }
    const bool group = key.starts_with(kGroupPrefix);
    const std::string name = group ? key.substr(std::string_view(kGroupPrefix).size()) : key;
    const char* kind = group ? "group" : "map";
    if (Status valid = ValidateName(kind, name); !valid.ok()) return bad(valid.message());
    if (!IsShardName(shard)) {
      return bad("shard name '" + shard + "' must have 1 to 64 characters of [A-Za-z0-9_]");
    }
    if (!(group ? table.group_owners_ : table.owners_).emplace(name, shard).second) {
      return bad(std::string(kind) + " '" + name + "' is listed twice");
    }
  }
  return table;
}

std::optional<std::string> PlacementTable::OwnerOf(const std::string& map) const {
  const auto it = owners_.find(map);
  if (it == owners_.end()) return std::nullopt;
  return it->second;
}

std::optional<std::string> PlacementTable::OwnerOfGroup(const std::string& group) const {
  const auto it = group_owners_.find(group);
  if (it == group_owners_.end()) return std::nullopt;
  return it->second;
}

}  // namespace recog::server
