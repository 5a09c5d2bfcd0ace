// The writer of RocksDbCrashTest.AKillDuringACompactionLosesNoAcknowledgedEntry; see
// compacting_writer.h. A process of its own (started with fork and exec) rather than a forked
// child of the test: a forked child inherits RocksDB's thread pool bookkeeping without its
// threads, so it could never flush or compact.
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iterator>
#include <memory>
#include <string>
#include <system_error>

#include <spdlog/spdlog.h>

#include "storage/rocksdb_index_store.h"
#include "storage/testing/compacting_writer.h"

namespace recog {
namespace {

using testing::CompactingWriterRecord;
using testing::CrashEntry;
using testing::kCompactingWriterEntriesPerFlush;
using testing::kCompactingWriterMaps;

constexpr int kMaps = int(std::size(kCompactingWriterMaps));

int Fail(const std::string& what, const Status& status) {
  std::fprintf(stderr, "compacting_writer: %s: %s\n", what.c_str(), status.ToString().c_str());
  return 1;
}

bool Tell(int fd, const CompactingWriterRecord& record) {
  if (::write(fd, &record, sizeof(record)) == sizeof(record)) return true;
  std::perror("compacting_writer: cannot write to the pipe");
  return false;
}

int Run(const std::string& dir, int pipe_fd) {
  RocksDbStoreOptions options;
  options.sync = SyncPolicy::kEveryWrite;
  auto store = OpenRocksDbIndexStore(dir, options);
  if (!store.ok()) return Fail("cannot open " + dir, store.status());
  IndexStore& index = **store;
  MapId maps[kMaps];
  EntryId next[kMaps];
  for (int m = 0; m < kMaps; ++m) {
    auto info = index.GetMap(kCompactingWriterMaps[m]);
    if (!info.ok()) return Fail(kCompactingWriterMaps[m], info.status());
    auto next_id = index.NextEntryId(info->id);
    if (!next_id.ok()) return Fail(kCompactingWriterMaps[m], next_id.status());
    maps[m] = info->id;
    next[m] = *next_id;
  }

  // IndexStore::Flush only syncs the write-ahead log, and the memtables (64 MB) would take far
  // too long to fill: a checkpoint is the store's one operation that flushes them. The copy
  // itself (hard links) is thrown away; a leftover of a killed predecessor goes first.
  const std::string flush_dir = dir + ".flush";
  for (uint64_t n = 0;; ++n) {
    const int m = int(n % kMaps);
    const EntryId id = next[m]++;
    const Status committed = index.CommitEntry(maps[m], CrashEntry(id));
    if (!committed.ok()) return Fail("cannot commit entry " + std::to_string(id), committed);
    if (!Tell(pipe_fd, {CompactingWriterRecord::kCommitted, uint32_t(m), id})) return 1;
    if ((n + 1) % kCompactingWriterEntriesPerFlush == 0) {
      std::error_code ec;
      std::filesystem::remove_all(flush_dir, ec);
      std::filesystem::remove_all(flush_dir + ".tmp", ec);  // RocksDB's name while writing it
      if (!Tell(pipe_fd, {CompactingWriterRecord::kFlushing})) return 1;
      const Status flushed = index.Checkpoint(flush_dir);
      if (!flushed.ok()) return Fail("cannot flush", flushed);
      if (!Tell(pipe_fd, {CompactingWriterRecord::kFlushed})) return 1;
    }
  }
}

}  // namespace
}  // namespace recog

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: storage_compacting_writer <store directory> <pipe fd>\n");
    return 2;
  }
  spdlog::set_level(spdlog::level::warn);  // a line per checkpoint would drown the test's output
  return recog::Run(argv[1], std::atoi(argv[2]));
}
