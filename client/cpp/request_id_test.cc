// NewRequestId: the UUID v4 form, and ids that differ between calls and threads.
#include "client/cpp/request_id.h"

#include <mutex>
#include <set>
#include <string_view>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace recog::client::internal {
namespace {

// Whether `id` is a canonical UUID v4: lowercase hex digits in groups of 8-4-4-4-12, version 4,
// variant 10xx.
bool IsUuidV4(const std::string& id) {
  if (id.size() != 36) return false;
  for (size_t i = 0; i < id.size(); ++i) {
    const bool dash = i == 8 || i == 13 || i == 18 || i == 23;
    const bool hex = (id[i] >= '0' && id[i] <= '9') || (id[i] >= 'a' && id[i] <= 'f');
    if (dash ? id[i] != '-' : !hex) return false;
  }
  return id[14] == '4' && std::string_view("89ab").find(id[19]) != std::string_view::npos;
}

TEST(RequestIdTest, IdsAreCanonicalUuidV4) {
  EXPECT_FALSE(IsUuidV4("2f1c9a7e-4b1d-3c5e-9f3a-0d6b8e2a1c44"));  // version 3
  EXPECT_FALSE(IsUuidV4("2f1c9a7e-4b1d-4c5e-cf3a-0d6b8e2a1c44"));  // variant 110x
  EXPECT_TRUE(IsUuidV4("2f1c9a7e-4b1d-4c5e-9f3a-0d6b8e2a1c44"));
  for (int i = 0; i < 200; ++i) {
    const std::string id = NewRequestId();
    EXPECT_TRUE(IsUuidV4(id)) << id;
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
