// OpenSqlite3File: one rosbag2 .db3 file read with libsqlite3.
//
// The file is opened read-only with the `immutable=1` URI parameter: SQLite then takes no lock
// and writes nothing beside the file, so a bag in a read-only folder opens (a plain read-only open
// of a WAL-mode .db3 must create its -shm file, and fails there), and a bag in a writable folder
// is not given -wal and -shm files by being read. The one exception is a .db3 beside a non-empty
// -wal file, a recording that was not closed: its last messages are in that log, which immutable
// mode would not read, so such a file is opened plainly read-only and SQLite needs to write its
// -shm (a read-only folder refuses it, and the error says so).
//
// Tables: topics(id, name, type, serialization_format, ...) and messages(id, topic_id, timestamp,
// data) in every version; schema and metadata (the bag's metadata.yaml, version 8) when there.
// A message's id is its row id.

#include <sqlite3.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <climits>
#include <filesystem>
#include <fstream>
#include <map>
#include <system_error>

#include "tools/bag/bag_store.h"
#include "tools/bag/decompress.h"
#include "tools/bag/rosbag2_metadata.h"

namespace recog::bag {
namespace {

constexpr std::string_view kSqliteMagic("SQLite format 3\0", 16);
constexpr size_t kSqliteHeaderBytes = 100;

struct DatabaseCloser {
  void operator()(sqlite3* db) const { sqlite3_close_v2(db); }
};
struct StatementFinalizer {
  void operator()(sqlite3_stmt* statement) const { sqlite3_finalize(statement); }
};
using Database = std::unique_ptr<sqlite3, DatabaseCloser>;
using Statement = std::unique_ptr<sqlite3_stmt, StatementFinalizer>;

// Resets a cached statement however its use ends, so that it holds no read transaction.
class ResetOnExit {
 public:
  explicit ResetOnExit(sqlite3_stmt* statement) : statement_(statement) {}
  ~ResetOnExit() {
    sqlite3_reset(statement_);
    sqlite3_clear_bindings(statement_);
  }
  ResetOnExit(const ResetOnExit&) = delete;
  ResetOnExit& operator=(const ResetOnExit&) = delete;

 private:
  sqlite3_stmt* statement_;
};

uint32_t BigEndian32(std::span<const uint8_t> bytes, size_t offset) {
  return uint32_t(bytes[offset]) << 24 | uint32_t(bytes[offset + 1]) << 16 |
         uint32_t(bytes[offset + 2]) << 8 | uint32_t(bytes[offset + 3]);
}

// A URI naming `path` for sqlite3_open_v2, every byte outside the unreserved set escaped.
std::string ImmutableUri(const std::string& path) {
  std::error_code error;
  const std::string absolute = std::filesystem::absolute(path, error).string();
  std::string uri = "file://";
  for (const unsigned char c : error ? path : absolute) {
    if (std::isalnum(c) || c == '/' || c == '-' || c == '.' || c == '_' || c == '~') {
      uri += char(c);
    } else {
      constexpr std::string_view kHex = "0123456789ABCDEF";
      uri += '%';
      uri += kHex[c >> 4];
      uri += kHex[c & 15];
    }
  }
  return uri + "?immutable=1";
}

bool HasPendingWriteAheadLog(const std::string& path) {
  std::error_code error;
  const uint64_t size = std::filesystem::file_size(path + "-wal", error);
  return !error && size > 0;
}

// The file's first bytes: an SQLite header, and not cut short of the pages it counts (when the
// header's page count is valid, i.e. its change counter matches its version-valid-for number).
Status CheckHeader(const std::string& path, bool pending_write_ahead_log) {
  std::ifstream file(path, std::ios::binary);
  std::array<uint8_t, kSqliteHeaderBytes> header{};
  file.read(reinterpret_cast<char*>(header.data()), std::streamsize(header.size()));
  const size_t read = size_t(file.gcount());
  const std::string_view magic(reinterpret_cast<const char*>(header.data()),
                               std::min(read, kSqliteMagic.size()));
  if (magic != kSqliteMagic) {
    return Status::InvalidArgument("file " + Quoted(path) +
                                   " is not an sqlite3 file (no 'SQLite format 3' header)");
  }
  if (read < kSqliteHeaderBytes) {
    return Status::DataLoss("sqlite3 file " + Quoted(path) + " is cut short: " +
                            std::to_string(read) + " bytes, less than its header");
  }
  const uint32_t page_size_field = uint32_t(header[16]) << 8 | header[17];
  const uint64_t page_size = page_size_field == 1 ? 65536 : page_size_field;
  if (page_size < 512 || page_size > 65536 || (page_size & (page_size - 1)) != 0) {
    return Status::DataLoss("sqlite3 file " + Quoted(path) + " is damaged: page size " +
                            std::to_string(page_size));
  }
  const uint64_t pages = BigEndian32(header, 28);
  const bool page_count_valid = pages != 0 && BigEndian32(header, 24) == BigEndian32(header, 92);
  std::error_code error;
  const uint64_t file_size = std::filesystem::file_size(path, error);
  if (!pending_write_ahead_log && page_count_valid && !error && file_size < pages * page_size) {
    return Status::DataLoss("sqlite3 file " + Quoted(path) + " is cut short: its header counts " +
                            std::to_string(pages) + " pages of " + std::to_string(page_size) +
                            " bytes, " + std::to_string(file_size) + " bytes are there");
  }
  return Status::Ok();
}

class Sqlite3Store final : public BagStore {
 public:
  explicit Sqlite3Store(std::string path) : path_(std::move(path)) {}

