#include "storage/info_log_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <vector>

namespace recog::storage {
namespace fs = std::filesystem;

namespace {

constexpr char kLogName[] = "LOG";
constexpr char kOldPrefix[] = "LOG.old.";

// Renames `dir`/LOG to LOG.old.<now in µs> and removes all but the newest `keep` old logs.
void RollOldLogs(const fs::path& dir, int keep) {
  std::error_code ec;
  const auto now_us = std::chrono::duration_cast<std::chrono::microseconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count();
  if (fs::exists(dir / kLogName, ec)) {
    fs::rename(dir / kLogName, dir / (kOldPrefix + std::to_string(now_us)), ec);
  }
  std::vector<std::pair<long long, fs::path>> old_logs;
  for (const fs::directory_entry& file : fs::directory_iterator(dir, ec)) {
    const std::string name = file.path().filename().string();
    if (!name.starts_with(kOldPrefix)) continue;
    old_logs.emplace_back(std::atoll(name.c_str() + std::strlen(kOldPrefix)), file.path());
  }
  std::sort(old_logs.begin(), old_logs.end(), std::greater<>());
  for (size_t i = size_t(std::max(keep, 0)); i < old_logs.size(); ++i) {
    fs::remove(old_logs[i].second, ec);
  }
}

// "2026/11/26-16:43:01.566123 " in UTC, RocksDB's LOG format.
std::string Timestamp() {
  const auto now = std::chrono::system_clock::now();
  const std::time_t seconds = std::chrono::system_clock::to_time_t(now);
  const auto micros =
      std::chrono::duration_cast<std::chrono::microseconds>(now.time_since_epoch()).count() %
      1000000;
  std::tm utc{};
  ::gmtime_r(&seconds, &utc);
  char text[64];
  std::snprintf(text, sizeof(text), "%04d/%02d/%02d-%02d:%02d:%02d.%06lld ", utc.tm_year + 1900,
                utc.tm_mon + 1, utc.tm_mday, utc.tm_hour, utc.tm_min, utc.tm_sec,
                static_cast<long long>(micros));
  return text;
}

}  // namespace

StatusOr<std::shared_ptr<InfoLogFile>> InfoLogFile::Open(const std::string& dir,
                                                         int keep_old_files) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  RollOldLogs(dir, keep_old_files);
  const std::string path = (fs::path(dir) / kLogName).string();
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0) {
    return Status::Unavailable("cannot open '" + path + "': " + std::strerror(errno));
  }
  return std::shared_ptr<InfoLogFile>(new InfoLogFile(fd));
}

InfoLogFile::~InfoLogFile() { ::close(fd_); }

void InfoLogFile::Logv(const char* format, va_list ap) {
  std::string line = Timestamp();
  const size_t prefix = line.size();
  va_list copy;
  va_copy(copy, ap);
  const int length = std::vsnprintf(nullptr, 0, format, copy);
  va_end(copy);
  if (length < 0) return;
  line.resize(prefix + size_t(length) + 1);
  std::vsnprintf(line.data() + prefix, size_t(length) + 1, format, ap);
  line.back() = '\n';  // replaces vsnprintf's terminating zero
  if (::write(fd_, line.data(), line.size()) != ssize_t(line.size())) {
    lost_lines_.fetch_add(1, std::memory_order_relaxed);
  }
}

}  // namespace recog::storage
