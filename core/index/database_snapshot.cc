// Database::SaveSnapshot and Database::LoadSnapshot: the in-memory index written to the store as
// one checksummed snapshot, and read back (database.h says what a snapshot holds). Kept apart from
// the index itself (database.cc): this file is the snapshot's byte format and its checks, which
// change only with kSnapshotVersion.
#include "core/index/database.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <memory>
#include <new>

#include <xxhash.h>

namespace recog {
namespace {

// The snapshot's framing (Database::SaveSnapshot): the header, and writing or reading the bytes
// while hashing them with XXH3-64 (about 20 GB/s, far faster than the disk).
constexpr char kSnapshotMagic[8] = {'R', 'C', 'G', 'I', 'N', 'D', 'E', 'X'};
constexpr uint32_t kSnapshotVersion = 2;
static_assert(std::endian::native == std::endian::little, "snapshots are little-endian");

struct SnapshotHeader {
  char magic[8];
  uint32_t version;
  uint32_t map_id;
  uint64_t vocabulary_checksum;
  uint64_t words;
  uint64_t covers;
  uint64_t entries;
  uint64_t postings;
};
static_assert(sizeof(SnapshotHeader) == 56);

struct HashStateDeleter {
  void operator()(XXH3_state_t* state) const { XXH3_freeState(state); }
};
using HashState = std::unique_ptr<XXH3_state_t, HashStateDeleter>;

HashState NewHashState() {
  HashState state(XXH3_createState());
  if (state == nullptr) throw std::bad_alloc();
  XXH3_64bits_reset(state.get());
  return state;
}

// Buffers what it writes (the lists of a large vocabulary are mostly a few bytes each) and hashes
// it; Finish appends the hash.
class SnapshotEncoder {
 public:
  explicit SnapshotEncoder(IndexStore::SnapshotWriter* writer) : writer_(writer) {
    buffer_.reserve(kBufferBytes);
  }
  Status Write(const void* data, size_t size) {
    if (size == 0) return Status::Ok();  // `data` may be null then
    XXH3_64bits_update(hash_.get(), data, size);
    bytes_ += size;
    if (buffer_.size() + size > kBufferBytes) RECOG_RETURN_IF_ERROR(FlushBuffer());
    if (size >= kBufferBytes) return writer_->Append({static_cast<const char*>(data), size});
    buffer_.append(static_cast<const char*>(data), size);
    return Status::Ok();
  }
  Status Finish() {
    const uint64_t hash = XXH3_64bits_digest(hash_.get());
    buffer_.append(reinterpret_cast<const char*>(&hash), sizeof(hash));
    bytes_ += sizeof(hash);
    return FlushBuffer();
  }
  uint64_t bytes() const { return bytes_; }

 private:
  static constexpr size_t kBufferBytes = size_t(1) << 20;
  Status FlushBuffer() {
    if (buffer_.empty()) return Status::Ok();
    const Status appended = writer_->Append(buffer_);
    buffer_.clear();
    return appended;
  }

  IndexStore::SnapshotWriter* writer_;
  HashState hash_ = NewHashState();
  std::string buffer_;
  uint64_t bytes_ = 0;
};

// Reads and hashes; Finish checks the hash at the end and that nothing follows it.
class SnapshotDecoder {
 public:
  explicit SnapshotDecoder(IndexStore::SnapshotReader* reader) : reader_(reader) {}
  Status Read(void* data, size_t size) {
    if (size == 0) return Status::Ok();  // `data` may be null then
    RECOG_RETURN_IF_ERROR(reader_->Read(data, size));
    XXH3_64bits_update(hash_.get(), data, size);
    bytes_ += size;
    return Status::Ok();
  }
  // The bytes left to read: what a length read from the snapshot, not yet checked by its
  // checksum, is bounded by before anything is allocated for it.
  uint64_t remaining() const { return reader_->size() - std::min(reader_->size(), bytes_); }
  Status Finish() {
    uint64_t stored = 0;
    RECOG_RETURN_IF_ERROR(reader_->Read(&stored, sizeof(stored)));
    if (stored != XXH3_64bits_digest(hash_.get())) {
      return Status::DataLoss("the snapshot's checksum does not match its bytes");
    }
    if (bytes_ + sizeof(stored) != reader_->size()) {
      return Status::DataLoss("the snapshot has " +
                              std::to_string(reader_->size() - bytes_ - sizeof(stored)) +
                              " bytes after its checksum");
    }
    return Status::Ok();
  }

