#include "server/runtime/worker_pool.h"

#include <atomic>
#include <future>

#include <gtest/gtest.h>

namespace recog::server {
namespace {

TEST(WorkerPoolTest, BoundedSubmissionsAreRefusedWhenTheQueueIsFull) {
  WorkerPool pool(1, 2);
  std::promise<void> release;
  std::shared_future<void> gate = release.get_future().share();
  std::promise<void> started;
  ASSERT_TRUE(pool.TrySubmit([&] {
    started.set_value();
    gate.wait();
  }));
  started.get_future().wait();  // the only worker is busy now
  std::atomic<int> ran{0};
  EXPECT_TRUE(pool.TrySubmit([&] { ++ran; }));
  EXPECT_TRUE(pool.TrySubmit([&] { ++ran; }));
  EXPECT_FALSE(pool.TrySubmit([&] { ++ran; }));  // two are waiting: full
  EXPECT_EQ(pool.queued(), 2u);
  EXPECT_EQ(pool.busy(), 1u);
  EXPECT_TRUE(pool.Submit([&] { ++ran; }));  // unbounded submissions still go in
  EXPECT_EQ(pool.queued(), 3u);
  release.set_value();
  pool.Stop();  // runs what is queued
  EXPECT_EQ(ran.load(), 3);
  EXPECT_EQ(pool.queued(), 0u);
}

TEST(WorkerPoolTest, AStoppedPoolRefusesWorkAndStopIsIdempotent) {
  WorkerPool pool(2, 4);
  std::atomic<int> ran{0};
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(pool.TrySubmit([&] { ++ran; }));
  pool.Stop();
  EXPECT_EQ(ran.load(), 4);
  EXPECT_FALSE(pool.TrySubmit([&] { ++ran; }));
  EXPECT_FALSE(pool.Submit([&] { ++ran; }));
  pool.Stop();
  EXPECT_EQ(ran.load(), 4);
  EXPECT_EQ(pool.threads(), 2u);
}

TEST(WorkerPoolTest, TasksRunOnSeveralThreadsAtOnce) {
  WorkerPool pool(2, 8);
  std::promise<void> both_running;
  std::atomic<int> running{0};
  std::shared_future<void> together = both_running.get_future().share();
  for (int i = 0; i < 2; ++i) {
    ASSERT_TRUE(pool.TrySubmit([&] {
      if (++running == 2) both_running.set_value();
      together.wait();  // would never return if the tasks ran one after the other
    }));
  }
  EXPECT_EQ(together.wait_for(std::chrono::seconds(30)), std::future_status::ready);
  pool.Stop();
}

}  // namespace
}  // namespace recog::server
