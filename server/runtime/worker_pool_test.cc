#include "server/runtime/worker_pool.h"

#include <atomic>
#include <future>
#include <set>
#include <thread>

#include <gtest/gtest.h>

namespace recog::server {
namespace {

// What a worker of these tests keeps: the thread it was made on.
struct TestContext {
  std::thread::id made_on = std::this_thread::get_id();
};

using TestPool = WorkerPool<TestContext>;

std::unique_ptr<TestContext> MakeContext() { return std::make_unique<TestContext>(); }

TEST(WorkerPoolTest, BoundedSubmissionsAreRefusedWhenTheQueueIsFull) {
  TestPool pool(1, 2, MakeContext);
  std::promise<void> release;
  std::shared_future<void> gate = release.get_future().share();
  std::promise<void> started;
  ASSERT_TRUE(pool.TrySubmit([&](TestContext&) {
    started.set_value();
    gate.wait();
  }));
  started.get_future().wait();  // the only worker is busy now
  std::atomic<int> ran{0};
  EXPECT_TRUE(pool.TrySubmit([&](TestContext&) { ++ran; }));
  EXPECT_TRUE(pool.TrySubmit([&](TestContext&) { ++ran; }));
  EXPECT_FALSE(pool.TrySubmit([&](TestContext&) { ++ran; }));  // two are waiting: full
  EXPECT_EQ(pool.queued(), 2u);
  EXPECT_EQ(pool.busy(), 1u);
  EXPECT_TRUE(pool.Submit([&](TestContext&) { ++ran; }));  // unbounded submissions still go in
  EXPECT_EQ(pool.queued(), 3u);
  release.set_value();
  pool.Stop();  // runs what is queued
  EXPECT_EQ(ran.load(), 3);
  EXPECT_EQ(pool.queued(), 0u);
}

TEST(WorkerPoolTest, AStoppedPoolRefusesWorkAndStopIsIdempotent) {
  TestPool pool(2, 4, MakeContext);
  std::atomic<int> ran{0};
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(pool.TrySubmit([&](TestContext&) { ++ran; }));
  pool.Stop();
  EXPECT_EQ(ran.load(), 4);
  EXPECT_FALSE(pool.TrySubmit([&](TestContext&) { ++ran; }));
  EXPECT_FALSE(pool.Submit([&](TestContext&) { ++ran; }));
  pool.Stop();
  EXPECT_EQ(ran.load(), 4);
  EXPECT_EQ(pool.threads(), 2u);
}

TEST(WorkerPoolTest, TasksRunOnSeveralThreadsAtOnce) {
  TestPool pool(2, 8, MakeContext);
  std::promise<void> both_running;
  std::atomic<int> running{0};
  std::shared_future<void> together = both_running.get_future().share();
  for (int i = 0; i < 2; ++i) {
    ASSERT_TRUE(pool.TrySubmit([&](TestContext&) {
      if (++running == 2) both_running.set_value();
      together.wait();  // would never return if the tasks ran one after the other
    }));
  }
  EXPECT_EQ(together.wait_for(std::chrono::seconds(30)), std::future_status::ready);
  pool.Stop();
}

TEST(WorkerPoolTest, EachWorkerGetsItsOwnContextMadeOnceOnItsThread) {
  std::atomic<int> made{0};
  std::mutex mutex;
  std::set<const TestContext*> seen;
  bool on_own_thread = true;
  {
    WorkerPool<TestContext> pool(2, 64, [&] {
      ++made;
      return std::make_unique<TestContext>();
    });
    // Two tasks held together make sure both workers run some task.
    std::promise<void> both_running;
    std::atomic<int> running{0};
    std::shared_future<void> together = both_running.get_future().share();
    auto record = [&](TestContext& context) {
      std::lock_guard lock(mutex);
      seen.insert(&context);
      on_own_thread = on_own_thread && context.made_on == std::this_thread::get_id();
    };
    for (int i = 0; i < 2; ++i) {
      ASSERT_TRUE(pool.TrySubmit([&](TestContext& context) {
        record(context);
        if (++running == 2) both_running.set_value();
        together.wait();
      }));
    }
    for (int i = 0; i < 40; ++i) ASSERT_TRUE(pool.Submit(record));
    pool.Stop();
  }
  EXPECT_EQ(made.load(), 2);   // once per worker, however many tasks it ran
  EXPECT_EQ(seen.size(), 2u);  // each worker its own
  EXPECT_TRUE(on_own_thread);  // made on the worker that uses it
}

TEST(WorkerPoolTest, AWorkerThatRunsNothingMakesNoContext) {
  std::atomic<int> made{0};
  {
    WorkerPool<TestContext> pool(3, 4, [&] {
      ++made;
      return std::make_unique<TestContext>();
    });
    std::promise<void> ran;
    ASSERT_TRUE(pool.TrySubmit([&](TestContext&) { ran.set_value(); }));
    ran.get_future().wait();
    pool.Stop();
  }
  EXPECT_EQ(made.load(), 1);
}

}  // namespace
}  // namespace recog::server
