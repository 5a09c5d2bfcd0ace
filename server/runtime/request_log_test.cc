// RequestLog: answers remembered and repeated, keys reused for other requests refused, failures
// forgotten, expiry, the entry bound, the request id rule, and a concurrent duplicate waiting for
// the first call.
#include "server/runtime/request_log.h"

#include <atomic>
#include <thread>

#include <gtest/gtest.h>

#include "tests/testing/wait.h"

namespace recog::server {
namespace {

using std::chrono::milliseconds;
using std::chrono::minutes;
using Kind = RequestLog::Claim::Kind;
using Clock = RequestLog::Clock;
using recog::testing::WaitUntil;

const Clock::time_point kLogStart{};

// Called once a thread is about to call Begin for a running key: gives it a moment to block in
// Begin's wait, so that End's wake-up is what usually returns it. Pacing, not synchronisation: a
// Begin that comes after End finds the outcome at once and gives the same claim, so no assertion
// depends on it (that Begin waits at all is checked by the kTimedOut case).
void GiveTimeToBlock() { std::this_thread::sleep_for(milliseconds(50)); }
const std::string kDigest = "digest of the request";

TEST(RequestLogTest, ASuccessfulAnswerIsRepeatedForTheSameKeyOnly) {
  RequestLog log(10);
  EXPECT_EQ(log.Begin("a", kDigest, kLogStart, kLogStart).kind, Kind::kRun);
  log.End("a", "answer a", kLogStart);
  const RequestLog::Claim repeat = log.Begin("a", kDigest, kLogStart + minutes(1), kLogStart);
  EXPECT_EQ(repeat.kind, Kind::kRepeat);
  EXPECT_EQ(repeat.answer, "answer a");
  EXPECT_EQ(log.Begin("b", kDigest, kLogStart, kLogStart).kind, Kind::kRun);
  EXPECT_EQ(log.size(), 1u);
}

TEST(RequestLogTest, AKeyReusedForAnotherRequestIsAConflictNotARepeat) {
  RequestLog log(10);
  ASSERT_EQ(log.Begin("a", kDigest, kLogStart, kLogStart).kind, Kind::kRun);
  // While the first call runs: no waiting for it, no running beside it.
  EXPECT_EQ(log.Begin("a", "another request", kLogStart, kLogStart + minutes(1)).kind,
            Kind::kConflict);
  log.End("a", "answer a", kLogStart);
  const RequestLog::Claim reused = log.Begin("a", "another request", kLogStart, kLogStart);
  EXPECT_EQ(reused.kind, Kind::kConflict);
  EXPECT_TRUE(reused.answer.empty());  // never another request's answer
  EXPECT_EQ(log.Begin("a", kDigest, kLogStart, kLogStart).kind, Kind::kRepeat);
}

TEST(RequestLogTest, AFailedCallIsForgottenSoItsRepeatRunsAgain) {
  RequestLog log(10);
  ASSERT_EQ(log.Begin("a", kDigest, kLogStart, kLogStart).kind, Kind::kRun);
  log.End("a", std::nullopt, kLogStart);
  EXPECT_EQ(log.Begin("a", kDigest, kLogStart, kLogStart).kind, Kind::kRun);
  EXPECT_EQ(log.size(), 0u);
}

TEST(RequestLogTest, AnswersExpireAfterTheWindow) {
  RequestLog log(10, minutes(10));
  ASSERT_EQ(log.Begin("a", kDigest, kLogStart, kLogStart).kind, Kind::kRun);
  log.End("a", "x", kLogStart);
  EXPECT_EQ(log.Begin("a", kDigest, kLogStart + minutes(10) - milliseconds(1), kLogStart).kind,
            Kind::kRepeat);
  EXPECT_EQ(log.Begin("a", kDigest, kLogStart + minutes(10), kLogStart).kind, Kind::kRun);
  EXPECT_EQ(log.size(), 0u);
}

TEST(RequestLogTest, TheOldestAnswersAreForgottenBeyondTheCapacity) {
  RequestLog log(2);
  for (const char* key : {"a", "b", "c"}) {
    ASSERT_EQ(log.Begin(key, kDigest, kLogStart, kLogStart).kind, Kind::kRun);
    log.End(key, key, kLogStart);
  }
  EXPECT_EQ(log.size(), 2u);
  EXPECT_EQ(log.Begin("b", kDigest, kLogStart, kLogStart).kind, Kind::kRepeat);
  EXPECT_EQ(log.Begin("c", kDigest, kLogStart, kLogStart).kind, Kind::kRepeat);
  EXPECT_EQ(log.Begin("a", kDigest, kLogStart, kLogStart).kind, Kind::kRun);  // forgotten
}

TEST(RequestLogTest, CapacityZeroRemembersNothing) {
  RequestLog log(0);
  ASSERT_EQ(log.Begin("a", kDigest, kLogStart, kLogStart).kind, Kind::kRun);
  log.End("a", "x", kLogStart);
  EXPECT_EQ(log.Begin("a", kDigest, kLogStart, kLogStart).kind, Kind::kRun);
  EXPECT_EQ(log.size(), 0u);
}

TEST(RequestLogTest, RequestIdsAreOneTo128PrintableCharacters) {
  EXPECT_TRUE(RequestLog::ValidRequestId("2f1c9a7e-4b1d-4c5e-9f3a-0d6b8e2a1c44"));
  EXPECT_TRUE(RequestLog::ValidRequestId("a b~"));
  EXPECT_TRUE(RequestLog::ValidRequestId(std::string(128, 'x')));
  EXPECT_FALSE(RequestLog::ValidRequestId(""));
  EXPECT_FALSE(RequestLog::ValidRequestId(std::string(129, 'x')));
  EXPECT_FALSE(RequestLog::ValidRequestId("tab\there"));
  EXPECT_FALSE(RequestLog::ValidRequestId("new\nline"));
  EXPECT_FALSE(RequestLog::ValidRequestId("\x7f"));
  EXPECT_FALSE(RequestLog::ValidRequestId("caf\xc3\xa9"));
}

TEST(RequestLogTest, AConcurrentDuplicateWaitsForTheFirstCallAndGetsItsAnswer) {
  RequestLog log(10);
  ASSERT_EQ(log.Begin("a", kDigest, Clock::now(), Clock::now()).kind, Kind::kRun);
  std::atomic<bool> ended{false};
  std::atomic<bool> calling{false};
  RequestLog::Claim duplicate;
  std::thread waiter([&] {
    calling = true;
    duplicate = log.Begin("a", kDigest, Clock::now(), Clock::now() + std::chrono::seconds(30));
    EXPECT_TRUE(ended.load());  // it returned only after End
  });
  EXPECT_TRUE(WaitUntil([&] { return calling.load(); })) << "the duplicate's thread did not run";
  GiveTimeToBlock();
  ended = true;
  log.End("a", "first", Clock::now());
  waiter.join();
  EXPECT_EQ(duplicate.kind, Kind::kRepeat);
  EXPECT_EQ(duplicate.answer, "first");
}

TEST(RequestLogTest, ADuplicateOfAFailedCallRunsItselfAndOneStillRunningTimesOut) {
  RequestLog log(10);
  ASSERT_EQ(log.Begin("a", kDigest, Clock::now(), Clock::now()).kind, Kind::kRun);
  EXPECT_EQ(log.Begin("a", kDigest, Clock::now(), Clock::now() + milliseconds(20)).kind,
            Kind::kTimedOut);
  std::atomic<bool> calling{false};
  RequestLog::Claim duplicate;
  std::thread waiter([&] {
    calling = true;
    duplicate = log.Begin("a", kDigest, Clock::now(), Clock::now() + std::chrono::seconds(30));
  });
  EXPECT_TRUE(WaitUntil([&] { return calling.load(); })) << "the duplicate's thread did not run";
  GiveTimeToBlock();
  log.End("a", std::nullopt, Clock::now());
  waiter.join();
  EXPECT_EQ(duplicate.kind, Kind::kRun);  // the first failed: the duplicate is the call now
  log.End("a", "second", Clock::now());
  EXPECT_EQ(log.Begin("a", kDigest, Clock::now(), Clock::now()).answer, "second");
}

}  // namespace
}  // namespace recog::server
