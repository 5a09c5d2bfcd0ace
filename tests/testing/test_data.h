// Test-side helpers over data_paths.h: tests that need the shared data call
// RECOG_SKIP_WITHOUT_SHARED_DATA(relative_path) first, which skips the test with a clear message
// when the file or folder is missing, so a fresh clone still passes on its own. With
// RECOG_REQUIRE_SHARED_DATA=1 (CI, where the shared data is beside the clone) a missing file fails
// the test instead: a real-data test must not pass by skipping there.
#pragma once

#include <gtest/gtest.h>

#include "tests/testing/data_paths.h"

#define RECOG_SKIP_WITHOUT_SHARED_DATA(relative)                                              \
  do {                                                                                        \
    if (!::recog::testing::HasSharedData(relative)) {                                         \
      if (::recog::testing::SharedDataRequired()) {                                           \
        GTEST_FAIL() << "shared data '" << ::recog::testing::SharedData(relative)             \
                     << "' not found, and RECOG_REQUIRE_SHARED_DATA=1 says it must be there"; \
      }                                                                                       \
      GTEST_SKIP() << "shared data '" << ::recog::testing::SharedData(relative)               \
                   << "' not found; set RECOG_SHARED_DATA to the shared data folder to run";  \
    }                                                                                         \
  } while (false)
