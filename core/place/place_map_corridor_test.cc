// PlaceMap on the corridor's photos (shared data; skipped without it): a query with the camera
// matrix gets the relative pose of the frame it matched. The synthetic place map tests are in
// place_map_test.cc.
#include "core/place/place_map.h"

#include <gtest/gtest.h>

#include "core/index/memory_index_store.h"
#include "core/place/map_registry.h"
#include "core/place/place_test_frames.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tests/testing/test_data.h"

namespace recog {
namespace {

TEST(PlaceMapOnTheCorridorTest, AQueryWithTheCameraGetsTheRelativePoseOfTheNeighbouringFrame) {
  RECOG_SKIP_WITHOUT_SHARED_DATA("places/corridor/images/11.jpg");
  auto vocabulary = LoadVocabulary(DefaultPlaceVocabularyPath());
  ASSERT_TRUE(vocabulary.ok()) << vocabulary.status().ToString();
  MemoryIndexStore store;
  auto registry =
      MapRegistry::Open(&store, std::make_shared<const Vocabulary>(std::move(vocabulary).value()));
  ASSERT_TRUE(registry.ok());
  auto map = (*registry)->Create("walk", LoopDetectorParams{});
  ASSERT_TRUE(map.ok());
  const auto corridor = [](int n) {
    auto image =
        ReadGrayImage(testing::SharedData("places/corridor/images/" + std::to_string(n) + ".jpg"));
    EXPECT_TRUE(image.ok());
    return testing::Extract({image.value()})[0];
  };
  for (int n = 2; n <= 20; n += 2) ASSERT_TRUE((*map)->Add(corridor(n), 0).ok());
  PlaceResultOptions options;
  options.include_relative_pose = true;
  options.camera_matrix = cv::Matx33d(400, 0, 256, 0, 400, 192, 0, 0, 1);
  auto r = (*map)->Query(corridor(11), options);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->loop.status, LoopStatus::kLoopDetected);
  EXPECT_TRUE(r->loop.match == 4u || r->loop.match == 5u) << r->loop.match;  // frame 10 or 12
  ASSERT_TRUE(r->relative_pose.has_value());
  EXPECT_NEAR(cv::norm(r->relative_pose->t), 1.0, 1e-6);  // up to scale: unit length
  EXPECT_NEAR(cv::determinant(r->relative_pose->R), 1.0, 1e-6);
  EXPECT_FALSE(r->fundamental.has_value());  // not asked for
}

}  // namespace
}  // namespace recog
