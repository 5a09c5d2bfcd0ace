// What the compacting writer (compacting_writer.cc, an executable of its own) and the crash tests
// (storage/rocksdb_crash_test.cc) agree on: the content of every entry, the maps the writer fills
// and the records it writes to its pipe.
//
//   storage_compacting_writer <store directory> <pipe fd>
//
// opens the store (SyncPolicy::kEveryWrite), whose maps kCompactingWriterMaps the test has
// created, and commits entries to them in turn, ids continuing from each map's NextEntryId, until
// it is killed. Every kCompactingWriterEntriesPerFlush entries it has RocksDB flush its memtables,
// so that level-0 files pile up and RocksDB's background compactions run all the time; no other
// flush happens in the writer. It tells the test what it does with CompactingWriterRecords on the
// pipe, and exits (with a message on stderr) only on a failure.
#pragma once

#include <cstdint>

#include "core/index/entry.h"
#include "storage/store_test_util.h"

namespace recog::testing {

// The content of entry `id` (in any map), recomputable by the test. Sizes vary with the id: most
// entries are small (up to 200 features), every eighth one is large (up to 2000 features,
// ~170 KB).
inline EntryRecord CrashEntry(EntryId id) {
  return MakeTestEntry(id, 11, DescriptorFormat::Orb(), id % 8 == 0 ? 2000 : 200);
}

// Two maps written in turn: each memtable flush then spans the key ranges of both, so successive
// level-0 files overlap and compacting them rewrites their records into new table files (files
// of one map alone, with increasing ids, would not overlap, and RocksDB would just move them down
// a level without writing anything).
inline constexpr const char* kCompactingWriterMaps[] = {"compacting_writer_a",
                                                        "compacting_writer_b"};
inline constexpr int kCompactingWriterEntriesPerFlush = 16;

// What the writer writes to its pipe: kCommitted per entry once CommitEntry has returned OK, and
// kFlushing / kFlushed around each flush of the memtables.
struct CompactingWriterRecord {
  enum Kind : uint32_t { kCommitted, kFlushing, kFlushed };
  Kind kind = kCommitted;
  uint32_t map = 0;  // kCommitted: the index of the entry's map in kCompactingWriterMaps
  EntryId id = kInvalidEntryId;  // kCommitted: the entry
};

}  // namespace recog::testing
