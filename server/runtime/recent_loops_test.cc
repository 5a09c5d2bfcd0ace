#include "server/runtime/recent_loops.h"

#include <gtest/gtest.h>

namespace recog::server {
namespace {

RecordedLoop Loop(uint64_t frame) {
  RecordedLoop loop;
  loop.frame_id = frame;
  loop.match_frame_id = frame / 2;
  loop.pairs = {cv::Vec4f(1, 2, 3, 4)};
  return loop;
}

TEST(RecentLoops, KeepsTheLastLoopsOfEachMapNewestFirst) {
  RecentLoops loops(3);
  for (uint64_t frame = 10; frame < 15; ++frame) loops.Record("corridor", Loop(frame));
  loops.Record("lab", Loop(99));
  const std::vector<RecordedLoop> corridor = loops.Of("corridor");
  ASSERT_EQ(corridor.size(), 3u);
  EXPECT_EQ(corridor[0].frame_id, 14u);
  EXPECT_EQ(corridor[2].frame_id, 12u);
  EXPECT_EQ(corridor[0].pairs.front(), cv::Vec4f(1, 2, 3, 4));
  EXPECT_EQ(loops.Count("lab"), 1u);
  EXPECT_EQ(loops.Count("unknown"), 0u);
  EXPECT_TRUE(loops.Of("unknown").empty());
}

TEST(RecentLoops, ForgetsADeletedMap) {
  RecentLoops loops(5);
  loops.Record("corridor", Loop(1));
  loops.Forget("corridor");
  EXPECT_EQ(loops.Count("corridor"), 0u);
  loops.Record("corridor", Loop(2));  // a new map of the same name starts afresh
  EXPECT_EQ(loops.Of("corridor").front().frame_id, 2u);
}

}  // namespace
}  // namespace recog::server
