// InfoLogFile: RocksDB's info log of a store (the LOG file in the store's directory), written so
// that a full disk cannot stop the store.
//
// RocksDB's own LOG writer remembers a failed write and, in the Debian build of RocksDB 7.8
// (compiled with assertions), aborts the process on its next line: a disk that fills up while
// frames stream in would kill recogd instead of refusing the writes. This one writes each line
// with a single write(2) to a file opened for appending; a line that finds no room is lost and
// counted, and the next line is tried again, so logging resumes by itself when space returns.
//
// On open the previous LOG becomes LOG.old.<microseconds since the epoch> (RocksDB's names) and
// only the newest `keep_old_files` of those are kept.
#pragma once

#include <atomic>
#include <cstdarg>
#include <memory>
#include <string>

#include <rocksdb/env.h>

#include "core/common/status.h"

namespace recog::storage {

class InfoLogFile final : public rocksdb::Logger {
 public:
  // Creates `dir` when missing. UNAVAILABLE when the file cannot be opened.
  static StatusOr<std::shared_ptr<InfoLogFile>> Open(const std::string& dir, int keep_old_files);
  ~InfoLogFile() override;
  InfoLogFile(const InfoLogFile&) = delete;
  InfoLogFile& operator=(const InfoLogFile&) = delete;

  // Lines that could not be written (no room, I/O error) since the file was opened.
  uint64_t lost_lines() const { return lost_lines_.load(std::memory_order_relaxed); }

  using rocksdb::Logger::Logv;
  void Logv(const char* format, va_list ap) override;

 private:
  explicit InfoLogFile(int fd) : fd_(fd) {}

  const int fd_;
  std::atomic<uint64_t> lost_lines_{0};
};

}  // namespace recog::storage
