#include "tools/evaluation/dataset_layouts.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <utility>

#include "tools/common/cli_support.h"

namespace recog::cli {
namespace {

namespace fs = std::filesystem;

// One data line of a list file: its number (1-based, for messages) and its text.
struct ListLine {
  int number = 0;
  std::string text;
};

// 'path' (GCC 12 warns, wrongly, about "'" + path.string()).
std::string Quoted(const fs::path& path) {
  std::string quoted = "'";
  quoted += path.string();
  quoted += "'";
  return quoted;
}

// 'list' line N, for messages.
std::string Where(const fs::path& list, const ListLine& line) {
  return Quoted(list) + " line " + std::to_string(line.number);
}

// The non-empty, non-comment lines of `path` (trailing '\r' and blanks dropped). NOT_FOUND when
// the file does not exist.
StatusOr<std::vector<ListLine>> ReadListLines(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) {
    return Status::NotFound(Quoted(path) + " does not exist");
  }
  std::ifstream in(path);
  if (!in) return Status::NotFound("cannot open " + Quoted(path));
  std::vector<ListLine> lines;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    while (!line.empty() && std::isspace(uint8_t(line.back()))) line.pop_back();
    const size_t start = line.find_first_not_of(" \t");
    if (start == std::string::npos || line[start] == '#') continue;
    lines.push_back(ListLine{number, line.substr(start)});
  }
  return lines;
}

Status Malformed(const fs::path& file, const ListLine& line, const std::string& expected) {
  return Status::InvalidArgument(Where(file, line) + ": expected " + expected + ", got '" +
                                 line.text + "'");
}

// Parses a time in seconds: finite and not negative.
bool ParseSeconds(const std::string& text, double* seconds) {
  auto parsed = ParseNumbers("time", text);
  if (!parsed.ok() || parsed->size() != 1 || (*parsed)[0] < 0) return false;
  *seconds = (*parsed)[0];
  return true;
}

bool ParseNanoseconds(std::string_view text, int64_t* ns) {
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), *ns);
  return error == std::errc() && end == text.data() + text.size() && *ns >= 0;
}

Status CheckExists(const fs::path& file, const fs::path& list, const ListLine& line) {
  std::error_code ec;
  if (fs::is_regular_file(file, ec)) return Status::Ok();
  return Status::NotFound(Quoted(file) + ", listed in " + Where(list, line) + ", does not exist");
}

Status CheckIncreasing(double previous, double timestamp, const fs::path& list,
                       const ListLine& line) {
  if (timestamp > previous) return Status::Ok();
  return Status::InvalidArgument(Where(list, line) +
                                 ": timestamps must increase, but this one does not follow the "
                                 "previous line's");
}

// A TUM list file ("timestamp path" lines): (timestamp, absolute path) in order.
StatusOr<std::vector<std::pair<double, std::string>>> ReadTumList(const fs::path& dir,
                                                                  const std::string& name) {
  const fs::path list = dir / name;
  RECOG_ASSIGN_OR_RETURN(const std::vector<ListLine> lines, ReadListLines(list));
  std::vector<std::pair<double, std::string>> entries;
  for (const ListLine& line : lines) {
    std::istringstream fields(line.text);
    std::string time, path, extra;
    double timestamp = 0;
    if (!(fields >> time >> path) || (fields >> extra) || !ParseSeconds(time, &timestamp)) {
      return Malformed(list, line, "'timestamp path'");
    }
    if (!entries.empty()) {
      RECOG_RETURN_IF_ERROR(CheckIncreasing(entries.back().first, timestamp, list, line));
    }
    const fs::path file = dir / path;
    RECOG_RETURN_IF_ERROR(CheckExists(file, list, line));
    entries.emplace_back(timestamp, file.string());
  }
  return entries;
}

StatusOr<std::vector<DatasetFrame>> ReadTum(const fs::path& dir) {
  RECOG_ASSIGN_OR_RETURN(const auto rgb, ReadTumList(dir, "rgb.txt"));
  std::vector<std::pair<double, std::string>> depth;
  std::error_code ec;
  if (fs::exists(dir / "depth.txt", ec)) {
    RECOG_ASSIGN_OR_RETURN(depth, ReadTumList(dir, "depth.txt"));
  }
  std::vector<DatasetFrame> frames;
  for (const auto& [timestamp, image] : rgb) {
    DatasetFrame frame{timestamp, image, "", ""};
    // The depth images are in time order: the nearest is next to the first one not earlier.
    const auto later = std::lower_bound(depth.begin(), depth.end(), timestamp,
                                        [](const auto& d, double t) { return d.first < t; });
    double best = kTumMaxDepthOffset;
    for (auto it : {later, later - (later == depth.begin() ? 0 : 1)}) {
      if (it == depth.end() || std::abs(it->first - timestamp) > best) continue;
      best = std::abs(it->first - timestamp);
      frame.depth = it->second;
    }
    frames.push_back(std::move(frame));
  }
  return frames;
}

StatusOr<std::vector<DatasetFrame>> ReadEuroc(const fs::path& dir) {
  std::error_code ec;
  const fs::path root = fs::exists(dir / "mav0" / "cam0" / "data.csv", ec) ? dir / "mav0" : dir;
  RECOG_ASSIGN_OR_RETURN(const auto left, ReadEurocCameraList((root / "cam0").string()));
  std::map<int64_t, std::string> right;
  if (fs::exists(root / "cam1" / "data.csv", ec)) {
    RECOG_ASSIGN_OR_RETURN(const auto entries, ReadEurocCameraList((root / "cam1").string()));
    right.insert(entries.begin(), entries.end());
  }
  std::vector<DatasetFrame> frames;
  for (const auto& [ns, image] : left) {
    const auto it = right.find(ns);
    frames.push_back(
        DatasetFrame{double(ns) * 1e-9, image, "", it == right.end() ? "" : it->second});
  }
  return frames;
}

