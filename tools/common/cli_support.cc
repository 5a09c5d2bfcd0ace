#include "tools/common/cli_support.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <stdexcept>

namespace recog::cli {

StatusOr<std::vector<double>> ParseNumbers(const std::string& flag, const std::string& text) {
  std::vector<double> values;
  std::stringstream in(text);
  std::string field;
  while (std::getline(in, field, ',')) {
    try {
      size_t used = 0;
      values.push_back(std::stod(field, &used));
      if (used != field.size() || !std::isfinite(values.back())) throw std::invalid_argument(field);
    } catch (const std::exception&) {
      return Status::InvalidArgument(flag + ": '" + field + "' is not a finite number");
    }
  }
  return values;
}

namespace fs = std::filesystem;

bool NaturalLess(std::string_view a, std::string_view b) {
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    const bool da = std::isdigit(uint8_t(a[i])) != 0;
    const bool db = std::isdigit(uint8_t(b[j])) != 0;
    if (da && db) {
      size_t ei = i, ej = j;
      while (ei < a.size() && std::isdigit(uint8_t(a[ei]))) ++ei;
      while (ej < b.size() && std::isdigit(uint8_t(b[ej]))) ++ej;
      // Compare the numbers without leading zeros: longer is larger, then digit by digit.
      size_t si = i, sj = j;
      while (si + 1 < ei && a[si] == '0') ++si;
      while (sj + 1 < ej && b[sj] == '0') ++sj;
      if (ei - si != ej - sj) return ei - si < ej - sj;
      const int c = a.substr(si, ei - si).compare(b.substr(sj, ej - sj));
      if (c != 0) return c < 0;
      if (ei - i != ej - j) return ei - i < ej - j;  // fewer leading zeros first
      i = ei;
      j = ej;
    } else {
      if (a[i] != b[j]) return uint8_t(a[i]) < uint8_t(b[j]);
      ++i;
      ++j;
    }
  }
  return a.size() - i < b.size() - j;
}

StatusOr<std::vector<std::string>> ListImages(const std::string& dir) {
  std::error_code ec;
  if (!fs::exists(dir, ec)) return Status::NotFound("image folder '" + dir + "' does not exist");
  if (!fs::is_directory(dir, ec)) {
    return Status::InvalidArgument("'" + dir + "' is not a folder");
  }
  static const std::vector<std::string> kExtensions = {".jpg", ".jpeg", ".png", ".bmp",
                                                       ".pgm", ".ppm",  ".tif", ".tiff"};
  std::vector<std::string> files;
  for (fs::recursive_directory_iterator it(dir, fs::directory_options::skip_permission_denied, ec),
       end;
       it != end; it.increment(ec)) {
    if (ec) break;
    if (!it->is_regular_file(ec)) continue;
    std::string ext = it->path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return std::tolower(c); });
    if (std::find(kExtensions.begin(), kExtensions.end(), ext) != kExtensions.end()) {
      files.push_back(it->path().string());
    }
  }
  if (ec) return Status::InvalidArgument("cannot list '" + dir + "': " + ec.message());
  if (files.empty()) return Status::InvalidArgument("no image files found under '" + dir + "'");
  std::sort(files.begin(), files.end(), NaturalLess);
  return files;
}

int Fail(const char* command, const Status& status) {
  std::fprintf(stderr, "recog %s: %s\n", command, status.ToString().c_str());
  return 1;
}

std::string DemoImageDir() { return RECOG_DEMO_DATA_DIR; }

double PeakRssMiB() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return double(usage.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
}

std::string HexChecksum(uint64_t checksum) {
  char buf[19];
  std::snprintf(buf, sizeof(buf), "0x%016llx", static_cast<unsigned long long>(checksum));
  return buf;
}

ProgressBar::ProgressBar(bool enabled)
    : enabled_(enabled),
      tty_(isatty(STDERR_FILENO) != 0),
      start_(std::chrono::steady_clock::now()) {}

void ProgressBar::Update(std::string_view stage, uint64_t done, uint64_t total) {
  if (!enabled_ || total == 0) return;
  const auto now = std::chrono::steady_clock::now();
  if (stage != stage_) {
    Finish();
    stage_ = stage;
    last_decile_ = -1;
    start_ = now;
  }
  const double fraction = std::min(1.0, double(done) / double(total));
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  const int decile = int(fraction * 10);
  if (tty_) {
    if (done < total && now - last_draw_ < std::chrono::milliseconds(100)) return;
    const int width = 30;
    const int filled = int(fraction * width);
    std::fprintf(stderr, "\r%-12s [%s%s] %5.1f%% %llu/%llu %.0fs", stage_.c_str(),
                 std::string(size_t(filled), '#').c_str(),
                 std::string(size_t(width - filled), ' ').c_str(), 100 * fraction,
                 static_cast<unsigned long long>(done), static_cast<unsigned long long>(total),
                 elapsed);
    line_open_ = true;
  } else {
    if (decile == last_decile_) return;
    std::fprintf(stderr, "%s: %3d%% (%llu/%llu) %.1fs\n", stage_.c_str(), decile * 10,
                 static_cast<unsigned long long>(done), static_cast<unsigned long long>(total),
                 elapsed);
  }
  last_decile_ = decile;
  last_draw_ = now;
  std::fflush(stderr);
}

void ProgressBar::Finish() {
  if (line_open_) std::fputc('\n', stderr);
  line_open_ = false;
}

}  // namespace recog::cli
