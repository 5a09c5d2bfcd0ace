// Photos for the rig drives of the tests (rig_sequence_test.cc, rig_place_test.cc): the 3 x 3
// tiles of the four project corridor photos, and seeded textures of random shapes, richer in
// corners than the corridor's blurred walls (as the photos of a real run would be).
#pragma once

#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tests/testing/data_paths.h"

namespace recog::cli::testing {

inline std::vector<cv::Mat> CorridorTiles() {
  std::vector<cv::Mat> photos;
  for (const char* name : {"1.jpg", "20.jpg", "41.jpg", "60.jpg"}) {
    const cv::Mat photo = cv::imread(
        recog::testing::ProjectTestData(std::string("corridor/") + name), cv::IMREAD_GRAYSCALE);
    EXPECT_FALSE(photo.empty()) << name;
    const int w = photo.cols / 3, h = photo.rows / 3;
    for (int q = 0; q < 9; ++q) photos.push_back(photo(cv::Rect((q % 3) * w, (q / 3) * h, w, h)));
  }
  return photos;
}

// `count` 320 x 240 textures: grey noise under 60 filled circles, rectangles and thick lines of
// random grey levels, each texture from its own seed.
inline std::vector<cv::Mat> ShapeTextures(int count, uint64_t seed = 1) {
  std::vector<cv::Mat> textures;
  for (int i = 0; i < count; ++i) {
    cv::RNG rng(seed * 1000003 + uint64_t(i));
    cv::Mat texture(240, 320, CV_8U);
    rng.fill(texture, cv::RNG::UNIFORM, 60, 200);
    cv::GaussianBlur(texture, texture, cv::Size(0, 0), 3);
    for (int s = 0; s < 60; ++s) {
      const cv::Point p(rng.uniform(0, 320), rng.uniform(0, 240));
      const cv::Scalar grey(rng.uniform(0, 256));
      switch (rng.uniform(0, 3)) {
        case 0:
          cv::circle(texture, p, rng.uniform(4, 24), grey, cv::FILLED);
          break;
        case 1:
          cv::rectangle(texture, p, p + cv::Point(rng.uniform(6, 40), rng.uniform(6, 40)), grey,
                        cv::FILLED);
          break;
        default:
          cv::line(texture, p, cv::Point(rng.uniform(0, 320), rng.uniform(0, 240)), grey,
                   rng.uniform(2, 6));
      }
    }
    textures.push_back(texture);
  }
  return textures;
}

}  // namespace recog::cli::testing
