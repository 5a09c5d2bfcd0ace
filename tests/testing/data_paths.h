// Where tests and benchmarks find their data (no test framework needed).
//
// Fixtures every run needs live in the project under tests/data/ (ProjectTestData). The large real
// data sets live outside the project, in the folder named by the environment variable
// RECOG_SHARED_DATA (default: ../shared/data next to the project root). RECOG_SOURCE_DIR is
// defined by the build for every test and benchmark target.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <string>

namespace recog::testing {

inline std::string ProjectTestData(const std::string& relative) {
  return std::string(RECOG_SOURCE_DIR) + "/tests/data/" + relative;
}

inline std::filesystem::path SharedDataRoot() {
  if (const char* env = std::getenv("RECOG_SHARED_DATA"); env != nullptr && *env != '\0') {
    return env;
  }
  return std::filesystem::path(RECOG_SOURCE_DIR) / ".." / "shared" / "data";
}

inline std::string SharedData(const std::string& relative) {
  return (SharedDataRoot() / relative).string();
}

inline bool HasSharedData(const std::string& relative) {
  return std::filesystem::exists(SharedData(relative));
}

// RECOG_REQUIRE_SHARED_DATA=1: the shared data must be there (CI sets it when it is), so a test
// that needs a missing file fails rather than skips.
inline bool SharedDataRequired() {
  const char* env = std::getenv("RECOG_REQUIRE_SHARED_DATA");
  return env != nullptr && std::string(env) == "1";
}

}  // namespace recog::testing
