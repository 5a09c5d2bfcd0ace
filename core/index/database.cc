#include "core/index/database.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <span>
#include <thread>

namespace recog {
namespace {

constexpr size_t kMaxUserDataBytes = 64 * 1024;

// Per-thread accumulators of a query. A scoring query (ScanLists) sums one range of entry ids at
// a time in `range_sums`; BC matching sums every entry in `score` and `second_score`, with a
// one-byte stamp per entry id: an entry whose stamp is not the current query's generation has not
// been touched yet, so nothing is cleared between queries but once every 255 (when the
// generation wraps).
struct QueryScratch {
  std::vector<double> range_sums;  // all -0 between queries, when range_sums_clean
  bool range_sums_clean = false;
  std::vector<double> score, second_score;
  std::vector<uint8_t> stamp;
  uint8_t generation = 0;
  // A bounded query's words: those whose lists are read in full, and the others.
  std::vector<BowEntry> scanned_words, completed_words;
  std::vector<std::pair<size_t, uint32_t>> list_lengths;  // postings, index in the query
  std::vector<QueryResult> candidates;   // a bounded query's best entries on its rarer words
  std::vector<size_t> candidate_blocks;  // where each candidate is in one completed word's list
  std::vector<size_t> scan_positions;    // by query word: where a scan reads its list next
  std::vector<size_t> scan_stops;        // by query word: where its list's current page ends
  std::vector<float> scan_weights;       // by query word: its weight in the vocabulary

  // Readies the stamps and sums of BC matching for `entries` ids.
  void PrepareStamps(size_t entries) {
    if (score.size() < entries) {
      score.resize(entries);
      second_score.resize(entries);
      stamp.resize(entries, 0);
    }
    if (++generation == 0) {  // wrapped: forget every old stamp
      std::fill(stamp.begin(), stamp.end(), 0);
      generation = 1;
    }
  }

