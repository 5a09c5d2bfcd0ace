// PostingList: one word's postings in Database's inverted index, three bytes each.
//
// A posting is an entry that contains the word, with the entry's weight (value) for it. The list
// keeps its postings sorted by entry id and splits the ids into pages of 65,536: a posting holds
// the low 16 bits of its id, and a directory holds where each page's postings end (4 bytes per
// page up to the list's last one). Its value costs one byte: a bag of words made by the vocabulary
// weighs a word by the word's weight (idf) times its occurrences in the entry times one scale
// common to the whole entry (the tf denominator and the normalisation), so the byte holds the
// occurrences (1 to 31) and how many float steps (-3 to +3) the stored value lies from
// word weight x occurrences x entry scale computed in float (roundings). Every posting is checked
// as it is appended: it decodes to exactly the value given, bit for bit, or it keeps that value on
// the side (a bag of words from elsewhere, an entry with a word more than 31 times), so scores are
// exactly those of the uncompressed values. The caller keeps each entry's scale (FitScale).
//
// A query reads a list range by range (VisitRange, within one page, in increasing id order) or
// looks single entries up (BlockOf, FindInBlock): every kBlock-th posting's entry id is kept, so
// a lookup walks that small array and counts within one block of 96 bytes.
//
// Lists grow by an eighth at a time rather than doubling: with 3-byte postings, headroom would
// otherwise be a third of the index.
//
// Thread safety: none of its own; Database appends under its exclusive lock and reads under the
// shared one.
#pragma once

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/bow/bow_vector.h"
#include "core/index/entry.h"

namespace recog {

class Vocabulary;

class PostingList {
 public:
  static constexpr int kPageBits = 16;
  static constexpr size_t kBlock = 32;
  static constexpr size_t kNotFound = SIZE_MAX;
  static constexpr uint32_t kMaxOccurrences = 31;

  // A posting: the low bits of its entry id, then its value's code (occurrences << 3 | float
  // steps + 3, or kStoredCode when the value is kept on the side).
  struct Posting {
    uint8_t low[2];
    uint8_t code;
    uint32_t Low() const { return uint32_t(low[0]) | uint32_t(low[1]) << 8; }
  };
  static_assert(sizeof(Posting) == 3);
  // A value kept as it is, by the position of its posting.
  struct StoredValue {
    uint32_t position;
    float value;
  };
  static_assert(sizeof(StoredValue) == 8);
  // Everything a list holds but its block index: what a snapshot writes and restores.
  struct Parts {
    std::vector<Posting> postings;
    std::vector<uint32_t> page_end;  // by page: one past its last posting
    std::vector<StoredValue> stored;
  };

  // The scale of an entry whose bag of words is `bow` (made with `vocabulary`): what its values
  // divided by their word's weight are whole multiples of, as closely as the floats allow; 0 when
  // none is (every value is then stored as it is).
  static float FitScale(std::span<const BowEntry> bow, const Vocabulary& vocabulary);

  // Appends `entry`, above every entry in the list, with `value`; `word_weight` is the word's
  // weight in the vocabulary and `entry_scale` the entry's FitScale.
  void Append(EntryId entry, float value, float word_weight, float entry_scale);
  // Removes the posting of `entry`; false when there is none.
  bool Erase(EntryId entry);
  void Reserve(size_t postings);
  // The capacity to give the postings of word `word`'s list when `postings` of them are restored
  // from a snapshot: room for between none and one growth step more, spread by the word. A list
  // that grew posting by posting has such room, at a point of its growth that differs from list
  // to list. A restored list without room would copy itself on its first new posting, every list
  // at once (tens of milliseconds per frame in a map of a million frames after a restart), and
  // with the same room in every list they would all fill up together again later.
  static size_t RestoredCapacity(size_t postings, uint32_t word);

  size_t size() const { return parts_.postings.size(); }
  bool empty() const { return parts_.postings.empty(); }
  size_t stored_values() const { return parts_.stored.size(); }
  size_t capacity_bytes() const;
  // Where posting `position` is in memory (a prefetch hint; `position` may be the end).
  const void* address(size_t position) const { return parts_.postings.data() + position; }
  // Where the block index is in memory (a prefetch hint).
  const void* block_index_address() const { return block_first_.data(); }

  // Where page `page`'s postings end: the position after its last one (the list's size when no
  // posting is on that page or after it). A page's postings start where the previous page's end.
  size_t PageEnd(size_t page) const {
    return page < parts_.page_end.size() ? parts_.page_end[page] : size();
  }
  // Where PageEnd(page) is in memory (a prefetch hint).
  const void* page_end_address(size_t page) const {
    return parts_.page_end.data() + std::min(page, parts_.page_end.size());
  }

