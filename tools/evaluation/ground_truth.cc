#include "tools/evaluation/ground_truth.h"

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string_view>

namespace recog::cli {
namespace {

constexpr std::string_view kSparseHeader = "# recog sparse ground truth v1 ";

bool IsSpace(char c) { return c == ' ' || c == '\t' || c == '\r'; }

bool IsBlank(std::string_view line) { return std::all_of(line.begin(), line.end(), IsSpace); }

// Splits `line` at runs of spaces/tabs (a trailing '\r' counts as space).
std::vector<std::string_view> Tokens(std::string_view line) {
  std::vector<std::string_view> tokens;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && IsSpace(line[i])) ++i;
    const size_t start = i;
    while (i < line.size() && !IsSpace(line[i])) ++i;
    if (i > start) tokens.push_back(line.substr(start, i - start));
  }
  return tokens;
}

// A whole token as a non-negative decimal int.
bool ParseIndex(std::string_view token, int* value) {
  if (token.empty() || token.front() == '-' || token.front() == '+') return false;
  const auto [end, error] = std::from_chars(token.data(), token.data() + token.size(), *value);
  return error == std::errc() && end == token.data() + token.size();
}

class LineError {
 public:
  explicit LineError(const std::string& path) : path_(path) {}
  Status operator()(long long line, const std::string& what) const {
    return Status::DataLoss("ground truth '" + path_ + "' line " + std::to_string(line) + ": " +
                            what);
  }

 private:
  const std::string& path_;
};

StatusOr<GroundTruth> ParseDense(const std::string& path, std::ifstream& in, std::string first_line,
                                 long long first_line_number) {
  const LineError error(path);
  GroundTruth truth;
  long long line_number = first_line_number;
  std::string line = std::move(first_line);
  int row = 0;
  do {
    if (IsBlank(line)) continue;
    const std::vector<std::string_view> values = Tokens(line);
    if (row == 0) {
      truth.frames = int(values.size());
      truth.matches.resize(values.size());
    }
    if (row >= truth.frames) {
      return error(line_number, "more than " + std::to_string(truth.frames) +
                                    " rows for a matrix with " + std::to_string(truth.frames) +
                                    " columns");
    }
    if (int(values.size()) != truth.frames) {
      return error(line_number, "has " + std::to_string(values.size()) + " values, expected " +
                                    std::to_string(truth.frames));
    }
    for (int column = 0; column < truth.frames; ++column) {
      const std::string_view v = values[size_t(column)];
      if (v != "0" && v != "1") {
        return error(line_number, "column " + std::to_string(column + 1) + ": value '" +
                                      std::string(v) + "' is not 0 or 1");
      }
      if (v == "1") {
        if (column < row) {
          truth.matches[size_t(row)].push_back(column);
        } else {
          ++truth.ignored_entries;
        }
      }
    }
    ++row;
  } while (++line_number, std::getline(in, line));
  if (in.bad()) return Status::DataLoss("cannot read ground truth '" + path + "'");
  if (row != truth.frames) {
    return Status::DataLoss("ground truth '" + path + "' has " + std::to_string(row) +
                            " rows, expected " + std::to_string(truth.frames) +
                            " (one per column)");
  }
  return truth;
}

StatusOr<GroundTruth> ParseSparse(const std::string& path, std::ifstream& in,
                                  const std::string& header, long long header_line) {
  const LineError error(path);
  std::string_view h = header;
  while (!h.empty() && IsSpace(h.back())) h.remove_suffix(1);
  GroundTruth truth;
  if (h.substr(0, kSparseHeader.size()) != kSparseHeader ||
      !ParseIndex(h.substr(kSparseHeader.size()), &truth.frames)) {
    return error(header_line, "expected the header '" + std::string(kSparseHeader) +
                                  "N' (a dense matrix has no '#' line)");
  }
  truth.matches.resize(size_t(truth.frames));
  std::string line;
  long long line_number = header_line;
  int previous_query = 0;
  while (++line_number, std::getline(in, line)) {
    if (IsBlank(line) || line.front() == '#') continue;
    const size_t colon = line.find(':');
    int query = 0;
    if (colon == std::string::npos) return error(line_number, "expected 'i: j1 j2 ...'");
    std::string_view head = std::string_view(line).substr(0, colon);
    while (!head.empty() && IsSpace(head.front())) head.remove_prefix(1);
    while (!head.empty() && IsSpace(head.back())) head.remove_suffix(1);
    if (!ParseIndex(head, &query)) {
      return error(line_number, "query frame '" + std::string(head) + "' is not a number");
    }
    if (query < 1 || query > truth.frames) {
      return error(line_number, "query frame " + std::to_string(query) + " is outside 1.." +
                                    std::to_string(truth.frames));
    }
    if (query <= previous_query) {
      return error(line_number, "query frame " + std::to_string(query) + " is not after " +
                                    std::to_string(previous_query));
    }
    previous_query = query;
    std::vector<int>& matches = truth.matches[size_t(query - 1)];
    for (std::string_view token : Tokens(std::string_view(line).substr(colon + 1))) {
      int other = 0;
      if (!ParseIndex(token, &other)) {
        return error(line_number, "frame '" + std::string(token) + "' is not a number");
      }
      if (other < 1 || other >= query) {
        return error(line_number, "frame " + std::to_string(other) + " is not in 1.." +
                                      std::to_string(query - 1) + " (matches must be earlier)");
      }
      if (!matches.empty() && other - 1 <= matches.back()) {
        return error(line_number, "frames are not in increasing order at " + std::to_string(other));
      }
      matches.push_back(other - 1);
    }
  }
  if (in.bad()) return Status::DataLoss("cannot read ground truth '" + path + "'");
  return truth;
}

