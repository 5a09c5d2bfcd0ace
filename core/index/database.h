// Database: one map's recognition database — an inverted index in memory over entries persisted
// through an IndexStore (thesis §3.1.4, §4.3.2, §5.4.3).
//
// The inverted index keeps, for every word, the list of <entry, value> pairs of the entries that
// contain it (PostingList: 3 bytes a posting, sorted by entry id, the values exact), so a query
// scores every stored entry that shares a word with it while touching nothing else (thesis
// Algorithm 1). In a large map, where that would mean millions of postings, a query reads its
// rarest words' lists in full and looks up only its best candidates in the others
// (QueryOptions::full_scan_postings). The direct index and the features of each entry stay in the
// store and are read on demand (Get) when a candidate has to be verified geometrically.
//
// Writes go to the store first, then to memory: Add() returns only after the entry is committed
// (atomically, every part), and a query sees an entry only once it is fully indexed.
//
// Opening a database loads the index from the map's snapshot in the store (SaveSnapshot; checked
// with its checksum and against the map) and then reads the entries added since; without a
// usable snapshot (a map written before snapshots existed, one removed from since, a damaged
// snapshot) it rebuilds the whole index from the entries. Every entry read is checked: its bag of
// words, direct index and metadata must agree with each other and with the vocabulary.
//
// A database refuses a vocabulary other than the one its map was created with
// (FAILED_PRECONDITION): word ids of two vocabularies mean different things.
//
// Thread safety: Query, Get, Contains, size and Stats may run from any number of threads while
// one or more threads Add/Remove; writers are serialised among themselves, and a query never
// waits for a store write, only for the short in-memory update that follows it.
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <span>
#include <string>
#include <vector>

#include "core/common/feature_set.h"
#include "core/common/status.h"
#include "core/index/entry.h"
#include "core/index/index_store.h"
#include "core/index/posting_list.h"
#include "core/vocabulary/vocabulary.h"

namespace recog {

struct QueryOptions {
  size_t max_results = 10;
  // Only entries with an id below this bound are scored (leave out the most recent frames).
  EntryId max_entry_id = kInvalidEntryId;
  // The postings a query reads in full; 0 for no bound. A query whose words' lists hold more (in
  // a map of hundreds of thousands of entries) reads its rarest words' lists in full up to this
  // many postings (at least one list), keeps the `rescored_candidates` (at least `max_results`)
  // entries that score best on them, and completes the scores of those alone with its commoner
  // words' lists (a search per candidate, not a scan). The scores returned are exact; what the
  // bound may change is which entries are scored: one that shares mostly common words with the
  // query may be missed. Below it (most queries of maps of up to 100,000 real frames) a query is
  // exhaustive.
  size_t full_scan_postings = 500'000;
  size_t rescored_candidates = 50;
};

struct QueryResult {
  EntryId id = kInvalidEntryId;
  double score = 0.0;
  friend bool operator==(const QueryResult&, const QueryResult&) = default;
};

struct BcMatch {
  EntryId id = kInvalidEntryId;
  double bhattacharyya = 0.0;  // s_B in [0, 1]
  double chi_square = 0.0;     // s_chi2 in [0, 1], what the ranking uses
  friend bool operator==(const BcMatch&, const BcMatch&) = default;
};

// How Open built the index.
struct DatabaseOpenReport {
  bool from_snapshot = false;     // loaded from the map's snapshot ...
  EntryId snapshot_covers = 0;    // ... which held the entries below this id
  size_t entries_read = 0;        // entries read from the store: all of them, or those after it
  std::string snapshot_rejected;  // why the store's snapshot was not used (empty: no such thing)
};

struct DatabaseStats {
  size_t entries = 0;
  size_t postings = 0;
  size_t values_stored_aside = 0;  // postings whose value is not coded in their byte (PostingList)
  size_t words_in_use = 0;         // words with at least one posting
  size_t index_bytes = 0;          // memory held by the inverted index
  EntryId next_entry_id = 0;
};

class Database {
 public:
  // Creates map `name` in `store` for `vocabulary`, then opens it.
  static StatusOr<std::unique_ptr<Database>> Create(IndexStore* store, const std::string& name,
                                                    std::shared_ptr<const Vocabulary> vocabulary,
                                                    ScoringType scoring = ScoringType::kL1,
                                                    uint32_t direct_index_levels_up = 2);
  // Opens map `name` of `store` and loads its index (see above; open_report() says how).
  // NOT_FOUND for an unknown map, FAILED_PRECONDITION for another vocabulary, DATA_LOSS when the
  // stored entries disagree.
  static StatusOr<std::unique_ptr<Database>> Open(IndexStore* store, const std::string& name,
                                                  std::shared_ptr<const Vocabulary> vocabulary);

  const MapInfo& info() const { return info_; }
  const DatabaseOpenReport& open_report() const { return open_report_; }
  const Vocabulary& vocabulary() const { return *vocabulary_; }