  // Calls visit(entry, value) for the postings from *position on, before `stop` (a PageEnd) and
  // with an entry below `end`, where `page` is the page of those postings, in increasing entry
  // order; leaves *position after the last posting visited. A scan that goes range by range
  // through the ids (no range across two pages) thus reads each posting once. `entry_scales` is
  // indexed by entry id. `visit` is copied, so that its captures are locals the compiler can keep
  // in registers.
  template <class Visit>
  void VisitRange(size_t* position, size_t stop, uint64_t page, uint64_t end, float word_weight,
                  const float* entry_scales, const Visit& visit) const {
    Visit local_visit = visit;
    const uint32_t base = uint32_t(page << kPageBits);
    const uint64_t low_end = end - base;
    const Posting* const postings = parts_.postings.data();
    size_t p = *position;
    for (; p < stop; ++p) {
      const uint32_t low = postings[p].Low();
      if (low >= low_end) break;
      const EntryId entry = base | low;
      local_visit(entry, ValueOf(p, postings[p].code, word_weight, entry_scales[entry]));
    }
    *position = p;
  }
  // Calls visit(entry, value) for every posting, in increasing entry order.
  template <class Visit>
  void ForEach(float word_weight, const float* entry_scales, const Visit& visit) const {
    size_t position = 0;
    for (uint64_t page = 0; page < parts_.page_end.size(); ++page) {
      VisitRange(&position, parts_.page_end[page], page, (page + 1) << kPageBits, word_weight,
                 entry_scales, visit);
    }
  }

  // The block that holds `entry` if any posting does: the last one starting at or before it,
  // walked to from block `from` (the previous answer, for entries in increasing order; kNotFound
  // to start at the first); kNotFound when `entry` precedes every posting.
  size_t BlockOf(EntryId entry, size_t from) const {
    const std::vector<EntryId>& first = block_first_;
    if (first.empty() || entry < first[0]) return kNotFound;
    size_t block = from == kNotFound ? 0 : from;
    while (block + 1 < first.size() && first[block + 1] <= entry) ++block;
    return block;
  }
  // The position of `entry`'s posting in `block`, or kNotFound.
  size_t FindInBlock(size_t block, EntryId entry) const {
    const size_t page = entry >> kPageBits;
    if (page >= parts_.page_end.size()) return kNotFound;
    const size_t begin = std::max(block * kBlock, PageBegin(page));
    const size_t end = std::min(block * kBlock + kBlock, size_t(parts_.page_end[page]));
    const uint32_t low = entry & ((1u << kPageBits) - 1);
    const Posting* const postings = parts_.postings.data();
    size_t below = 0;  // counted rather than searched: no branch to mispredict
    for (size_t i = begin; i < end; ++i) below += postings[i].Low() < low;
    const size_t found = begin + below;
    return found < end && postings[found].Low() == low ? found : kNotFound;
  }
  // The value of the posting at `position`, whose entry has `entry_scale`.
  float ValueAt(size_t position, float word_weight, float entry_scale) const {
    return ValueOf(position, parts_.postings[position].code, word_weight, entry_scale);
  }

  const Parts& parts() const { return parts_; }
  // Replaces the list with `parts` (from a snapshot) after checking them: every posting's entry
  // below `covers` and flagged in `present`, entries increasing, values finite and not negative.
  // Returns what is wrong (the list is then left empty), or an empty string.
  std::string Restore(Parts parts, EntryId covers, const uint8_t* present, float word_weight,
                      const float* entry_scales);

 private:
  static constexpr uint8_t kStoredCode = 7;  // the low three bits of a stored value's code

  // The value that `occurrences` encode before the float steps: computed the same way when a
  // posting is appended and when it is read.
  static float Estimate(float word_weight, uint32_t occurrences, float entry_scale) {
    return word_weight * float(occurrences) * entry_scale;
  }
  float ValueOf(size_t position, uint8_t code, float word_weight, float entry_scale) const {
    if ((code & 7) == kStoredCode) [[unlikely]] {
      return StoredValueAt(position);
    }
    return Decode(code, word_weight, entry_scale);
  }
  static float Decode(uint8_t code, float word_weight, float entry_scale) {
    const uint32_t bits = std::bit_cast<uint32_t>(Estimate(word_weight, code >> 3, entry_scale));
    return std::bit_cast<float>(bits + (code & 7) - 3);
  }
  float StoredValueAt(size_t position) const;
  size_t PageBegin(size_t page) const { return page == 0 ? 0 : parts_.page_end[page - 1]; }
  EntryId EntryAt(size_t position) const;
  void IndexBlocks(size_t first_block);  // recomputes block_first_ from that block on

  Parts parts_;
  std::vector<EntryId> block_first_;  // the entry of every kBlock-th posting
};

}  // namespace recog
