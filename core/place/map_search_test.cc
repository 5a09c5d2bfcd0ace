#include "core/place/map_search.h"

#include <gtest/gtest.h>

#include "core/index/memory_index_store.h"
#include "core/place/map_registry.h"
#include "core/place/place_test_frames.h"

namespace recog {
namespace {

// Robot A has been at places 0 and 1, robot B at places 2 and 3 (place_test_frames.h).
class MapSearchTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    vocabulary_ = new std::shared_ptr<const Vocabulary>(testing::TrainPlacesVocabulary());
  }
  static void TearDownTestSuite() { delete vocabulary_; }

  void SetUp() override {
    auto registry = MapRegistry::Open(&store_, *vocabulary_);
    ASSERT_TRUE(registry.ok()) << registry.status().ToString();
    registry_ = std::move(registry).value();
    places_ = testing::Places();
    robot_a_ = AddVisits("robot-a", {0, 1});
    robot_b_ = AddVisits("robot-b", {2, 3});
  }

  std::shared_ptr<PlaceMap> AddVisits(const std::string& name, std::vector<int> places) {
    auto map = registry_->Create(name, {}, "fleet");
    EXPECT_TRUE(map.ok()) << map.status().ToString();
    for (int p : places) {
      for (const FeatureSet& f : testing::Extract(testing::Visit(places_[size_t(p)], 4))) {
        EXPECT_TRUE(map.value()->Add(f, std::nullopt).ok());
      }
    }
    return map.value();
  }

  // A new view of `place`, shifted further than any stored one.
  FeatureSet Revisit(int place) const {
    return testing::Extract(testing::Visit(places_[size_t(place)], 1, 5)).front();
  }

  static std::shared_ptr<const Vocabulary>* vocabulary_;
  MemoryIndexStore store_;
  std::unique_ptr<MapRegistry> registry_;
  std::vector<cv::Mat> places_;
  std::shared_ptr<PlaceMap> robot_a_, robot_b_;
};
std::shared_ptr<const Vocabulary>* MapSearchTest::vocabulary_ = nullptr;

TEST_F(MapSearchTest, APlaceIsFoundInTheMapThatHasBeenThere) {
  const std::vector<std::shared_ptr<PlaceMap>> fleet = {robot_b_, robot_a_};
  for (int place = 0; place < 4; ++place) {
    auto found = SearchMaps(fleet, Revisit(place));
    ASSERT_TRUE(found.ok()) << found.status().ToString();
    ASSERT_EQ(found->size(), 1u) << "place " << place << " is in one map only";
    const MapMatch& m = found->front();
    EXPECT_EQ(m.map, place < 2 ? "robot-a" : "robot-b") << place;
    EXPECT_EQ(m.result.loop.status, LoopStatus::kLoopDetected);
    EXPECT_EQ(m.result.loop.acceptance, LoopAcceptance::kRelocalisation);
    // Each map holds its two places as frames 0-3 and 4-7.
    EXPECT_EQ(m.result.loop.match / 4, EntryId(place % 2)) << place;
  }
  EXPECT_EQ(robot_a_->frames(), 8u) << "searching adds nothing";
  EXPECT_EQ(robot_b_->frames(), 8u);
}

TEST_F(MapSearchTest, MapsThatHaveNotBeenThereAreLeftOut) {
  const std::vector<std::shared_ptr<PlaceMap>> only_a = {robot_a_};
  auto found = SearchMaps(only_a, Revisit(3));
  ASSERT_TRUE(found.ok());
  EXPECT_TRUE(found->empty());
  EXPECT_TRUE(SearchMaps({}, Revisit(0)).value().empty());
}

TEST_F(MapSearchTest, MatchesComeBestFirst) {
  // A third map that has seen place 0 once, from further away than robot A's four views.
  auto glimpse = registry_->Create("robot-c", {}, "fleet");
  ASSERT_TRUE(glimpse.ok());
  ASSERT_TRUE((*glimpse)
                  ->Add(testing::Extract(testing::Visit(places_[0], 1, 12)).front(), std::nullopt)
                  .ok());
  const std::vector<std::shared_ptr<PlaceMap>> fleet = {*glimpse, robot_b_, robot_a_};
  auto found = SearchMaps(fleet, Revisit(0));
  ASSERT_TRUE(found.ok());
  ASSERT_EQ(found->size(), 2u) << "robot A and robot C have been there";
  EXPECT_GT((*found)[0].result.loop.inliers.size(), (*found)[1].result.loop.inliers.size());
  EXPECT_EQ((*found)[0].map, "robot-a") << "four close views beat one distant one";
  EXPECT_EQ((*found)[1].map, "robot-c");
}

