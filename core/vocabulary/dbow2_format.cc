#include "core/vocabulary/dbow2_format.h"

#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cfloat>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <system_error>
#include <vector>

#include <opencv2/core.hpp>

namespace recog {
namespace {

constexpr size_t kDescriptorBytes = 32;
constexpr uint32_t kNone = std::numeric_limits<uint32_t>::max();
// Fields of a node line of the text format: parent, is_leaf, 32 bytes, weight.
constexpr size_t kTextFieldsPerNode = 3 + kDescriptorBytes;

// Separators inside a line. '\r' counts as one so that CRLF files parse like LF files.
inline bool IsBlank(char c) { return c == ' ' || c == '\t' || c == '\r'; }

// The next blank-separated token of [*p, end), advancing *p past it; empty at the end.
inline std::string_view NextToken(const char*& p, const char* end) {
  while (p < end && IsBlank(*p)) ++p;
  const char* start = p;
  while (p < end && !IsBlank(*p)) ++p;
  return {start, size_t(p - start)};
}

size_t CountTokens(const char* p, const char* end) {
  size_t n = 0;
  while (!NextToken(p, end).empty()) ++n;
  return n;
}

// A decimal integer without sign, at most UINT32_MAX.
inline bool ParseUint(std::string_view token, uint32_t* out) {
  if (token.empty() || token.size() > 10) return false;
  uint64_t v = 0;
  for (char c : token) {
    const unsigned digit = unsigned(c) - unsigned('0');
    if (digit > 9) return false;
    v = v * 10 + digit;
  }
  if (v > std::numeric_limits<uint32_t>::max()) return false;
  *out = uint32_t(v);
  return true;
}

// A character that ends a field of a node line.
inline bool IsFieldEnd(char c) { return IsBlank(c) || c == '\n' || c == '\0'; }

// Reads the next blank-separated field as an unsigned decimal integer, in a single pass (the hot
// loop of the text import). The line must be followed by a readable '\n' or '\0' (std::string
// keeps a '\0' after its last character), which stops every loop here without bounds checks.
// `field` receives the field's text, empty at the end of the line, for error messages.
[[gnu::always_inline]] inline bool ReadUintField(const char*& p, uint32_t* value,
                                                 std::string_view* field) {
  while (IsBlank(*p)) ++p;
  const char* start = p;
  uint64_t v = 0;
  for (unsigned digit; (digit = unsigned(*p) - unsigned('0')) <= 9 && p - start <= 10; ++p) {
    v = v * 10 + digit;
  }
  const bool ok =
      p > start && p - start <= 10 && v <= std::numeric_limits<uint32_t>::max() && IsFieldEnd(*p);
  while (!IsFieldEnd(*p)) ++p;
  *field = {start, size_t(p - start)};
  *value = uint32_t(v);
  return ok;
}

size_t CountLines(const char* p, const char* end) {
  size_t n = 0;
  while ((p = static_cast<const char*>(std::memchr(p, '\n', size_t(end - p)))) != nullptr) {
    ++n;
    ++p;
  }
  return n;
}

// A token for an error message, shortened when long.
std::string Quote(std::string_view token) {
  std::string s = "'";
  if (token.size() > 24) {
    s.append(token.substr(0, 20));
    s += "...";
  } else {
    s.append(token);
  }
  s += "'";
  return s;
}

// Reads a whole file; a gzip-compressed file is decompressed (zlib passes other files through).
StatusOr<std::string> ReadWholeFile(const std::string& path) {
  std::error_code ec;
  const std::filesystem::file_status st = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(st)) return Status::NotFound(path + ": no such file");
  if (!std::filesystem::is_regular_file(st)) {
    return Status::NotFound(path + ": not a regular file");
  }
  const uintmax_t size = std::filesystem::file_size(path, ec);
  gzFile file = gzopen(path.c_str(), "rb");
  if (file == nullptr) {
    return Status::NotFound(path + ": cannot open: " + std::strerror(errno));
  }
  gzbuffer(file, 1u << 20);
  std::string content;
  // One more byte than the file so that a plain file is read in one call and then sees its end.
  content.resize(ec ? size_t(1) << 20 : size_t(size) + 1);
  size_t used = 0;
  while (true) {
    if (used == content.size()) content.resize(content.size() * 2);
    const size_t want = std::min<size_t>(content.size() - used, size_t(1) << 30);
    const int got = gzread(file, content.data() + used, unsigned(want));
    if (got < 0) {
      int code = 0;
      const std::string message = gzerror(file, &code);
      gzclose(file);
      return Status::DataLoss(path + ": cannot read: " + message);
    }
    if (got == 0) break;
    used += size_t(got);
  }
  gzclose(file);
  content.resize(used);
  return content;
}

Status CheckHeaderValues(uint32_t k, uint32_t depth, uint32_t scoring, uint32_t weighting) {
  if (k < 2 || k > 255) {
    return Status::DataLoss("branching factor k=" + std::to_string(k) + " is out of range 2..255");
  }
  if (depth < 1 || depth > 255) {
    return Status::DataLoss("depth L=" + std::to_string(depth) + " is out of range 1..255");
  }
  if (scoring > uint32_t(ScoringType::kDotProduct)) {
    return Status::DataLoss("scoring type " + std::to_string(scoring) + " is out of range 0..5");
  }
  if (weighting > uint32_t(WeightingType::kBinary)) {
    return Status::DataLoss("weighting type " + std::to_string(weighting) +
                            " is out of range 0..3");
  }
  return Status::Ok();
}

VocabularyInfo MakeInfo(uint32_t k, uint32_t depth, uint32_t scoring, uint32_t weighting) {
  VocabularyInfo info;
  info.descriptor = DescriptorFormat::Orb();
  info.branching = k;
  info.depth = depth;
  info.num_trees = 1;
  info.scoring = ScoringType(scoring);
  info.weighting = WeightingType(weighting);
  return info;
}

StatusOr<Vocabulary> BuildVocabulary(const std::string& path, const VocabularyInfo& info,
                                     const TreeNodeTable& table) {
  StatusOr<Vocabulary> vocabulary = Vocabulary::FromTrees(info, std::span(&table, 1));
  if (!vocabulary.ok()) return vocabulary.status().WithContext(path, StatusCode::kDataLoss);
  return vocabulary;
}

// --- YAML helpers. ---

// Reads an integer field of a FileStorage map; false when it is missing or not an integer.
bool ReadInt(const cv::FileNode& map, const char* key, int* out) {
  const cv::FileNode field = map[key];
  if (!field.isInt()) return false;
  *out = int(field);
  return true;
}

StatusOr<Vocabulary> ParseDbow2Yaml(const std::string& path, const std::string& content) {
  const cv::FileStorage fs(content, cv::FileStorage::READ | cv::FileStorage::MEMORY);
  if (!fs.isOpened()) return Status::DataLoss(path + ": not an OpenCV YAML file");
  const cv::FileNode voc = fs["vocabulary"];
  if (!voc.isMap()) return Status::DataLoss(path + ": no 'vocabulary' map");

  int header[4];
  const char* const header_keys[4] = {"k", "L", "scoringType", "weightingType"};
  for (int i = 0; i < 4; ++i) {
    if (!ReadInt(voc, header_keys[i], &header[i]) || header[i] < 0) {
      return Status::DataLoss(path + ": vocabulary." + header_keys[i] +
                              " is missing or not a non-negative integer");
    }
  }
  const uint32_t k = uint32_t(header[0]);
  const uint32_t depth_limit = uint32_t(header[1]);
  if (Status s = CheckHeaderValues(k, depth_limit, uint32_t(header[2]), uint32_t(header[3]));
      !s.ok()) {
    return s.WithContext(path, StatusCode::kDataLoss);
  }

  // Nodes, indexed by their position in the file (+1; 0 is the root) so that children keep
  // their order of appearance, which is DBoW2's order.
  const cv::FileNode nodes = voc["nodes"];
  if (!nodes.isSeq()) return Status::DataLoss(path + ": vocabulary.nodes is missing or not a list");
  const size_t n_listed = nodes.size();
  if (n_listed == 0) return Status::DataLoss(path + ": vocabulary.nodes is empty");
  if (n_listed >= size_t(std::numeric_limits<int>::max())) {
    return Status::DataLoss(path + ": too many nodes");
  }
  const size_t n = n_listed + 1;
  TreeNodeTable table;
  table.parent.assign(n, 0);
  table.descriptors.assign(n * kDescriptorBytes, 0);
  table.word.assign(n, kInvalidWordId);
  table.weight.assign(n, 0.f);
  std::vector<uint32_t> index_of_id(n, kNone);  // DBoW2 node id -> table index
  std::vector<uint32_t> id_of_index(n, 0);      // table index -> DBoW2 node id
  std::vector<uint32_t> parent_id(n, 0);
  index_of_id[0] = 0;

  auto node_error = [&](size_t index, const std::string& what) {
    std::string where = path + ": vocabulary.nodes[" + std::to_string(index - 1) + "]";
    if (id_of_index[index] != 0) where += " (nodeId " + std::to_string(id_of_index[index]) + ")";
    return Status::DataLoss(where + ": " + what);
  };

  size_t index = 1;
  for (cv::FileNodeIterator it = nodes.begin(); it != nodes.end() && index < n; ++it, ++index) {
    const cv::FileNode node = *it;
    if (!node.isMap()) return node_error(index, "not a map");
    int id = 0;
    int pid = 0;
    if (!ReadInt(node, "nodeId", &id)) return node_error(index, "nodeId is missing");
    if (id < 1 || size_t(id) >= n) {
      return node_error(
          index, "nodeId " + std::to_string(id) + " is out of range 1.." + std::to_string(n - 1));
    }
    if (index_of_id[id] != kNone) {
      return node_error(index, "nodeId " + std::to_string(id) + " appears twice");
    }
    index_of_id[id] = uint32_t(index);
    id_of_index[index] = uint32_t(id);
    if (!ReadInt(node, "parentId", &pid)) return node_error(index, "parentId is missing");
    if (pid < 0 || size_t(pid) >= n) {
      return node_error(index, "parentId " + std::to_string(pid) + " is out of range 0.." +
                                   std::to_string(n - 1));
    }
    if (pid == id) return node_error(index, "the node is its own parent");
    parent_id[index] = uint32_t(pid);

    const cv::FileNode weight = node["weight"];
    if (!weight.isReal() && !weight.isInt()) return node_error(index, "weight is missing");
    const double w = double(weight);
    if (!std::isfinite(w) || std::fabs(w) > double(FLT_MAX)) {
      return node_error(index, "weight is not a finite float");
    }
    table.weight[index] = float(w);

    const cv::FileNode descriptor = node["descriptor"];
    if (!descriptor.isString()) return node_error(index, "descriptor is missing");
    StatusOr<std::array<uint8_t, 32>> bytes = ParseDbow2Descriptor(std::string(descriptor));
    if (!bytes.ok()) return node_error(index, bytes.status().message());
    std::memcpy(table.descriptors.data() + index * kDescriptorBytes, bytes->data(),
                kDescriptorBytes);
  }
  // n - 1 distinct ids in 1..n-1: every id is present, so every parent id resolves.
  for (size_t i = 1; i < n; ++i) table.parent[i] = index_of_id[parent_id[i]];

  // Shape: children per node, reachability from the root (no cycles) and depth.
  std::vector<uint32_t> first_child(n + 1, 0);
  for (size_t i = 1; i < n; ++i) ++first_child[table.parent[i] + 1];
  for (size_t i = 0; i < n; ++i) {
    const uint32_t count = first_child[i + 1];
    if (count > k) {
      const std::string name =
          i == 0 ? std::string("the root") : "nodeId " + std::to_string(id_of_index[i]);
      return Status::DataLoss(path + ": " + name + " has " + std::to_string(count) +
                              " children, more than k=" + std::to_string(k));
    }
    first_child[i + 1] += first_child[i];
  }
  std::vector<uint32_t> children(n - 1);
  {
    std::vector<uint32_t> fill(first_child.begin(), first_child.end() - 1);
    for (size_t i = 1; i < n; ++i) children[fill[table.parent[i]]++] = uint32_t(i);
  }
  std::vector<uint32_t> depth(n, 0);
  std::vector<uint32_t> queue;
  queue.reserve(n);
  queue.push_back(0);
  for (size_t head = 0; head < queue.size(); ++head) {
    const uint32_t node = queue[head];
    for (uint32_t c = first_child[node]; c < first_child[node + 1]; ++c) {
      const uint32_t child = children[c];
      depth[child] = depth[node] + 1;
      if (depth[child] > depth_limit) {
        return Status::DataLoss(path + ": nodeId " + std::to_string(id_of_index[child]) +
                                " is at depth " + std::to_string(depth[child]) +
                                ", deeper than L=" + std::to_string(depth_limit));
      }
      queue.push_back(child);
    }
  }
  if (queue.size() != n) {
    std::vector<uint8_t> reached(n, 0);
    for (uint32_t node : queue) reached[node] = 1;
    const size_t orphan = size_t(std::find(reached.begin(), reached.end(), 0) - reached.begin());
    return Status::DataLoss(path + ": nodeId " + std::to_string(id_of_index[orphan]) +
                            " is not reachable from the root (its parents form a cycle)");
  }

  // Words: every leaf (node without children) has exactly one, ids 0..W-1 each used once.
  const cv::FileNode words = voc["words"];
  if (!words.isSeq()) return Status::DataLoss(path + ": vocabulary.words is missing or not a list");
  const size_t num_words = words.size();
  size_t num_leaves = 0;
  for (size_t i = 1; i < n; ++i) num_leaves += first_child[i + 1] == first_child[i] ? 1 : 0;
  std::vector<uint8_t> word_seen(num_words, 0);
  size_t position = 0;
  for (cv::FileNodeIterator it = words.begin(); it != words.end() && position < num_words;
       ++it, ++position) {
    const cv::FileNode entry = *it;
    const std::string where = path + ": vocabulary.words[" + std::to_string(position) + "]: ";
    int word_id = 0;
    int node_id = 0;
    if (!entry.isMap() || !ReadInt(entry, "wordId", &word_id) ||
        !ReadInt(entry, "nodeId", &node_id)) {
      return Status::DataLoss(where + "expected {wordId, nodeId} integers");
    }
    if (word_id < 0 || size_t(word_id) >= num_words) {
      return Status::DataLoss(where + "wordId " + std::to_string(word_id) + " is out of range 0.." +
                              std::to_string(num_words - 1));
    }
    if (word_seen[word_id]) {
      return Status::DataLoss(where + "wordId " + std::to_string(word_id) + " appears twice");
    }
    word_seen[word_id] = 1;
    if (node_id < 1 || size_t(node_id) >= n) {
      return Status::DataLoss(where + "nodeId " + std::to_string(node_id) +
                              " is not a node of the vocabulary");
    }
    const uint32_t leaf = index_of_id[node_id];
    if (first_child[leaf + 1] != first_child[leaf]) {
      return Status::DataLoss(where + "nodeId " + std::to_string(node_id) +
                              " has children, so it cannot be a word");
    }
    if (table.word[leaf] != kInvalidWordId) {
      return Status::DataLoss(where + "nodeId " + std::to_string(node_id) + " already is word " +
                              std::to_string(table.word[leaf]));
    }
    table.word[leaf] = WordId(word_id);
  }
  if (num_words != num_leaves) {
    for (size_t i = 1; i < n; ++i) {
      if (first_child[i + 1] == first_child[i] && table.word[i] == kInvalidWordId) {
        return Status::DataLoss(path + ": nodeId " + std::to_string(id_of_index[i]) +
                                " is a leaf but no word refers to it");
      }
    }
  }
  return BuildVocabulary(path, MakeInfo(k, depth_limit, uint32_t(header[2]), uint32_t(header[3])),
                         table);
}

// "0 " to "255 ": each byte value in decimal followed by a blank, padded to 4 characters.
struct ByteText {
  char text[4];
  uint8_t size;
};
constexpr std::array<ByteText, 256> MakeByteTexts() {
  std::array<ByteText, 256> table{};
  for (unsigned v = 0; v < 256; ++v) {
    ByteText& t = table[v];
    if (v >= 100) t.text[t.size++] = char('0' + v / 100);
    if (v >= 10) t.text[t.size++] = char('0' + v / 10 % 10);
    t.text[t.size++] = char('0' + v % 10);
    t.text[t.size++] = ' ';
  }
  return table;
}
constexpr std::array<ByteText, 256> kByteTexts = MakeByteTexts();

// Writes `data` to `path` through a temporary file in the same folder, renamed into place.
Status WriteFileAtomically(const std::string& path, std::string_view data) {
  static std::atomic<uint64_t> counter{0};
  const std::string tmp =
      path + ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter++);
  std::FILE* file = std::fopen(tmp.c_str(), "wb");
  if (file == nullptr) {
    return Status::NotFound("cannot create '" + tmp + "': " + std::strerror(errno));
  }
  bool ok = std::fwrite(data.data(), 1, data.size(), file) == data.size();
  ok = ok && std::fflush(file) == 0;
  ok = ok && ::fsync(::fileno(file)) == 0;
  const int write_errno = errno;
  ok = std::fclose(file) == 0 && ok;
  if (!ok) {
    std::remove(tmp.c_str());
    return Status::Internal("cannot write '" + tmp + "': " + std::strerror(write_errno));
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int rename_errno = errno;
    std::remove(tmp.c_str());
    return Status::Internal("cannot rename '" + tmp + "' to '" + path +
                            "': " + std::strerror(rename_errno));
  }
  return Status::Ok();
}

}  // namespace

