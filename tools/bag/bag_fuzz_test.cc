// The bag readers fuzzed with seeded mutations of real bags and messages: every input is a seed
// (a fixture of tests/data/bags, and with the shared data its bags too) changed at random, given
// to the readers as a file, a folder or bytes in memory. CI runs it in the release build and in
// the AddressSanitizer + UndefinedBehaviorSanitizer build.
//
// The cases, each drawing its inputs from std::mt19937_64 seeded by (seed, case, input number):
//  - Mcap: an MCAP file's bytes mutated — bits flipped, bytes set to 0, 0xff or at random,
//    interesting 8/16/32/64-bit values (0, 1, 2^31, 2^32 - 1, 2^63, ...) written at random or
//    into the record lengths, chunk sizes, string lengths and offsets that a walk of the seed's
//    records finds (nested in uncompressed chunks), CRCs zeroed (so that damage reaches the
//    parser), a chunk decompressed, mutated and recompressed (zstd, lz4 or none), cut short,
//    ranges inserted, repeated or deleted, two seeds spliced — written to a file and opened
//    with OpenBag. A bag that opens has every topic visited (ForEachMessage, sometimes stopped by
//    the visit's own error, which must come back), a few ids read again (ReadMessage must give
//    the visit's bytes) and a few made up, and every message's bytes decoded as the three
//    sensor_msgs types in both serializations, with every image inspected and decoded for both
//    roles. Seeds: the five fixture MCAP files; shared: bags/mcap-conformance/**/*.mcap and
//    bags/rosbag2/**/*.mcap.
//  - Rosbag2: rosbag2 sqlite3 files and folders: a lone .db3 mutated as above, or a copy of a
//    folder with its metadata.yaml mutated as text (field values from a dictionary of versions,
//    storages, compression names and modes, file names, YAML oddities; lines deleted, repeated,
//    swapped, re-indented; bytes mutated) and/or one of its files mutated, a file dropped or
//    added; opened with OpenBag and exercised as above. Its zstd decompressions go to a private
//    TMPDIR, which must be empty again when the store is gone. Seeds: fixture_sqlite3 (folder
//    and .db3); shared: bags/rosbag2/**/*.db3 and every folder of bags/rosbag2.
//  - Messages: Image, CompressedImage and CameraInfo messages — the fixtures' (CDR little and
//    big endian) and made-up ones (raw images of every encoding, JPEG and PNG of 8 and 16 bits,
//    compressedDepth PNG and RVL of 16UC1 and 32FC1) — mutated as fields (sizes, steps,
//    encodings and formats from a dictionary, compressedDepth's quantisation floats, the PNG's
//    chunks with their CRCs fixed, the RVL words and header, the JPEG's frame header) and/or as
//    serialized bytes (ROS 1, CDR LE or CDR BE, their count fields targeted), decoded in both
//    serializations; each decoded image through InspectImage (both roles), DecodeGray (with and
//    without colour) and DecodeDepth, in memory.
//  - Decompress: zstd and lz4 frames (made here with libzstd and liblz4 from several contents
//    and options, and the fixtures' chunks) mutated, through DecompressExactly with declared
//    sizes true, near, random and huge and a random limit, DecompressZstd with a random limit
//    and, for one input in 64, DecompressZstdFile.
//
// Checked for every input: no crash and no sanitizer report; every failure is a Status that is
// not OK and has a message; the results agree (a decoded image has the inspected size and type,
// an image that inspects decodes when it is raw, ReadMessage gives the bytes the visit gave, a
// visit's error comes back, an unmutated seed decompresses to its bytes, a limit is honoured, a
// failed DecompressZstdFile leaves no output); VmRSS stays below 3 GiB (read every 32 to 4096
// inputs). One line per case gives the inputs, the outcomes by status code (and the decoded
// messages and images) and the inputs per second. Not a failure, counted as "read again
// NOT_FOUND": an sqlite3 file whose b-tree the mutation left out of order (PRAGMA
// integrity_check: "Rowid 10 out of order") gives a row to the visit's scan that its lookup by
// id does not find; SQLite itself cannot tell that from a missing row.
//
// Environment:
//   RECOG_BAG_FUZZ_INPUTS  inputs per case (default per case, 11.5 to 15 s for the binary in
//                          the ASan + UBSan build on 2 cores, 1.3 s in release: Mcap 1000,
//                          Rosbag2 300, Messages 20000, Decompress 3000)
//   RECOG_BAG_FUZZ_SEED    the seed (default 1)
//   RECOG_BAG_FUZZ_ONLY    run only that input number, keeping its files (to replay a failure;
//                          with --gtest_filter naming its case). A crash prints the case, the
//                          input and this replay line on stderr.
//   RECOG_BAG_FUZZ_STDERR  1: keep stderr during the cases (libpng and libjpeg print a line per
//                          damaged image there, so it goes to /dev/null by default; the
//                          sanitizers' reports go to the real stderr either way)
// The campaign, 1,410,000 inputs with the shared data there (seeds: 5 + 416 + 18 MCAP files,
// 1 + 26 .db3 files, 1 + 26 rosbag2 folders), from the project's root in the sanitizer build, two
// processes at a time on 2 cores (14.7 minutes in all), 0 failures, 0 sanitizer reports:
//   export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:intercept_tls_get_addr=0
//   ASAN_OPTIONS+=:max_allocation_size_mb=1200:allocator_may_return_null=0
//   export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
//   export LSAN_OPTIONS=suppressions=$PWD/.ci/lsan.supp:print_suppressions=0
//   RECOG_BAG_FUZZ_INPUTS=150000 build-asan/tests/bag_fuzz_test --gtest_filter=BagFuzz.Mcap &
//   for run in "Messages 1000000" "Decompress 200000" "Rosbag2 60000"; do set -- $run
//     RECOG_BAG_FUZZ_INPUTS=$2 build-asan/tests/bag_fuzz_test --gtest_filter=BagFuzz.$1; done
// measured (seed 1; inputs, seconds, inputs/s, outcomes):
//   Mcap          150,000  883.8 s     170/s  opened 23,882; refused DATA_LOSS 111,097,
//                                             INVALID_ARGUMENT 14,857, RESOURCE_EXHAUSTED 164
//   Messages    1,000,000   99.2 s  10,081/s  Image OK 486,515, CompressedImage OK 582,916;
//                                             143,003 images and 85,189 depths decoded
//   Decompress    200,000  357.1 s     560/s  DecompressExactly OK 19,733, DATA_LOSS 141,523,
//                                             INVALID_ARGUMENT 38,744
//   Rosbag2        60,000  301.0 s     199/s  opened 15,395; refused DATA_LOSS 37,009,
//                                             INVALID_ARGUMENT 5,702, NOT_FOUND 1,894
// and in the release build, RECOG_BAG_FUZZ_SEED=2 RECOG_BAG_FUZZ_INPUTS=500000 of Mcap: 137.7 s.
#include <fcntl.h>
#include <lz4frame.h>
#include <signal.h>
#include <stdlib.h>
#include <unistd.h>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <map>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <tuple>
#include <variant>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "tests/testing/data_paths.h"
#include "tools/bag/bag_store.h"
#include "tools/bag/decompress.h"
#include "tools/bag/ros_images.h"
#include "tools/bag/ros_messages.h"

namespace recog::bag {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<uint8_t>;

constexpr double kMaxRssMiB = 3 * 1024;

size_t EnvNumber(const char* name, size_t fallback) {
  const char* value = std::getenv(name);
  return value != nullptr && *value != '\0' ? size_t(std::strtoull(value, nullptr, 10)) : fallback;
}

double RssMiB() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::strtod(line.c_str() + 6, nullptr) / 1024;
  }
  return 0;
}

