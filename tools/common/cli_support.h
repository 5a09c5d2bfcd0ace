// Small pieces shared by the recog subcommands: finding image files, showing progress, reading
// the process's peak memory, and locating the bundled vocabularies and demo images.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/status.h"
#include "core/vocabulary/vocabulary_io.h"  // BundledVocabularyPath and the defaults

namespace recog::cli {

// Prints "recog <command>: CODE: message" on stderr and returns 1, the exit status (the overload
// for calls to recogd, grpc::Status, is in remote_support.h).
int Fail(const char* command, const Status& status);

// Comma-separated numbers ("0.1,0.2,0.3"); INVALID_ARGUMENT naming `flag` for a field that is not
// a finite number.
StatusOr<std::vector<double>> ParseNumbers(const std::string& flag, const std::string& text);

// Natural ("human") order of file names: digit runs compare as numbers, so 2.jpg < 10.jpg.
bool NaturalLess(std::string_view a, std::string_view b);

// Image files (.jpg .jpeg .png .bmp .pgm .ppm .tif .tiff, any case) under `dir`, recursively,
// in natural order of their paths. NOT_FOUND when `dir` is missing, INVALID_ARGUMENT when it is
// not a folder or holds no image.
StatusOr<std::vector<std::string>> ListImages(const std::string& dir);

// Folder of the demo images shipped with the project (corridor frames 1, 20, 41, 60).
std::string DemoImageDir();

// Largest resident set size of this process so far, in MiB.
double PeakRssMiB();

// "0x1234abcd..." (16 hex digits).
std::string HexChecksum(uint64_t checksum);

// A progress line on stderr. On a terminal it redraws one line (at most 10 times a second);
// otherwise it prints a line at every 10 % so that logs stay readable.
class ProgressBar {
 public:
  explicit ProgressBar(bool enabled = true);
  void Update(std::string_view stage, uint64_t done, uint64_t total);
  // Ends the current line, if any.
  void Finish();

 private:
  bool enabled_;
  bool tty_;
  std::string stage_;
  int last_decile_ = -1;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_;
  bool line_open_ = false;
};

// A CLI11 check that `parse` accepts the value (a bad value is a usage error: exit status 2).
template <typename Parse>
std::function<std::string(const std::string&)> Accepts(Parse parse) {
  return [parse](const std::string& text) {
    auto parsed = parse(text);
    return parsed.ok() ? std::string() : parsed.status().message();
  };
}

}  // namespace recog::cli