Status WriteFile(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return Status::Internal("cannot create '" + path + "'");
  out.write(text.data(), std::streamsize(text.size()));
  out.close();
  if (!out) return Status::Internal("cannot write '" + path + "'");
  return Status::Ok();
}

}  // namespace

bool GroundTruth::Matches(int query, int other) const {
  if (query < 0 || query >= int(matches.size())) return false;
  const std::vector<int>& m = matches[size_t(query)];
  return std::binary_search(m.begin(), m.end(), other);
}

bool GroundTruth::IsAmbiguous(int query, int other) const {
  return ambiguous.count({std::max(query, other), std::min(query, other)}) > 0;
}

Status ReadAmbiguousPairs(const std::string& path, GroundTruth* truth) {
  std::ifstream in(path);
  if (!in) return Status::NotFound("ambiguous pairs '" + path + "' not found");
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    int i = 0, j = 0;
    char rest = 0;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;  // blank or comment
    const int read = std::sscanf(line.c_str(), "%d %d %c", &i, &j, &rest);
    if (read != 2 || i < 1 || j < 1 || i > truth->frames || j > truth->frames || i == j) {
      return Status::DataLoss("ambiguous pairs '" + path + "' line " + std::to_string(number) +
                              ": expected two different frame numbers from 1 to " +
                              std::to_string(truth->frames));
    }
    truth->ambiguous.insert({std::max(i, j) - 1, std::min(i, j) - 1});
  }
  return Status::Ok();
}

int GroundTruth::QueriesWithMatches() const {
  return int(std::count_if(matches.begin(), matches.end(),
                           [](const std::vector<int>& m) { return !m.empty(); }));
}

long long GroundTruth::NumPairs() const {
  long long pairs = 0;
  for (const std::vector<int>& m : matches) pairs += static_cast<long long>(m.size());
  return pairs;
}

Status GroundTruth::Validate() const {
  if (frames < 0) return Status::InvalidArgument("ground truth has a negative frame count");
  if (int(matches.size()) != frames) {
    return Status::InvalidArgument("ground truth has " + std::to_string(matches.size()) +
                                   " match lists for " + std::to_string(frames) + " frames");
  }
  for (int i = 0; i < frames; ++i) {
    int previous = -1;
    for (int j : matches[size_t(i)]) {
      if (j <= previous || j >= i) {
        return Status::InvalidArgument("ground truth of frame " + std::to_string(i) +
                                       " lists frame " + std::to_string(j) +
                                       ", which is not earlier or not in increasing order");
      }
      previous = j;
    }
  }
  return Status::Ok();
}

StatusOr<GroundTruth> ReadGroundTruth(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    return Status::NotFound("ground truth file '" + path + "' does not exist");
  }
  if (std::filesystem::is_directory(path, ec)) {
    return Status::InvalidArgument("ground truth '" + path + "' is a folder, not a file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::NotFound("cannot open ground truth file '" + path + "'");
  std::string line;
  long long line_number = 0;
  while (++line_number, std::getline(in, line)) {
    if (IsBlank(line)) continue;
    if (line.front() == '#') return ParseSparse(path, in, line, line_number);
    return ParseDense(path, in, std::move(line), line_number);
  }
  if (in.bad()) return Status::DataLoss("cannot read ground truth '" + path + "'");
  return Status::DataLoss("ground truth '" + path + "' is empty");
}

Status WriteDenseGroundTruth(const GroundTruth& truth, const std::string& path) {
  RECOG_RETURN_IF_ERROR(truth.Validate());
  const size_t n = size_t(truth.frames);
  std::string text;
  text.reserve(n * 2 * n);
  std::string row(n == 0 ? 0 : 2 * n - 1, ' ');
  for (size_t i = 0; i < n; ++i) {
    for (size_t j = 0; j < n; ++j) row[2 * j] = '0';
    for (int j : truth.matches[i]) row[2 * size_t(j)] = '1';
    text += row;
    text += '\n';
  }
  return WriteFile(path, text);
}

Status WriteSparseGroundTruth(const GroundTruth& truth, const std::string& path) {
  RECOG_RETURN_IF_ERROR(truth.Validate());
  std::string text = std::string(kSparseHeader) + std::to_string(truth.frames) + "\n";
  for (int i = 0; i < truth.frames; ++i) {
    const std::vector<int>& m = truth.matches[size_t(i)];
    if (m.empty()) continue;
    text += std::to_string(i + 1);
    text += ':';
    for (int j : m) {
      text += ' ';
      text += std::to_string(j + 1);
    }
    text += '\n';
  }
  return WriteFile(path, text);
}

}  // namespace recog::cli
