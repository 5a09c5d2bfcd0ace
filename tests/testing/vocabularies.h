// The bundled object vocabulary (vocabularies/object_orb_t12_k10_l4.rvoc), loaded once per test
// binary and shared, for tests that build and recognise object models.
#pragma once

#include <memory>
#include <string>

#include <gtest/gtest.h>

#include "core/vocabulary/vocabulary_io.h"

namespace recog::testing {

inline std::shared_ptr<const Vocabulary> BundledObjectVocabulary() {
  static const std::shared_ptr<const Vocabulary> vocabulary = [] {
    auto loaded =
        LoadVocabulary(std::string(RECOG_SOURCE_DIR) + "/vocabularies/object_orb_t12_k10_l4.rvoc");
    EXPECT_TRUE(loaded.ok()) << loaded.status().ToString();
    return std::make_shared<const Vocabulary>(std::move(*loaded));
  }();
  return vocabulary;
}

}  // namespace recog::testing