StatusOr<std::array<uint8_t, 32>> ParseDbow2Descriptor(std::string_view text) {
  std::array<uint8_t, 32> out{};
  const auto is_space = [](char c) { return IsBlank(c) || c == '\n'; };
  while (!text.empty() && is_space(text.front())) text.remove_prefix(1);
  while (!text.empty() && is_space(text.back())) text.remove_suffix(1);

  // BRIEF: 256 binary digits, the first being the highest bit of the bitset. Read backwards, the
  // string gives bit 0, 1, ... which are the bytes most-significant bit first.
  if (text.size() == 256 &&
      std::all_of(text.begin(), text.end(), [](char c) { return c == '0' || c == '1'; })) {
    for (size_t b = 0; b < kDescriptorBytes; ++b) {
      unsigned byte = 0;
      for (size_t t = 0; t < 8; ++t) {
        byte = (byte << 1) | unsigned(text[255 - (8 * b + t)] == '1');
      }
      out[b] = uint8_t(byte);
    }
    return out;
  }

  // ORB: decimal bytes separated by blanks.
  const char* p = text.data();
  const char* const end = p + text.size();
  const size_t count = CountTokens(p, end);
  if (count != kDescriptorBytes) {
    return Status::DataLoss("descriptor has " + std::to_string(count) +
                            " values; expected 32 decimal bytes (ORB) or 256 binary digits "
                            "(BRIEF)");
  }
  for (size_t b = 0; b < kDescriptorBytes; ++b) {
    const std::string_view token = NextToken(p, end);
    uint32_t value = 0;
    if (!ParseUint(token, &value) || value > 255) {
      return Status::DataLoss("descriptor value " + Quote(token) + " is not a byte (0..255)");
    }
    out[b] = uint8_t(value);
  }
  return out;
}