std::string Lowercase(std::string text) {
  for (char& c : text) c = char(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

Bytes ReadFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void WriteFile(const fs::path& path, std::span<const uint8_t> bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

// The shared files under bags/<folder> whose names end with one of `extensions`, sorted.
std::vector<fs::path> SharedFiles(const std::string& folder,
                                  const std::vector<std::string>& extensions) {
  std::vector<fs::path> files;
  const fs::path root = recog::testing::SharedData("bags/" + folder);
  std::error_code error;
  if (!fs::is_directory(root, error)) return files;
  for (const auto& entry : fs::recursive_directory_iterator(root, error)) {
    if (!entry.is_regular_file(error)) continue;
    const std::string name = entry.path().filename().string();
    for (const std::string& extension : extensions) {
      if (name.size() > extension.size() && name.ends_with(extension)) {
        files.push_back(entry.path());
        break;
      }
    }
  }
  std::sort(files.begin(), files.end());
  return files;
}

// ---- Where a crash happened ----

char g_current[512] = "";
int g_report_fd = STDERR_FILENO;

void OnAbort(int signal_number) {
  if (g_current[0] != '\0') {
    const ssize_t ignored = write(g_report_fd, g_current, std::strlen(g_current));
    (void)ignored;
  }
  ::signal(signal_number, SIG_DFL);
  ::raise(signal_number);
}

// ---- Quiet decoders ----

}  // namespace
}  // namespace recog::bag

// The sanitizers' own output file descriptor (in their runtime; null without one).
extern "C" void __sanitizer_set_report_fd(void* fd) __attribute__((weak));

namespace recog::bag {
namespace {

// libpng and libjpeg print every damaged image on stderr (a line or two per input): stderr goes to
// /dev/null during a case, the sanitizers' reports and the crash note to the real one.
// RECOG_BAG_FUZZ_STDERR=1 keeps it.
class QuietStderr {
 public:
  QuietStderr() {
    if (EnvNumber("RECOG_BAG_FUZZ_STDERR", 0) == 1) return;
    std::fflush(stderr);
    saved_ = dup(STDERR_FILENO);
    const int null = open("/dev/null", O_WRONLY);
    if (saved_ < 0 || null < 0) {
      if (null >= 0) close(null);
      return;
    }
    if (__sanitizer_set_report_fd != nullptr) {
      __sanitizer_set_report_fd(reinterpret_cast<void*>(intptr_t(saved_)));
    }
    dup2(null, STDERR_FILENO);
    close(null);
    g_report_fd = saved_;
  }
  ~QuietStderr() {
    if (saved_ < 0) return;
    std::fflush(stderr);
    dup2(saved_, STDERR_FILENO);
    if (__sanitizer_set_report_fd != nullptr) {
      __sanitizer_set_report_fd(reinterpret_cast<void*>(intptr_t(STDERR_FILENO)));
    }
    g_report_fd = STDERR_FILENO;
    close(saved_);
  }
  QuietStderr(const QuietStderr&) = delete;
  QuietStderr& operator=(const QuietStderr&) = delete;

 private:
  int saved_ = -1;
};

// ---- Random choices ----

class Rng {
 public:
  Rng(uint64_t seed, uint32_t stream, uint64_t input) {
    std::seed_seq sequence{uint32_t(seed), uint32_t(seed >> 32), stream, uint32_t(input),
                           uint32_t(input >> 32)};
    engine_.seed(sequence);
  }
  uint64_t Next() { return engine_(); }
  // Uniform in [0, n); 0 for n = 0.
  uint64_t Below(uint64_t n) { return n == 0 ? 0 : engine_() % n; }
  bool OneIn(uint64_t n) { return Below(n) == 0; }
  bool Chance(double p) { return std::uniform_real_distribution<double>(0, 1)(engine_) < p; }
  template <typename T>
  const T& Pick(const std::vector<T>& items) {
    return items[size_t(Below(items.size()))];
  }

 private:
  std::mt19937_64 engine_;
};

// Values that lengths, counts and sizes are checked against: the edges of 8, 16, 32 and 64 bits,
// the readers' own limits (2^26 pixels, 1 GiB), small numbers.
// clang-format off
constexpr uint64_t kInteresting[] = {
    0, 1, 2, 3, 4, 7, 8, 9, 12, 16, 32, 64, 127, 128, 255, 256, 1000, 4095, 4096, 32767, 32768,
    65535, 65536, 65537, (1u << 24) - 1, 1u << 26, 0x7fffffff, 0x80000000, 0xfffffffe, 0xffffffff,
    uint64_t(1) << 32, (uint64_t(1) << 32) + 1, uint64_t(1) << 30, (uint64_t(1) << 30) + 1,
    uint64_t(1) << 52, uint64_t(1) << 62, uint64_t(1) << 63, ~uint64_t(0) - 1, ~uint64_t(0)};
// clang-format on

uint64_t Interesting(Rng& rng) { return kInteresting[rng.Below(std::size(kInteresting))]; }

void Store(Bytes* data, size_t at, uint64_t value, int size, bool big_endian) {
  for (int i = 0; i < size && at + size_t(i) < data->size(); ++i) {
    const int shift = big_endian ? 8 * (size - 1 - i) : 8 * i;
    (*data)[at + size_t(i)] = uint8_t(value >> shift);
  }
}

uint64_t Load(const Bytes& data, size_t at, int size, bool big_endian) {
  uint64_t value = 0;
  for (int i = 0; i < size && at + size_t(i) < data.size(); ++i) {
    const int shift = big_endian ? 8 * (size - 1 - i) : 8 * i;
    value |= uint64_t(data[at + size_t(i)]) << shift;
  }
  return value;
}

// A field of a seed that the mutator aims at: a length, count, size or offset.
struct Field {
  size_t offset = 0;
  int size = 4;
  bool big_endian = false;
};

struct Structure {
  std::vector<Field> fields;
  std::vector<Field> crcs;  // zeroed at times (MCAP: 0 = not checked)
};

// One to a few random mutations of *data, kept below `max_size` bytes. `other` is another seed
// for splicing (may be null); `structure` the seed's fields (may be null; offsets past the end
// are ignored).
void MutateBytes(Rng& rng, Bytes* data, const Structure* structure, const Bytes* other,
                 size_t max_size) {
  const int steps = rng.OneIn(8) ? 1 + int(rng.Below(16)) : 1 + int(rng.Below(3));
  for (int step = 0; step < steps; ++step) {
    const size_t size = data->size();
    switch (rng.Below(structure != nullptr && !structure->fields.empty() ? 13 : 11)) {
      case 0:  // a bit flipped
        if (size > 0) (*data)[rng.Below(size)] ^= uint8_t(1u << rng.Below(8));
        break;
      case 1: {  // a byte set
        if (size == 0) break;
        const uint64_t choice = rng.Below(3);
        (*data)[rng.Below(size)] = choice == 0 ? 0 : choice == 1 ? 0xff : uint8_t(rng.Next());
        break;
      }
      case 2:
      case 3: {  // an interesting value at a random place
        if (size == 0) break;
        const int width = 1 << rng.Below(4);
        Store(data, rng.Below(size), Interesting(rng), width, rng.OneIn(3));
        break;
      }
      case 4:  // cut short
        if (size > 0) data->resize(rng.Below(size));
        break;
      case 5: {  // spliced with another seed
        if (other == nullptr || other->empty()) break;
        const size_t keep = rng.Below(size + 1);
        const size_t from = rng.Below(other->size());
        data->resize(keep);
        data->insert(data->end(), other->begin() + ptrdiff_t(from), other->end());
        break;
      }
      case 6: {  // random bytes inserted
        const size_t at = rng.Below(size + 1);
        const size_t count = 1 + rng.Below(rng.OneIn(4) ? 512 : 16);
        Bytes inserted(count);
        const uint64_t fill = rng.Below(3);
        for (uint8_t& byte : inserted) {
          byte = fill == 0 ? 0 : fill == 1 ? 0xff : uint8_t(rng.Next());
        }
        data->insert(data->begin() + ptrdiff_t(at), inserted.begin(), inserted.end());
        break;
      }
      case 7: {  // a range deleted
        if (size == 0) break;
        const size_t at = rng.Below(size);
        const size_t count = 1 + rng.Below(std::min<size_t>(size - at, rng.OneIn(4) ? 4096 : 16));
        data->erase(data->begin() + ptrdiff_t(at), data->begin() + ptrdiff_t(at + count));
        break;
      }
      case 8: {  // a range repeated
        if (size == 0) break;
        const size_t at = rng.Below(size);
        const size_t count = 1 + rng.Below(std::min<size_t>(size - at, 64));
        const Bytes range(data->begin() + ptrdiff_t(at), data->begin() + ptrdiff_t(at + count));
        const size_t times = 1 + rng.Below(rng.OneIn(8) ? 256 : 4);
        for (size_t i = 0; i < times && data->size() + count <= max_size; ++i) {
          data->insert(data->begin() + ptrdiff_t(at), range.begin(), range.end());
        }
        break;
      }
      case 9: {  // a small number added to a byte or a 32-bit word
        if (size == 0) break;
        const int width = rng.OneIn(2) ? 1 : 4;
        const size_t at = rng.Below(size);
        const bool big = rng.OneIn(2);
        const int64_t delta = int64_t(rng.Below(33)) - 16;
        Store(data, at, Load(*data, at, width, big) + uint64_t(delta), width, big);
        break;
      }
      case 10: {  // a range overwritten by another seed's bytes at the same place
        if (other == nullptr || size == 0) break;
        const size_t at = rng.Below(size);
        const size_t count = std::min<size_t>(1 + rng.Below(256), size - at);
        for (size_t i = 0; i < count && at + i < other->size(); ++i) {
          (*data)[at + i] = (*other)[at + i];
        }
        break;
      }
      default: {  // a structural field: interesting, near its value, or pointing at the end
        const Field& field = rng.Pick(structure->fields);
        if (field.offset >= size) break;
        const uint64_t old = Load(*data, field.offset, field.size, field.big_endian);
        const uint64_t choice = rng.Below(4);
        const uint64_t value = choice == 0   ? Interesting(rng)
                               : choice == 1 ? old + uint64_t(int64_t(rng.Below(17)) - 8)
                               : choice == 2 ? uint64_t(size - field.offset) + rng.Below(3) - 1
                                             : rng.Next() >> rng.Below(64);
        Store(data, field.offset, value, field.size, field.big_endian);
        break;
      }
    }
    if (data->size() > max_size) data->resize(max_size);
  }
}

// ---- Failures and outcomes ----

// The outcomes of one case: counts by name, the first failures, the memory.
class Tally {
 public:
  explicit Tally(std::string name) : name_(std::move(name)) {}

  void Count(const std::string& outcome, uint64_t n = 1) { counts_[outcome] += n; }
  // A status the fuzzer got: a failure must say what failed.
  void Check(const Status& status, const char* what) {
    if (!status.ok() && status.message().empty()) {
      Fail(std::string(what) + " failed with " + std::string(StatusCodeName(status.code())) +
           " and no message");
    }
  }
  void Fail(const std::string& text) {
    ++failures_;
    if (messages_.size() < 20) messages_.push_back(where_ + ": " + text);
  }
  void SetInput(uint64_t seed, uint64_t input) {
    where_ = name_ + " input " + std::to_string(input) +
             " (RECOG_BAG_FUZZ_SEED=" + std::to_string(seed) +
             " RECOG_BAG_FUZZ_ONLY=" + std::to_string(input) + ")";
    std::snprintf(g_current, sizeof(g_current),
                  "\nbag_fuzz_test: died in case %s, %s\nreplay: RECOG_BAG_FUZZ_SEED=%llu "
                  "RECOG_BAG_FUZZ_ONLY=%llu --gtest_filter=BagFuzz.%s\n",
                  name_.c_str(), where_.c_str(), (unsigned long long)seed,
                  (unsigned long long)input, name_.c_str());
  }
  void CheckMemory() {
    const double rss = RssMiB();
    peak_rss_ = std::max(peak_rss_, rss);
    if (rss > kMaxRssMiB) Fail("VmRSS " + std::to_string(rss) + " MiB");
  }

  // The summary line, and the test's failures.
  void Finish(uint64_t inputs, double seconds) {
    g_current[0] = '\0';
    CheckMemory();
    std::ostringstream line;
    line << "bag fuzz " << name_ << ": " << inputs << " inputs in " << std::fixed
         << std::setprecision(1) << seconds << " s, " << std::setprecision(0)
         << double(inputs) / std::max(seconds, 1e-9) << " inputs/s;";
    for (const auto& [outcome, count] : counts_) line << " " << outcome << " " << count << ",";
    line << " peak VmRSS " << std::setprecision(0) << peak_rss_ << " MiB";
    std::printf("%s\n", line.str().c_str());
    std::fflush(stdout);
    for (const std::string& message : messages_) ADD_FAILURE() << message;
    EXPECT_EQ(failures_, 0u) << "failures in " << name_;
  }

 private:
  std::string name_;
  std::string where_;
  std::map<std::string, uint64_t> counts_;
  std::vector<std::string> messages_;
  uint64_t failures_ = 0;
  double peak_rss_ = 0;
};

std::string Outcome(const Status& status) {
  return status.ok() ? "OK" : std::string(StatusCodeName(status.code()));
}

// The case's loop: `run(rng, input)` for every input (or RECOG_BAG_FUZZ_ONLY's), the memory
// checked every `memory_every` inputs.
template <typename Run>
void RunCase(uint32_t stream, size_t default_inputs, size_t memory_every, Tally* tally, Run run) {
  const uint64_t seed = EnvNumber("RECOG_BAG_FUZZ_SEED", 1);
  const size_t inputs = EnvNumber("RECOG_BAG_FUZZ_INPUTS", default_inputs);
  const char* only_text = std::getenv("RECOG_BAG_FUZZ_ONLY");
  const bool only = only_text != nullptr && *only_text != '\0';
  const uint64_t only_input = only ? std::strtoull(only_text, nullptr, 10) : 0;
  ::signal(SIGABRT, OnAbort);
  // Under the sanitizers, theirs: they report the SEGV, then abort.
  if (__sanitizer_set_report_fd == nullptr) ::signal(SIGSEGV, OnAbort);
  const QuietStderr quiet;
  const auto start = std::chrono::steady_clock::now();
  uint64_t done = 0;
  for (uint64_t input = only ? only_input : 0; only ? input == only_input : input < inputs;
       ++input) {
    tally->SetInput(seed, input);
    Rng rng(seed, stream, input);
    run(rng, input);
    ++done;
    if (done % memory_every == 0) tally->CheckMemory();
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  tally->Finish(done, seconds);
}

// ---- Decoding messages and images ----

void ExerciseImage(const ImageMessage& message, Tally* tally) {
  StatusOr<ImageLayout> as_image = InspectImage(message, ImageRole::kImage);
  StatusOr<ImageLayout> as_depth = InspectImage(message, ImageRole::kDepth);
  tally->Check(as_image.status(), "InspectImage(Image, image)");
  tally->Check(as_depth.status(), "InspectImage(Image, depth)");
  cv::Mat gray, color, depth;
  const Status gray_status = DecodeGray(message, &gray, &color);
  tally->Check(gray_status, "DecodeGray(Image)");
  if (gray_status.ok() != as_image.ok()) {
    tally->Fail("raw image: InspectImage(image) " + Outcome(as_image.status()) +
                " but DecodeGray " + Outcome(gray_status));
  } else if (gray_status.ok()) {
    tally->Count("image decoded");
    if (gray.type() != CV_8UC1 || gray.size() != as_image->size) {
      tally->Fail("raw image: DecodeGray gives a Mat other than the inspected grey size");
    }
    if (!color.empty() && (color.type() != CV_8UC3 || color.size() != as_image->size)) {
      tally->Fail("raw image: DecodeGray gives a colour Mat other than the inspected size");
    }
    const Status again = DecodeGray(message, &gray, nullptr);
    if (!again.ok()) tally->Fail("raw image: DecodeGray without colour fails: " + again.message());
  }
  const Status depth_status = DecodeDepth(message, &depth);
  tally->Check(depth_status, "DecodeDepth(Image)");
  if (depth_status.ok() != as_depth.ok()) {
    tally->Fail("raw image: InspectImage(depth) " + Outcome(as_depth.status()) +
                " but DecodeDepth " + Outcome(depth_status));
  } else if (depth_status.ok()) {
    tally->Count("depth decoded");
    if (depth.type() != as_depth->depth_type || depth.size() != as_depth->size) {
      tally->Fail("raw image: DecodeDepth gives a Mat other than the inspected type and size");
    }
  }
}

void ExerciseCompressed(const CompressedImageMessage& message, Tally* tally) {
  StatusOr<ImageLayout> as_image = InspectImage(message, ImageRole::kImage);
  StatusOr<ImageLayout> as_depth = InspectImage(message, ImageRole::kDepth);
  tally->Check(as_image.status(), "InspectImage(CompressedImage, image)");
  tally->Check(as_depth.status(), "InspectImage(CompressedImage, depth)");
  cv::Mat gray, color, depth;
  if (as_image.ok()) {
    for (const bool with_color : {true, false}) {
      const Status status = DecodeGray(message, &gray, with_color ? &color : nullptr);
      tally->Check(status, "DecodeGray(CompressedImage)");
      if (!status.ok()) continue;
      tally->Count("image decoded");
      if (gray.type() != CV_8UC1 || gray.size() != as_image->size) {
        tally->Fail("compressed image: DecodeGray gives a Mat other than the inspected size");
      }
      if (with_color && !color.empty() &&
          (color.type() != CV_8UC3 || color.size() != as_image->size)) {
        tally->Fail("compressed image: DecodeGray's colour Mat is not the inspected size");
      }
    }
  } else {
    const Status status = DecodeGray(message, &gray, &color);
    if (status.ok()) tally->Fail("compressed image: DecodeGray OK where InspectImage fails");
    tally->Check(status, "DecodeGray(CompressedImage)");
  }
  const Status depth_status = DecodeDepth(message, &depth);
  tally->Check(depth_status, "DecodeDepth(CompressedImage)");
  if (depth_status.ok()) {
    tally->Count("depth decoded");
    if (!as_depth.ok()) {
      tally->Fail("compressed image: DecodeDepth OK where InspectImage(depth) fails");
    } else if (depth.type() != as_depth->depth_type || depth.size() != as_depth->size) {
      tally->Fail("compressed image: DecodeDepth gives a Mat other than the inspected one");
    }
  }
}

// `bytes` decoded as each of the three messages, in `serialization`.
void DecodeAll(Serialization serialization, std::span<const uint8_t> bytes, Tally* tally) {
  StatusOr<ImageMessage> image = DecodeImageMessage(serialization, bytes);
  tally->Check(image.status(), "DecodeImageMessage");
  tally->Count("Image " + Outcome(image.status()));
  if (image.ok()) ExerciseImage(*image, tally);
  StatusOr<CompressedImageMessage> compressed = DecodeCompressedImageMessage(serialization, bytes);
  tally->Check(compressed.status(), "DecodeCompressedImageMessage");
  tally->Count("CompressedImage " + Outcome(compressed.status()));
  if (compressed.ok()) ExerciseCompressed(*compressed, tally);
  StatusOr<CameraInfoMessage> info = DecodeCameraInfoMessage(serialization, bytes);
  tally->Check(info.status(), "DecodeCameraInfoMessage");
  tally->Count("CameraInfo " + Outcome(info.status()));
}

// ---- Opened bags ----

// Every topic of an opened bag visited, some messages read again and decoded.
void ExerciseBag(BagStore& store, Rng& rng, Tally* tally) {
  const BagSummary summary = store.summary();
  for (const TopicSummary& topic : summary.topics) {
    std::vector<std::pair<uint64_t, Bytes>> kept;
    size_t visited = 0;
    // At times the visit stops with its own error, which must come back as it is.
    const size_t stop_after = rng.OneIn(8) ? rng.Below(4) : std::numeric_limits<size_t>::max();
    const Status stop = Status::Unavailable("the fuzzer's visit stops here");
    bool stopped = false;
    const Status status = store.ForEachMessage(topic.name, [&](const StoredMessage& message) {
      if (stopped) tally->Fail("ForEachMessage visits on after its visit's error");
      if (visited == stop_after) {
        stopped = true;
        return stop;
      }
      ++visited;
      if (kept.size() < 3 || rng.OneIn(16)) {
        if (kept.size() >= 6) kept.erase(kept.begin() + ptrdiff_t(rng.Below(kept.size())));
        kept.emplace_back(message.id, Bytes(message.data.begin(), message.data.end()));
      }
      if (visited <= 8) DecodeAll(topic.serialization, message.data, tally);
      return Status::Ok();
    });
    tally->Count("messages visited", visited);
    tally->Check(status, "ForEachMessage");
    if (stopped && (status.code() != stop.code() || status.message() != stop.message())) {
      tally->Fail("ForEachMessage gives " + status.ToString() + ", not its visit's error");
    }
    if (!status.ok()) tally->Count("visit " + Outcome(status));
    std::vector<uint8_t> data;
    for (const auto& [id, bytes] : kept) {
      const Status read = store.ReadMessage(topic.name, id, &data);
      tally->Check(read, "ReadMessage");
      if (read.ok() && data != bytes) {
        tally->Fail("ReadMessage of topic '" + topic.name + "' id " + std::to_string(id) +
                    " gives other bytes than its visit");
      }
      if (!read.ok()) tally->Count("read again " + Outcome(read));
    }
    // Made-up ids and topics: any status, with a message when it fails.
    for (int i = 0; i < 2; ++i) {
      const uint64_t id = kept.empty() || rng.OneIn(2)
                              ? rng.Next() >> rng.Below(64)
                              : kept[0].first ^ (uint64_t(1) << rng.Below(64));
      tally->Check(store.ReadMessage(topic.name, id, &data), "ReadMessage (made-up id)");
    }
  }
  std::vector<uint8_t> data;
  tally->Check(store.ReadMessage("/no/such/topic", 1, &data), "ReadMessage (no such topic)");
  const Status missing =
      store.ForEachMessage("/no/such/topic", [](const StoredMessage&) { return Status::Ok(); });
  if (missing.ok()) tally->Fail("ForEachMessage of a topic the bag does not have is OK");
  tally->Check(missing, "ForEachMessage (no such topic)");
}

// `path` opened (a mutated bag) and exercised when it opens.
void OpenAndExercise(const std::string& path, Rng& rng, Tally* tally) {
  StatusOr<std::unique_ptr<BagStore>> store = OpenBag(path);
  tally->Check(store.status(), "OpenBag");
  tally->Count(store.ok() ? "opened" : "refused " + Outcome(store.status()));
  if (store.ok()) ExerciseBag(**store, rng, tally);
}

// ---- A private folder for the inputs ----

class ScratchFolder {
 public:
  ScratchFolder() {
    std::error_code error;
    const fs::path base = fs::is_directory("/dev/shm", error) && access("/dev/shm", W_OK) == 0
                              ? fs::path("/dev/shm")
                              : fs::temp_directory_path();
    std::string pattern = (base / "recog-bag-fuzz-XXXXXX").string();
    if (mkdtemp(pattern.data()) != nullptr) path_ = pattern;
  }
  // Kept when replaying one input (RECOG_BAG_FUZZ_ONLY), to look at it.
  ~ScratchFolder() {
    std::error_code ignored;
    if (path_.empty()) return;
    if (std::getenv("RECOG_BAG_FUZZ_ONLY") != nullptr) {
      std::printf("the input is kept in %s\n", path_.c_str());
    } else {
      fs::remove_all(path_, ignored);
    }
  }
  ScratchFolder(const ScratchFolder&) = delete;
  ScratchFolder& operator=(const ScratchFolder&) = delete;

  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

// ---- MCAP structure ----

void AddField(Structure* structure, size_t offset, int size) {
  structure->fields.push_back({.offset = offset, .size = size});
}

// The records of an MCAP byte range [begin, end): their lengths and the fields that are sizes,
// offsets and CRCs, and the chunks' places.
struct ChunkPlace {
  size_t record = 0;  // the opcode's byte
  size_t end = 0;     // past the record
  std::string compression;
  size_t records = 0;  // the compressed records' first byte
  size_t records_size = 0;
  uint64_t uncompressed_size = 0;
};

void WalkRecords(const Bytes& data, size_t begin, size_t end, Structure* structure,
                 std::vector<ChunkPlace>* chunks, int depth) {
  size_t at = begin;
  while (at + 9 <= end) {
    const uint8_t opcode = data[at];
    const uint64_t length = Load(data, at + 1, 8, false);
    AddField(structure, at + 1, 8);
    const size_t content = at + 9;
    if (length > end - content) break;
    const size_t record_end = content + size_t(length);
    const auto string_at = [&](size_t offset) {  // a u32-prefixed string: its end
      AddField(structure, offset, 4);
      return offset + 4 + size_t(Load(data, offset, 4, false));
    };
    switch (opcode) {
      case 0x02:  // Footer
        AddField(structure, content, 8);
        AddField(structure, content + 8, 8);
        structure->crcs.push_back({.offset = content + 16, .size = 4});
        break;
      case 0x03: {  // Schema
        const size_t name_end = string_at(content + 2);
        if (name_end + 4 <= record_end) {
          const size_t encoding_end = string_at(name_end);
          if (encoding_end + 4 <= record_end) AddField(structure, encoding_end, 4);
        }
        break;
      }
      case 0x04: {  // Channel
        const size_t topic_end = string_at(content + 4);
        if (topic_end + 4 <= record_end) {
          const size_t encoding_end = string_at(topic_end);
          if (encoding_end + 4 <= record_end) AddField(structure, encoding_end, 4);
        }
        break;
      }
      case 0x06: {  // Chunk
        if (length < 40) break;
        AddField(structure, content + 16, 8);
        structure->crcs.push_back({.offset = content + 24, .size = 4});
        ChunkPlace chunk;
        chunk.record = at;
        chunk.end = record_end;
        chunk.uncompressed_size = Load(data, content + 16, 8, false);
        const size_t compression_end = string_at(content + 28);
        if (compression_end + 8 > record_end) break;
        chunk.compression.assign(data.begin() + ptrdiff_t(content + 32),
                                 data.begin() + ptrdiff_t(compression_end));
        AddField(structure, compression_end, 8);
        chunk.records = compression_end + 8;
        chunk.records_size = size_t(
            std::min<uint64_t>(Load(data, compression_end, 8, false), record_end - chunk.records));
        chunks->push_back(chunk);
        if (chunk.compression.empty() && depth == 0) {
          WalkRecords(data, chunk.records, chunk.records + chunk.records_size, structure, chunks,
                      depth + 1);
        }
        break;
      }
      case 0x07:  // MessageIndex: the records' byte length
        AddField(structure, content + 2, 4);
        break;
      case 0x08:  // ChunkIndex
        for (size_t field = 16; field <= 24; field += 8) AddField(structure, content + field, 8);
        AddField(structure, content + 32, 4);
        break;
      case 0x09:  // Attachment
        string_at(content + 16);
        structure->crcs.push_back({.offset = record_end - 4, .size = 4});
        break;
      case 0x0A:  // AttachmentIndex
        for (size_t field = 0; field <= 32; field += 8) AddField(structure, content + field, 8);
        break;
      case 0x0B:  // Statistics
        AddField(structure, content, 8);
        for (size_t field = 10; field <= 22; field += 4) AddField(structure, content + field, 4);
        AddField(structure, content + 42, 4);
        break;
      case 0x0D:  // MetadataIndex
      case 0x0E:  // SummaryOffset
        AddField(structure, content + (opcode == 0x0E ? 1 : 0), 8);
        AddField(structure, content + (opcode == 0x0E ? 9 : 8), 8);
        break;
      case 0x0F:  // DataEnd
        structure->crcs.push_back({.offset = content, .size = 4});
        break;
      default:
        break;
    }
    at = record_end;
  }
}

struct McapSeed {
  std::string name;
  Bytes bytes;
  Structure structure;
  std::vector<ChunkPlace> chunks;
};

McapSeed MakeMcapSeed(const fs::path& path) {
  McapSeed seed;
  seed.name = path.string();
  seed.bytes = ReadFile(path);
  if (seed.bytes.size() > 8) {
    WalkRecords(seed.bytes, 8, seed.bytes.size(), &seed.structure, &seed.chunks, 0);
  }
  return seed;
}

// The decompressed bytes of a chunk (the test's own calls of libzstd and liblz4); none when it
// does not decompress.
std::optional<Bytes> Decompress(const std::string& compression, std::span<const uint8_t> input,
                                uint64_t size) {
  if (size > (uint64_t(64) << 20)) return std::nullopt;
  Bytes output(static_cast<size_t>(size));
  if (compression.empty()) {
    if (input.size() != size) return std::nullopt;
    std::copy(input.begin(), input.end(), output.begin());
    return output;
  }
  if (compression == "zstd") {
    const size_t result = ZSTD_decompress(output.data(), output.size(), input.data(), input.size());
    if (ZSTD_isError(result) || result != size) return std::nullopt;
    return output;
  }
  if (compression == "lz4") {
    LZ4F_dctx* context = nullptr;
    if (LZ4F_isError(LZ4F_createDecompressionContext(&context, LZ4F_VERSION))) return std::nullopt;
    size_t out_size = output.size();
    size_t in_size = input.size();
    const size_t result =
        LZ4F_decompress(context, output.data(), &out_size, input.data(), &in_size, nullptr);
    LZ4F_freeDecompressionContext(context);
    if (LZ4F_isError(result) || out_size != size) return std::nullopt;
    return output;
  }
  return std::nullopt;
}

Bytes CompressZstd(std::span<const uint8_t> input, int level, bool content_size, bool checksum) {
  ZSTD_CCtx* context = ZSTD_createCCtx();
  ZSTD_CCtx_setParameter(context, ZSTD_c_compressionLevel, level);
  ZSTD_CCtx_setParameter(context, ZSTD_c_contentSizeFlag, content_size ? 1 : 0);
  ZSTD_CCtx_setParameter(context, ZSTD_c_checksumFlag, checksum ? 1 : 0);
  Bytes output(ZSTD_compressBound(input.size()));
  size_t size = 0;
  if (content_size) {
    size = ZSTD_compress2(context, output.data(), output.size(), input.data(), input.size());
  } else {
    // Streamed without a pledged size: the frame does not say its content size.
    ZSTD_inBuffer source{input.data(), input.size(), 0};
    ZSTD_outBuffer destination{output.data(), output.size(), 0};
    size = ZSTD_compressStream2(context, &destination, &source, ZSTD_e_end);
    size = ZSTD_isError(size) ? size : destination.pos;
  }
  ZSTD_freeCCtx(context);
  output.resize(ZSTD_isError(size) ? 0 : size);
  return output;
}

Bytes CompressLz4(std::span<const uint8_t> input, bool linked, bool checksums, bool content_size,
                  bool big_blocks) {
  LZ4F_preferences_t preferences{};
  preferences.frameInfo.blockSizeID = big_blocks ? LZ4F_max4MB : LZ4F_max64KB;
  preferences.frameInfo.blockMode = linked ? LZ4F_blockLinked : LZ4F_blockIndependent;
  preferences.frameInfo.contentChecksumFlag =
      checksums ? LZ4F_contentChecksumEnabled : LZ4F_noContentChecksum;
  preferences.frameInfo.blockChecksumFlag =
      checksums ? LZ4F_blockChecksumEnabled : LZ4F_noBlockChecksum;
  preferences.frameInfo.contentSize = content_size ? input.size() : 0;
  Bytes output(LZ4F_compressFrameBound(input.size(), &preferences));
  const size_t size =
      LZ4F_compressFrame(output.data(), output.size(), input.data(), input.size(), &preferences);
  output.resize(LZ4F_isError(size) ? 0 : size);
  return output;
}

void PutLe(Bytes* out, uint64_t value, int size) {
  for (int i = 0; i < size; ++i) out->push_back(uint8_t(value >> (8 * i)));
}

// A chunk of *data decompressed, its records mutated (their own structure aimed at) and
// recompressed with zstd, lz4 or none, its lengths set to match (its CRC 0, not checked).
void RechunkMutation(Rng& rng, const McapSeed& seed, Bytes* data) {
  if (seed.chunks.empty()) return;
  const ChunkPlace& chunk = rng.Pick(seed.chunks);
  if (chunk.end > data->size()) return;
  const std::optional<Bytes> records =
      Decompress(chunk.compression,
                 std::span<const uint8_t>(seed.bytes).subspan(chunk.records, chunk.records_size),
                 chunk.uncompressed_size);
  if (!records) return;
  Bytes mutated = *records;
  Structure inner;
  std::vector<ChunkPlace> ignored;
  WalkRecords(mutated, 0, mutated.size(), &inner, &ignored, 1);
  MutateBytes(rng, &mutated, &inner, nullptr, mutated.size() * 2 + 1024);
  const uint64_t choice = rng.Below(3);
  const std::string compression = choice == 0 ? "zstd" : choice == 1 ? "lz4" : "";
  const Bytes compressed =
      choice == 0   ? CompressZstd(mutated, 1, rng.OneIn(2), false)
      : choice == 1 ? CompressLz4(mutated, rng.OneIn(2), rng.OneIn(4), rng.OneIn(2), rng.OneIn(2))
                    : mutated;
  Bytes record;
  record.push_back(0x06);
  const uint64_t length = 8 + 8 + 8 + 4 + 4 + compression.size() + 8 + compressed.size();
  PutLe(&record, length, 8);
  record.insert(record.end(), data->begin() + ptrdiff_t(chunk.record + 9),
                data->begin() + ptrdiff_t(chunk.record + 9 + 16));  // start and end times
  PutLe(&record, mutated.size(), 8);
  PutLe(&record, 0, 4);
  PutLe(&record, compression.size(), 4);
  record.insert(record.end(), compression.begin(), compression.end());
  PutLe(&record, compressed.size(), 8);
  record.insert(record.end(), compressed.begin(), compressed.end());
  data->erase(data->begin() + ptrdiff_t(chunk.record), data->begin() + ptrdiff_t(chunk.end));
  data->insert(data->begin() + ptrdiff_t(chunk.record), record.begin(), record.end());
}

std::vector<McapSeed> McapSeeds() {
  std::vector<McapSeed> seeds;
  for (const char* name : {"fixture.mcap", "fixture_cdr_be.mcap", "fixture_lz4.mcap",
                           "fixture_nochunk.mcap", "fixture_noindex.mcap"}) {
    seeds.push_back(MakeMcapSeed(recog::testing::ProjectTestData(std::string("bags/") + name)));
  }
  for (const fs::path& path : SharedFiles("mcap-conformance", {".mcap"})) {
    seeds.push_back(MakeMcapSeed(path));
  }
  for (const fs::path& path : SharedFiles("rosbag2", {".mcap"})) {
    seeds.push_back(MakeMcapSeed(path));
  }
  return seeds;
}

// A seed: the fixtures (in one input of two, they are the richest) or any.
template <typename Seed>
const Seed& PickSeed(Rng& rng, const std::vector<Seed>& seeds, size_t fixtures) {
  return rng.OneIn(2) ? seeds[rng.Below(fixtures)] : rng.Pick(seeds);
}

TEST(BagFuzz, Mcap) {
  const std::vector<McapSeed> seeds = McapSeeds();
  ASSERT_GE(seeds.size(), 5u);
  for (const McapSeed& seed : seeds) ASSERT_GT(seed.bytes.size(), 16u) << seed.name;
  ScratchFolder scratch;
  ASSERT_FALSE(scratch.path().empty());
  const std::string path = (scratch.path() / "input.mcap").string();
  Tally tally("Mcap");
  RunCase(1, 1000, 256, &tally, [&](Rng& rng, uint64_t) {
    const McapSeed& seed = PickSeed(rng, seeds, 5);
    Bytes data = seed.bytes;
    if (rng.OneIn(2)) {
      for (const Field& crc : seed.structure.crcs) Store(&data, crc.offset, 0, 4, false);
    }
    if (rng.OneIn(4)) RechunkMutation(rng, seed, &data);
    if (!rng.OneIn(6)) {
      MutateBytes(rng, &data, &seed.structure, &rng.Pick(seeds).bytes,
                  seed.bytes.size() * 2 + 4096);
    }
    WriteFile(path, data);
    OpenAndExercise(path, rng, &tally);
  });
}

// ---- rosbag2 ----

struct FolderSeed {
  std::string name;
  std::optional<std::string> metadata;
  std::vector<std::pair<std::string, Bytes>> files;  // name, bytes
};

FolderSeed MakeFolderSeed(const fs::path& folder) {
  FolderSeed seed;
  seed.name = folder.string();
  std::vector<fs::path> entries;
  for (const auto& entry : fs::directory_iterator(folder)) entries.push_back(entry.path());
  std::sort(entries.begin(), entries.end());
  for (const fs::path& path : entries) {
    const Bytes bytes = ReadFile(path);
    if (path.filename() == "metadata.yaml") {
      seed.metadata = std::string(bytes.begin(), bytes.end());
    } else {
      seed.files.emplace_back(path.filename().string(), bytes);
    }
  }
  return seed;
}

// metadata.yaml's text changed: a field's value from the dictionary, a key renamed, lines
// deleted, repeated, swapped or re-indented, a file added to the list, or bytes mutated.
std::string MutateYaml(Rng& rng, const std::string& yaml, const std::vector<std::string>& names) {
  // clang-format off
  static const std::vector<std::string> kValues = {
      "0", "1", "2", "3", "4", "5", "6", "7", "8", "9", "42", "-1", "-2147483649", "2147483648",
      "99999999999999999999999", "1e400", "0x10", "~", "null", "''", "\"\"", "[]", "{}", "[a, b]",
      "{a: 1}", "[[[[[[[[]]]]]]]]", "sqlite3", "mcap", "ros1", "SQLITE3", "zstd", "ZSTD", "lz4",
      "bz2", "none", "NONE", "None", "FILE", "MESSAGE", "file", "message", "cdr", "ros1",
      "wrong_format", "json", "missing_0.db3", "sub/missing.db3", "x.db3.zstd", "&anchor value",
      "*anchor", "!!binary AAAA", "|", ">", "'unterminated", "\"\\x00\"", "true", "false", ".inf",
      "-.inf", ".nan", "sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage",
      "sensor_msgs/msg/CameraInfo", "/camera/image_raw", std::string(300, 'a')};
  // clang-format on
  // clang-format off
  static const std::vector<std::string> kKeys = {
      "version", "storage_identifier", "relative_file_paths", "files", "path", "compression_mode",
      "compression_format", "topics_with_message_count", "topic_metadata", "topic_and_type",
      "name", "type", "serialization_format", "message_count", "rosbag2_bagfile_information"};
  // clang-format on
  std::vector<std::string> lines;
  std::istringstream in(yaml);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  const int steps = 1 + int(rng.Below(3));
  for (int step = 0; step < steps && !lines.empty(); ++step) {
    const size_t at = rng.Below(lines.size());
    std::string& line = lines[at];
    const size_t colon = line.find(':');
    switch (rng.Below(9)) {
      case 0:
      case 1:
      case 2: {  // a value
        std::string value = rng.OneIn(4) && !names.empty() ? rng.Pick(names) : rng.Pick(kValues);
        if (colon != std::string::npos) {
          line = line.substr(0, colon + 1) + " " + value;
        } else if (line.find("- ") != std::string::npos) {
          line = line.substr(0, line.find("- ") + 2) + value;
        }
        break;
      }
      case 3:  // a key
        if (colon != std::string::npos) {
          const size_t indent = line.find_first_not_of(" -");
          if (indent != std::string::npos && indent < colon) {
            line = line.substr(0, indent) + rng.Pick(kKeys) + line.substr(colon);
          }
        }
        break;
      case 4:
        lines.erase(lines.begin() + ptrdiff_t(at));
        break;
      case 5: {
        const std::string copy = line;
        lines.insert(lines.begin() + ptrdiff_t(rng.Below(lines.size() + 1)), copy);
        break;
      }
      case 6:
        std::swap(line, lines[rng.Below(lines.size())]);
        break;
      case 7:
        if (rng.OneIn(2)) {
          line.insert(0, "  ");
        } else if (line.starts_with("  ")) {
          line.erase(0, 2);
        }
        break;
      default: {
        const std::string name = names.empty() ? "x.db3" : rng.Pick(names);
        lines.insert(lines.begin() + ptrdiff_t(at), "    - " + name);
        break;
      }
    }
  }
  std::string text;
  for (const std::string& line : lines) text += line + "\n";
  if (rng.OneIn(5)) {
    Bytes bytes(text.begin(), text.end());
    MutateBytes(rng, &bytes, nullptr, nullptr, bytes.size() * 2 + 1024);
    text.assign(bytes.begin(), bytes.end());
  }
  return text;
}

TEST(BagFuzz, Rosbag2) {
  std::vector<FolderSeed> folders = {
      MakeFolderSeed(recog::testing::ProjectTestData("bags/fixture_sqlite3"))};
  std::vector<McapSeed> files = {
      MakeMcapSeed(recog::testing::ProjectTestData("bags/fixture_sqlite3/fixture_0.db3"))};
  const fs::path shared = recog::testing::SharedData("bags/rosbag2");
  std::error_code error;
  if (fs::is_directory(shared, error)) {
    std::vector<fs::path> entries;
    for (const auto& entry : fs::directory_iterator(shared)) entries.push_back(entry.path());
    std::sort(entries.begin(), entries.end());
    for (const fs::path& entry : entries) {
      if (fs::is_directory(entry)) folders.push_back(MakeFolderSeed(entry));
    }
    for (const fs::path& path : SharedFiles("rosbag2", {".db3"})) {
      files.push_back(MakeMcapSeed(path));
      files.back().structure = {};
      files.back().chunks.clear();
    }
  }
  files[0].structure = {};
  files[0].chunks.clear();
  // The header fields of an sqlite3 file: page size, page counts, schema cookie, freelist.
  Structure sqlite_header;
  for (const auto& [offset, size] : std::vector<std::pair<size_t, int>>{{16, 2},
                                                                        {24, 4},
                                                                        {28, 4},
                                                                        {32, 4},
                                                                        {36, 4},
                                                                        {40, 4},
                                                                        {44, 4},
                                                                        {48, 4},
                                                                        {52, 4},
                                                                        {56, 4},
                                                                        {60, 4},
                                                                        {64, 4},
                                                                        {92, 4},
                                                                        {96, 4},
                                                                        {100 + 3, 2},
                                                                        {100 + 5, 2}}) {
    sqlite_header.fields.push_back({.offset = offset, .size = size, .big_endian = true});
  }
  ScratchFolder scratch;
  ASSERT_FALSE(scratch.path().empty());
  const fs::path temporary = scratch.path() / "tmp";
  fs::create_directories(temporary);
  const char* old_tmpdir = std::getenv("TMPDIR");
  const std::optional<std::string> saved_tmpdir =
      old_tmpdir ? std::optional<std::string>(old_tmpdir) : std::nullopt;
  setenv("TMPDIR", temporary.c_str(), 1);
  const fs::path lone = scratch.path() / "lone.db3";
  const fs::path folder = scratch.path() / "bag";
  Tally tally("Rosbag2");
  RunCase(2, 300, 32, &tally, [&](Rng& rng, uint64_t) {
    const auto mutate_file = [&](const Bytes& seed_bytes, Bytes* data) {
      const bool sqlite =
          seed_bytes.size() >= 16 && std::memcmp(seed_bytes.data(), "SQLite", 6) == 0;
      MutateBytes(rng, data, sqlite ? &sqlite_header : nullptr, &rng.Pick(files).bytes,
                  seed_bytes.size() * 2 + 4096);
    };
    if (rng.OneIn(3)) {
      const McapSeed& seed = PickSeed(rng, files, 1);
      Bytes data = seed.bytes;
      mutate_file(seed.bytes, &data);
      WriteFile(lone, data);
      OpenAndExercise(lone.string(), rng, &tally);
    } else {
      const FolderSeed& seed = PickSeed(rng, folders, 1);
      std::error_code ignored;
      fs::remove_all(folder, ignored);
      fs::create_directories(folder);
      std::vector<std::string> names;
      for (const auto& [name, bytes] : seed.files) names.push_back(name);
      const uint64_t what = rng.Below(5);  // 0-1 metadata, 2-3 a file, 4 both
      std::vector<std::pair<std::string, Bytes>> contents = seed.files;
      if (what >= 2 && !contents.empty()) {
        auto& [name, bytes] = contents[rng.Below(contents.size())];
        const Bytes original = bytes;
        mutate_file(original, &bytes);
      }
      if (rng.OneIn(10) && !contents.empty())
        contents.erase(contents.begin() + ptrdiff_t(rng.Below(contents.size())));
      if (rng.OneIn(10) && !contents.empty()) {
        contents.push_back(contents[rng.Below(contents.size())]);
        contents.back().first = rng.OneIn(2) ? "extra_9.db3" : "extra_9.mcap";
        names.push_back(contents.back().first);
      }
      for (const auto& [name, bytes] : contents) WriteFile(folder / name, bytes);
      if (seed.metadata && !rng.OneIn(20)) {
        const std::string yaml =
            what <= 1 || what == 4 ? MutateYaml(rng, *seed.metadata, names) : *seed.metadata;
        WriteFile(folder / "metadata.yaml",
                  std::span(reinterpret_cast<const uint8_t*>(yaml.data()), yaml.size()));
      }
      OpenAndExercise(folder.string(), rng, &tally);
    }
    // A decompressed file's temporary folder is gone with its store.
    if (!fs::is_empty(temporary, error)) {
      tally.Fail("a temporary folder is left in TMPDIR after the store is gone");
      fs::remove_all(temporary, error);
      fs::create_directories(temporary, error);
    }
  });
  if (saved_tmpdir) {
    setenv("TMPDIR", saved_tmpdir->c_str(), 1);
  } else {
    unsetenv("TMPDIR");
  }
}

// ---- Messages ----

struct HeaderFields {
  int64_t sec = 1700000000;
  uint32_t nanosec = 0;
  std::string frame_id = "camera";
};
struct ImageFields {
  HeaderFields header;
  uint32_t height = 0, width = 0;
  std::string encoding;
  uint8_t is_bigendian = 0;
  uint32_t step = 0;
  Bytes data;
};
struct CompressedFields {
  HeaderFields header;
  std::string format;
  Bytes data;
};
struct CameraInfoFields {
  HeaderFields header;
  uint32_t height = 48, width = 64;
  std::string model = "plumb_bob";
  std::vector<double> d = {0, 0, 0, 0, 0};
  std::array<double, 9> k{}, r{};
  std::array<double, 12> p{};
  std::array<uint32_t, 6> rest{};
  uint8_t rectify = 0;
};
using MessageFields = std::variant<ImageFields, CompressedFields, CameraInfoFields>;

// A message serialized in ROS 1's way or CDR (LE or BE); it remembers where its counts are.
class Writer {
 public:
  Writer(Serialization serialization, bool big_endian)
      : ros1_(serialization == Serialization::kRos1), big_(!ros1_ && big_endian) {
    if (!ros1_) bytes_ = {0x00, uint8_t(big_ ? 0x00 : 0x01), 0x00, 0x00};
  }
  void U8(uint8_t value) { bytes_.push_back(value); }
  void U32(uint32_t value, bool count = false) {
    Align(4);
    if (count)
      structure_.fields.push_back({.offset = bytes_.size(), .size = 4, .big_endian = big_});
    Put(value, 4);
  }
  void F64(double value) {
    Align(8);
    uint64_t bits = 0;
    std::memcpy(&bits, &value, sizeof(bits));
    Put(bits, 8);
  }
  void String(const std::string& text) {
    U32(uint32_t(text.size() + (ros1_ ? 0 : 1)), true);
    bytes_.insert(bytes_.end(), text.begin(), text.end());
    if (!ros1_) bytes_.push_back(0);
  }
  void ByteSequence(const Bytes& data) {
    U32(uint32_t(data.size()), true);
    bytes_.insert(bytes_.end(), data.begin(), data.end());
  }
  void Header(const HeaderFields& header) {
    if (ros1_) U32(1);
    U32(uint32_t(header.sec));
    U32(header.nanosec);
    String(header.frame_id);
  }
  Bytes& bytes() { return bytes_; }
  const Structure& structure() const { return structure_; }

 private:
  void Align(size_t size) {
    if (ros1_) return;
    while ((bytes_.size() - 4) % size != 0) bytes_.push_back(0);
  }
  void Put(uint64_t value, int size) {
    for (int i = 0; i < size; ++i) {
      bytes_.push_back(uint8_t(value >> (8 * (big_ ? size - 1 - i : i))));
    }
  }

  bool ros1_;
  bool big_;
  Bytes bytes_;
  Structure structure_;
};

void Serialize(const MessageFields& fields, Writer* w) {
  if (const auto* image = std::get_if<ImageFields>(&fields)) {
    w->Header(image->header);
    w->U32(image->height, true);
    w->U32(image->width, true);
    w->String(image->encoding);
    w->U8(image->is_bigendian);
    w->U32(image->step, true);
    w->ByteSequence(image->data);
  } else if (const auto* compressed = std::get_if<CompressedFields>(&fields)) {
    w->Header(compressed->header);
    w->String(compressed->format);
    w->ByteSequence(compressed->data);
  } else {
    const auto& info = std::get<CameraInfoFields>(fields);
    w->Header(info.header);
    w->U32(info.height);
    w->U32(info.width);
    w->String(info.model);
    w->U32(uint32_t(info.d.size()), true);
    for (const double value : info.d) w->F64(value);
    for (const double value : info.k) w->F64(value);
    for (const double value : info.r) w->F64(value);
    for (const double value : info.p) w->F64(value);
    for (const uint32_t value : info.rest) w->U32(value);
    w->U8(info.rectify);
  }
}

HeaderFields FromHeader(const MessageHeader& header) {
  return {.sec = header.stamp_ns / 1000000000,
          .nanosec = uint32_t(header.stamp_ns % 1000000000),
          .frame_id = header.frame_id};
}

// RVL as compressed_depth_image_transport writes it (the test's own encoder of the format that
// ros_images.h describes): runs of zeros and of non-zero pixels, the latter as zigzag deltas.
class RvlWriter {
 public:
  void Value(uint64_t value) {
    do {
      uint32_t nibble = uint32_t(value & 7);
      value >>= 3;
      if (value != 0) nibble |= 8;
      word_ |= nibble << (28 - 4 * nibbles_);
      if (++nibbles_ == 8) Flush();
    } while (value != 0);
  }
  Bytes Finish() {
    if (nibbles_ > 0) Flush();
    return bytes_;
  }

 private:
  void Flush() {
    PutLe(&bytes_, word_, 4);
    word_ = 0;
    nibbles_ = 0;
  }
  Bytes bytes_;
  uint32_t word_ = 0;
  int nibbles_ = 0;
};

Bytes EncodeRvl(const cv::Mat& depth) {
  RvlWriter writer;
  const uint16_t* pixels = depth.ptr<uint16_t>();
  const size_t total = depth.total();
  size_t at = 0;
  int previous = 0;
  while (at < total) {
    size_t zeros = 0;
    while (at + zeros < total && pixels[at + zeros] == 0) ++zeros;
    at += zeros;
    size_t nonzeros = 0;
    while (at + nonzeros < total && pixels[at + nonzeros] != 0) ++nonzeros;
    writer.Value(zeros);
    writer.Value(nonzeros);
    for (size_t i = 0; i < nonzeros; ++i) {
      const int delta = int(pixels[at + i]) - previous;
      previous = pixels[at + i];
      writer.Value(uint64_t(uint32_t((delta << 1) ^ (delta >> 31))));
    }
    at += nonzeros;
  }
  Bytes out;
  PutLe(&out, uint32_t(depth.cols), 4);
  PutLe(&out, uint32_t(depth.rows), 4);
  const Bytes words = writer.Finish();
  out.insert(out.end(), words.begin(), words.end());
  return out;
}

Bytes Encode(const cv::Mat& image, const std::string& extension) {
  std::vector<uchar> bytes;
  cv::imencode(extension, image, bytes);
  return Bytes(bytes.begin(), bytes.end());
}

Bytes DepthHeader(float a, float b) {
  Bytes header(12, 0);
  std::memcpy(header.data() + 4, &a, 4);
  std::memcpy(header.data() + 8, &b, 4);
  return header;
}

Bytes Concatenated(Bytes a, const Bytes& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

// The message seeds: the fixtures' messages (as decoded) and made-up ones.
std::vector<MessageFields> MessageSeeds() {
  std::vector<MessageFields> seeds;
  for (const char* name : {"fixture.mcap", "fixture_cdr_be.mcap"}) {
    StatusOr<std::unique_ptr<BagStore>> store =
        OpenBag(recog::testing::ProjectTestData(std::string("bags/") + name));
    if (!store.ok()) continue;
    for (const TopicSummary& topic : (*store)->summary().topics) {
      int taken = 0;
      (void)(*store)->ForEachMessage(topic.name, [&](const StoredMessage& message) {
        if (taken++ >= 2) return Status::Ok();
        if (IsMessageType(topic.type, "sensor_msgs", "Image")) {
          StatusOr<ImageMessage> m = DecodeImageMessage(topic.serialization, message.data);
          if (m.ok()) {
            seeds.push_back(ImageFields{FromHeader(m->header), m->height, m->width, m->encoding,
                                        uint8_t(m->is_bigendian), m->step,
                                        Bytes(m->data.begin(), m->data.end())});
          }
        } else if (IsMessageType(topic.type, "sensor_msgs", "CompressedImage")) {
          StatusOr<CompressedImageMessage> m =
              DecodeCompressedImageMessage(topic.serialization, message.data);
          if (m.ok()) {
            seeds.push_back(CompressedFields{FromHeader(m->header), m->format,
                                             Bytes(m->data.begin(), m->data.end())});
          }
        } else if (IsMessageType(topic.type, "sensor_msgs", "CameraInfo")) {
          StatusOr<CameraInfoMessage> m =
              DecodeCameraInfoMessage(topic.serialization, message.data);
          if (m.ok()) {
            CameraInfoFields info{.header = FromHeader(m->header),
                                  .height = m->height,
                                  .width = m->width,
                                  .model = m->distortion_model,
                                  .d = m->d,
                                  .k = m->k,
                                  .r = m->r,
                                  .p = m->p};
            seeds.push_back(info);
          }
        }
        return Status::Ok();
      });
    }
  }
  // Raw images of every encoding, both byte orders, rows padded or not.
  std::mt19937_64 random(7);
  // clang-format off
  const std::vector<std::pair<std::string, int>> encodings = {
      {"mono8", 1}, {"8UC1", 1}, {"rgb8", 3}, {"bgr8", 3}, {"rgba8", 4}, {"bgra8", 4},
      {"16UC1", 2}, {"mono16", 2}, {"32FC1", 4}, {"yuv422", 2}, {"bayer_rggb8", 1}};
  // clang-format on
  for (const auto& [encoding, bytes_per_pixel] : encodings) {
    for (const auto& [width, height, pad] :
         std::vector<std::tuple<uint32_t, uint32_t, uint32_t>>{{5, 3, 0}, {17, 4, 3}}) {
      ImageFields image;
      image.height = height;
      image.width = width;
      image.encoding = encoding;
      image.is_bigendian = uint8_t(pad != 0);
      image.step = width * uint32_t(bytes_per_pixel) + pad;
      image.data.resize(size_t(image.step) * height);
      for (uint8_t& byte : image.data) byte = uint8_t(random());
      seeds.push_back(image);
    }
  }
  // Encoded images: JPEG and PNG, grey and colour, 8 and 16 bits; compressedDepth PNG and RVL.
  cv::Mat gray(7, 9, CV_8UC1), bgr(6, 11, CV_8UC3), bgra(5, 4, CV_8UC4), depth(6, 10, CV_16UC1);
  cv::randu(gray, 0, 255);
  cv::randu(bgr, 0, 255);
  cv::randu(bgra, 0, 255);
  cv::randu(depth, 0, 3000);
  depth.at<uint16_t>(0, 0) = 0;
  depth.at<uint16_t>(2, 3) = 0;
  depth.at<uint16_t>(2, 4) = 0;
  const Bytes depth_png = Encode(depth, ".png");
  const Bytes depth_rvl = EncodeRvl(depth);
  const std::vector<std::pair<std::string, Bytes>> compressed = {
      {"jpeg", Encode(gray, ".jpg")},
      {"bgr8; jpeg compressed bgr8", Encode(bgr, ".jpg")},
      {"png", Encode(gray, ".png")},
      {"rgb8; png compressed bgr8", Encode(bgr, ".png")},
      {"bgra8; png compressed bgra8", Encode(bgra, ".png")},
      {"16UC1; png compressed ", depth_png},
      {"16UC1; compressedDepth png", Concatenated(DepthHeader(0, 0), depth_png)},
      {"16UC1; compressedDepth", Concatenated(DepthHeader(0, 0), depth_png)},
      {"16UC1; compressedDepth rvl", Concatenated(DepthHeader(0, 0), depth_rvl)},
      {"32FC1; compressedDepth png", Concatenated(DepthHeader(1500.f, 0.5f), depth_png)},
      {"32FC1; compressedDepth rvl", Concatenated(DepthHeader(1500.f, 0.5f), depth_rvl)},
      {"mono16; compressedDepth rvl", Concatenated(DepthHeader(0, 0), depth_rvl)},
  };
  for (const auto& [format, data] : compressed) {
    CompressedFields message;
    message.format = format;
    message.data = data;
    seeds.push_back(message);
  }
  CameraInfoFields info;
  info.model = "rational_polynomial";
  info.d = std::vector<double>(8, 0.01);
  info.k = {500, 0, 320, 0, 500, 240, 0, 0, 1};
  seeds.push_back(info);
  return seeds;
}

// The structure of an encoded image: a PNG's chunk lengths and IHDR fields, a JPEG's segment
// lengths and frame sizes, an RVL header (at `offset` in the message's data).
Structure PayloadStructure(const Bytes& data, size_t offset, bool* png) {
  Structure structure;
  *png = false;
  const auto field = [&](size_t at, int size, bool big) {
    structure.fields.push_back({.offset = at, .size = size, .big_endian = big});
  };
  if (data.size() >= offset + 8 && data[offset] == 0x89 && data[offset + 1] == 'P') {
    *png = true;
    for (size_t at = offset + 8; at + 12 <= data.size();) {
      const uint64_t length = Load(data, at, 4, true);
      field(at, 4, true);
      if (std::memcmp(data.data() + at + 4, "IHDR", 4) == 0) {
        field(at + 8, 4, true);
        field(at + 12, 4, true);
        field(at + 16, 1, true);
        field(at + 17, 1, true);
      }
      at += 12 + size_t(length);
    }
  } else if (data.size() >= offset + 4 && data[offset] == 0xff && data[offset + 1] == 0xd8) {
    for (size_t at = offset + 2; at + 4 <= data.size() && data[at] == 0xff;) {
      field(at + 2, 2, true);
      const uint8_t marker = data[at + 1];
      if (marker >= 0xc0 && marker <= 0xc3) {
        field(at + 5, 2, true);
        field(at + 7, 2, true);
        field(at + 4, 1, true);
        field(at + 9, 1, true);
      }
      if (marker == 0xda) break;
      at += 2 + size_t(Load(data, at + 2, 2, true));
    }
  } else if (data.size() >= offset + 8) {  // RVL: width, height
    field(offset, 4, false);
    field(offset + 4, 4, false);
  }
  return structure;
}

// Every PNG chunk's CRC computed again, so that a mutation inside reaches the decoder.
void FixPngCrcs(Bytes* data, size_t offset) {
  for (size_t at = offset + 8; at + 12 <= data->size();) {
    const uint64_t length = Load(*data, at, 4, true);
    if (length > data->size() - at - 12) break;
    const uLong crc = crc32(0, data->data() + at + 4, uInt(length + 4));
    Store(data, at + 8 + size_t(length), crc, 4, true);
    at += 12 + size_t(length);
  }
}

void MutateHeader(Rng& rng, HeaderFields* header) {
  switch (rng.Below(3)) {
    case 0:
      header->sec = rng.OneIn(2) ? int64_t(int32_t(Interesting(rng))) : -1;
      break;
    case 1:
      header->nanosec = uint32_t(Interesting(rng));
      break;
    default:
      header->frame_id = rng.OneIn(2) ? "" : std::string(rng.Below(300), char('a' + rng.Below(26)));
      break;
  }
}

// The data of a compressed image mutated: the payload after compressedDepth's header aimed at,
// its PNG CRCs fixed in most inputs; the header's floats set to odd values.
void MutatePayload(Rng& rng, const std::string& format, Bytes* data,
                   const std::vector<MessageFields>& seeds) {
  const bool depth_header = Lowercase(format).find("compresseddepth") != std::string::npos;
  const size_t offset = depth_header ? 12 : 0;
  if (depth_header && data->size() >= 12 && rng.OneIn(3)) {
    static const float kFloats[] = {0.f,
                                    -0.f,
                                    1.f,
                                    -1.f,
                                    0.5f,
                                    1e-38f,
                                    1e-45f,
                                    1e38f,
                                    65535.f,
                                    std::numeric_limits<float>::infinity(),
                                    -std::numeric_limits<float>::infinity(),
                                    std::numeric_limits<float>::quiet_NaN()};
    const float value = kFloats[rng.Below(std::size(kFloats))];
    std::memcpy(data->data() + 4 + 4 * rng.Below(2), &value, 4);
    if (rng.OneIn(4)) Store(data, 0, Interesting(rng), 4, false);
    if (rng.OneIn(2)) return;
  }
  if (rng.OneIn(12)) {  // another seed's data in its place
    const MessageFields& other = rng.Pick(seeds);
    if (const auto* c = std::get_if<CompressedFields>(&other)) {
      data->resize(std::min(data->size(), offset));
      const size_t other_offset =
          Lowercase(c->format).find("compresseddepth") != std::string::npos ? 12 : 0;
      if (c->data.size() > other_offset) {
        data->insert(data->end(), c->data.begin() + ptrdiff_t(other_offset), c->data.end());
      }
      return;
    }
  }
  bool png = false;
  const Structure structure = PayloadStructure(*data, offset, &png);
  MutateBytes(rng, data, &structure, nullptr, data->size() * 2 + 1024);
  if (png && !rng.OneIn(4)) FixPngCrcs(data, offset);
}

void MutateFields(Rng& rng, MessageFields* fields, const std::vector<MessageFields>& seeds) {
  // clang-format off
  static const std::vector<std::string> kEncodings = {
      "mono8", "8UC1", "rgb8", "bgr8", "rgba8", "bgra8", "16UC1", "mono16", "32FC1", "16SC1",
      "8UC3", "64FC1", "", "MONO8", "mono8 ", "rgb16", "bayer_rggb8", "yuv422"};
  // clang-format on
  // clang-format off
  static const std::vector<std::string> kFormats = {
      "jpeg", "png", "jpg", "", "bgr8; jpeg compressed bgr8", "mono8; png compressed mono8",
      "16UC1; png compressed", "16UC1; compressedDepth png", "16UC1; compressedDepth rvl",
      "16UC1; compressedDepth", "32FC1; compressedDepth png", "32FC1; compressedDepth rvl",
      "32FC1; compressedDepth", "mono16; compressedDepth", "16uc1;COMPRESSEDDEPTH RVL",
      "compressedDepth", "; compressedDepth", "8UC1; compressedDepth png",
      "16UC1; compressedDepth zz", "16UC1; compressedDepth rvl png", "32FC1;compressedDepth rvl  ",
      "16UC1; compressedDepth ;", "tiff", "rvl", "16UC1; rvl", "bgr8; png compressed bgr8", ";",
      "compressedDepth png; jpeg"};
  // clang-format on
  const int steps = 1 + int(rng.Below(3));
  for (int step = 0; step < steps; ++step) {
    if (auto* image = std::get_if<ImageFields>(fields)) {
      switch (rng.Below(7)) {
        case 0:
          image->height = rng.OneIn(2) ? uint32_t(Interesting(rng))
                                       : image->height + uint32_t(rng.Below(5)) - 2;
          break;
        case 1:
          image->width =
              rng.OneIn(2) ? uint32_t(Interesting(rng)) : image->width + uint32_t(rng.Below(5)) - 2;
          break;
        case 2:
          image->step =
              rng.OneIn(2) ? uint32_t(Interesting(rng)) : image->step + uint32_t(rng.Below(9)) - 4;
          break;
        case 3:
          image->encoding = rng.Pick(kEncodings);
          break;
        case 4:
          image->is_bigendian = uint8_t(rng.OneIn(2) ? rng.Below(2) : rng.Next());
          break;
        case 5:
          MutateHeader(rng, &image->header);
          break;
        default:
          MutateBytes(rng, &image->data, nullptr, nullptr, image->data.size() * 2 + 64);
          break;
      }
    } else if (auto* compressed = std::get_if<CompressedFields>(fields)) {
      switch (rng.Below(5)) {
        case 0:
          compressed->format = rng.Pick(kFormats);
          break;
        case 1:
          MutateHeader(rng, &compressed->header);
          break;
        default:
          MutatePayload(rng, compressed->format, &compressed->data, seeds);
          break;
      }
    } else {
      auto& info = std::get<CameraInfoFields>(*fields);
      switch (rng.Below(4)) {
        case 0:
          info.d.resize(rng.Below(20));
          break;
        case 1:
          info.model = rng.OneIn(2) ? "" : std::string(rng.Below(64), 'x');
          break;
        case 2:
          info.k[rng.Below(9)] = std::numeric_limits<double>::quiet_NaN();
          break;
        default:
          MutateHeader(rng, &info.header);
          break;
      }
    }
  }
}

TEST(BagFuzz, Messages) {
  const std::vector<MessageFields> seeds = MessageSeeds();
  ASSERT_GE(seeds.size(), 40u);
  Tally tally("Messages");
  RunCase(3, 20000, 4096, &tally, [&](Rng& rng, uint64_t) {
    MessageFields fields = rng.Pick(seeds);
    const bool field_mutation = !rng.OneIn(4);
    if (field_mutation) MutateFields(rng, &fields, seeds);
    const Serialization serialization = rng.OneIn(3) ? Serialization::kRos1 : Serialization::kCdr;
    Writer writer(serialization, rng.OneIn(2));
    Serialize(fields, &writer);
    Bytes& bytes = writer.bytes();
    if (!field_mutation || rng.OneIn(3)) {
      MutateBytes(rng, &bytes, &writer.structure(), nullptr, bytes.size() * 2 + 1024);
    }
    tally.Count(serialization == Serialization::kRos1 ? "ros1" : "cdr");
    DecodeAll(serialization, bytes, &tally);
    // The other serialization too: bytes of one read as the other.
    if (rng.OneIn(4)) {
      DecodeAll(serialization == Serialization::kRos1 ? Serialization::kCdr : Serialization::kRos1,
                bytes, &tally);
    }
  });
}

// ---- Decompression ----

struct FrameSeed {
  std::string compression;
  Bytes frame;
  Bytes content;
};

std::vector<FrameSeed> FrameSeeds() {
  std::mt19937_64 random(11);
  std::vector<Bytes> contents;
  contents.push_back({});
  contents.push_back({42});
  contents.push_back(Bytes(1000, 0));
  Bytes text;
  for (int i = 0; text.size() < 100000; ++i) {
    const std::string line = "message " + std::to_string(i % 97) + " of a repetitive text\n";
    text.insert(text.end(), line.begin(), line.end());
  }
  contents.push_back(text);
  Bytes noise(5000);
  for (uint8_t& byte : noise) byte = uint8_t(random());
  contents.push_back(noise);
  Bytes mixed(300000);
  for (size_t i = 0; i < mixed.size(); ++i) mixed[i] = i % 4096 < 100 ? uint8_t(random()) : 7;
  contents.push_back(mixed);
  std::vector<FrameSeed> seeds;
  for (const Bytes& content : contents) {
    seeds.push_back({"zstd", CompressZstd(content, 3, true, false), content});
    seeds.push_back({"zstd", CompressZstd(content, 19, false, true), content});
    seeds.push_back(
        {"lz4", CompressLz4(content, true, false, false, content.size() > 200000), content});
    seeds.push_back({"lz4", CompressLz4(content, false, true, true, false), content});
    seeds.push_back({"", content, content});
  }
  // Two zstd frames, and a skippable frame before one.
  FrameSeed two{"zstd", Concatenated(seeds[5].frame, seeds[15].frame),
                Concatenated(seeds[5].content, seeds[15].content)};
  seeds.push_back(two);
  Bytes skippable = {0x50, 0x2a, 0x4d, 0x18, 4, 0, 0, 0, 1, 2, 3, 4};
  seeds.push_back({"zstd", Concatenated(skippable, seeds[5].frame), seeds[5].content});
  // The fixtures' chunks.
  for (const char* name : {"fixture.mcap", "fixture_lz4.mcap"}) {
    const McapSeed mcap =
        MakeMcapSeed(recog::testing::ProjectTestData(std::string("bags/") + name));
    for (const ChunkPlace& chunk : mcap.chunks) {
      const std::span<const uint8_t> frame =
          std::span<const uint8_t>(mcap.bytes).subspan(chunk.records, chunk.records_size);
      const std::optional<Bytes> content =
          Decompress(chunk.compression, frame, chunk.uncompressed_size);
      if (content)
        seeds.push_back({chunk.compression, Bytes(frame.begin(), frame.end()), *content});
    }
  }
  return seeds;
}

TEST(BagFuzz, Decompress) {
  const std::vector<FrameSeed> seeds = FrameSeeds();
  ASSERT_GE(seeds.size(), 30u);
  for (const FrameSeed& seed : seeds) ASSERT_TRUE(seed.compression.empty() || !seed.frame.empty());
  ScratchFolder scratch;
  ASSERT_FALSE(scratch.path().empty());
  const std::string input_path = (scratch.path() / "input.zstd").string();
  const std::string output_path = (scratch.path() / "output").string();
  Tally tally("Decompress");
  RunCase(4, 3000, 512, &tally, [&](Rng& rng, uint64_t) {
    const FrameSeed& seed = rng.Pick(seeds);
    Bytes frame = seed.frame;
    const bool mutated = !rng.OneIn(10);
    if (mutated) MutateBytes(rng, &frame, nullptr, &rng.Pick(seeds).frame, frame.size() * 2 + 1024);
    const uint64_t true_size = seed.content.size();
    uint64_t declared = true_size;
    switch (rng.Below(8)) {
      case 0:
      case 1:
        declared = true_size + rng.Below(9) - 4;
        break;
      case 2:
        declared = Interesting(rng);
        break;
      case 3:
        declared = rng.Below(2 * true_size + 100);
        break;
      default:
        break;
    }
    uint64_t max_size = kMaxDecompressedBytes;
    switch (rng.Below(4)) {
      case 0:
        max_size = rng.Below(2 * true_size + 1000);
        break;
      case 1:
        max_size = uint64_t(64) << 20;
        break;
      default:
        break;
    }
    // No declared size that would zero-fill many MiB for nothing: those above 4 MiB are
    // kept only when the limit refuses them first.
    if (declared > (uint64_t(4) << 20) && declared <= max_size && !rng.OneIn(512)) {
      declared = true_size;
    }
    static const std::vector<std::string> kNames = {
        "", "zstd", "lz4", "ZSTD", "bz2", "gzip", std::string("zstd\0", 5)};
    const std::string compression = rng.OneIn(10) ? rng.Pick(kNames) : seed.compression;
    Bytes output;
    const Status exact =
        DecompressExactly(compression, frame, declared, &output, "fuzz input", max_size);
    tally.Check(exact, "DecompressExactly");
    tally.Count("exactly " + Outcome(exact));
    if (exact.ok() && output.size() != declared) {
      tally.Fail("DecompressExactly OK with " + std::to_string(output.size()) +
                 " bytes, not the declared " + std::to_string(declared));
    }
    if (!mutated && compression == seed.compression && declared == true_size &&
        max_size >= true_size && (!exact.ok() || output != seed.content)) {
      tally.Fail("DecompressExactly of an unmutated " + seed.compression + " seed of " +
                 std::to_string(true_size) + " bytes: " + exact.ToString());
    }
    if (seed.compression == "zstd" || rng.OneIn(8)) {
      const uint64_t limit = rng.OneIn(2) ? rng.Below(2 * true_size + 1000) : uint64_t(64) << 20;
      const Status zstd = DecompressZstd(frame, &output, "fuzz input", limit);
      tally.Check(zstd, "DecompressZstd");
      tally.Count("zstd " + Outcome(zstd));
      if (zstd.ok() && output.size() > limit) tally.Fail("DecompressZstd past its limit");
      if (!mutated && seed.compression == "zstd" && limit >= true_size && !seed.frame.empty() &&
          (!zstd.ok() || output != seed.content)) {
        tally.Fail("DecompressZstd of an unmutated seed: " + zstd.ToString());
      }
    }
    if (rng.OneIn(64)) {
      WriteFile(input_path, frame);
      const uint64_t limit = rng.OneIn(2) ? rng.Below(2 * true_size + 1000) : uint64_t(64) << 20;
      const Status file = DecompressZstdFile(input_path, output_path, limit);
      tally.Check(file, "DecompressZstdFile");
      tally.Count("file " + Outcome(file));
      std::error_code error;
      if (file.ok() && fs::file_size(output_path, error) > limit) {
        tally.Fail("DecompressZstdFile past its limit");
      }
      if (!file.ok() && fs::exists(output_path, error)) {
        tally.Fail("DecompressZstdFile failed and left its output");
      }
      fs::remove(output_path, error);
    }
  });
}

}  // namespace
}  // namespace recog::bag
