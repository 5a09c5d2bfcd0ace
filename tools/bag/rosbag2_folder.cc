// OpenRosbag2Folder: a rosbag2 folder as one store over its files.
//
// The files are the ones metadata.yaml lists, in its order (a split bag), or, in a folder without
// metadata.yaml, every file that is an sqlite3, MCAP or zstd file, in natural name order (x_2
// before x_10). Each is opened by its content. A zstd file (compression mode FILE, X.db3.zstd) is
// first decompressed into a temporary folder under std::filesystem::temp_directory_path(),
// removed when the store is destroyed; one file may decompress to at most 16 GiB, and to no more
// than the space free in that folder when it starts.
//
// The store lists the topics of all its files (the same name in several files adds the counts;
// a different type or serialization is an error) and those metadata.yaml names that no file has
// (with 0 messages); metadata.yaml's serialization formats are checked too, since a file's own
// tables may say cdr for a bag rosbag2 itself refuses. A topic's messages are visited file by
// file, in file order. A message's id is its file's own id when the folder has one file; with
// several, the file's index goes into bits 52 to 62 of the file's id, which neither store uses
// in practice (an sqlite3 row id below 2^52; an MCAP file offset below 2^52, or bit 63 and a
// chunk number below 2^20): a folder holds at most 2048 files, and a message whose file id uses
// those bits is refused as RESOURCE_EXHAUSTED when visited.

#include <stdlib.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <system_error>

#include "tools/bag/bag_store.h"
#include "tools/bag/decompress.h"
#include "tools/bag/rosbag2_metadata.h"