StatusOr<Vocabulary> ImportDbow2Text(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(const std::string content, ReadWholeFile(path));
  if (content.empty()) return Status::DataLoss(path + ": the file is empty");
  auto fail = [&path](size_t line, const std::string& what) {
    return Status::DataLoss(path + ": line " + std::to_string(line) + ": " + what);
  };
  const char* p = content.data();
  const char* const end = p + content.size();

  // Header: "k L scoring weighting".
  const char* eol = static_cast<const char*>(std::memchr(p, '\n', size_t(end - p)));
  if (eol == nullptr) return fail(1, "the header has no end of line (the file is truncated)");
  uint32_t header[4];
  {
    const char* c = p;
    for (uint32_t& value : header) {
      const std::string_view token = NextToken(c, eol);
      if (!ParseUint(token, &value)) {
        return fail(1, token.empty()
                           ? std::string("expected 'k L scoring weighting'")
                           : "header value " + Quote(token) + " is not a non-negative integer");
      }
    }
    if (!NextToken(c, eol).empty()) return fail(1, "expected 'k L scoring weighting' only");
    if (Status s = CheckHeaderValues(header[0], header[1], header[2], header[3]); !s.ok()) {
      return fail(1, s.message());
    }
  }
  const uint32_t k = header[0];
  const uint32_t depth_limit = header[1];
  p = eol + 1;

  // Nodes: one per line, node id = line number - 1.
  const size_t capacity = CountLines(p, end) + 2;
  if (capacity >= kNone) return fail(2, "too many lines");
  TreeNodeTable table;
  table.parent.resize(capacity);
  table.descriptors.resize(capacity * kDescriptorBytes);
  table.word.resize(capacity);
  table.weight.resize(capacity);
  std::vector<uint32_t> child_count(capacity, 0);
  std::vector<uint8_t> depth(capacity, 0);
  table.parent[0] = 0;
  table.word[0] = kInvalidWordId;
  table.weight[0] = 0.f;

  uint32_t n = 1;  // id of the next node
  WordId next_word = 0;
  while (p < end) {
    const size_t line = size_t(n) + 1;
    eol = static_cast<const char*>(std::memchr(p, '\n', size_t(end - p)));
    const bool complete = eol != nullptr;
    if (!complete) eol = end;
    const char* c = p;
    std::string_view token;
    uint32_t parent = 0;
    const bool parent_ok = ReadUintField(c, &parent, &token);
    if (token.empty()) {
      // Blank lines may only end the file.
      if (std::all_of(p, end, [](char ch) { return IsBlank(ch) || ch == '\n'; })) break;
      return fail(line, "empty line among the nodes");
    }
    if (!complete) return fail(line, "the line has no end of line (the file is truncated)");

    auto field_error = [&](size_t field, std::string_view bad) -> Status {
      if (bad.empty()) {
        return fail(line, "expected " + std::to_string(kTextFieldsPerNode) +
                              " fields (parent, is_leaf, 32 descriptor bytes, weight), found " +
                              std::to_string(CountTokens(p, eol)));
      }
      std::string what = field == 0   ? "parent id"
                         : field == 1 ? "is_leaf"
                         : field < 2 + kDescriptorBytes
                             ? "descriptor byte " + std::to_string(field - 2)
                             : "weight";
      return fail(line, what + " " + Quote(bad) + " is not valid");
    };

    if (!parent_ok) return field_error(0, token);
    if (parent >= n) {
      return fail(line, "parent " + std::to_string(parent) +
                            " is not an earlier node (this line is node " + std::to_string(n) +
                            ")");
    }
    if (table.word[parent] != kInvalidWordId) {
      return fail(line, "parent " + std::to_string(parent) + " is a leaf (line " +
                            std::to_string(size_t(parent) + 1) + ")");
    }
    if (++child_count[parent] > k) {
      return fail(line, "node " + std::to_string(parent) +
                            " gets more than k=" + std::to_string(k) + " children");
    }
    const uint32_t node_depth = uint32_t(depth[parent]) + 1;
    if (node_depth > depth_limit) {
      return fail(line, "node " + std::to_string(n) + " is at depth " + std::to_string(node_depth) +
                            ", deeper than L=" + std::to_string(depth_limit));
    }
    depth[n] = uint8_t(node_depth);
    table.parent[n] = parent;

    uint32_t is_leaf = 0;
    if (!ReadUintField(c, &is_leaf, &token)) return field_error(1, token);
    if (is_leaf > 1) return fail(line, "is_leaf is " + std::to_string(is_leaf) + ", not 0 or 1");

    uint8_t* row = table.descriptors.data() + size_t(n) * kDescriptorBytes;
    for (size_t b = 0; b < kDescriptorBytes; ++b) {
      uint32_t value = 0;
      if (!ReadUintField(c, &value, &token)) return field_error(2 + b, token);
      if (value > 255) {
        return fail(line, "descriptor byte " + std::to_string(b) + " is " + std::to_string(value) +
                              ", not in 0..255");
      }
      row[b] = uint8_t(value);
    }

    token = NextToken(c, eol);
    float weight = 0.f;
    const std::from_chars_result r = std::from_chars(token.data(), token.data() + token.size(),
                                                     weight, std::chars_format::general);
    if (token.empty() || r.ec != std::errc() || r.ptr != token.data() + token.size() ||
        !std::isfinite(weight)) {
      return field_error(2 + kDescriptorBytes, token);
    }
    table.weight[n] = weight;
    if (!NextToken(c, eol).empty()) {
      return fail(line, "more than " + std::to_string(kTextFieldsPerNode) + " fields");
    }
    table.word[n] = is_leaf ? next_word++ : kInvalidWordId;
    ++n;
    p = eol + 1;
  }
  if (n == 1) return Status::DataLoss(path + ": no node follows the header");
  for (uint32_t i = 0; i < n; ++i) {
    if (table.word[i] == kInvalidWordId && child_count[i] == 0) {
      return fail(size_t(i) + 1,
                  "node " + std::to_string(i) + " is not a leaf (is_leaf 0) but has no children");
    }
  }
  table.parent.resize(n);
  table.descriptors.resize(size_t(n) * kDescriptorBytes);
  table.word.resize(n);
  table.weight.resize(n);
  return BuildVocabulary(path, MakeInfo(k, depth_limit, header[2], header[3]), table);
}