  Status Load(const Sqlite3Options& options);

  const BagSummary& summary() const override { return summary_; }
  Status ForEachMessage(const std::string& topic,
                        const std::function<Status(const StoredMessage&)>& visit) override;
  Status ReadMessage(const std::string& topic, uint64_t id, std::vector<uint8_t>* data) override;

 private:
  // SQLite's error `code` while `doing` something, with the code its cause calls for: damage is
  // DATA_LOSS, memory RESOURCE_EXHAUSTED, anything else (a missing column) INVALID_ARGUMENT.
  Status SqliteError(int code, std::string_view doing) const;
  StatusOr<Statement> Prepare(std::string_view sql, unsigned flags = 0) const;
  Status Open(bool pending_write_ahead_log);
  // The row counts topics and messages need; true in *has_metadata when the metadata table is.
  Status CheckTables(bool* has_metadata);
  Status ReadTopics();
  Status CountMessages();
  StatusOr<Rosbag2Compression> CompressionOfFile(bool has_metadata);
  StatusOr<int64_t> TopicId(const std::string& topic) const;
  // The data column of `statement`'s row: its bytes, or decompressed into *scratch.
  StatusOr<std::span<const uint8_t>> MessageBytes(sqlite3_stmt* statement, int column, int64_t id,
                                                  std::vector<uint8_t>* scratch) const;

