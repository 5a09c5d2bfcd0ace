#include "tools/bag/rosbag2_metadata.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <system_error>

namespace recog::bag {
namespace {

std::string Uppercase(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(),
                 [](unsigned char c) { return char(std::toupper(c)); });
  return text;
}

// The `key` of a map node as text; "" when absent or null.
std::string TextField(const YAML::Node& node, const char* key) {
  const YAML::Node field = node[key];
  return field && !field.IsNull() ? field.as<std::string>() : std::string();
}

StatusOr<Rosbag2Compression> CompressionOf(const YAML::Node& info, std::string_view where) {
  if (!info["compression_mode"]) return Rosbag2Compression::kUnknown;
  const std::string mode = Uppercase(TextField(info, "compression_mode"));
  const std::string format = TextField(info, "compression_format");
  if (mode.empty() || mode == "NONE") return Rosbag2Compression::kNone;
  if (mode != "FILE" && mode != "MESSAGE") {
    return Status::InvalidArgument(std::string(where) + ": unknown compression_mode " +
                                   Quoted(mode) + " (FILE, MESSAGE or none are rosbag2's)");
  }
  if (format != "zstd") {
    return Status::InvalidArgument(std::string(where) + ": unsupported compression_format " +
                                   Quoted(format) + " (only zstd is read)");
  }
  return mode == "FILE" ? Rosbag2Compression::kFile : Rosbag2Compression::kMessage;
}

StatusOr<Rosbag2Metadata> MetadataFromYaml(const YAML::Node& root, std::string_view where) {
  const YAML::Node info = root.IsMap() && root["rosbag2_bagfile_information"]
                              ? root["rosbag2_bagfile_information"]
                              : root;
  if (!info.IsMap() || !info["version"]) {
    return Status::InvalidArgument(
        std::string(where) + ": not rosbag2 metadata (no rosbag2_bagfile_information version)");
  }
  Rosbag2Metadata metadata;
  metadata.version = info["version"].as<int>();
  if (metadata.version < 1) {
    return Status::InvalidArgument(std::string(where) + ": metadata version " +
                                   std::to_string(metadata.version) + " (rosbag2's start at 1)");
  }
  metadata.storage_identifier = TextField(info, "storage_identifier");
  if (metadata.storage_identifier != "sqlite3" && metadata.storage_identifier != "mcap") {
    return Status::InvalidArgument(std::string(where) + ": unsupported storage_identifier " +
                                   Quoted(metadata.storage_identifier) +
                                   " (sqlite3 and mcap are read)");
  }
  RECOG_ASSIGN_OR_RETURN(metadata.compression, CompressionOf(info, where));

  // relative_file_paths in every version; `files` (version 5 on) repeats them with statistics.
  if (const YAML::Node paths = info["relative_file_paths"]; paths && paths.IsSequence()) {
    for (const YAML::Node& path : paths) metadata.file_paths.push_back(path.as<std::string>());
  } else if (const YAML::Node files = info["files"]; files && files.IsSequence()) {
    for (const YAML::Node& file : files) metadata.file_paths.push_back(TextField(file, "path"));
  }
  for (const std::string& path : metadata.file_paths) {
    if (path.empty()) {
      return Status::InvalidArgument(std::string(where) + ": a file path is empty");
    }
  }

  if (const YAML::Node topics = info["topics_with_message_count"]; topics) {
    if (!topics.IsSequence()) {
      return Status::InvalidArgument(std::string(where) +
                                     ": topics_with_message_count is not a list");
    }
    for (const YAML::Node& entry : topics) {
      // Version 1 says topic_and_type, later versions topic_metadata.
      const YAML::Node topic =
          entry["topic_metadata"] ? entry["topic_metadata"] : entry["topic_and_type"];
      if (!topic || !topic.IsMap() || TextField(topic, "name").empty()) {
        return Status::InvalidArgument(std::string(where) +
                                       ": a topics_with_message_count entry names no topic");
      }
      metadata.topics.push_back(
          {.name = TextField(topic, "name"),
           .type = TextField(topic, "type"),
           .serialization_format = TextField(topic, "serialization_format"),
           .message_count = entry["message_count"] ? entry["message_count"].as<uint64_t>() : 0});
    }
  }
  return metadata;
}

}  // namespace

std::string Quoted(std::string_view text) {
  std::string quoted = "'";
  quoted.append(text);
  quoted += '\'';
  return quoted;
}

bool StartsWithZstdMagic(std::string_view bytes) {
  return bytes.size() >= 4 && bytes.substr(0, 4) == std::string_view("\x28\xB5\x2F\xFD", 4);
}

StatusOr<Rosbag2Metadata> ParseRosbag2Metadata(const std::string& yaml, std::string_view where) {
  // yaml-cpp reports bad documents and bad conversions by throwing; none may leave this function.
  try {
    return MetadataFromYaml(YAML::Load(yaml), where);
  } catch (const YAML::ParserException& error) {
    return Status::DataLoss(std::string(where) + ": damaged, not YAML: " + error.what());
  } catch (const std::exception& error) {
    return Status::InvalidArgument(std::string(where) +
                                   ": not valid rosbag2 metadata: " + error.what());
  }
}

StatusOr<Rosbag2Metadata> ReadRosbag2Metadata(const std::string& path) {
  std::error_code error;
  const uint64_t size = std::filesystem::file_size(path, error);
  if (error) return Status::NotFound("rosbag2 metadata " + Quoted(path) + " not found");
  if (size > kMaxRosbag2MetadataBytes) {
    return Status::ResourceExhausted("rosbag2 metadata " + Quoted(path) + " has " +
                                     std::to_string(size) + " bytes, more than the " +
                                     std::to_string(kMaxRosbag2MetadataBytes) + " read");
  }
  std::ifstream file(path, std::ios::binary);
  std::string text(size_t(size), '\0');
  if (!file.read(text.data(), std::streamsize(size))) {
    return Status::DataLoss("rosbag2 metadata " + Quoted(path) + " could not be read whole");
  }
  return ParseRosbag2Metadata(text, Quoted(path));
}

}  // namespace recog::bag
