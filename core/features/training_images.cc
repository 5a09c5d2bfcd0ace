#include "core/features/training_images.h"

#include <atomic>
#include <mutex>
#include <thread>

namespace recog {

StatusOr<TrainingSet> ExtractTrainingSet(const std::vector<std::string>& files,
                                         const FeatureOptions& options, uint32_t threads,
                                         const TrainingProgress& progress,
                                         TrainingImagesReport* report) {
  RECOG_ASSIGN_OR_RETURN(std::unique_ptr<FeatureExtractor> probe, CreateFeatureExtractor(options));
  std::vector<cv::Mat> per_image(files.size());
  std::vector<char> unreadable(files.size(), 0);
  std::atomic<size_t> next{0}, done{0};
  std::mutex progress_mutex;
  auto work = [&](std::unique_ptr<FeatureExtractor> extractor) {
    FeatureSet features;
    for (size_t i = next++; i < files.size(); i = next++) {
      auto image = ReadGrayImage(files[i]);
      if (!image.ok() || !extractor->Extract(*image, &features).ok()) {
        unreadable[i] = 1;
      } else {
        per_image[i] = features.descriptors.clone();
      }
      const size_t now = ++done;
      if (progress) {
        std::lock_guard lock(progress_mutex);
        progress("features", now, files.size());
      }
    }
  };
  std::vector<std::thread> pool;
  for (uint32_t t = 1; t < std::max(1u, threads); ++t) {
    pool.emplace_back(work, std::move(CreateFeatureExtractor(options)).value());
  }
  const DescriptorFormat format = probe->format();
  work(std::move(probe));
  for (std::thread& t : pool) t.join();

  size_t rows = 0;
  for (const cv::Mat& m : per_image) rows += size_t(m.rows);
  TrainingSet set;
  set.format = format;
  set.descriptors.reserve(rows * format.size_bytes);
  TrainingImagesReport local;
  for (size_t i = 0; i < files.size(); ++i) {
    if (unreadable[i]) {
      ++local.images_unreadable;
      continue;
    }
    RECOG_RETURN_IF_ERROR(set.AddImage(per_image[i]));
    per_image[i].release();  // keep the peak near one copy of the descriptors
    ++local.images_used;
  }
  if (report != nullptr) *report = local;
  return set;
}

}  // namespace recog
