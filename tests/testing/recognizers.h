// Object recognisers for tests: ObjectRecognizer::Create with options the test expects to be
// valid. A refusal fails the test (gtest reports the status, then the exception of reading the
// missing value).
#pragma once

#include <memory>
#include <utility>

#include <gtest/gtest.h>

#include "core/object/recognition/object_recognizer.h"

namespace recog::testing {

inline ObjectRecognizer MakeRecognizer(std::shared_ptr<const ObjectDatabase> database,
                                       RecognitionOptions options = {}) {
  StatusOr<ObjectRecognizer> recognizer =
      ObjectRecognizer::Create(std::move(database), std::move(options));
  EXPECT_TRUE(recognizer.ok()) << recognizer.status().ToString();
  return std::move(recognizer).value();
}

}  // namespace recog::testing
