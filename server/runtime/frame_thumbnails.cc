#include "server/runtime/frame_thumbnails.h"

#include <spdlog/spdlog.h>
#include <algorithm>
#include <cstdio>
#include <cstring>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

namespace recog::server {
namespace {

constexpr char kPrefix[] = "thumb/";
constexpr char kMarker[] = "on";
constexpr size_t kHeaderBytes = 8;  // the frame's width and height

std::string MapPrefix(uint32_t map_id) { return kPrefix + std::to_string(map_id) + "/"; }

// Frame keys sort by id: 16 hexadecimal digits.
std::string FrameKey(uint32_t map_id, uint64_t frame_id) {
  char id[17];
  std::snprintf(id, sizeof(id), "%016llx", static_cast<unsigned long long>(frame_id));
  return MapPrefix(map_id) + id;
}

}  // namespace

FrameThumbnails::FrameThumbnails(IndexStore* store, size_t queue_capacity)
    : store_(store), queue_capacity_(queue_capacity), thread_([this] { Run(); }) {}

FrameThumbnails::~FrameThumbnails() {
  {
    std::lock_guard lock(queue_mutex_);
    stopping_ = true;
  }
  queue_changed_.notify_all();
  thread_.join();
}

StatusOr<std::unique_ptr<FrameThumbnails>> FrameThumbnails::Open(IndexStore* store,
                                                                 size_t queue_capacity) {
  RECOG_ASSIGN_OR_RETURN(std::vector<std::string> keys, store->ListBlobKeys(kPrefix));
  std::unique_ptr<FrameThumbnails> thumbnails(new FrameThumbnails(store, queue_capacity));
  for (const std::string& key : keys) {
    if (!key.ends_with(std::string("/") + kMarker)) continue;
    const std::string id =
        key.substr(sizeof(kPrefix) - 1, key.size() - (sizeof(kPrefix) - 1) - sizeof(kMarker));
    thumbnails->enabled_.insert(uint32_t(std::stoul(id)));
  }
  return thumbnails;
}

Status FrameThumbnails::Enable(uint32_t map_id) {
  RECOG_RETURN_IF_ERROR(store_->PutBlob(MapPrefix(map_id) + kMarker, "1"));
  std::unique_lock lock(enabled_mutex_);
  enabled_.insert(map_id);
  return Status::Ok();
}

bool FrameThumbnails::Enabled(uint32_t map_id) const {
  std::shared_lock lock(enabled_mutex_);
  return enabled_.contains(map_id);
}

Status FrameThumbnails::Keep(uint32_t map_id, uint64_t frame_id, const cv::Mat& image) {
  if (image.empty() || !Enabled(map_id)) return Status::Ok();
  Job job{map_id, frame_id, image.clone()};  // a copy: the frame's image goes with its call
  {
    std::lock_guard lock(queue_mutex_);
    if (queue_.size() >= queue_capacity_) {
      return Status::ResourceExhausted("the thumbnail of frame " + std::to_string(frame_id) +
                                       " is dropped: " + std::to_string(queue_capacity_) +
                                       " are waiting to be written");
    }
    queue_.push_back(std::move(job));
  }
  queue_changed_.notify_all();
  return Status::Ok();
}

void FrameThumbnails::Flush() {
  std::unique_lock lock(queue_mutex_);
  queue_changed_.wait(lock, [this] { return queue_.empty() && !writing_; });
}

void FrameThumbnails::Run() {
  std::unique_lock lock(queue_mutex_);
  while (true) {
    queue_changed_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
    if (queue_.empty()) return;  // stopping, with everything written
    Job job = std::move(queue_.front());
    queue_.pop_front();
    writing_ = true;
    lock.unlock();
    Write(job);
    lock.lock();
    writing_ = false;
    queue_changed_.notify_all();  // Flush may be waiting
  }
}

void FrameThumbnails::Write(const Job& job) {
  const cv::Size frame_size = job.image.size();
  const double scale =
      std::min(1.0, double(kMaxSide) / std::max(frame_size.width, frame_size.height));
  cv::Mat small = job.image;
  if (scale < 1) cv::resize(job.image, small, cv::Size(), scale, scale, cv::INTER_AREA);
  std::vector<uchar> jpeg;
  if (!cv::imencode(".jpg", small, jpeg, {cv::IMWRITE_JPEG_QUALITY, kQuality})) {
    spdlog::warn("map id {}: the thumbnail of frame {} cannot be encoded", job.map_id,
                 job.frame_id);
    return;
  }
  std::string blob(kHeaderBytes, '\0');
  const uint32_t size[2] = {uint32_t(frame_size.width), uint32_t(frame_size.height)};
  std::memcpy(blob.data(), size, kHeaderBytes);  // little-endian machines only (as the store)
  blob.append(reinterpret_cast<const char*>(jpeg.data()), jpeg.size());
  std::lock_guard lock(write_mutex_);
  if (!Enabled(job.map_id)) return;  // the map was deleted meanwhile
  const Status put = store_->PutBlob(FrameKey(job.map_id, job.frame_id), blob);
  if (!put.ok()) {
    spdlog::warn("map id {}: the thumbnail of frame {} is not kept: {}", job.map_id, job.frame_id,
                 put.ToString());
  }
}

StatusOr<Thumbnail> FrameThumbnails::Get(uint32_t map_id, uint64_t frame_id) const {
  StatusOr<std::string> blob = store_->GetBlob(FrameKey(map_id, frame_id));
  if (!blob.ok() && blob.status().code() == StatusCode::kNotFound) {
    return Status::NotFound("no thumbnail was kept of frame " + std::to_string(frame_id));
  }
  if (!blob.ok()) return blob.status();
  if (blob->size() <= kHeaderBytes) {
    return Status::DataLoss("the thumbnail of frame " + std::to_string(frame_id) + " is truncated");
  }
  uint32_t size[2];
  std::memcpy(size, blob->data(), kHeaderBytes);
  return Thumbnail{cv::Size(int(size[0]), int(size[1])), blob->substr(kHeaderBytes)};
}

StatusOr<uint64_t> FrameThumbnails::Count(uint32_t map_id) const {
  RECOG_ASSIGN_OR_RETURN(std::vector<std::string> keys, store_->ListBlobKeys(MapPrefix(map_id)));
  return uint64_t(std::count_if(keys.begin(), keys.end(),
                                [](const std::string& key) { return !key.ends_with(kMarker); }));
}

Status FrameThumbnails::RemoveFrame(uint32_t map_id, uint64_t frame_id) {
  if (!Enabled(map_id)) return Status::Ok();
  Flush();  // its thumbnail may still be queued
  std::lock_guard lock(write_mutex_);
  const Status deleted = store_->DeleteBlob(FrameKey(map_id, frame_id));
  return deleted.code() == StatusCode::kNotFound ? Status::Ok() : deleted;  // a features frame
}

Status FrameThumbnails::RemoveMap(uint32_t map_id) {
  std::lock_guard lock(write_mutex_);
  {
    std::unique_lock enabled(enabled_mutex_);
    if (enabled_.erase(map_id) == 0) return Status::Ok();
  }
  RECOG_ASSIGN_OR_RETURN(std::vector<std::string> keys, store_->ListBlobKeys(MapPrefix(map_id)));
  for (const std::string& key : keys) RECOG_RETURN_IF_ERROR(store_->DeleteBlob(key));
  return Status::Ok();
}

}  // namespace recog::server