  std::string path_;
  Database db_;
  bool zstd_messages_ = false;
  std::map<std::string, int64_t> topic_ids_;
  std::map<int64_t, TopicSummary> topics_by_id_;
  Statement read_statement_;
  BagSummary summary_;
};

Status Sqlite3Store::SqliteError(int code, std::string_view doing) const {
  const std::string message = "sqlite3 file " + Quoted(path_) + ": " + std::string(doing) + ": " +
                              (db_ ? sqlite3_errmsg(db_.get()) : sqlite3_errstr(code));
  switch (code & 0xff) {
    case SQLITE_CORRUPT:
    case SQLITE_NOTADB:
    case SQLITE_IOERR:
    case SQLITE_FORMAT:
    case SQLITE_MISMATCH:
      return Status::DataLoss(message);
    case SQLITE_NOMEM:
    case SQLITE_TOOBIG:
    case SQLITE_FULL:
      return Status::ResourceExhausted(message);
    default:
      return Status::InvalidArgument(message);
  }
}

StatusOr<Statement> Sqlite3Store::Prepare(std::string_view sql, unsigned flags) const {
  sqlite3_stmt* statement = nullptr;
  const int code =
      sqlite3_prepare_v3(db_.get(), sql.data(), int(sql.size()), flags, &statement, nullptr);
  if (code != SQLITE_OK) {
    sqlite3_finalize(statement);
    return SqliteError(code, "preparing \"" + std::string(sql) + "\"");
  }
  return Statement(statement);
}

Status Sqlite3Store::Open(bool pending_write_ahead_log) {
  sqlite3* db = nullptr;
  const int code = pending_write_ahead_log
                       ? sqlite3_open_v2(path_.c_str(), &db, SQLITE_OPEN_READONLY, nullptr)
                       : sqlite3_open_v2(ImmutableUri(path_).c_str(), &db,
                                         SQLITE_OPEN_READONLY | SQLITE_OPEN_URI, nullptr);
  db_.reset(db);
  if (code != SQLITE_OK) return SqliteError(code, "opening");
  // A hostile file may hold anything: no blob larger than any message may be, no SQL of the
  // file's schema (views, triggers) run, damaged cells found as they are read.
  sqlite3_limit(db, SQLITE_LIMIT_LENGTH, int(std::min<uint64_t>(kMaxDecompressedBytes, INT_MAX)));
  sqlite3_db_config(db, SQLITE_DBCONFIG_DEFENSIVE, 1, nullptr);
  sqlite3_db_config(db, SQLITE_DBCONFIG_TRUSTED_SCHEMA, 0, nullptr);
  const int pragma = sqlite3_exec(db, "PRAGMA cell_size_check = ON", nullptr, nullptr, nullptr);
  if (pragma != SQLITE_OK) return SqliteError(pragma, "configuring");
  if (pending_write_ahead_log) {
    // Fails here, not at the first query, when the -shm cannot be written.
    const int check = sqlite3_exec(db, "SELECT 1 FROM sqlite_master", nullptr, nullptr, nullptr);
    if (check != SQLITE_OK) {
      return SqliteError(check,
                         "reading beside its non-empty -wal file (a recording that was not "
                         "closed; SQLite must write its -shm file to read it)");
    }
  }
  return Status::Ok();
}

Status Sqlite3Store::CheckTables(bool* has_metadata) {
  RECOG_ASSIGN_OR_RETURN(
      const Statement statement,
      Prepare("SELECT name, type FROM sqlite_master WHERE name IN ('topics', 'messages', "
              "'metadata')"));
  std::map<std::string, std::string> type_of;
  int code;
  while ((code = sqlite3_step(statement.get())) == SQLITE_ROW) {
    const auto* name = reinterpret_cast<const char*>(sqlite3_column_text(statement.get(), 0));
    const auto* type = reinterpret_cast<const char*>(sqlite3_column_text(statement.get(), 1));
    if (name != nullptr && type != nullptr) type_of[name] = type;
  }
  if (code != SQLITE_DONE) return SqliteError(code, "reading its schema");
  for (const char* table : {"topics", "messages"}) {
    if (!type_of.contains(table)) {
      return Status::InvalidArgument("sqlite3 file " + Quoted(path_) + " has no " + Quoted(table) +
                                     " table: not a rosbag2 bag");
    }
  }
  for (const auto& [name, type] : type_of) {
    // Only tables: a view could run any query the file's author wrote.
    if (type != "table") {
      return Status::InvalidArgument("sqlite3 file " + Quoted(path_) + ": " + Quoted(name) +
                                     " is a " + type + ", not a table: not a rosbag2 bag");
    }
  }
  *has_metadata = type_of.contains("metadata");
  return Status::Ok();
}

Status Sqlite3Store::ReadTopics() {
  RECOG_ASSIGN_OR_RETURN(
      const Statement statement,
      Prepare("SELECT id, name, type, serialization_format FROM topics ORDER BY id"));
  const auto text = [&](int column) {
    const auto* value = reinterpret_cast<const char*>(sqlite3_column_text(statement.get(), column));
    return value == nullptr ? std::string() : std::string(value);
  };
  int code;
  while ((code = sqlite3_step(statement.get())) == SQLITE_ROW) {
    const int64_t id = sqlite3_column_int64(statement.get(), 0);
    TopicSummary topic{.name = text(1), .type = text(2)};
    const std::string format = text(3);
    if (format != "cdr") {
      return Status::InvalidArgument("sqlite3 file " + Quoted(path_) + ": topic " +
                                     Quoted(topic.name) + " has serialization format " +
                                     Quoted(format) + " (only cdr is read)");
    }
    topic.serialization = Serialization::kCdr;
    if (!topic_ids_.emplace(topic.name, id).second) {
      return Status::InvalidArgument("sqlite3 file " + Quoted(path_) + ": topic " +
                                     Quoted(topic.name) + " is listed twice in its topics table");
    }
    topics_by_id_.emplace(id, std::move(topic));
  }
  if (code != SQLITE_DONE) return SqliteError(code, "reading its topics");
  return Status::Ok();
}

Status Sqlite3Store::CountMessages() {
  RECOG_ASSIGN_OR_RETURN(const Statement statement,
                         Prepare("SELECT topic_id, COUNT(*), MIN(timestamp), MAX(timestamp) "
                                 "FROM messages GROUP BY topic_id"));
  int code;
  while ((code = sqlite3_step(statement.get())) == SQLITE_ROW) {
    const int64_t topic_id = sqlite3_column_int64(statement.get(), 0);
    const uint64_t count = uint64_t(sqlite3_column_int64(statement.get(), 1));
    const auto topic = topics_by_id_.find(topic_id);
    if (topic == topics_by_id_.end()) {
      return Status::DataLoss("sqlite3 file " + Quoted(path_) + ": " + std::to_string(count) +
                              " messages of topic id " + std::to_string(topic_id) +
                              ", which its topics table does not list");
    }
    topic->second.messages = count;
    const int64_t first = sqlite3_column_int64(statement.get(), 2);
    const int64_t last = sqlite3_column_int64(statement.get(), 3);
    summary_.start_ns = summary_.messages == 0 ? first : std::min(summary_.start_ns, first);
    summary_.end_ns = summary_.messages == 0 ? last : std::max(summary_.end_ns, last);
    summary_.messages += count;
  }
  if (code != SQLITE_DONE) return SqliteError(code, "counting its messages");
  return Status::Ok();
}

StatusOr<Rosbag2Compression> Sqlite3Store::CompressionOfFile(bool has_metadata) {
  if (has_metadata) {
    RECOG_ASSIGN_OR_RETURN(const Statement statement,
                           Prepare("SELECT metadata FROM metadata ORDER BY id DESC LIMIT 1"));
    const int code = sqlite3_step(statement.get());
    if (code == SQLITE_ROW) {
      const auto* text = reinterpret_cast<const char*>(sqlite3_column_text(statement.get(), 0));
      RECOG_ASSIGN_OR_RETURN(
          const Rosbag2Metadata metadata,
          ParseRosbag2Metadata(text == nullptr ? "" : text,
                               "sqlite3 file " + Quoted(path_) + ", metadata table"));
      if (metadata.compression != Rosbag2Compression::kUnknown) return metadata.compression;
    } else if (code != SQLITE_DONE) {
      return SqliteError(code, "reading its metadata table");
    }
  }
  RECOG_ASSIGN_OR_RETURN(const Statement statement,
                         Prepare("SELECT substr(data, 1, 4) FROM messages ORDER BY id LIMIT 1"));
  const int code = sqlite3_step(statement.get());
  if (code == SQLITE_DONE) return Rosbag2Compression::kNone;
  if (code != SQLITE_ROW) return SqliteError(code, "reading its first message");
  const std::string_view start(static_cast<const char*>(sqlite3_column_blob(statement.get(), 0)),
                               size_t(sqlite3_column_bytes(statement.get(), 0)));
  return StartsWithZstdMagic(start) ? Rosbag2Compression::kMessage : Rosbag2Compression::kNone;
}

Status Sqlite3Store::Load(const Sqlite3Options& options) {
  const bool pending_write_ahead_log = HasPendingWriteAheadLog(path_);
  RECOG_RETURN_IF_ERROR(CheckHeader(path_, pending_write_ahead_log));
  RECOG_RETURN_IF_ERROR(Open(pending_write_ahead_log));
  bool has_metadata = false;
  RECOG_RETURN_IF_ERROR(CheckTables(&has_metadata));
  RECOG_RETURN_IF_ERROR(ReadTopics());
  RECOG_RETURN_IF_ERROR(CountMessages());
  Rosbag2Compression compression = options.compression;
  if (compression == Rosbag2Compression::kUnknown) {
    RECOG_ASSIGN_OR_RETURN(compression, CompressionOfFile(has_metadata));
  }
  if (compression == Rosbag2Compression::kFile) {
    return Status::InvalidArgument("sqlite3 file " + Quoted(path_) +
                                   " is said to be compressed whole; decompress it first");
  }
  zstd_messages_ = compression == Rosbag2Compression::kMessage;
  RECOG_ASSIGN_OR_RETURN(
      read_statement_,
      Prepare("SELECT topic_id, data FROM messages WHERE id = ?", SQLITE_PREPARE_PERSISTENT));

  summary_.path = path_;
  summary_.storage = "sqlite3";
  summary_.files = {path_};
  summary_.compression = zstd_messages_ ? "zstd (message)" : "none";
  for (const auto& [name, id] : topic_ids_) summary_.topics.push_back(topics_by_id_.at(id));
  return Status::Ok();
}

StatusOr<int64_t> Sqlite3Store::TopicId(const std::string& topic) const {
  const auto found = topic_ids_.find(topic);
  if (found == topic_ids_.end()) {
    return Status::NotFound("sqlite3 file " + Quoted(path_) + " has no topic " + Quoted(topic));
  }
  return found->second;
}

StatusOr<std::span<const uint8_t>> Sqlite3Store::MessageBytes(sqlite3_stmt* statement, int column,
                                                              int64_t id,
                                                              std::vector<uint8_t>* scratch) const {
  const std::string where = "sqlite3 file " + Quoted(path_) + ", message id " + std::to_string(id);
  if (sqlite3_column_type(statement, column) == SQLITE_NULL) {
    return Status::DataLoss(where + " has no data");
  }
  const auto* bytes = static_cast<const uint8_t*>(sqlite3_column_blob(statement, column));
  const int size = sqlite3_column_bytes(statement, column);
  if (bytes == nullptr && size > 0) return SqliteError(SQLITE_NOMEM, where);
  const std::span<const uint8_t> stored(bytes, size_t(size));
  if (!zstd_messages_) return stored;
  RECOG_RETURN_IF_ERROR(DecompressZstd(stored, scratch, where));
  return std::span<const uint8_t>(*scratch);
}

Status Sqlite3Store::ForEachMessage(const std::string& topic,
                                    const std::function<Status(const StoredMessage&)>& visit) {
  RECOG_ASSIGN_OR_RETURN(const int64_t topic_id, TopicId(topic));
  // Prepared per visit (a visit may start another one), finalized however it ends.
  RECOG_ASSIGN_OR_RETURN(
      const Statement statement,
      Prepare(
          "SELECT id, timestamp, data FROM messages WHERE topic_id = ? ORDER BY timestamp, id"));
  sqlite3_bind_int64(statement.get(), 1, topic_id);
  std::vector<uint8_t> decompressed;
  int code;
  while ((code = sqlite3_step(statement.get())) == SQLITE_ROW) {
    const int64_t id = sqlite3_column_int64(statement.get(), 0);
    StoredMessage message{
        .id = uint64_t(id), .log_time_ns = sqlite3_column_int64(statement.get(), 1), .data = {}};
    RECOG_ASSIGN_OR_RETURN(message.data, MessageBytes(statement.get(), 2, id, &decompressed));
    RECOG_RETURN_IF_ERROR(visit(message));
  }
  if (code != SQLITE_DONE)
    return SqliteError(code, "reading the messages of topic " + Quoted(topic));
  return Status::Ok();
}

Status Sqlite3Store::ReadMessage(const std::string& topic, uint64_t id,
                                 std::vector<uint8_t>* data) {
  RECOG_ASSIGN_OR_RETURN(const int64_t topic_id, TopicId(topic));
  sqlite3_stmt* statement = read_statement_.get();
  const ResetOnExit reset(statement);
  sqlite3_bind_int64(statement, 1, int64_t(id));
  const int code = sqlite3_step(statement);
  const std::string message = "message id " + std::to_string(int64_t(id));
  if (code == SQLITE_DONE) {
    return Status::NotFound("sqlite3 file " + Quoted(path_) + " has no " + message);
  }
  if (code != SQLITE_ROW) return SqliteError(code, "reading " + message);
  if (sqlite3_column_int64(statement, 0) != topic_id) {
    return Status::NotFound("sqlite3 file " + Quoted(path_) + ": " + message + " is not of topic " +
                            Quoted(topic));
  }
  RECOG_ASSIGN_OR_RETURN(const std::span<const uint8_t> bytes,
                         MessageBytes(statement, 1, int64_t(id), data));
  if (!zstd_messages_) data->assign(bytes.begin(), bytes.end());
  return Status::Ok();
}

}  // namespace

StatusOr<std::unique_ptr<BagStore>> OpenSqlite3File(const std::string& path,
                                                    const Sqlite3Options& options) {
  std::error_code error;
  const std::filesystem::file_status status = std::filesystem::status(path, error);
  if (!std::filesystem::exists(status)) {
    return Status::NotFound("sqlite3 file " + Quoted(path) + " not found");
  }
  if (!std::filesystem::is_regular_file(status)) {
    return Status::InvalidArgument(Quoted(path) + " is not a file (an sqlite3 bag is one)");
  }
  auto store = std::make_unique<Sqlite3Store>(path);
  RECOG_RETURN_IF_ERROR(store->Load(options));
  return std::unique_ptr<BagStore>(std::move(store));
}

StatusOr<std::unique_ptr<BagStore>> OpenSqlite3File(const std::string& path) {
  return OpenSqlite3File(path, Sqlite3Options{});
}

}  // namespace recog::bag