  // Splits the query's words: the shortest lists up to `budget` postings in all (and at least
  // the first non-empty one) are scanned, in the query's word order; the rest completed. False
  // when every list is scanned.
  template <class Lists>
  bool SplitByListLength(const BowVector& query, const Lists& lists, size_t budget) {
    const std::span<const BowEntry> words = query.entries();
    list_lengths.clear();
    size_t total = 0;
    constexpr size_t kAhead = 8;  // each list's size is a cache miss away
    for (size_t i = 0; i < words.size(); ++i) {
      if (i + kAhead < words.size()) __builtin_prefetch(&lists[words[i + kAhead].word]);
      list_lengths.push_back({lists[words[i].word].size(), uint32_t(i)});
      total += list_lengths.back().first;
    }
    if (total <= budget) return false;
    std::sort(list_lengths.begin(), list_lengths.end());
    size_t read = 0, scanned = 0;
    while (scanned < list_lengths.size() &&
           (read == 0 || read + list_lengths[scanned].first <= budget)) {
      read += list_lengths[scanned++].first;
    }
    if (scanned == list_lengths.size()) return false;
    // Back to word order, which the scan's prefetching follows.
    std::sort(list_lengths.begin(), list_lengths.begin() + long(scanned),
              [](const auto& a, const auto& b) { return a.second < b.second; });
    scanned_words.clear();
    completed_words.clear();
    for (size_t k = 0; k < list_lengths.size(); ++k) {
      (k < scanned ? scanned_words : completed_words).push_back(words[list_lengths[k].second]);
    }
    return true;
  }
};

// CommonTerm of a query word's value `v` and a posting's value `w`. The L1 term, their minimum, is
// taken in float (the same value as the double minimum of the two), which the compiler makes a
// min instruction: with one operand a double it branched, and mispredicted about every other
// posting.
template <ScoringType kType>
double PostingTerm(float v, float w) {
  if constexpr (kType == ScoringType::kL1) {
    return double(v < w ? v : w);
  } else {
    return CommonTerm(kType, v, w);
  }
}

// A range's sums start as -0, which no sum of terms is: x + -0 is x for every x, +0 included,
// and a term is never -0 (lists keep no -0 value). So a sum whose bits are still those of -0
// belongs to an entry that no posting touched, and the first term replaces it exactly.
constexpr uint64_t kUntouchedBits = 0x8000'0000'0000'0000;
constexpr double kNoFloor = -std::numeric_limits<double>::infinity();
static_assert(std::bit_cast<uint64_t>(-0.0) == kUntouchedBits);

// Four sums, and four lanes of 0 or all ones (a comparison's answer), as the compiler's vector
// types: one instruction each on a target with 256-bit vectors, two or four elsewhere.
using FourSums = double __attribute__((vector_size(32)));
using FourBits = uint64_t __attribute__((vector_size(32)));
using FourFlags = int64_t __attribute__((vector_size(32)));

// Calls touched(offset, sum) for every sum of `sums[0, count)` that some term reached and with
// sign * sum > *floor, in increasing offset order, and sets every sum back to -0 (untouched) as
// it goes: one pass over the sums, while they are in the core's cache, instead of a scan and a
// fill. `touched` may raise *floor as it goes (it is read again every few sums; those it lets
// through anyway are the caller's to test). Eight sums are tested at a time, in vectors: in a
// bounded query (a floor) nearly every group has none to pass on.
template <class Touched>
void TakeTouched(double* sums, size_t count, double sign, const double* floor, Touched&& touched) {
  constexpr size_t kGroup = 8;
  const FourSums untouched = {-0.0, -0.0, -0.0, -0.0};
  size_t i = 0;
  for (; i + kGroup <= count; i += kGroup) {
    FourSums low, high;
    std::memcpy(&low, sums + i, sizeof low);
    std::memcpy(&high, sums + i + 4, sizeof high);
    std::memcpy(sums + i, &untouched, sizeof untouched);
    std::memcpy(sums + i + 4, &untouched, sizeof untouched);
    const double current_floor = *floor;
    const FourFlags low_passes = (FourBits(low) != kUntouchedBits) & (low * sign > current_floor);
    const FourFlags high_passes =
        (FourBits(high) != kUntouchedBits) & (high * sign > current_floor);
    const FourFlags either = low_passes | high_passes;
    if ((either[0] | either[1] | either[2] | either[3]) == 0) continue;
    for (size_t k = 0; k < 4; ++k) {
      if (low_passes[k] != 0) touched(i + k, low[k]);
    }
    for (size_t k = 0; k < 4; ++k) {
      if (high_passes[k] != 0) touched(i + 4 + k, high[k]);
    }
  }
  for (; i < count; ++i) {
    const double sum = sums[i];
    sums[i] = -0.0;
    if (std::bit_cast<uint64_t>(sum) != kUntouchedBits && sign * sum > *floor) touched(i, sum);
  }
}

// Sums CommonTerm(v, w) of every posting below `bound` in the lists of `words`, by entry. The
// entry ids are taken kScanRange at a time: every list's postings in one range are added before
// the next range's, so that the range's sums stay in the core's cache instead of each posting
// missing it in a map of a million entries (the lists are sorted by entry id, so each is read
// once, in order). After each range that any posting fell in, `finish_range(range_begin, sums,
// count)` is called, where sums[id - range_begin] is the sum of entry id for the range's `count`
// ids, or -0 when nothing touched it; finish_range hands them to TakeTouched, which sets them back
// to -0 for the next range. Each posting costs one add: no test of whether its entry was touched
// before, which cost as much as the rest of the scan on a map of a million entries.
constexpr EntryId kScanRange = 1 << 14;  // 16K entries: 128 KB of sums
static_assert((1u << PostingList::kPageBits) % kScanRange == 0, "no range across two pages");

template <ScoringType kType, class FinishRange>
void ScanLists(const std::vector<PostingList>& lists, const Vocabulary& vocabulary,
               const float* entry_scales, std::span<const BowEntry> words, EntryId bound,
               QueryScratch& scratch, FinishRange&& finish_range) {
  std::vector<double>& range_sums = scratch.range_sums;
  // Each word's posting list is a cache miss away (its vector, then its postings), which costs
  // more than scoring a short list: the lists of the words a few steps ahead are fetched
  // meanwhile. (Measured by bench_place Relocalize_Group10x2600_vs_One26K, whose small maps have
  // short lists.)
  constexpr size_t kListsAhead = 4, kVectorsAhead = 8;
  // A scan leaves every sum it touched at -0 again (TakeTouched); one cut short by an exception
  // leaves them dirty, and the next one clears them.
  if (!scratch.range_sums_clean || range_sums.size() < std::min<uint64_t>(kScanRange, bound)) {
    range_sums.assign(kScanRange, -0.0);
  }
  scratch.range_sums_clean = false;
  std::vector<size_t>& positions = scratch.scan_positions;
  std::vector<size_t>& stops = scratch.scan_stops;
  positions.assign(words.size(), 0);
  stops.resize(words.size());
  std::vector<float>& weights = scratch.scan_weights;
  weights.resize(words.size());
  for (size_t i = 0; i < words.size(); ++i) weights[i] = vocabulary.WordWeight(words[i].word);
  for (uint64_t range_begin = 0; range_begin < bound; range_begin += kScanRange) {
    const EntryId range_end = EntryId(std::min<uint64_t>(bound, range_begin + kScanRange));
    const uint64_t page = range_begin >> PostingList::kPageBits;
    if (range_begin % (uint64_t(1) << PostingList::kPageBits) == 0) {
      // A new page: where each list's postings on it end (its postings start where the scan is).
      for (size_t i = 0; i < words.size(); ++i) {
        if (i + kVectorsAhead < words.size()) {
          __builtin_prefetch(&lists[words[i + kVectorsAhead].word]);
        }
        if (i + kListsAhead < words.size()) {
          __builtin_prefetch(lists[words[i + kListsAhead].word].page_end_address(page));
        }
        stops[i] = lists[words[i].word].PageEnd(page);
      }
    }
    double* const sums = range_sums.data();
    const EntryId base = EntryId(range_begin);
    // The postings of a range fall on nearly every (64-byte) cache line of its entries' scales,
    // in no order: those lines are fetched first, in order, rather than missed one by one.
    constexpr size_t kScalesPerLine = 64 / sizeof(float);
    for (EntryId entry = base; entry < range_end; entry += kScalesPerLine) {
      __builtin_prefetch(entry_scales + entry);
    }
    bool touched = false;
    for (size_t i = 0; i < words.size(); ++i) {
      if (i + kVectorsAhead < words.size()) {
        __builtin_prefetch(&lists[words[i + kVectorsAhead].word]);
      }
      if (i + kListsAhead < words.size()) {
        __builtin_prefetch(lists[words[i + kListsAhead].word].address(positions[i + kListsAhead]));
      }
      const BowEntry& q = words[i];
      if (q.value <= 0.f || positions[i] == stops[i]) continue;
      const float v = q.value;
      const size_t first = positions[i];
      lists[q.word].VisitRange(
          &positions[i], stops[i], page, range_end, weights[i], entry_scales,
          [=](EntryId entry, float value) { sums[entry - base] += PostingTerm<kType>(v, value); });
      touched |= positions[i] != first;
    }
    if (touched) {
      finish_range(base, sums, size_t(range_end - base));
    }
  }
  scratch.range_sums_clean = true;
}

// Orders query results best first; equal scores by increasing id.
auto BetterResult(bool higher_is_better) {
  return [higher_is_better](const QueryResult& a, const QueryResult& b) {
    if (a.score != b.score) return higher_is_better ? a.score > b.score : a.score < b.score;
    return a.id < b.id;
  };
}

}  // namespace

Database::Database(IndexStore* store, MapInfo info, std::shared_ptr<const Vocabulary> vocabulary)
    : store_(store),
      info_(std::move(info)),
      vocabulary_(std::move(vocabulary)),
      postings_(vocabulary_->num_words()) {}

StatusOr<std::unique_ptr<Database>> Database::Create(IndexStore* store, const std::string& name,
                                                     std::shared_ptr<const Vocabulary> vocabulary,
                                                     ScoringType scoring,
                                                     uint32_t direct_index_levels_up) {
  if (vocabulary == nullptr || vocabulary->empty()) {
    return Status::InvalidArgument("a database needs a non-empty vocabulary");
  }
  MapConfig config;
  config.name = name;
  config.vocabulary_checksum = vocabulary->checksum();
  config.vocabulary_words = uint32_t(vocabulary->num_words());
  config.vocabulary_nodes = uint32_t(vocabulary->num_nodes());
  config.descriptor = vocabulary->info().descriptor;
  config.scoring = scoring;
  config.direct_index_levels_up = direct_index_levels_up;
  RECOG_RETURN_IF_ERROR(store->CreateMap(config).status());
  return Open(store, name, std::move(vocabulary));
}

StatusOr<std::unique_ptr<Database>> Database::Open(IndexStore* store, const std::string& name,
                                                   std::shared_ptr<const Vocabulary> vocabulary) {
  if (vocabulary == nullptr || vocabulary->empty()) {
    return Status::InvalidArgument("a database needs a non-empty vocabulary");
  }
  RECOG_ASSIGN_OR_RETURN(MapInfo info, store->GetMap(name));
  if (info.config.vocabulary_checksum != vocabulary->checksum() ||
      info.config.vocabulary_words != vocabulary->num_words()) {
    char buf[160];
    std::snprintf(buf, sizeof(buf),
                  "map '%s' was created with vocabulary %016llx (%u words); this one is %016llx "
                  "(%zu words)",
                  name.c_str(), static_cast<unsigned long long>(info.config.vocabulary_checksum),
                  info.config.vocabulary_words,
                  static_cast<unsigned long long>(vocabulary->checksum()), vocabulary->num_words());
    return Status::FailedPrecondition(buf);
  }
  std::unique_ptr<Database> db(new Database(store, std::move(info), std::move(vocabulary)));
  RECOG_ASSIGN_OR_RETURN(db->next_id_, store->NextEntryId(db->info_.id));
  db->present_.assign(db->next_id_, 0);
  db->entry_scale_.assign(db->next_id_, 0.f);

  DatabaseOpenReport& report = db->open_report_;
  StatusOr<std::unique_ptr<IndexStore::SnapshotReader>> snapshot =
      store->ReadSnapshot(db->info_.id);
  if (snapshot.ok()) {
    const Status loaded = db->LoadSnapshot(**snapshot);
    if (loaded.ok()) {
      report.from_snapshot = true;
      report.snapshot_covers = (*snapshot)->covers();
      db->snapshot_covers_ = report.snapshot_covers;
    } else {
      report.snapshot_rejected = loaded.message();
      db->postings_.assign(db->postings_.size(), PostingList());
      db->present_.assign(db->next_id_, 0);
      db->entry_scale_.assign(db->next_id_, 0.f);
      db->num_entries_ = db->num_postings_ = 0;
      (void)store->DropSnapshot(db->info_.id);  // best effort: SaveSnapshot replaces it anyway
    }
  } else if (snapshot.status().code() != StatusCode::kNotFound) {
    report.snapshot_rejected = snapshot.status().message();
  }
  RECOG_RETURN_IF_ERROR(db->IndexStoredEntries(report.snapshot_covers));
  return db;
}

Status Database::IndexStoredEntries(EntryId first) {
  // Appending posting by posting to a million lists would miss the cache twice per posting, so
  // the scan first routes the postings into buckets by word-id range (sequential appends); each
  // bucket is then spread over its lists, which fit in the cache, each list being grown once to
  // its final size. Entries arrive in id order, after every posting already in the lists, so
  // every list stays sorted by entry id.
  const size_t words = postings_.size();
  const int shift = std::max(0, int(std::bit_width(words)) - 6);  // about 64 buckets
  std::vector<std::vector<PendingPosting>> buckets(((words - 1) >> shift) + 1);
  std::vector<uint32_t> count(words, 0);
  const Status scanned = store_->ScanEntries(
      info_.id, first, kEntryMetadata | kEntryBow | kEntryDirect,
      [&](EntryRecord& record) -> Status {
        std::string problem;
        if (record.id >= next_id_) {
          problem = "id is beyond the map's next id " + std::to_string(next_id_);
        } else if (record.id < first) {
          problem = "id is below the first one asked for, " + std::to_string(first);
        } else {
          problem = CheckParts(record.bow, record.direct, record.metadata.num_features);
        }
        if (!problem.empty()) {
          return Status::DataLoss("map '" + info_.config.name + "' entry " +
                                  std::to_string(record.id) + ": " + problem);
        }
        for (const BowEntry& e : record.bow.entries()) {
          ++count[e.word];
          buckets[e.word >> shift].push_back({e.word, record.id, e.value});
        }
        present_[record.id] = 1;
        entry_scale_[record.id] = PostingList::FitScale(record.bow.entries(), *vocabulary_);
        ++num_entries_;
        ++open_report_.entries_read;
        num_postings_ += record.bow.size();
        return Status::Ok();
      });
  RECOG_RETURN_IF_ERROR(scanned);
  // Buckets cover disjoint words: two threads fill them without sharing a list.
  auto fill = [&](size_t first_bucket) {
    for (size_t b = first_bucket; b < buckets.size(); b += 2) {
      const size_t end_word = std::min(words, (b + 1) << shift);
      for (size_t w = b << shift; w < end_word; ++w) {
        if (count[w] != 0) postings_[w].Reserve(postings_[w].size() + count[w]);
      }
      for (const PendingPosting& p : buckets[b]) {
        postings_[p.word].Append(p.entry, p.value, vocabulary_->WordWeight(p.word),
                                 entry_scale_[p.entry]);
      }
      std::vector<PendingPosting>().swap(buckets[b]);  // release as we go
    }
  };
  std::thread helper(fill, 1);
  fill(0);
  helper.join();
  return Status::Ok();
}

std::string Database::CheckParts(const BowVector& bow, const FeatureVector& direct,
                                 uint32_t num_features) const {
  const size_t words = vocabulary_->num_words();
  WordId previous_word = 0;
  for (size_t i = 0; i < bow.size(); ++i) {
    const BowEntry& e = bow.entries()[i];
    if (e.word >= words) {
      return "word " + std::to_string(e.word) + " is outside the vocabulary (" +
             std::to_string(words) + " words)";
    }
    if (i > 0 && e.word <= previous_word) return "bag-of-words entries are not sorted by word";
    if (!std::isfinite(e.value) || e.value < 0.f) return "bag-of-words value is not a weight";
    previous_word = e.word;
  }
  const size_t nodes = vocabulary_->num_nodes();
  size_t features_in_direct = 0;
  for (size_t i = 0; i < direct.size(); ++i) {
    if (direct.node(i) >= nodes || (i > 0 && direct.node(i) <= direct.node(i - 1))) {
      return "direct index node " + std::to_string(direct.node(i)) +
             " is out of range or out of order";
    }
    uint32_t previous_feature = 0;
    const auto features = direct.features(i);
    for (size_t j = 0; j < features.size(); ++j) {
      if (features[j] >= num_features || (j > 0 && features[j] <= previous_feature)) {
        return "direct index refers to feature " + std::to_string(features[j]) + " of " +
               std::to_string(num_features);
      }
      previous_feature = features[j];
    }
    features_in_direct += features.size();
  }
  if (features_in_direct != num_features) {
    return "direct index holds " + std::to_string(features_in_direct) +
           " features; the entry has " + std::to_string(num_features);
  }
  return {};
}

void Database::IndexEntry(EntryId id, const BowVector& bow) {
  if (present_.size() <= id) {
    present_.resize(size_t(id) + 1, 0);
    entry_scale_.resize(size_t(id) + 1, 0.f);
  }
  const float scale = entry_scale_[id] = PostingList::FitScale(bow.entries(), *vocabulary_);
  for (const BowEntry& e : bow.entries()) {
    postings_[e.word].Append(id, e.value, vocabulary_->WordWeight(e.word), scale);
  }
  present_[id] = 1;
  ++num_entries_;
  num_postings_ += bow.size();
}

StatusOr<EntryId> Database::Add(const FeatureSet& features, EntryMetadata metadata) {
  BowVector bow;
  FeatureVector direct;
  RECOG_RETURN_IF_ERROR(vocabulary_->Transform(features.descriptors, &bow, &direct,
                                               int(info_.config.direct_index_levels_up),
                                               TraitsOf(info_.config.scoring).normalization));
  return AddConverted(bow, direct, features, std::move(metadata));
}

StatusOr<EntryId> Database::AddConverted(const BowVector& bow, const FeatureVector& direct,
                                         const FeatureSet& features, EntryMetadata metadata,
                                         std::vector<cv::Point3f> points,
                                         const cv::Matx33d& camera) {
  RECOG_RETURN_IF_ERROR(CheckDescriptorMatrix(features.descriptors, info_.config.descriptor));
  const size_t rows = features.descriptors.empty() ? 0 : size_t(features.descriptors.rows);
  if (features.keypoints.size() != rows) {
    return Status::InvalidArgument("entry has " + std::to_string(features.keypoints.size()) +
                                   " keypoints but " + std::to_string(rows) + " descriptors");
  }
  if (!points.empty() && points.size() != rows) {
    return Status::InvalidArgument("entry has " + std::to_string(points.size()) +
                                   " 3D points but " + std::to_string(rows) + " descriptors");
  }
  if (camera != cv::Matx33d::zeros() &&
      !(camera(0, 0) > 0.0 && camera(1, 1) > 0.0 && cv::checkRange(camera))) {
    return Status::InvalidArgument("entry camera matrix needs finite fx, fy > 0");
  }
  if (metadata.user_data.size() > kMaxUserDataBytes) {
    return Status::InvalidArgument("entry user data exceeds 64 KiB");
  }
  if (metadata.client_id.size() > kMaxClientIdBytes) {
    return Status::InvalidArgument("entry client id exceeds " + std::to_string(kMaxClientIdBytes) +
                                   " bytes");
  }
  metadata.num_features = uint32_t(rows);
  if (std::string problem = CheckParts(bow, direct, metadata.num_features); !problem.empty()) {
    return Status::InvalidArgument("entry does not fit map '" + info_.config.name +
                                   "': " + problem);
  }

  std::lock_guard write_lock(write_mutex_);
  EntryRecord record;
  {
    std::shared_lock read_lock(index_mutex_);
    record.id = next_id_;
  }
  if (record.id == kInvalidEntryId) return Status::ResourceExhausted("map is full (2^32 entries)");
  record.metadata = std::move(metadata);
  record.bow = bow;
  record.direct = direct;
  record.keypoints = features.keypoints;
  record.descriptors = features.descriptors;
  record.points = std::move(points);
  record.camera = camera;
  // The store write happens outside the index lock: queries go on meanwhile.
  RECOG_RETURN_IF_ERROR(store_->CommitEntry(info_.id, record));
  std::unique_lock index_lock(index_mutex_);
  IndexEntry(record.id, record.bow);
  next_id_ = record.id + 1;
  return record.id;
}

template <ScoringType kType>
void Database::ScoreEntries(const BowVector& query, const QueryOptions& options, EntryId bound,
                            std::vector<QueryResult>* touched) const {
  thread_local QueryScratch scratch;
  const double constant = QueryConstant(kType, query);
  const float* const scales = entry_scale_.data();
  if (options.full_scan_postings == 0 || num_postings_ <= options.full_scan_postings ||
      !scratch.SplitByListLength(query, postings_, options.full_scan_postings)) {
    ScanLists<kType>(
        postings_, *vocabulary_, scales, query.entries(), bound, scratch,
        [&](EntryId range_begin, double* sums, size_t count) {
          TakeTouched(sums, count, 1.0, &kNoFloor, [&](size_t offset, double sum) {
            touched->push_back({range_begin + EntryId(offset), FinishScore(kType, sum, constant)});
          });
        });
    return;
  }
  // Bounded query: the rarest words' lists are read in full; the entries that score best on them
  // (kept range by range, while their sums are in the cache) get the commoner words' terms too.
  const size_t keep = std::max(options.rescored_candidates, options.max_results);
  const double sign = TraitsOf(kType).higher_is_better ? 1.0 : -1.0;
  const auto better = BetterResult(true);
  std::vector<QueryResult>& best = scratch.candidates;  // a heap, the worst on top
  best.clear();
  // An entry is kept only above the worst kept one (ranges come in increasing id order, so a tie
  // goes to the kept one): TakeTouched passes only those, and none at all until `keep` are kept.
  double worst_kept = kNoFloor;
  ScanLists<kType>(postings_, *vocabulary_, scales, scratch.scanned_words, bound, scratch,
                   [&](EntryId range_begin, double* sums, size_t count) {
                     TakeTouched(sums, count, sign, &worst_kept, [&](size_t offset, double sum) {
                       const QueryResult candidate{range_begin + EntryId(offset), sign * sum};
                       if (best.size() == keep) {
                         if (!better(candidate, best.front())) return;
                         std::pop_heap(best.begin(), best.end(), better);
                         best.pop_back();
                       }
                       best.push_back(candidate);
                       std::push_heap(best.begin(), best.end(), better);
                       if (best.size() == keep) worst_kept = best.front().score;
                     });
                   });
  // From here on each candidate's score is its sum of terms (sign is +-1: exact).
  touched->clear();
  for (const QueryResult& b : best) touched->push_back({b.id, sign * b.score});
  const std::span<const BowEntry> completed = scratch.completed_words;
  std::sort(touched->begin(), touched->end(),
            [](const QueryResult& a, const QueryResult& b) { return a.id < b.id; });
  std::vector<size_t>& blocks = scratch.candidate_blocks;
  blocks.resize(touched->size());
  constexpr size_t kBlocksAhead = 8;
  for (size_t w = 0; w < completed.size(); ++w) {
    if (w + 2 < completed.size()) __builtin_prefetch(&postings_[completed[w + 2].word]);
    if (w + 1 < completed.size()) {
      __builtin_prefetch(postings_[completed[w + 1].word].block_index_address());
    }
    const BowEntry& q = completed[w];
    const PostingList& list = postings_[q.word];
    if (q.value <= 0.f || list.empty()) continue;
    const float word_weight = vocabulary_->WordWeight(q.word);
    // Where each candidate's posting would be (the candidates in increasing id order), from the
    // small array of block starts; then the blocks, the first few fetched at once and the others
    // a few candidates ahead.
    size_t block = PostingList::kNotFound;
    for (size_t i = 0; i < blocks.size(); ++i) {
      block = blocks[i] = list.BlockOf((*touched)[i].id, block);
    }
    const auto fetch_block = [&](size_t i) {
      if (i >= blocks.size() || blocks[i] == PostingList::kNotFound) return;
      const size_t position = blocks[i] * PostingList::kBlock;
      __builtin_prefetch(list.address(position));
      __builtin_prefetch(list.address(position + PostingList::kBlock - 1));
    };
    for (size_t i = 0; i < kBlocksAhead; ++i) fetch_block(i);
    for (size_t i = 0; i < blocks.size(); ++i) {
      fetch_block(i + kBlocksAhead);
      if (blocks[i] == PostingList::kNotFound) continue;
      QueryResult& candidate = (*touched)[i];
      if (const size_t p = list.FindInBlock(blocks[i], candidate.id); p != PostingList::kNotFound) {
        candidate.score +=
            PostingTerm<kType>(q.value, list.ValueAt(p, word_weight, scales[candidate.id]));
      }
    }
  }
  for (QueryResult& r : *touched) r.score = FinishScore(kType, r.score, constant);
}

Status Database::CheckQueryWords(const BowVector& query) const {
  const size_t words = vocabulary_->num_words();
  for (const BowEntry& e : query.entries()) {
    if (e.word >= words) {
      return Status::InvalidArgument("query word " + std::to_string(e.word) +
                                     " is outside the vocabulary (" + std::to_string(words) +
                                     " words)");
    }
  }
  return Status::Ok();
}

Status Database::QueryBcMatching(const BowVector& query, double beta, size_t max_results,
                                 std::vector<BcMatch>* results) const {
  results->clear();
  if (TraitsOf(info_.config.scoring).normalization != BowNormalization::kL1) {
    return Status::FailedPrecondition("BC matching needs a map of L1-normalised vectors; map '" +
                                      info_.config.name + "' is scored with " +
                                      std::string(ScoringName(info_.config.scoring)));
  }
  RECOG_RETURN_IF_ERROR(CheckQueryWords(query));
  if (max_results == 0) return Status::Ok();
  thread_local QueryScratch scratch;
  {
    std::shared_lock lock(index_mutex_);
    scratch.PrepareStamps(next_id_);
    const uint8_t generation = scratch.generation;
    double* const bhattacharyya = scratch.score.data();
    double* const chi_square = scratch.second_score.data();
    uint8_t* const stamp = scratch.stamp.data();
    for (const BowEntry& q : query.entries()) {
      if (q.value <= 0.f) continue;
      const double v = q.value;
      postings_[q.word].ForEach(vocabulary_->WordWeight(q.word), entry_scale_.data(),
                                [&](EntryId entry, float value) {
                                  const double w = value;
                                  if (stamp[entry] != generation) {
                                    stamp[entry] = generation;
                                    bhattacharyya[entry] = 0.0;
                                    chi_square[entry] = 0.0;
                                    results->push_back({entry, 0.0, 0.0});
                                  }
                                  bhattacharyya[entry] += std::sqrt(v * w);
                                  chi_square[entry] += 2.0 * v * w / (v + w);
                                });
    }
    for (BcMatch& r : *results) {
      r.bhattacharyya = bhattacharyya[r.id];
      r.chi_square = chi_square[r.id];
    }
  }
  double best = 0.0;
  for (const BcMatch& r : *results) best = std::max(best, r.bhattacharyya);
  const double bound = beta * best;
  std::erase_if(*results, [bound](const BcMatch& r) { return r.bhattacharyya < bound; });
  const auto better = [](const BcMatch& a, const BcMatch& b) {
    if (a.chi_square != b.chi_square) return a.chi_square > b.chi_square;
    return a.id < b.id;
  };
  const size_t keep = std::min(max_results, results->size());
  std::partial_sort(results->begin(), results->begin() + long(keep), results->end(), better);
  results->resize(keep);
  return Status::Ok();
}

Status Database::Query(const BowVector& query, const QueryOptions& options,
                       std::vector<QueryResult>* results) const {
  results->clear();
  RECOG_RETURN_IF_ERROR(CheckQueryWords(query));
  if (options.max_results == 0) return Status::Ok();
  const ScoringType type = info_.config.scoring;
  {
    std::shared_lock lock(index_mutex_);
    const EntryId bound = std::min(options.max_entry_id, next_id_);
    switch (type) {
      case ScoringType::kL1:
        ScoreEntries<ScoringType::kL1>(query, options, bound, results);
        break;
      case ScoringType::kL2:
        ScoreEntries<ScoringType::kL2>(query, options, bound, results);
        break;
      case ScoringType::kChiSquare:
        ScoreEntries<ScoringType::kChiSquare>(query, options, bound, results);
        break;
      case ScoringType::kKL:
        ScoreEntries<ScoringType::kKL>(query, options, bound, results);
        break;
      case ScoringType::kBhattacharyya:
        ScoreEntries<ScoringType::kBhattacharyya>(query, options, bound, results);
        break;
      case ScoringType::kDotProduct:
        ScoreEntries<ScoringType::kDotProduct>(query, options, bound, results);
        break;
    }
  }
  const size_t keep = std::min(options.max_results, results->size());
  std::partial_sort(results->begin(), results->begin() + long(keep), results->end(),
                    BetterResult(TraitsOf(type).higher_is_better));
  results->resize(keep);
  return Status::Ok();
}

StatusOr<EntryRecord> Database::Get(EntryId id, uint32_t parts) const {
  if (!Contains(id)) {
    return Status::NotFound("map '" + info_.config.name + "' has no entry " + std::to_string(id));
  }
  EntryRecord record;
  RECOG_RETURN_IF_ERROR(store_->ReadEntry(info_.id, id, parts, &record));
  return record;
}

bool Database::Contains(EntryId id) const {
  std::shared_lock lock(index_mutex_);
  return id < present_.size() && present_[id] != 0;
}

Status Database::ScanEntries(uint32_t parts,
                             const std::function<Status(EntryRecord&)>& visit) const {
  return store_->ScanEntries(info_.id, 0, parts, visit);
}

Status Database::Remove(EntryId id) {
  std::lock_guard write_lock(write_mutex_);
  if (!Contains(id)) {
    return Status::NotFound("map '" + info_.config.name + "' has no entry " + std::to_string(id));
  }
  EntryRecord record;
  RECOG_RETURN_IF_ERROR(store_->ReadEntry(info_.id, id, kEntryBow, &record));
  snapshot_covers_ = kInvalidEntryId;  // the store drops it, even when the removal then fails
  RECOG_RETURN_IF_ERROR(store_->RemoveEntry(info_.id, id));
  std::unique_lock index_lock(index_mutex_);
  for (const BowEntry& e : record.bow.entries()) num_postings_ -= postings_[e.word].Erase(id);
  present_[id] = 0;
  --num_entries_;
  return Status::Ok();
}

Status Database::Clear() {
  std::vector<EntryId> ids;
  {
    std::shared_lock lock(index_mutex_);
    for (EntryId id = 0; id < present_.size(); ++id) {
      if (present_[id]) ids.push_back(id);
    }
  }
  for (EntryId id : ids) RECOG_RETURN_IF_ERROR(Remove(id));
  return Status::Ok();
}

size_t Database::size() const {
  std::shared_lock lock(index_mutex_);
  return num_entries_;
}

EntryId Database::next_entry_id() const {
  std::shared_lock lock(index_mutex_);
  return next_id_;
}

DatabaseStats Database::Stats() const {
  std::shared_lock lock(index_mutex_);
  DatabaseStats stats;
  stats.entries = num_entries_;
  stats.postings = num_postings_;
  stats.next_entry_id = next_id_;
  stats.index_bytes = postings_.capacity() * sizeof(PostingList) + present_.capacity() +
                      entry_scale_.capacity() * sizeof(float);
  for (const PostingList& list : postings_) {
    stats.words_in_use += !list.empty();
    stats.values_stored_aside += list.stored_values();
    stats.index_bytes += list.capacity_bytes();
  }
  return stats;
}

}  // namespace recog
