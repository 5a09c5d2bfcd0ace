// ByteBudget: reservations within the total only, given back when destroyed, never overcharged
// under contention.
#include "server/runtime/byte_budget.h"

#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace recog::server {
namespace {

TEST(ByteBudgetTest, ReservesUpToTheTotalAndGivesBackOnDestruction) {
  ByteBudget budget(100);
  std::optional<ByteBudget::Reservation> first = budget.Reserve(60);
  ASSERT_TRUE(first.has_value());
  EXPECT_FALSE(budget.Reserve(41).has_value());
  EXPECT_EQ(budget.used(), 60u);  // a refusal charges nothing
  {
    const std::optional<ByteBudget::Reservation> second = budget.Reserve(40);
    ASSERT_TRUE(second.has_value());
    EXPECT_FALSE(budget.Reserve(1).has_value());
  }
  EXPECT_EQ(budget.used(), 60u);
  std::optional<ByteBudget::Reservation> moved = std::move(first);
  first.reset();  // the moved-from reservation holds nothing
  EXPECT_EQ(budget.used(), 60u);
  moved.reset();
  EXPECT_EQ(budget.used(), 0u);
}

TEST(ByteBudgetTest, AReservationLargerThanTheWholeBudgetNeverFits) {
  ByteBudget budget(100);
  EXPECT_FALSE(budget.Reserve(101).has_value());
  EXPECT_FALSE(budget.Reserve(UINT64_MAX).has_value());
  EXPECT_EQ(budget.used(), 0u);
}

TEST(ByteBudgetTest, ConcurrentReservationsNeverPassTheTotal) {
  ByteBudget budget(1000);
  std::atomic<uint64_t> peak{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&] {
      for (int i = 0; i < 20000; ++i) {
        const std::optional<ByteBudget::Reservation> reserved = budget.Reserve(7);
        if (!reserved.has_value()) continue;
        uint64_t seen = budget.used(), high = peak.load();
        while (seen > high && !peak.compare_exchange_weak(high, seen)) {
        }
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_LE(peak.load(), 1000u);
  EXPECT_GT(peak.load(), 0u);
  EXPECT_EQ(budget.used(), 0u);
}

}  // namespace
}  // namespace recog::server