StatusOr<Vocabulary> ImportDbow2Yaml(const std::string& path) {
  RECOG_ASSIGN_OR_RETURN(const std::string content, ReadWholeFile(path));
  if (content.empty()) return Status::DataLoss(path + ": the file is empty");
  try {
    return ParseDbow2Yaml(path, content);
  } catch (const cv::Exception& e) {
    return Status::DataLoss(path + ": not a valid OpenCV YAML file: " + e.err);
  }
}

// Node order of the export. DBoW2 text numbers the words in the order their leaves appear, and a
// node's children in the order they appear. So the nodes are emitted on demand, leaf by leaf in
// word-id order: before a leaf come its ancestors and, for each of them and for the leaf, the
// earlier siblings. When the earlier sibling of some node is a leaf with a larger word id, no
// order can keep the ids; the file is still correct, but re-imported word ids follow DBoW2's rule
// (leaf order). Vocabularies trained here (breadth-first word ids) and vocabularies imported from
// DBoW2 (ids in DBoW2's creation order, where siblings are consecutive) keep their ids.
// ORB-SLAM's own loader also refuses k > 20 or L > 10; such vocabularies are still written.
Status ExportDbow2Text(const Vocabulary& vocabulary, const std::string& path) {
  const VocabularyInfo& info = vocabulary.info();
  if (vocabulary.empty()) return Status::InvalidArgument("cannot export an empty vocabulary");
  if (info.num_trees != 1) {
    return Status::InvalidArgument("DBoW2 text holds a single tree; this vocabulary has " +
                                   std::to_string(info.num_trees));
  }
  if (info.descriptor.type != DescriptorType::kBinary ||
      info.descriptor.size_bytes != kDescriptorBytes) {
    return Status::InvalidArgument(
        "DBoW2 text holds 256-bit binary descriptors; this vocabulary "
        "has " +
        info.descriptor.ToString());
  }
  const uint32_t num_nodes = uint32_t(vocabulary.num_nodes());
  const size_t num_words = vocabulary.num_words();
  const NodeId root = vocabulary.Root(0);

  // Parents and the leaf of every word, by a walk from the root.
  std::vector<uint32_t> parent(num_nodes, kNone);
  std::vector<NodeId> leaf_of_word(num_words, kNone);
  std::vector<NodeId> next_child(num_nodes, 0);  // next child of a node still to be emitted
  {
    std::vector<NodeId> queue;
    queue.reserve(num_nodes);
    queue.push_back(root);
    for (size_t head = 0; head < queue.size(); ++head) {
      const NodeId node = queue[head];
      if (vocabulary.IsLeaf(node)) {
        const WordId word = vocabulary.WordOf(node);
        if (word >= num_words || leaf_of_word[word] != kNone) {
          return Status::Internal("vocabulary has an inconsistent word id " + std::to_string(word));
        }
        leaf_of_word[word] = node;
        continue;
      }
      const NodeId first = vocabulary.FirstChild(node);
      next_child[node] = first;
      for (NodeId c = first; c < first + vocabulary.ChildCount(node); ++c) {
        if (c >= num_nodes || parent[c] != kNone || c == root) {
          return Status::Internal("vocabulary has an inconsistent tree at node " +
                                  std::to_string(node));
        }
        parent[c] = node;
        queue.push_back(c);
      }
    }
  }

  std::vector<uint32_t> new_id(num_nodes, kNone);
  std::vector<NodeId> order;
  order.reserve(num_nodes);
  new_id[root] = 0;
  order.push_back(root);
  std::vector<NodeId> chain;
  for (size_t word = 0; word < num_words; ++word) {
    const NodeId leaf = leaf_of_word[word];
    if (leaf == kNone) return Status::Internal("word " + std::to_string(word) + " has no leaf");
    chain.clear();
    for (NodeId x = leaf; new_id[x] == kNone; x = parent[x]) chain.push_back(x);
    for (auto it = chain.rbegin(); it != chain.rend(); ++it) {
      const NodeId p = parent[*it];
      while (next_child[p] <= *it) {
        const NodeId sibling = next_child[p]++;
        new_id[sibling] = uint32_t(order.size());
        order.push_back(sibling);
      }
    }
  }
  if (order.size() != num_nodes) {
    return Status::Internal("vocabulary has nodes that lead to no word");
  }

  // Longest node line: parent (10) + is_leaf (2) + 32 bytes (4 each) + weight (<= 16) + '\n'.
  constexpr size_t kMaxLine = 10 + 1 + 2 + 4 * kDescriptorBytes + 32 + 1;
  std::string text(64 + size_t(num_nodes) * kMaxLine, '\0');
  char* w = text.data();
  char* const text_end = text.data() + text.size();
  auto put_uint = [&](uint32_t v) { w = std::to_chars(w, text_end, v).ptr; };
  put_uint(info.branching);
  *w++ = ' ';
  put_uint(info.depth);
  *w++ = ' ';
  put_uint(uint32_t(info.scoring));
  *w++ = ' ';
  put_uint(uint32_t(info.weighting));
  *w++ = '\n';
  for (size_t i = 1; i < order.size(); ++i) {
    const NodeId node = order[i];
    const bool leaf = vocabulary.IsLeaf(node);
    put_uint(new_id[parent[node]]);
    *w++ = ' ';
    *w++ = leaf ? '1' : '0';
    *w++ = ' ';
    const uint8_t* d = vocabulary.NodeDescriptor(node);
    for (size_t b = 0; b < kDescriptorBytes; ++b) {
      std::memcpy(w, kByteTexts[d[b]].text, 4);  // the line has room for 4 bytes each
      w += kByteTexts[d[b]].size;
    }
    if (leaf) {
      // Shortest text that reads back as the same float.
      w = std::to_chars(w, text_end, vocabulary.WordWeight(vocabulary.WordOf(node))).ptr;
    } else {
      *w++ = '0';
    }
    *w++ = '\n';
  }
  text.resize(size_t(w - text.data()));
  return WriteFileAtomically(path, text);
}

}  // namespace recog
