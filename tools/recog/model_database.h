// The object models that the offline object commands recognise with (recog recognize --models,
// recog eval sequence --models): the model files (.robj) and RoboEarth folders named on the
// command line, loaded into an object database held in memory.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/index/memory_index_store.h"
#include "core/object/recognition/object_database.h"

namespace recog::cli {

// Opens an object database in `store`, which must outlive it, for the object vocabulary at
// `vocabulary_path` (the bundled one when empty), and puts in it every model that `paths` name
// (see FindModelSources); RoboEarth folders are built into models without their training images.
// INVALID_ARGUMENT when `paths` name no model; a model that cannot be read is an error.
StatusOr<std::shared_ptr<ObjectDatabase>> LoadModelDatabase(const std::vector<std::string>& paths,
                                                            const std::string& vocabulary_path,
                                                            MemoryIndexStore* store);

}  // namespace recog::cli
