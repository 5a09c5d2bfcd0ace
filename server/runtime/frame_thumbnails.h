// FrameThumbnails: the small JPEG a place map keeps of each frame sent as an image, for the web
// console (MapSettings.keep_thumbnails).
//
// A map opts in at creation (Enable); from then on every frame it keeps that arrived as an image
// is stored as a grey JPEG whose longest side is at most kMaxSide pixels (quality kQuality: a
// few KB a frame, docs/console.md) in the store's blobs, under "thumb/<map id>/<frame id>",
// beside the marker "thumb/<map id>/on"; a blob is the frame's full size (two little-endian
// uint32, width and height) followed by the JPEG. Map ids are never reused, so a recreated map
// starts without thumbnails. Removing a frame or a map removes its thumbnails.
//
// Keep only copies the image on the caller's thread (a frame's answer does not wait for the
// JPEG or the store): a background thread shrinks, encodes and writes, at most `queue_capacity`
// frames behind; beyond that a thumbnail is dropped (RESOURCE_EXHAUSTED, the frame itself is not
// affected). A write that fails is logged. Thread-safe.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <opencv2/core.hpp>
#include <shared_mutex>
#include <string>
#include <thread>
#include <unordered_set>

#include "core/common/status.h"
#include "core/index/index_store.h"

namespace recog::server {

struct Thumbnail {
  cv::Size frame_size;  // of the frame it was made from
  std::string jpeg;
};

class FrameThumbnails {
 public:
  static constexpr int kMaxSide = 320;
  static constexpr int kQuality = 75;
  static constexpr size_t kDefaultQueueCapacity = 64;  // ~20 MB of 640x480 grey frames at most

  // Reads which maps keep thumbnails from `store`, which must outlive this object.
  static StatusOr<std::unique_ptr<FrameThumbnails>> Open(
      IndexStore* store, size_t queue_capacity = kDefaultQueueCapacity);
  ~FrameThumbnails();  // writes what is queued, then stops the thread
  FrameThumbnails(const FrameThumbnails&) = delete;
  FrameThumbnails& operator=(const FrameThumbnails&) = delete;

  // Map `map_id` keeps thumbnails from now on.
  Status Enable(uint32_t map_id);
  bool Enabled(uint32_t map_id) const;

  // Queues the thumbnail of frame `frame_id` (a grey or BGR image); nothing when the map does not
  // keep thumbnails or `image` is empty. RESOURCE_EXHAUSTED when the queue is full (dropped).
  Status Keep(uint32_t map_id, uint64_t frame_id, const cv::Mat& image);
  // Waits until every queued thumbnail is written.
  void Flush();
  // The thumbnail of a frame; NOT_FOUND when none was kept (or it is still queued), DATA_LOSS for
  // a malformed blob.
  StatusOr<Thumbnail> Get(uint32_t map_id, uint64_t frame_id) const;
  // The number of thumbnails kept for a map.
  StatusOr<uint64_t> Count(uint32_t map_id) const;

  Status RemoveFrame(uint32_t map_id, uint64_t frame_id);
  // Removes every thumbnail of the map and its marker.
  Status RemoveMap(uint32_t map_id);

 private:
  struct Job {
    uint32_t map_id;
    uint64_t frame_id;
    cv::Mat image;  // the frame's, copied
  };

  FrameThumbnails(IndexStore* store, size_t queue_capacity);
  void Run();
  void Write(const Job& job);

  IndexStore* store_;
  const size_t queue_capacity_;
  mutable std::shared_mutex enabled_mutex_;
  std::unordered_set<uint32_t> enabled_;
  // Held while a map's thumbnails are written or removed, so that a write never follows the
  // removal of its map.
  std::mutex write_mutex_;
  std::mutex queue_mutex_;
  std::condition_variable queue_changed_;
  std::deque<Job> queue_;
  bool writing_ = false;  // the thread holds a job taken from the queue
  bool stopping_ = false;
  std::thread thread_;  // last: starts once the members above exist
};

}  // namespace recog::server
