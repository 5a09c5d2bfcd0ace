// Whole-file reads and atomic writes, shared by the project's file formats (vocabularies, object
// models, RoboEarth folders).
#pragma once

#include <cstdio>
#include <initializer_list>
#include <memory>
#include <string>
#include <string_view>

#include "core/common/status.h"

namespace recog {

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

// Reads a whole regular file in one call. `what` names it in errors ("PLY file 'x.ply'"):
// NOT_FOUND when it is missing, not a regular file or cannot be opened, DATA_LOSS when it cannot
// be read in full.
StatusOr<std::string> ReadWholeFile(const std::string& path, const std::string& what);

// Writes `parts` one after another to path + ".tmp", then renames it over `path`, so that readers
// never see a partly written file. NOT_FOUND when the temporary file cannot be created,
// RESOURCE_EXHAUSTED when writing fails (disk full), INTERNAL when the rename fails; the
// temporary file is removed on failure.
Status WriteFileAtomically(const std::string& path, std::initializer_list<std::string_view> parts);

}  // namespace recog
