// Building a TrainingSet from image files: the first half of training a vocabulary.
#pragma once

#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/status.h"
#include "core/features/feature_extractor.h"
#include "core/vocabulary/vocabulary_trainer.h"

namespace recog {

struct TrainingImagesReport {
  size_t images_used = 0;
  size_t images_unreadable = 0;  // missing or undecodable files, skipped
};

// Extracts the features of every file with `threads` threads (one extractor each) and appends
// them to a TrainingSet in file order, so the set does not depend on the thread count. Files that
// cannot be read are skipped and counted. `progress` (optional) is called with stage "features".
// Peak memory is about one copy of the descriptors.
StatusOr<TrainingSet> ExtractTrainingSet(const std::vector<std::string>& files,
                                         const FeatureOptions& options, uint32_t threads,
                                         const TrainingProgress& progress,
                                         TrainingImagesReport* report);

}  // namespace recog
