// Test frames for the place tests (loop_detector_test.cc, place_map_test.cc): four places cut from
// the bundled corridor frames, views of them shifted a few pixels, a tour that revisits two of
// them, and a small vocabulary trained on the places themselves (enough to tell them apart).
#pragma once

#include <memory>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/features/feature_extractor.h"
#include "core/vocabulary/vocabulary_trainer.h"
#include "tests/testing/data_paths.h"

namespace recog::testing {

// The textured halves of frames 20 and 1, and frame 20's right half upside down (ORB descriptors
// are not invariant to a mirror image).
inline std::vector<cv::Mat> Places() {
  auto frame1 = ReadGrayImage(ProjectTestData("corridor/1.jpg"));
  auto frame20 = ReadGrayImage(ProjectTestData("corridor/20.jpg"));
  EXPECT_TRUE(frame1.ok() && frame20.ok());
  const cv::Rect left(0, 0, 256, 384), right(256, 0, 256, 384);
  cv::Mat flipped;
  cv::flip((*frame20)(right), flipped, 0);
  return {(*frame20)(right).clone(), (*frame1)(right).clone(), (*frame20)(left).clone(), flipped};
}

// One visit of a place: `frames` views, each shifted 3 more pixels.
inline std::vector<cv::Mat> Visit(const cv::Mat& place, int frames, int first_shift = 0) {
  std::vector<cv::Mat> views;
  for (int f = 0; f < frames; ++f) {
    const double shift = first_shift + 3.0 * f;
    cv::Mat warped;
    const cv::Matx23d m(1, 0, shift, 0, 1, shift / 2);
    cv::warpAffine(place, warped, m, place.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
    views.push_back(warped);
  }
  return views;
}

// Places 0 1 2 3, then places 0 1 again: 4 frames a visit.
inline std::vector<cv::Mat> TourWithRevisits() {
  const std::vector<cv::Mat> places = Places();
  std::vector<cv::Mat> frames;
  for (int p : {0, 1, 2, 3, 0, 1}) {
    for (const cv::Mat& v : Visit(places[size_t(p)], 4, p >= 0 && frames.size() >= 16 ? 2 : 0)) {
      frames.push_back(v);
    }
  }
  return frames;
}

// The features of every frame, with the default extractor.
inline std::vector<FeatureSet> Extract(const std::vector<cv::Mat>& frames) {
  auto extractor = CreateFeatureExtractor(FeatureOptions{});
  std::vector<FeatureSet> features(frames.size());
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_TRUE((*extractor)->Extract(frames[i], &features[i]).ok());
  }
  return features;
}

// A small vocabulary trained on three views of each place; null (and a test failure) on error.
inline std::shared_ptr<const Vocabulary> TrainPlacesVocabulary() {
  TrainingSet set;
  for (const cv::Mat& place : Places()) {
    for (const FeatureSet& f : Extract(Visit(place, 3))) {
      if (!set.AddImage(f.descriptors).ok()) {
        ADD_FAILURE() << "training image refused";
        return nullptr;
      }
    }
  }
  TrainingOptions options;
  options.branching = 8;
  options.depth = 4;
  options.threads = 1;
  auto v = TrainVocabulary(std::move(set), options);
  if (!v.ok()) {
    ADD_FAILURE() << v.status().ToString();
    return nullptr;
  }
  return std::make_shared<const Vocabulary>(std::move(v).value());
}

}  // namespace recog::testing
