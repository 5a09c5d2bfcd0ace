// Helpers shared by the storage tests: temporary directories, map configs, and entries whose
// content is a pure function of (id, seed), so that a test (or the parent of a crashed child
// process) can recompute what an entry must hold from its id alone.
#pragma once

#include <sys/mount.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "core/index/entry.h"

namespace recog::testing {

// ThreadSanitizer kills a forked child that starts a thread (RocksDB does, when it opens a
// store); the tests that fork skip themselves under it.
#if defined(__SANITIZE_THREAD__)
inline constexpr bool kThreadSanitizer = true;
#else
inline constexpr bool kThreadSanitizer = false;
#endif
#define RECOG_SKIP_FORK_UNDER_TSAN()                                                        \
  do {                                                                                      \
    if (::recog::testing::kThreadSanitizer) {                                               \
      GTEST_SKIP() << "ThreadSanitizer does not support threads in a forked child process"; \
    }                                                                                       \
  } while (false)

// A fresh directory under the system temp dir, named after the pid, a tag and a counter;
// removed (whatever its permissions) when destroyed.
class TempDir {
 public:
  explicit TempDir(const std::string& tag) {
    static std::atomic<int> counter{0};
    path_ = std::filesystem::temp_directory_path() /
            ("recog_storage_" + tag + "_" + std::to_string(::getpid()) + "_" +
             std::to_string(counter++));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    for (auto it = std::filesystem::recursive_directory_iterator(path_, ec);
         !ec && it != std::filesystem::recursive_directory_iterator(); it.increment(ec)) {
      if (it->is_directory(ec)) {
        std::filesystem::permissions(it->path(), std::filesystem::perms::owner_all,
                                     std::filesystem::perm_options::add, ec);
      }
    }
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const std::filesystem::path& path() const { return path_; }
  // A path inside the directory (not created).
  std::string Sub(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

// A small filesystem of its own (tmpfs) mounted inside a TempDir, to fill up on purpose: the
// disk-full tests. Mounting needs CAP_SYS_ADMIN (root in CI); without it `error()` says why and
// the tests skip. Fill() leaves only a given number of bytes free, FreeSpace() gives the rest
// back; the mount goes away with the object.
class SmallFilesystem {
 public:
  SmallFilesystem(const std::string& tag, size_t bytes) : dir_(tag) {
    root_ = dir_.Sub("mnt");
    std::filesystem::create_directories(root_);
    const std::string size = "size=" + std::to_string(bytes);
    if (::mount("tmpfs", root_.c_str(), "tmpfs", 0, size.c_str()) != 0) {
      error_ = "cannot mount a tmpfs (" + std::string(std::strerror(errno)) + ")";
    }
  }
  ~SmallFilesystem() {
    if (error_.empty()) ::umount2(root_.c_str(), MNT_DETACH);
  }
  SmallFilesystem(const SmallFilesystem&) = delete;
  SmallFilesystem& operator=(const SmallFilesystem&) = delete;

  // "" when mounted.
  const std::string& error() const { return error_; }
  // A path on the small filesystem (not created).
  std::string Sub(const std::string& name) const { return root_ + "/" + name; }

  // Writes a filler file until only `leave_bytes` (rounded to 64 KiB) are free.
  void Fill(size_t leave_bytes) {
    const std::filesystem::space_info space = std::filesystem::space(root_);
    const size_t filler = space.available > leave_bytes ? space.available - leave_bytes : 0;
    std::ofstream out(Sub(kFiller), std::ios::binary | std::ios::app);
    const std::string block(64 << 10, '\0');
    for (size_t written = 0; written + block.size() <= filler; written += block.size()) {
      out.write(block.data(), std::streamsize(block.size()));
    }
  }
  void FreeSpace() { std::filesystem::remove(Sub(kFiller)); }

 private:
  static constexpr char kFiller[] = "filler";
  TempDir dir_;
  std::string root_;
  std::string error_;
};

inline MapConfig TestMapConfig(const std::string& name,
                               DescriptorFormat format = DescriptorFormat::Orb()) {
  MapConfig config;
  config.name = name;
  config.vocabulary_checksum = 0x1234567890abcdefull;
  config.vocabulary_words = 1000;
  config.vocabulary_nodes = 1111;
  config.descriptor = format;
  config.scoring = ScoringType::kL1;
  config.direct_index_levels_up = 2;
  return config;
}

// An entry with every part filled, derived from (id, seed) only. `max_features` bounds the
// number of keypoints (the actual number is random in [0, max_features]).
inline EntryRecord MakeTestEntry(EntryId id, uint32_t seed = 0,
                                 DescriptorFormat format = DescriptorFormat::Orb(),
                                 int max_features = 200) {
  std::mt19937 rng(id * 2654435761u + seed * 40503u + 17u);
  auto uniform = [&rng](float lo, float hi) {
    return std::uniform_real_distribution<float>(lo, hi)(rng);
  };
  EntryRecord e;
  e.id = id;
  const int n = std::uniform_int_distribution<int>(0, max_features)(rng);

  e.metadata.timestamp = 1000.0 + id * 0.5 + seed;
  e.metadata.num_features = uint32_t(n);
  const int user_bytes = std::uniform_int_distribution<int>(0, 300)(rng);
  for (int i = 0; i < user_bytes; ++i) e.metadata.user_data.push_back(char(rng() & 0xff));
  if (id % 2 == 1) e.metadata.client_id = "kf-" + std::to_string(id);  // both metadata formats

  e.keypoints.resize(size_t(n));
  for (cv::KeyPoint& k : e.keypoints) {
    k.pt = {uniform(0, 640), uniform(0, 480)};
    k.size = uniform(5, 50);
    k.angle = uniform(0, 360);
    k.response = uniform(0, 1);
    k.octave = int(rng() % 8);
  }
  if (format.type == DescriptorType::kBinary) {
    e.descriptors.create(n, format.cols(), CV_8U);
    for (int r = 0; r < n; ++r) {
      for (int c = 0; c < format.cols(); ++c) e.descriptors.at<uint8_t>(r, c) = uint8_t(rng());
    }
  } else {
    e.descriptors.create(n, format.cols(), CV_32F);
    for (int r = 0; r < n; ++r) {
      for (int c = 0; c < format.cols(); ++c) e.descriptors.at<float>(r, c) = uniform(-1, 1);
    }
  }

  // Bag of words: distinct sorted words with positive weights.
  std::vector<BowEntry> words;
  for (int i = 0; i < n; ++i) words.push_back({WordId(rng() % 1000), uniform(0.001f, 1)});
  e.bow = BowVector(std::move(words));

  // Direct index: every feature under one of a few nodes.
  std::vector<std::pair<NodeId, uint32_t>> pairs;
  for (int i = 0; i < n; ++i) pairs.emplace_back(NodeId(rng() % 50), uint32_t(i));
  std::sort(pairs.begin(), pairs.end());
  e.direct.AssignSorted(pairs);
  // Odd ids are object entries: every feature has a 3D point.
  if (id % 2 == 1) {
    for (int i = 0; i < n; ++i)
      e.points.emplace_back(uniform(-1, 1), uniform(-1, 1), uniform(0, 2));
  }
  // Every third id is a frame that came with its camera matrix (with 3D points or not).
  if (id % 3 == 0) e.camera = {uniform(400, 600), 0, 320, 0, uniform(400, 600), 240, 0, 0, 1};
  return e;
}

inline bool SameMatrix(const cv::Mat& a, const cv::Mat& b) {
  if (a.empty() && b.empty()) return true;
  if (a.rows != b.rows || a.cols != b.cols || a.type() != b.type()) return false;
  const size_t row_bytes = size_t(a.cols) * a.elemSize();
  for (int r = 0; r < a.rows; ++r) {
    if (std::memcmp(a.ptr(r), b.ptr(r), row_bytes) != 0) return false;
  }
  return true;
}

// "" when `a` and `b` agree on the requested parts (bit-exact), otherwise what differs.
inline std::string EntryDifference(const EntryRecord& a, const EntryRecord& b,
                                   uint32_t parts = kEntryAllParts) {
  std::string out;
  if (a.id != b.id) out += "id " + std::to_string(a.id) + " vs " + std::to_string(b.id) + "; ";
  if ((parts & kEntryMetadata) && !(a.metadata == b.metadata)) out += "metadata differs; ";
  if ((parts & kEntryBow) && !(a.bow == b.bow)) out += "bow differs; ";
  if ((parts & kEntryDirect) && !(a.direct == b.direct)) out += "direct index differs; ";
  if (parts & kEntryFeatures) {
    bool same = a.keypoints.size() == b.keypoints.size();
    for (size_t i = 0; same && i < a.keypoints.size(); ++i) {
      const cv::KeyPoint& p = a.keypoints[i];
      const cv::KeyPoint& q = b.keypoints[i];
      same = p.pt == q.pt && p.size == q.size && p.angle == q.angle && p.response == q.response &&
             p.octave == q.octave;
    }
    if (!same) out += "keypoints differ; ";
    if (!SameMatrix(a.descriptors, b.descriptors)) out += "descriptors differ; ";
    if (a.points != b.points) out += "3D points differ; ";
    if (a.camera != b.camera) out += "camera matrices differ; ";
  }
  return out;
}

}  // namespace recog::testing