  // Converts the features with the vocabulary (direct index at the map's level) and adds them.
  StatusOr<EntryId> Add(const FeatureSet& features, EntryMetadata metadata = {});
  // Adds an entry the caller has already converted with this database's vocabulary, with the
  // normalisation of the map's scoring and the direct index at the map's level. `points` is the
  // 3D point of every feature (object entries, frames with depth) or empty; `camera` the pinhole
  // matrix of the keypoints, or all zeros when unknown. INVALID_ARGUMENT when the parts do not
  // fit the vocabulary or each other, or a camera matrix has no positive, finite focal lengths.
  StatusOr<EntryId> AddConverted(const BowVector& bow, const FeatureVector& direct,
                                 const FeatureSet& features, EntryMetadata metadata = {},
                                 std::vector<cv::Point3f> points = {},
                                 const cv::Matx33d& camera = cv::Matx33d::zeros());

  // Scores the query against every entry sharing a word with it, with the map's scoring, and
  // returns the best `max_results` (best first; equal scores by increasing id). The query must
  // come from this database's vocabulary (INVALID_ARGUMENT for a word id out of range).
  Status Query(const BowVector& query, const QueryOptions& options,
               std::vector<QueryResult>* results) const;

  // BC matching (thesis Algorithm 5), for maps scored with L1-normalised vectors (Bhattacharyya
  // or chi-square; FAILED_PRECONDITION otherwise): one pass over the inverted index computes both
  // the Bhattacharyya coefficient s_B and the chi-square score s_chi2 = 2 sum v w / (v + w) of
  // every entry sharing a word with the query; the entries with s_B >= beta * max s_B are
  // returned ranked by s_chi2 (best first, at most max_results; equal scores by increasing id).
  Status QueryBcMatching(const BowVector& query, double beta, size_t max_results,
                         std::vector<BcMatch>* results) const;

  // Reads parts of an entry from the store. NOT_FOUND for an unknown or removed entry.
  StatusOr<EntryRecord> Get(EntryId id, uint32_t parts = kEntryAllParts) const;
  bool Contains(EntryId id) const;
  // Calls `visit` with the requested parts of every stored entry, in increasing id order (read
  // from the store: linear in the map's size); stops at the first error `visit` returns.
  Status ScanEntries(uint32_t parts, const std::function<Status(EntryRecord&)>& visit) const;
  // Removes an entry from the store and the index. NOT_FOUND when absent.
  Status Remove(EntryId id);
  // Removes every entry (ids keep increasing afterwards).
  Status Clear();

  // Writes the in-memory index to the store as the map's snapshot, so that the next Open loads it
  // instead of reading every entry; returns the bytes written, 0 when the store's snapshot is
  // already current. Adds and removals wait until it is written (seconds for a million entries:
  // meant for shutdown and quiet moments); queries go on. The snapshot holds, little-endian: a
  // header (the magic "RCGINDEX", format version 2, map id, vocabulary checksum and words, the
  // entry id bound it covers, entries, postings), a byte per entry id below that bound (1:
  // indexed), a float per entry id (its PostingList scale), for each word its PostingList::Parts
  // (each a 32-bit count and its items: postings, page ends, values kept aside), and an XXH3-64
  // checksum of all of that.
  StatusOr<uint64_t> SaveSnapshot();

  size_t size() const;
  // The id the next added entry will get (constant time, unlike Stats()).
  EntryId next_entry_id() const;
  DatabaseStats Stats() const;

 private:
  struct PendingPosting {  // a posting on its way to its list, while the index is rebuilt
    WordId word;
    EntryId entry;
    float value;
  };

  Database(IndexStore* store, MapInfo info, std::shared_ptr<const Vocabulary> vocabulary);
  // Checks that the parts of an entry fit the vocabulary and each other; returns a message, or
  // an empty string when they do.
  std::string CheckParts(const BowVector& bow, const FeatureVector& direct,
                         uint32_t num_features) const;
  void IndexEntry(EntryId id, const BowVector& bow);  // requires index_mutex_ exclusively
  // Loads the index from a snapshot of the store; DATA_LOSS (the index then half-filled) when it
  // is damaged or does not describe this map. Only while opening.
  Status LoadSnapshot(IndexStore::SnapshotReader& reader);
  // Reads the stored entries from id `first` on, checks them and indexes them; only while opening.
  Status IndexStoredEntries(EntryId first);

  // Checks that every word of `query` is in the vocabulary.
  Status CheckQueryWords(const BowVector& query) const;
  // Adds to `touched` every entry below `bound` that shares a word with the query, with its score;
  // with a bounded query (see QueryOptions) only the best candidates, exactly scored.
  template <ScoringType kType>
  void ScoreEntries(const BowVector& query, const QueryOptions& options, EntryId bound,
                    std::vector<QueryResult>* touched) const;

  IndexStore* store_;
  MapInfo info_;
  std::shared_ptr<const Vocabulary> vocabulary_;
  DatabaseOpenReport open_report_;

  std::mutex write_mutex_;  // serialises Add/Remove/Clear/SaveSnapshot
  // The id bound of the store's snapshot of this map, kInvalidEntryId when it has none (as far as
  // this database knows); guarded by write_mutex_.
  EntryId snapshot_covers_ = kInvalidEntryId;
  mutable std::shared_mutex index_mutex_;  // guards everything below
  std::vector<PostingList> postings_;      // by word
  std::vector<uint8_t> present_;           // by entry id: 1 when indexed
  std::vector<float> entry_scale_;         // by entry id: PostingList::FitScale of its words
  size_t num_entries_ = 0;
  size_t num_postings_ = 0;
  EntryId next_id_ = 0;
};

}  // namespace recog
