#include "tools/bag/bag_store.h"

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>

namespace recog::bag {
namespace {

namespace fs = std::filesystem;

std::string Quoted(const std::string& text) { return "'" + text + "'"; }

// The first bytes of each kind of file a bag may be.
constexpr std::string_view kRos1Magic = "#ROSBAG V";
constexpr std::string_view kMcapMagic = "\x89MCAP";
constexpr std::string_view kSqliteMagic = "SQLite format 3";
constexpr std::string_view kZstdMagic = "\x28\xb5\x2f\xfd";

// "starts with 12 34 56 ...": what a file that is no bag starts with, for its error.
std::string StartText(const std::string& start) {
  if (start.empty()) return "is empty";
  std::string text = "starts with";
  for (const char c : start.substr(0, 8)) {
    char hex[4];
    std::snprintf(hex, sizeof(hex), " %02x", unsigned(static_cast<unsigned char>(c)));
    text += hex;
  }
  return text;
}

}  // namespace

bool IsMessageType(std::string_view type, std::string_view package, std::string_view name) {
  if (type.size() <= package.size() + 1 || type.substr(0, package.size()) != package ||
      type[package.size()] != '/') {
    return false;
  }
  std::string_view rest = type.substr(package.size() + 1);
  if (rest.substr(0, 4) == "msg/") rest.remove_prefix(4);
  return rest == name;
}

StatusOr<std::unique_ptr<BagStore>> OpenBag(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return Status::NotFound("bag " + Quoted(path) + " does not exist");
  if (fs::is_directory(path, ec)) return OpenRosbag2Folder(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::NotFound("bag " + Quoted(path) + " cannot be read");
  std::string start(16, '\0');
  in.read(start.data(), std::streamsize(start.size()));
  start.resize(size_t(in.gcount()));
  if (start.starts_with(kRos1Magic)) return OpenRos1Bag(path);
  if (start.starts_with(kMcapMagic)) return OpenMcapFile(path);
  if (start.starts_with(kSqliteMagic)) return OpenSqlite3File(path);
  if (start.starts_with(kZstdMagic)) {
    return Status::InvalidArgument(
        Quoted(path) +
        " is a zstd-compressed file (a rosbag2 bag compressed per file?): give "
        "its folder, whose metadata.yaml says how to read it");
  }
  return Status::InvalidArgument(Quoted(path) + " is not a bag: it " + StartText(start) +
                                 " (a ROS 1 bag starts with #ROSBAG V2.0, an MCAP file with "
                                 "\\x89MCAP, a rosbag2 sqlite3 file with \"SQLite format 3\")");
}

}  // namespace recog::bag