StatusOr<std::vector<DatasetFrame>> ReadKitti(const fs::path& dir) {
  RECOG_ASSIGN_OR_RETURN(const std::vector<double> times, ReadKittiTimes(dir.string()));
  std::vector<DatasetFrame> frames;
  std::error_code ec;
  for (const double timestamp : times) {
    char name[32];
    std::snprintf(name, sizeof(name), "%06zu.png", frames.size());
    const fs::path left = dir / "image_0" / name, right = dir / "image_1" / name;
    if (!fs::is_regular_file(left, ec)) {
      return Status::NotFound(Quoted(left) + ", frame " + std::to_string(frames.size()) + " of " +
                              Quoted(dir / "times.txt") + ", does not exist");
    }
    frames.push_back(DatasetFrame{timestamp, left.string(), "",
                                  fs::is_regular_file(right, ec) ? right.string() : ""});
  }
  return frames;
}

}  // namespace

StatusOr<std::vector<std::pair<int64_t, std::string>>> ReadEurocCameraList(
    const std::string& camera_dir) {
  const fs::path camera(camera_dir);
  const fs::path list = camera / "data.csv";
  RECOG_ASSIGN_OR_RETURN(const std::vector<ListLine> lines, ReadListLines(list));
  std::vector<std::pair<int64_t, std::string>> entries;
  for (const ListLine& line : lines) {
    const size_t comma = line.text.find(',');
    int64_t ns = 0;
    std::string name = comma == std::string::npos ? "" : line.text.substr(comma + 1);
    name.erase(0, name.find_first_not_of(" \t"));
    if (comma == std::string::npos || name.empty() || name.find(',') != std::string::npos ||
        !ParseNanoseconds(std::string_view(line.text).substr(0, comma), &ns)) {
      return Malformed(list, line, "'timestamp [ns],filename'");
    }
    if (!entries.empty()) {
      RECOG_RETURN_IF_ERROR(CheckIncreasing(double(entries.back().first), double(ns), list, line));
    }
    const fs::path file = camera / "data" / name;
    RECOG_RETURN_IF_ERROR(CheckExists(file, list, line));
    entries.emplace_back(ns, file.string());
  }
  return entries;
}

StatusOr<std::vector<double>> ReadKittiTimes(const std::string& dir) {
  const fs::path list = fs::path(dir) / "times.txt";
  RECOG_ASSIGN_OR_RETURN(const std::vector<ListLine> lines, ReadListLines(list));
  std::vector<double> times;
  for (const ListLine& line : lines) {
    double timestamp = 0;
    if (!ParseSeconds(line.text, &timestamp)) return Malformed(list, line, "a time in seconds");
    if (!times.empty()) RECOG_RETURN_IF_ERROR(CheckIncreasing(times.back(), timestamp, list, line));
    times.push_back(timestamp);
  }
  return times;
}

std::string_view DatasetLayoutName(DatasetLayout layout) {
  switch (layout) {
    case DatasetLayout::kFolder:
      return "folder";
    case DatasetLayout::kTum:
      return "tum";
    case DatasetLayout::kEuroc:
      return "euroc";
    case DatasetLayout::kKitti:
      return "kitti";
  }
  return "?";
}

StatusOr<DatasetLayout> ParseDatasetLayout(std::string_view name) {
  for (const DatasetLayout layout : {DatasetLayout::kFolder, DatasetLayout::kTum,
                                     DatasetLayout::kEuroc, DatasetLayout::kKitti}) {
    if (name == DatasetLayoutName(layout)) return layout;
  }
  return Status::InvalidArgument("unknown dataset layout '" + std::string(name) +
                                 "' (tum, euroc, kitti or folder)");
}

DatasetLayout DetectDatasetLayout(const std::string& dir) {
  const fs::path root(dir);
  std::error_code ec;
  if (fs::exists(root / "rgb.txt", ec)) return DatasetLayout::kTum;
  if (fs::exists(root / "mav0" / "cam0" / "data.csv", ec) ||
      fs::exists(root / "cam0" / "data.csv", ec)) {
    return DatasetLayout::kEuroc;
  }
  if (fs::exists(root / "times.txt", ec)) {
    for (int n = 0; n < kKittiCameras; ++n) {
      if (fs::is_directory(root / ("image_" + std::to_string(n)), ec)) return DatasetLayout::kKitti;
    }
  }
  return DatasetLayout::kFolder;
}

StatusOr<std::vector<DatasetFrame>> ReadDatasetFrames(const std::string& dir,
                                                      DatasetLayout layout) {
  std::vector<DatasetFrame> frames;
  switch (layout) {
    case DatasetLayout::kFolder:
      return Status::InvalidArgument("'" + dir +
                                     "': a plain folder of images has no timestamps to read");
    case DatasetLayout::kTum: {
      RECOG_ASSIGN_OR_RETURN(frames, ReadTum(dir));
      break;
    }
    case DatasetLayout::kEuroc: {
      RECOG_ASSIGN_OR_RETURN(frames, ReadEuroc(dir));
      break;
    }
    case DatasetLayout::kKitti: {
      RECOG_ASSIGN_OR_RETURN(frames, ReadKitti(dir));
      break;
    }
  }
  if (frames.empty()) {
    return Status::InvalidArgument("the " + std::string(DatasetLayoutName(layout)) +
                                   " dataset in '" + dir + "' lists no frames");
  }
  return frames;
}

}  // namespace recog::cli
