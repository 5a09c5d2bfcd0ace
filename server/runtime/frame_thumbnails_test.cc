#include "server/runtime/frame_thumbnails.h"

#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>

#include "core/index/memory_index_store.h"

namespace recog::server {
namespace {

cv::Mat Gradient(int width, int height) {
  cv::Mat image(height, width, CV_8UC1);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) image.at<uint8_t>(y, x) = uint8_t((x + 2 * y) % 256);
  }
  return image;
}

TEST(FrameThumbnails, KeepsASmallJpegOfTheMapsThatAskAndRemembersThemAcrossOpenings) {
  MemoryIndexStore store;
  {
    auto thumbnails = FrameThumbnails::Open(&store);
    ASSERT_TRUE(thumbnails.ok()) << thumbnails.status().ToString();
    ASSERT_TRUE((*thumbnails)->Enable(7).ok());
    ASSERT_TRUE((*thumbnails)->Keep(7, 3, Gradient(640, 480)).ok());
    ASSERT_TRUE((*thumbnails)->Keep(8, 3, Gradient(640, 480)).ok());  // map 8 did not ask
  }  // written before it is destroyed
  auto reopened = FrameThumbnails::Open(&store);
  ASSERT_TRUE(reopened.ok());
  FrameThumbnails& thumbnails = **reopened;
  EXPECT_TRUE(thumbnails.Enabled(7));
  EXPECT_FALSE(thumbnails.Enabled(8));
  StatusOr<Thumbnail> kept = thumbnails.Get(7, 3);
  ASSERT_TRUE(kept.ok()) << kept.status().ToString();
  EXPECT_EQ(kept->frame_size, cv::Size(640, 480));
  const cv::Mat decoded = cv::imdecode(std::vector<uint8_t>(kept->jpeg.begin(), kept->jpeg.end()),
                                       cv::IMREAD_UNCHANGED);
  EXPECT_EQ(decoded.size(), cv::Size(FrameThumbnails::kMaxSide, 240));
  EXPECT_EQ(thumbnails.Get(8, 3).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(thumbnails.Get(7, 4).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(*thumbnails.Count(7), 1u);
}

TEST(FrameThumbnails, ASmallFrameIsKeptAtItsSizeAndAnEmptyOneNotAtAll) {
  MemoryIndexStore store;
  auto thumbnails = FrameThumbnails::Open(&store);
  ASSERT_TRUE(thumbnails.ok());
  ASSERT_TRUE((*thumbnails)->Enable(1).ok());
  ASSERT_TRUE((*thumbnails)->Keep(1, 0, Gradient(100, 60)).ok());
  ASSERT_TRUE((*thumbnails)->Keep(1, 1, cv::Mat()).ok());
  (*thumbnails)->Flush();
  EXPECT_EQ((*thumbnails)->Get(1, 0)->frame_size, cv::Size(100, 60));
  EXPECT_EQ((*thumbnails)->Get(1, 1).status().code(), StatusCode::kNotFound);
}

TEST(FrameThumbnails, RemovingAFrameOrTheMapRemovesItsThumbnails) {
  MemoryIndexStore store;
  auto thumbnails = FrameThumbnails::Open(&store);
  ASSERT_TRUE(thumbnails.ok());
  FrameThumbnails& t = **thumbnails;
  ASSERT_TRUE(t.Enable(1).ok());
  ASSERT_TRUE(t.Enable(11).ok());  // a map whose id starts like map 1's
  for (uint64_t frame = 0; frame < 3; ++frame) ASSERT_TRUE(t.Keep(1, frame, Gradient(64, 48)).ok());
  ASSERT_TRUE(t.Keep(11, 0, Gradient(64, 48)).ok());
  ASSERT_TRUE(t.RemoveFrame(1, 1).ok());   // waits for the queued ones
  ASSERT_TRUE(t.RemoveFrame(1, 99).ok());  // a frame that came as features has none: no error
  EXPECT_EQ(*t.Count(1), 2u);
  ASSERT_TRUE(t.RemoveMap(1).ok());
  EXPECT_FALSE(t.Enabled(1));
  EXPECT_EQ(*t.Count(1), 0u);
  EXPECT_EQ(*t.Count(11), 1u);
  auto keys = store.ListBlobKeys("thumb/1/");
  ASSERT_TRUE(keys.ok());
  EXPECT_TRUE(keys->empty());
}

TEST(FrameThumbnails, ThumbnailsQueuedForADeletedMapAreNeverWritten) {
  MemoryIndexStore store;
  auto thumbnails = FrameThumbnails::Open(&store);
  ASSERT_TRUE(thumbnails.ok());
  FrameThumbnails& t = **thumbnails;
  ASSERT_TRUE(t.Enable(3).ok());
  for (uint64_t frame = 0; frame < 50; ++frame)
    ASSERT_TRUE(t.Keep(3, frame, Gradient(640, 480)).ok());
  ASSERT_TRUE(t.RemoveMap(3).ok());
  t.Flush();
  auto keys = store.ListBlobKeys("thumb/3/");
  ASSERT_TRUE(keys.ok());
  EXPECT_TRUE(keys->empty()) << keys->size() << " thumbnails written after their map was removed";
}

TEST(FrameThumbnails, AFullQueueDropsTheThumbnailAndSaysSo) {
  MemoryIndexStore store;
  auto thumbnails = FrameThumbnails::Open(&store, /*queue_capacity=*/0);
  ASSERT_TRUE(thumbnails.ok());
  ASSERT_TRUE((*thumbnails)->Enable(1).ok());
  const Status dropped = (*thumbnails)->Keep(1, 0, Gradient(64, 48));
  EXPECT_EQ(dropped.code(), StatusCode::kResourceExhausted);
  EXPECT_NE(dropped.message().find("frame 0"), std::string::npos) << dropped.ToString();
  (*thumbnails)->Flush();
  EXPECT_EQ((*thumbnails)->Get(1, 0).status().code(), StatusCode::kNotFound);
}

TEST(FrameThumbnails, ATruncatedBlobIsDataLoss) {
  MemoryIndexStore store;
  auto thumbnails = FrameThumbnails::Open(&store);
  ASSERT_TRUE(thumbnails.ok());
  ASSERT_TRUE((*thumbnails)->Enable(2).ok());
  ASSERT_TRUE(store.PutBlob("thumb/2/0000000000000005", "abc").ok());
  EXPECT_EQ((*thumbnails)->Get(2, 5).status().code(), StatusCode::kDataLoss);
}

}  // namespace
}  // namespace recog::server
