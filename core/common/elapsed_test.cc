#include "core/common/elapsed.h"

#include <thread>

#include <gtest/gtest.h>

namespace recog {
namespace {

TEST(ElapsedTest, MillisecondsWithTheirFractions) {
  const auto start = std::chrono::steady_clock::now() - std::chrono::microseconds(1500);
  const double ms = MillisecondsSince(start);
  EXPECT_GE(ms, 1.5);
  EXPECT_LT(ms, 1000.0);
}

TEST(ElapsedTest, GrowsWithTheTimeWaited) {
  const auto start = std::chrono::steady_clock::now();
  // The time waited is what is measured.
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const double first = MillisecondsSince(start);
  EXPECT_GE(first, 20.0);
  std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_GE(MillisecondsSince(start), first + 5.0);
}

TEST(ElapsedTest, AStartStillToComeIsNegative) {
  EXPECT_LT(MillisecondsSince(std::chrono::steady_clock::now() + std::chrono::seconds(10)), -9000);
}

}  // namespace
}  // namespace recog
