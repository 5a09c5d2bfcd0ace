// RecentLoops: the last loops each place map detected, kept in memory for the web console.
//
// The place service records every verified loop of a single-camera map's frames (AddFrame's
// detection, StreamFrames, QueryPlace with add_frame) when the console is on; the console shows
// them with their inlier correspondences. At most `per_map` loops per map are kept, the oldest
// dropped first; a restart forgets them. Thread-safe.
#pragma once

#include <cstdint>
#include <deque>
#include <mutex>
#include <opencv2/core.hpp>
#include <string>
#include <unordered_map>
#include <vector>

namespace recog::server {

struct RecordedLoop {
  uint64_t frame_id = 0;        // the frame that closed the loop
  uint64_t match_frame_id = 0;  // the frame it matched
  int64_t unix_ms = 0;          // when it was detected
  double score = 0, normalized_score = 0;
  uint32_t inliers = 0;
  cv::Size frame_size;  // of the frame's image (0x0 when it came as features without a size)
  // RANSAC inliers: (x, y) in the frame, then (x, y) in the match, full-resolution pixels.
  std::vector<cv::Vec4f> pairs;
};

class RecentLoops {
 public:
  explicit RecentLoops(size_t per_map) : per_map_(per_map) {}

  void Record(const std::string& map, RecordedLoop loop);
  // The map's loops, newest first.
  std::vector<RecordedLoop> Of(const std::string& map) const;
  size_t Count(const std::string& map) const;
  // Drops a deleted map's loops.
  void Forget(const std::string& map);

 private:
  const size_t per_map_;
  mutable std::mutex mutex_;
  std::unordered_map<std::string, std::deque<RecordedLoop>> loops_;  // oldest first
};

}  // namespace recog::server
