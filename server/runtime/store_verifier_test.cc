#include "server/runtime/store_verifier.h"

#include <atomic>
#include <chrono>
#include <mutex>
#include <vector>

#include <gtest/gtest.h>

#include "core/index/memory_index_store.h"
#include "tests/testing/wait.h"

namespace recog::server {
namespace {

using namespace std::chrono_literals;
using recog::testing::WaitUntil;

// A store whose Verify reports `bytes` read, or DATA_LOSS once `damaged` is set.
class CheckedStore : public MemoryIndexStore {
 public:
  StatusOr<VerifyReport> Verify(uint64_t bytes_per_second) override {
    last_rate = bytes_per_second;
    ++checks;
    if (damaged) return Status::DataLoss("table file 000009.sst is damaged");
    return VerifyReport{3, 1000};
  }
  std::atomic<int> checks{0};
  std::atomic<uint64_t> last_rate{0};
  std::atomic<bool> damaged{false};
};

// The outcomes a verifier reported.
struct Outcomes {
  std::mutex mutex;
  std::vector<StatusCode> codes;
  StoreVerifier::OnResult Recorder() {
    return [this](const StoreVerifier::Result& result, std::chrono::duration<double>) {
      std::lock_guard lock(mutex);
      codes.push_back(result.status().code());
    };
  }
  size_t size() {
    std::lock_guard lock(mutex);
    return codes.size();
  }
};

TEST(StoreVerifierTest, ChecksEveryPeriodAtTheConfiguredRateAndReportsDamage) {
  CheckedStore store;
  Outcomes outcomes;
  {
    StoreVerifier verifier(&store, 1s, 4096, outcomes.Recorder());
    EXPECT_EQ(store.checks, 0);  // the first check waits one period
    ASSERT_TRUE(WaitUntil([&] { return outcomes.size() >= 1; })) << "no check was reported";
    ASSERT_EQ(outcomes.size(), 1u);
    EXPECT_EQ(store.last_rate, 4096u);
    store.damaged = true;
    ASSERT_TRUE(WaitUntil([&] { return outcomes.size() >= 2; })) << "no second check was reported";
    ASSERT_EQ(outcomes.size(), 2u);
  }
  EXPECT_EQ(outcomes.codes[0], StatusCode::kOk);
  EXPECT_EQ(outcomes.codes[1], StatusCode::kDataLoss);
}

TEST(StoreVerifierTest, RunNowChecksOnTheCallersThreadAndReportsTheSameWay) {
  CheckedStore store;
  Outcomes outcomes;
  StoreVerifier verifier(&store, 0s, 4096, outcomes.Recorder());  // no background thread
  auto result = verifier.RunNow(0);
  ASSERT_TRUE(result.ok());
  EXPECT_EQ(result->files, 3u);
  EXPECT_EQ(store.last_rate, 0u);
  EXPECT_EQ(outcomes.size(), 1u);
}

TEST(StoreVerifierTest, DestroyingItStopsAWaitingThreadAtOnce) {
  CheckedStore store;
  Outcomes outcomes;
  const auto start = std::chrono::steady_clock::now();
  { StoreVerifier verifier(&store, 3600s, 0, outcomes.Recorder()); }
  EXPECT_LT(std::chrono::steady_clock::now() - start, 2s);
  EXPECT_EQ(store.checks, 0);
}

}  // namespace
}  // namespace recog::server