namespace recog::bag {
namespace {

namespace fs = std::filesystem;

constexpr unsigned kFileIndexShift = 52;
constexpr size_t kMaxFiles = 2048;
constexpr uint64_t kFileIndexBits = uint64_t(kMaxFiles - 1) << kFileIndexShift;
constexpr uint64_t kMaxDecompressedFileBytes = uint64_t(16) << 30;

enum class FileKind { kSqlite3, kMcap, kZstd, kOther };

FileKind KindOf(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  std::string start(16, '\0');
  file.read(start.data(), std::streamsize(start.size()));
  start.resize(size_t(file.gcount()));
  if (start.starts_with(std::string_view("SQLite format 3\0", 16))) return FileKind::kSqlite3;
  if (start.starts_with("\x89MCAP")) return FileKind::kMcap;
  if (StartsWithZstdMagic(start)) return FileKind::kZstd;
  return FileKind::kOther;
}

// "a_2" before "a_10": runs of digits compare by their value.
bool NaturalLess(std::string_view a, std::string_view b) {
  const auto is_digit = [](char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; };
  const auto digits = [&](std::string_view text, size_t* position) {
    const size_t begin = *position;
    while (*position < text.size() && is_digit(text[*position])) ++*position;
    std::string_view run = text.substr(begin, *position - begin);
    while (run.size() > 1 && run.front() == '0') run.remove_prefix(1);
    return run;
  };
  size_t i = 0;
  size_t j = 0;
  while (i < a.size() && j < b.size()) {
    if (is_digit(a[i]) && is_digit(b[j])) {
      const std::string_view left = digits(a, &i);
      const std::string_view right = digits(b, &j);
      if (left.size() != right.size()) return left.size() < right.size();
      if (left != right) return left < right;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  if (a.size() - i != b.size() - j) return a.size() - i < b.size() - j;
  return a < b;
}

bool HasTopic(const BagSummary& summary, const std::string& topic) {
  return std::ranges::any_of(summary.topics,
                             [&](const TopicSummary& listed) { return listed.name == topic; });
}

// A folder of its own under the system's temporary folder, removed with what it holds.
class TemporaryFolder {
 public:
  static StatusOr<std::unique_ptr<TemporaryFolder>> Create() {
    std::error_code error;
    std::string pattern = (fs::temp_directory_path(error) / "recog-rosbag2-XXXXXX").string();
    if (error || mkdtemp(pattern.data()) == nullptr) {
      return Status::Internal("cannot create a temporary folder like " + Quoted(pattern) +
                              " to decompress a rosbag2 file into");
    }
    return std::unique_ptr<TemporaryFolder>(new TemporaryFolder(pattern));
  }
  ~TemporaryFolder() {
    std::error_code ignored;
    fs::remove_all(path_, ignored);
  }
  TemporaryFolder(const TemporaryFolder&) = delete;
  TemporaryFolder& operator=(const TemporaryFolder&) = delete;

  const fs::path& path() const { return path_; }

 private:
  explicit TemporaryFolder(fs::path path) : path_(std::move(path)) {}
  fs::path path_;
};

class Rosbag2FolderStore final : public BagStore {
 public:
  explicit Rosbag2FolderStore(std::string folder) : folder_(std::move(folder)) {}

  Status Load();

  const BagSummary& summary() const override { return summary_; }
  Status ForEachMessage(const std::string& topic,
                        const std::function<Status(const StoredMessage&)>& visit) override;
  Status ReadMessage(const std::string& topic, uint64_t id, std::vector<uint8_t>* data) override;

 private:
  // The folder's files in order, and metadata.yaml's content when there is one.
  StatusOr<std::vector<std::string>> ListFiles();
  // `path` opened by its content; a zstd file decompressed first.
  struct OpenedFile {
    std::unique_ptr<BagStore> store;
    std::string storage;  // "sqlite3" or "mcap"
    bool decompressed = false;
  };
  StatusOr<OpenedFile> OpenFile(const std::string& path);
  StatusOr<std::string> Decompress(const std::string& path);
  Status CheckMetadataTopics() const;
  Status AddTopics(const BagSummary& file);
  std::string Where() const { return "rosbag2 folder " + Quoted(folder_); }

  std::string folder_;
  std::optional<Rosbag2Metadata> metadata_;
  // Before the stores, so that their files are closed when it is removed.
  std::unique_ptr<TemporaryFolder> temporary_;
  std::vector<std::unique_ptr<BagStore>> files_;
  std::map<std::string, TopicSummary> topics_;
  BagSummary summary_;
};

StatusOr<std::vector<std::string>> Rosbag2FolderStore::ListFiles() {
  const fs::path folder(folder_);
  const fs::path metadata_path = folder / "metadata.yaml";
  std::error_code error;
  std::vector<std::string> files;
  if (fs::exists(metadata_path, error)) {
    RECOG_ASSIGN_OR_RETURN(metadata_, ReadRosbag2Metadata(metadata_path.string()));
    if (metadata_->file_paths.empty()) {
      return Status::InvalidArgument(Quoted(metadata_path.string()) + " names no files");
    }
    for (const std::string& relative : metadata_->file_paths) {
      fs::path path = folder / relative;
      // Early rosbag2 wrote the paths with the folder's name in front ("bag/bag_0.db3").
      if (!fs::exists(path, error) && fs::exists(folder / fs::path(relative).filename(), error)) {
        path = folder / fs::path(relative).filename();
      }
      if (!fs::is_regular_file(path, error)) {
        return Status::NotFound(Quoted(metadata_path.string()) + " names the file " +
                                Quoted(relative) + ", which is not there");
      }
      files.push_back(path.string());
    }
  } else {
    for (const fs::directory_entry& entry : fs::directory_iterator(folder, error)) {
      if (entry.is_regular_file(error) && KindOf(entry.path().string()) != FileKind::kOther) {
        files.push_back(entry.path().string());
      }
    }
    if (error) return Status::NotFound(Where() + " cannot be listed: " + error.message());
    if (files.empty()) {
      return Status::InvalidArgument(Where() +
                                     " has no metadata.yaml and no sqlite3, MCAP or zstd file");
    }
    std::ranges::sort(files, NaturalLess);
  }
  if (files.size() > kMaxFiles) {
    return Status::ResourceExhausted(Where() + " has " + std::to_string(files.size()) +
                                     " files, more than the " + std::to_string(kMaxFiles) +
                                     " a store reads");
  }
  return files;
}

StatusOr<std::string> Rosbag2FolderStore::Decompress(const std::string& path) {
  if (temporary_ == nullptr) {
    RECOG_ASSIGN_OR_RETURN(temporary_, TemporaryFolder::Create());
  }
  // Named after the file, behind its index in the folder (a list may name a file twice).
  const fs::path name = fs::path(path).filename();
  const fs::path output =
      temporary_->path() / (std::to_string(files_.size()) + "-" +
                            (name.extension() == ".zstd" ? name.stem() : name).string());
  std::error_code error;
  const uint64_t free_bytes = fs::space(temporary_->path(), error).available;
  const uint64_t cap =
      error ? kMaxDecompressedFileBytes : std::min(kMaxDecompressedFileBytes, free_bytes);
  const Status status = DecompressZstdFile(path, output.string(), cap);
  if (!status.ok()) {
    return status.WithContext(Where() + ": decompressing " + Quoted(path) + " to " +
                              Quoted(output.string()) + " (at most " + std::to_string(cap) +
                              " bytes: 16 GiB, or the space free there)");
  }
  return output.string();
}

StatusOr<Rosbag2FolderStore::OpenedFile> Rosbag2FolderStore::OpenFile(const std::string& path) {
  OpenedFile opened;
  std::string readable = path;
  FileKind kind = KindOf(path);
  if (kind == FileKind::kZstd) {
    RECOG_ASSIGN_OR_RETURN(readable, Decompress(path));
    opened.decompressed = true;
    kind = KindOf(readable);
  }
  if (kind != FileKind::kSqlite3 && kind != FileKind::kMcap) {
    return Status::InvalidArgument(Where() + ": " + Quoted(path) +
                                   (opened.decompressed ? ", decompressed," : "") +
                                   " is neither an sqlite3 nor an MCAP file");
  }
  opened.storage = kind == FileKind::kSqlite3 ? "sqlite3" : "mcap";
  const Rosbag2Compression compression =
      metadata_ ? metadata_->compression : Rosbag2Compression::kUnknown;
  if (kind == FileKind::kMcap) {
    if (compression == Rosbag2Compression::kMessage) {
      return Status::InvalidArgument(Where() + ": " + Quoted(path) +
                                     ": per-message compression of MCAP files is not read");
    }
    RECOG_ASSIGN_OR_RETURN(opened.store, OpenMcapFile(readable));
    return opened;
  }
  // A whole-file compressed bag's messages are not compressed again.
  RECOG_ASSIGN_OR_RETURN(
      opened.store,
      OpenSqlite3File(readable, {.compression = compression == Rosbag2Compression::kFile
                                                    ? Rosbag2Compression::kNone
                                                    : compression}));
  return opened;
}

Status Rosbag2FolderStore::AddTopics(const BagSummary& file) {
  for (const TopicSummary& topic : file.topics) {
    const auto [merged, added] = topics_.emplace(topic.name, topic);
    if (added) continue;
    if (merged->second.type != topic.type || merged->second.serialization != topic.serialization) {
      return Status::InvalidArgument(Where() + ": topic " + Quoted(topic.name) + " is of type " +
                                     Quoted(merged->second.type) + " in an earlier file and " +
                                     Quoted(topic.type) + " in " + Quoted(file.path));
    }
    merged->second.messages += topic.messages;
  }
  return Status::Ok();
}

Status Rosbag2FolderStore::CheckMetadataTopics() const {
  for (const Rosbag2TopicMetadata& topic : metadata_->topics) {
    if (topic.serialization_format != "cdr") {
      return Status::InvalidArgument(Where() + ", metadata.yaml: topic " + Quoted(topic.name) +
                                     " has serialization format " +
                                     Quoted(topic.serialization_format) + " (only cdr is read)");
    }
  }
  return Status::Ok();
}

Status Rosbag2FolderStore::Load() {
  RECOG_ASSIGN_OR_RETURN(const std::vector<std::string> paths, ListFiles());
  // Refused before any file is opened (or decompressed).
  if (metadata_) RECOG_RETURN_IF_ERROR(CheckMetadataTopics());
  std::vector<std::string> compressions;
  for (const std::string& path : paths) {
    RECOG_ASSIGN_OR_RETURN(OpenedFile file, OpenFile(path));
    const std::string expected = metadata_
                                     ? metadata_->storage_identifier
                                     : (summary_.storage.empty() ? file.storage : summary_.storage);
    if (file.storage != expected) {
      return Status::InvalidArgument(Where() + ": " + Quoted(path) + " is an " + file.storage +
                                     " file in a bag of " + expected + " files");
    }
    summary_.storage = file.storage;
    const BagSummary& file_summary = file.store->summary();
    RECOG_RETURN_IF_ERROR(AddTopics(file_summary));
    if (file_summary.messages > 0) {
      const bool first = summary_.messages == 0;
      summary_.start_ns =
          first ? file_summary.start_ns : std::min(summary_.start_ns, file_summary.start_ns);
      summary_.end_ns =
          first ? file_summary.end_ns : std::max(summary_.end_ns, file_summary.end_ns);
      summary_.messages += file_summary.messages;
    }
    const std::string compression = file.decompressed ? "zstd (file)" : file_summary.compression;
    if (std::ranges::find(compressions, compression) == compressions.end()) {
      compressions.push_back(compression);
    }
    summary_.files.push_back(path);
    files_.push_back(std::move(file.store));
  }
  // The topics metadata.yaml names that no file has, without messages.
  if (metadata_) {
    for (const Rosbag2TopicMetadata& topic : metadata_->topics) {
      topics_.emplace(topic.name, TopicSummary{.name = topic.name, .type = topic.type});
    }
  }
  summary_.path = folder_;
  for (const std::string& compression : compressions) {
    summary_.compression += (summary_.compression.empty() ? "" : ", ") + compression;
  }
  for (const auto& [name, topic] : topics_) summary_.topics.push_back(topic);
  return Status::Ok();
}

Status Rosbag2FolderStore::ForEachMessage(
    const std::string& topic, const std::function<Status(const StoredMessage&)>& visit) {
  if (!topics_.contains(topic)) return Status::NotFound(Where() + " has no topic " + Quoted(topic));
  for (size_t index = 0; index < files_.size(); ++index) {
    if (!HasTopic(files_[index]->summary(), topic)) continue;
    RECOG_RETURN_IF_ERROR(files_[index]->ForEachMessage(topic, [&](const StoredMessage& message) {
      if (files_.size() == 1) return visit(message);
      if ((message.id & kFileIndexBits) != 0) {
        return Status::ResourceExhausted(Where() + ": message id " + std::to_string(message.id) +
                                         " of " + Quoted(summary_.files[index]) +
                                         " uses the bits 52 to 62 that hold a file's index");
      }
      StoredMessage numbered = message;
      numbered.id = uint64_t(index) << kFileIndexShift | message.id;
      return visit(numbered);
    }));
  }
  return Status::Ok();
}

Status Rosbag2FolderStore::ReadMessage(const std::string& topic, uint64_t id,
                                       std::vector<uint8_t>* data) {
  if (files_.size() == 1) return files_[0]->ReadMessage(topic, id, data);
  const size_t index = size_t((id & kFileIndexBits) >> kFileIndexShift);
  if (index >= files_.size()) {
    return Status::NotFound(Where() + " has no message id " + std::to_string(id) + " (file " +
                            std::to_string(index) + " of " + std::to_string(files_.size()) + ")");
  }
  return files_[index]->ReadMessage(topic, id & ~kFileIndexBits, data);
}

}  // namespace

StatusOr<std::unique_ptr<BagStore>> OpenRosbag2Folder(const std::string& path) {
  std::error_code error;
  const fs::file_status status = fs::status(path, error);
  if (!fs::exists(status)) return Status::NotFound("rosbag2 folder " + Quoted(path) + " not found");
  if (!fs::is_directory(status)) {
    return Status::InvalidArgument(Quoted(path) + " is not a folder (a rosbag2 bag is one)");
  }
  auto store = std::make_unique<Rosbag2FolderStore>(path);
  RECOG_RETURN_IF_ERROR(store->Load());
  return std::unique_ptr<BagStore>(std::move(store));
}

}  // namespace recog::bag
