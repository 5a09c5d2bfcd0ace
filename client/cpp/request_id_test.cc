// NewRequestId: the UUID v4 form, and ids that differ between calls and threads.
#include "client/cpp/request_id.h"

#include <mutex>
#include <regex>
#include <set>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace recog::client::internal {
namespace {

TEST(RequestIdTest, IdsAreCanonicalUuidV4) {
  const std::regex uuid_v4("[0-9a-f]{8}-[0-9a-f]{4}-4[0-9a-f]{3}-[89ab][0-9a-f]{3}-[0-9a-f]{12}");
  for (int i = 0; i < 200; ++i) {
    const std::string id = NewRequestId();
    EXPECT_TRUE(std::regex_match(id, uuid_v4)) << id;
  }
}

TEST(RequestIdTest, IdsDifferBetweenCallsAndThreads) {
  std::set<std::string> ids;
  std::mutex mutex;
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&] {
      for (int i = 0; i < 500; ++i) {
        std::string id = NewRequestId();
        std::lock_guard lock(mutex);
        ids.insert(std::move(id));
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(ids.size(), 2000u);
}

TEST(RequestIdTest, ACallersOwnIdIsKept) {
  EXPECT_EQ(RequestIdOr("robot-7/frame-42"), "robot-7/frame-42");
  EXPECT_EQ(RequestIdOr("").size(), 36u);
}

}  // namespace
}  // namespace recog::client::internal