 private:
  IndexStore::SnapshotReader* reader_;
  HashState hash_ = NewHashState();
  uint64_t bytes_ = 0;
};

}  // namespace

StatusOr<uint64_t> Database::SaveSnapshot() {
  std::lock_guard write_lock(write_mutex_);
  std::shared_lock index_lock(index_mutex_);
  if (snapshot_covers_ == next_id_) return uint64_t{0};
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<IndexStore::SnapshotWriter> writer,
                         store_->WriteSnapshot(info_.id, next_id_));
  SnapshotEncoder out(writer.get());
  SnapshotHeader header{};
  std::memcpy(header.magic, kSnapshotMagic, sizeof(header.magic));
  header.version = kSnapshotVersion;
  header.map_id = info_.id;
  header.vocabulary_checksum = info_.config.vocabulary_checksum;
  header.words = postings_.size();
  header.covers = next_id_;
  header.entries = num_entries_;
  header.postings = num_postings_;
  RECOG_RETURN_IF_ERROR(out.Write(&header, sizeof(header)));
  RECOG_RETURN_IF_ERROR(out.Write(present_.data(), next_id_));
  RECOG_RETURN_IF_ERROR(out.Write(entry_scale_.data(), next_id_ * sizeof(float)));
  const auto write_array = [&out](const auto& items) {
    const uint32_t count = uint32_t(items.size());
    RECOG_RETURN_IF_ERROR(out.Write(&count, sizeof(count)));
    return out.Write(items.data(), count * sizeof(items[0]));
  };
  for (const PostingList& list : postings_) {
    RECOG_RETURN_IF_ERROR(write_array(list.parts().postings));
    RECOG_RETURN_IF_ERROR(write_array(list.parts().page_end));
    RECOG_RETURN_IF_ERROR(write_array(list.parts().stored));
  }
  RECOG_RETURN_IF_ERROR(out.Finish());
  RECOG_RETURN_IF_ERROR(writer->Commit());
  snapshot_covers_ = next_id_;
  return out.bytes();
}

Status Database::LoadSnapshot(IndexStore::SnapshotReader& reader) {
  SnapshotDecoder in(&reader);
  SnapshotHeader header{};
  RECOG_RETURN_IF_ERROR(in.Read(&header, sizeof(header)));
  const auto mismatch = [](const std::string& what, uint64_t stored, uint64_t expected) {
    return Status::DataLoss("the snapshot's " + what + " is " + std::to_string(stored) + ", not " +
                            std::to_string(expected));
  };
  if (std::memcmp(header.magic, kSnapshotMagic, sizeof(header.magic)) != 0) {
    return Status::DataLoss("the snapshot does not start with its magic bytes");
  }
  if (header.version != kSnapshotVersion) {
    return mismatch("format version", header.version, kSnapshotVersion);
  }
  if (header.map_id != info_.id) return mismatch("map id", header.map_id, info_.id);
  if (header.vocabulary_checksum != info_.config.vocabulary_checksum) {
    return mismatch("vocabulary checksum", header.vocabulary_checksum,
                    info_.config.vocabulary_checksum);
  }
  if (header.words != postings_.size())
    return mismatch("word count", header.words, postings_.size());
  if (header.covers != reader.covers()) {
    return mismatch("entry id bound", header.covers, reader.covers());
  }
  if (header.covers > next_id_) {
    return Status::DataLoss("the snapshot covers entry ids up to " + std::to_string(header.covers) +
                            ", beyond the map's next id " + std::to_string(next_id_));
  }
  const EntryId covers = EntryId(header.covers);
  RECOG_RETURN_IF_ERROR(in.Read(present_.data(), covers));
  for (EntryId id = 0; id < covers; ++id) {
    if (present_[id] > 1) return Status::DataLoss("the snapshot's entry flags are not 0 or 1");
    num_entries_ += present_[id];
  }
  if (num_entries_ != header.entries) return mismatch("entry count", num_entries_, header.entries);
  RECOG_RETURN_IF_ERROR(in.Read(entry_scale_.data(), covers * sizeof(float)));
  for (EntryId id = 0; id < covers; ++id) {
    if (!std::isfinite(entry_scale_[id]) || entry_scale_[id] < 0.f) {
      return Status::DataLoss("the snapshot's entry scales are not finite and positive");
    }
  }
  // Reads an array's length and items into `items`, with room for `capacity(length)` of them;
  // the length must fit the bytes left (checked before anything is allocated for it, since the
  // checksum is only read at the end).
  const auto read_array = [&in](auto* items, const auto& capacity) {
    uint32_t count = 0;
    RECOG_RETURN_IF_ERROR(in.Read(&count, sizeof(count)));
    if (uint64_t(count) * sizeof((*items)[0]) > in.remaining()) {
      return Status::DataLoss("the snapshot's lists hold more than its bytes");
    }
    items->reserve(capacity(count));
    items->resize(count);
    return in.Read(items->data(), count * sizeof((*items)[0]));
  };
  const auto exact = [](size_t count) { return count; };
  for (size_t word = 0; word < postings_.size(); ++word) {
    PostingList::Parts parts;
    RECOG_RETURN_IF_ERROR(read_array(&parts.postings, [word](size_t count) {
      return PostingList::RestoredCapacity(count, uint32_t(word));
    }));
    RECOG_RETURN_IF_ERROR(read_array(&parts.page_end, exact));
    RECOG_RETURN_IF_ERROR(read_array(&parts.stored, exact));
    const size_t count = parts.postings.size();
    if (count > header.postings - num_postings_) {
      return Status::DataLoss("the snapshot's lists hold more than its " +
                              std::to_string(header.postings) + " postings");
    }
    const std::string problem =
        postings_[word].Restore(std::move(parts), covers, present_.data(),
                                vocabulary_->WordWeight(WordId(word)), entry_scale_.data());
    if (!problem.empty()) {
      return Status::DataLoss("the snapshot's list of word " + std::to_string(word) + " has " +
                              problem);
    }
    num_postings_ += count;
  }
  if (num_postings_ != header.postings) {
    return mismatch("posting count", num_postings_, header.postings);
  }
  return in.Finish();
}

}  // namespace recog
