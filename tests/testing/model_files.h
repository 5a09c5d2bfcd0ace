// Object model files (.robj) built from the corridor images of tests/data/, for tests of the
// model repository (server and client): a planar poster, or a box with several faces.
#pragma once

#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "core/object/builder/model_builder.h"
#include "core/object/formats/model_file.h"
#include "tests/testing/data_paths.h"
#include "tests/testing/vocabularies.h"

namespace recog::testing {

// A model named `name` of class `object_class`: with one image, a planar poster (0.64 x 0.48 m) of
// corridor image `images[0]`; with more (at most four), a 0.64 m deep box whose front, back, left
// and right faces show them.
inline std::string ModelFile(const std::string& name, const std::vector<int>& images,
                             const std::string& object_class) {
  ModelBuilder builder(BundledObjectVocabulary());
  std::vector<FaceImage> faces;
  const BoxSide sides[] = {BoxSide::kFront, BoxSide::kBack, BoxSide::kLeft, BoxSide::kRight};
  for (size_t i = 0; i < images.size() && i < 4; ++i) {
    faces.push_back(
        {sides[i], cv::imread(ProjectTestData("corridor/" + std::to_string(images[i]) + ".jpg"),
                              cv::IMREAD_GRAYSCALE)});
  }
  auto model = builder.FromFaceImages(name, faces, 0.64, 0.48, images.size() > 1 ? 0.64 : 0.0);
  EXPECT_TRUE(model.ok()) << model.status().ToString();
  model.value().metadata.object_class = object_class;
  auto bytes = EncodeObjectModel(model.value());
  EXPECT_TRUE(bytes.ok());
  return bytes.value();
}

inline std::string PosterModelFile(const std::string& name, int n,
                                   const std::string& object_class) {
  return ModelFile(name, {n}, object_class);
}

}  // namespace recog::testing