TEST_F(MapSearchTest, BadOptionsAreRefusedNamingTheMap) {
  PlaceResultOptions options;
  options.top_k = PlaceResultOptions::kMaxTopK + 1;
  const std::vector<std::shared_ptr<PlaceMap>> fleet = {robot_a_};
  const Status refused = SearchMaps(fleet, Revisit(0), options).status();
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.message().find("robot-a"), std::string::npos) << refused.ToString();
}

// Maps searched together are normalised by the best score over all of them: a map whose best
// candidate scores under alpha (0.3) of the best map's is not verified.
TEST_F(MapSearchTest, AMapFarBelowTheBestMapsScoreIsNotVerified) {
  const FeatureSet query = Revisit(0);
  LoopDetector::ConvertedFrame frame;
  ASSERT_TRUE(robot_a_->ConvertForQuery(query, &frame).ok());
  auto shortlist = robot_a_->Shortlist(frame);
  ASSERT_TRUE(shortlist.ok()) << shortlist.status().ToString();
  ASSERT_GT(shortlist->best_score, 0);
  auto alone = robot_a_->Recognise(query, frame, *shortlist, shortlist->best_score);
  ASSERT_TRUE(alone.ok());
  EXPECT_EQ(alone->loop.status, LoopStatus::kLoopDetected);
  EXPECT_EQ(alone->loop.normalized_score, 1.0);
  auto outscored = robot_a_->Recognise(query, frame, *shortlist, 10 * shortlist->best_score);
  ASSERT_TRUE(outscored.ok());
  EXPECT_EQ(outscored->loop.status, LoopStatus::kLowScore);
  EXPECT_EQ(outscored->loop.timings.verification, 0.0);
  EXPECT_EQ(robot_b_->ConvertsLike(*robot_a_), true) << "one registry, one conversion";
}

// Relocalize over frames at places 3, 0, 1 and a blank one: robot A has seen two of them.
TEST_F(MapSearchTest, RelocalizationRanksTheMapThatRecognisesMostFramesFirst) {
  const std::vector<FeatureSet> seen = {Revisit(3), Revisit(0), Revisit(1), FeatureSet()};
  std::vector<RelocalizationFrame> frames;
  for (const FeatureSet& f : seen) frames.push_back({&f, nullptr});
  const std::vector<std::shared_ptr<PlaceMap>> fleet = {robot_b_, robot_a_};
  auto found = Relocalize(fleet, frames);
  ASSERT_TRUE(found.ok()) << found.status().ToString();
  ASSERT_EQ(found->size(), 2u);
  const Relocalization& a = (*found)[0];
  EXPECT_EQ(a.map, "robot-a");
  EXPECT_EQ(a.frames_recognised, 2u);
  ASSERT_TRUE(a.frame_index == 1 || a.frame_index == 2) << a.frame_index;
  // The answer is the frame with more inliers of the two robot A recognised.
  const size_t other = a.frame_index == 1 ? 2 : 1;
  auto alone = SearchMaps(std::vector<std::shared_ptr<PlaceMap>>{robot_a_}, seen[other]);
  ASSERT_TRUE(alone.ok());
  ASSERT_EQ(alone->size(), 1u);
  EXPECT_GE(a.result.loop.inliers.size(), alone->front().result.loop.inliers.size());
  EXPECT_EQ(a.result.loop.match / 4, EntryId(a.frame_index == 1 ? 0 : 1));
  const Relocalization& b = (*found)[1];
  EXPECT_EQ(b.map, "robot-b");
  EXPECT_EQ(b.frames_recognised, 1u);
  EXPECT_EQ(b.frame_index, 0u);
  EXPECT_EQ(b.result.loop.match / 4, EntryId(1)) << "place 3 is robot B's second";
  EXPECT_EQ(robot_a_->frames() + robot_b_->frames(), 16u) << "relocalising adds nothing";

  EXPECT_TRUE(Relocalize(fleet, {}).value().empty());
  const std::vector<RelocalizationFrame> blank = {frames.back()};
  EXPECT_TRUE(Relocalize(fleet, blank).value().empty());
  PlaceResultOptions options;
  options.top_k = PlaceResultOptions::kMaxTopK + 1;
  const Status refused = Relocalize(fleet, frames, options).status();
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.message().find("robot-b"), std::string::npos) << refused.ToString();
}

}  // namespace
}  // namespace recog
