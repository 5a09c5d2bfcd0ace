#include "core/index/database.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <span>
#include <thread>

namespace recog {
namespace {

constexpr size_t kMaxUserDataBytes = 64 * 1024;

// Appends with 25 % headroom instead of doubling, so that a posting list wastes at most a quarter
// of its size: about 10 bytes per 8-byte posting on average.
template <class T>
void AppendCompact(std::vector<T>& v, const T& item) {
  if (v.size() == v.capacity()) v.reserve(v.size() + v.size() / 4 + 4);
  v.push_back(item);
}

// Per-thread accumulators of a query: a score and a one-byte stamp per entry id. An entry whose
// stamp is not the current query's generation has not been touched yet, so nothing is cleared
// between queries but once every 255 (when the generation wraps). One byte rather than four keeps
// the stamps of a million entries in 1 MB of each querying thread, where the cache can hold them;
// the queries took the same time either way (bench_database's Scale cases, A/B).
struct QueryScratch {
  std::vector<double> score;
  std::vector<double> second_score;  // BC matching's chi-square sums
  std::vector<uint8_t> stamp;
  uint8_t generation = 0;

  void Prepare(size_t entries) {
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
};

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

  // Rebuild the index, checking every entry on the way. Appending posting by posting to a
  // million lists would miss the cache twice per posting, so the scan first routes the postings
  // into buckets by word-id range (sequential appends); each bucket is then spread over its lists,
  // which fit in the cache, each list being allocated once at its final size. Entries arrive in
  // id order, so every list ends up sorted by entry id.
  const size_t words = db->postings_.size();
  const int shift = std::max(0, int(std::bit_width(words)) - 6);  // about 64 buckets
  std::vector<std::vector<PendingPosting>> buckets(((words - 1) >> shift) + 1);
  std::vector<uint32_t> count(words, 0);
  const Status scanned = store->ScanEntries(
      db->info_.id, kEntryMetadata | kEntryBow | kEntryDirect, [&](EntryRecord& record) -> Status {
        std::string problem;
        if (record.id >= db->next_id_) {
          problem = "id is beyond the map's next id " + std::to_string(db->next_id_);
        } else {
          problem = db->CheckParts(record.bow, record.direct, record.metadata.num_features);
        }
        if (!problem.empty()) {
          return Status::DataLoss("map '" + name + "' entry " + std::to_string(record.id) + ": " +
                                  problem);
        }
        for (const BowEntry& e : record.bow.entries()) {
          ++count[e.word];
          buckets[e.word >> shift].push_back({e.word, {record.id, e.value}});
        }
        db->present_[record.id] = 1;
        ++db->num_entries_;
        db->num_postings_ += record.bow.size();
        return Status::Ok();
      });
  RECOG_RETURN_IF_ERROR(scanned);
  // Buckets cover disjoint words: two threads fill them without sharing a list.
  auto fill = [&](size_t first_bucket) {
    for (size_t b = first_bucket; b < buckets.size(); b += 2) {
      const size_t end_word = std::min(words, (b + 1) << shift);
      for (size_t w = b << shift; w < end_word; ++w) db->postings_[w].reserve(count[w]);
      for (const PendingPosting& p : buckets[b]) db->postings_[p.word].push_back(p.posting);
      std::vector<PendingPosting>().swap(buckets[b]);  // release as we go
    }
  };
  std::thread helper(fill, 1);
  fill(0);
  helper.join();
  return db;
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
  for (const BowEntry& e : bow.entries()) AppendCompact(postings_[e.word], Posting{id, e.value});
  if (present_.size() <= id) present_.resize(size_t(id) + 1, 0);
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
void Database::ScoreEntries(const BowVector& query, EntryId bound,
                            std::vector<QueryResult>* touched) const {
  thread_local QueryScratch scratch;
  scratch.Prepare(next_id_);
  const uint8_t generation = scratch.generation;
  double* const score = scratch.score.data();
  uint8_t* const stamp = scratch.stamp.data();
  // Each word's posting list is a cache miss away (its vector, then its first postings), which
  // costs more than scoring a short list: the lists of the words a few steps ahead are fetched
  // meanwhile. (Measured by bench_place Relocalize_Group10x2600_vs_One26K, whose small maps have
  // short lists.)
  const std::span<const BowEntry> words = query.entries();
  constexpr size_t kListsAhead = 4, kVectorsAhead = 8;
  for (size_t i = 0; i < words.size(); ++i) {
    if (i + kVectorsAhead < words.size())
      __builtin_prefetch(&postings_[words[i + kVectorsAhead].word]);
    if (i + kListsAhead < words.size())
      __builtin_prefetch(postings_[words[i + kListsAhead].word].data());
    const BowEntry& q = words[i];
    if (q.value <= 0.f) continue;
    const double v = q.value;
    for (const Posting& p : postings_[q.word]) {
      if (p.entry >= bound) break;  // postings are sorted by entry id
      const double term = CommonTerm(kType, v, p.value);
      if (stamp[p.entry] != generation) {
        stamp[p.entry] = generation;
        score[p.entry] = term;
        touched->push_back({p.entry, 0.0});
      } else {
        score[p.entry] += term;
      }
    }
  }
  const double constant = QueryConstant(kType, query);
  for (QueryResult& r : *touched) r.score = FinishScore(kType, score[r.id], constant);
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
    scratch.Prepare(next_id_);
    const uint8_t generation = scratch.generation;
    double* const bhattacharyya = scratch.score.data();
    double* const chi_square = scratch.second_score.data();
    uint8_t* const stamp = scratch.stamp.data();
    for (const BowEntry& q : query.entries()) {
      if (q.value <= 0.f) continue;
      const double v = q.value;
      for (const Posting& p : postings_[q.word]) {
        const double w = p.value;
        if (stamp[p.entry] != generation) {
          stamp[p.entry] = generation;
          bhattacharyya[p.entry] = 0.0;
          chi_square[p.entry] = 0.0;
          results->push_back({p.entry, 0.0, 0.0});
        }
        bhattacharyya[p.entry] += std::sqrt(v * w);
        chi_square[p.entry] += 2.0 * v * w / (v + w);
      }
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
        ScoreEntries<ScoringType::kL1>(query, bound, results);
        break;
      case ScoringType::kL2:
        ScoreEntries<ScoringType::kL2>(query, bound, results);
        break;
      case ScoringType::kChiSquare:
        ScoreEntries<ScoringType::kChiSquare>(query, bound, results);
        break;
      case ScoringType::kKL:
        ScoreEntries<ScoringType::kKL>(query, bound, results);
        break;
      case ScoringType::kBhattacharyya:
        ScoreEntries<ScoringType::kBhattacharyya>(query, bound, results);
        break;
      case ScoringType::kDotProduct:
        ScoreEntries<ScoringType::kDotProduct>(query, bound, results);
        break;
    }
  }
  const bool higher_is_better = TraitsOf(type).higher_is_better;
  const auto better = [higher_is_better](const QueryResult& a, const QueryResult& b) {
    if (a.score != b.score) return higher_is_better ? a.score > b.score : a.score < b.score;
    return a.id < b.id;
  };
  const size_t keep = std::min(options.max_results, results->size());
  std::partial_sort(results->begin(), results->begin() + long(keep), results->end(), better);
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
  return store_->ScanEntries(info_.id, parts, visit);
}

Status Database::Remove(EntryId id) {
  std::lock_guard write_lock(write_mutex_);
  if (!Contains(id)) {
    return Status::NotFound("map '" + info_.config.name + "' has no entry " + std::to_string(id));
  }
  EntryRecord record;
  RECOG_RETURN_IF_ERROR(store_->ReadEntry(info_.id, id, kEntryBow, &record));
  RECOG_RETURN_IF_ERROR(store_->RemoveEntry(info_.id, id));
  std::unique_lock index_lock(index_mutex_);
  for (const BowEntry& e : record.bow.entries()) {
    std::vector<Posting>& list = postings_[e.word];
    auto it = std::lower_bound(list.begin(), list.end(), id,
                               [](const Posting& p, EntryId value) { return p.entry < value; });
    if (it != list.end() && it->entry == id) {
      list.erase(it);
      --num_postings_;
    }
  }
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
  stats.index_bytes = postings_.capacity() * sizeof(std::vector<Posting>) + present_.capacity();
  for (const auto& list : postings_) {
    stats.words_in_use += !list.empty();
    stats.index_bytes += list.capacity() * sizeof(Posting);
  }
  return stats;
}

}  // namespace recog
