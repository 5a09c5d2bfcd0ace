// Helpers for core's line-oriented text readers (PLY, Bundler cameras, ViSP files): a line
// reader that counts lines for error messages, blank-separated tokens, exact number parsing and
// the shortest text that reads back as the same number. Header-only; nothing here allocates but
// Tokens(), Quote() and FormatNumber().
#pragma once

#include <array>
#include <charconv>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace recog {

// Splits a text into lines ("\n" or "\r\n" ends), numbering them from 1 for error messages.
class LineReader {
 public:
  explicit LineReader(std::string_view text) : rest_(text) {}

  // The next line without its end; false at the end of the text.
  bool Next(std::string_view* line) {
    if (rest_.empty()) return false;
    const size_t end = rest_.find('\n');
    *line = rest_.substr(0, end);
    rest_ = end == std::string_view::npos ? std::string_view() : rest_.substr(end + 1);
    if (!line->empty() && line->back() == '\r') line->remove_suffix(1);
    ++line_number_;
    return true;
  }
  int line_number() const { return line_number_; }
  // What follows the last line read (the body of a binary PLY file).
  std::string_view rest() const { return rest_; }

 private:
  std::string_view rest_;
  int line_number_ = 0;
};

// Separators between numbers ('\r' and '\n' only occur inside XML text: lines are split first).
inline bool IsBlank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; }

// The next blank-separated token of *line, removed from it; empty at the end of the line.
inline std::string_view NextToken(std::string_view* line) {
  size_t start = 0;
  while (start < line->size() && IsBlank((*line)[start])) ++start;
  size_t end = start;
  while (end < line->size() && !IsBlank((*line)[end])) ++end;
  const std::string_view token = line->substr(start, end - start);
  line->remove_prefix(end);
  return token;
}

inline std::vector<std::string_view> Tokens(std::string_view line) {
  std::vector<std::string_view> tokens;
  for (std::string_view t = NextToken(&line); !t.empty(); t = NextToken(&line)) {
    tokens.push_back(t);
  }
  return tokens;
}

// A whole token as a number (std::from_chars syntax: no leading '+').
template <class T>
inline bool ParseNumber(std::string_view token, T* out) {
  const auto [end, ec] = std::from_chars(token.data(), token.data() + token.size(), *out);
  return ec == std::errc() && end == token.data() + token.size();
}

// A token for an error message, shortened when long.
inline std::string Quote(std::string_view token) {
  constexpr size_t kShown = 24;
  std::string quoted = "'";
  quoted.append(token.substr(0, kShown));
  quoted.append(token.size() > kShown ? "...'" : "'");
  return quoted;
}

// The shortest text that reads back as exactly `value`.
template <class T>
inline void AppendNumber(std::string* out, T value) {
  std::array<char, 32> buffer;
  const auto [end, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  out->append(buffer.data(), end);
}

template <class T>
inline std::string FormatNumber(T value) {
  std::string s;
  AppendNumber(&s, value);
  return s;
}

}  // namespace recog
