// WaitUntil: how a test waits for something another thread or process does (a watch registered,
// a server that stopped, a file that appeared) instead of sleeping a guessed time. It polls a
// condition until it holds or a deadline passes; the caller asserts the result with a message
// saying what did not happen, e.g.
//   ASSERT_TRUE(WaitUntil([&] { return seen > 0; })) << "the watcher saw no event";
// The default deadline is generous (a sanitizer build on a loaded machine is slow): a wait that
// succeeds returns as soon as the condition holds, so only a failing test waits it out.
// No test framework needed.
#pragma once

#include <chrono>
#include <thread>

namespace recog::testing {

constexpr std::chrono::milliseconds kEventTimeout{60000};
constexpr std::chrono::milliseconds kEventPollInterval{5};

// Whether `condition` (a callable returning bool) held before `timeout` passed; it is checked at
// once, then every `poll_interval` (longer for a condition that costs, e.g. a call that writes),
// and once more at the deadline.
template <typename Condition>
bool WaitUntil(Condition&& condition, std::chrono::milliseconds timeout = kEventTimeout,
               std::chrono::milliseconds poll_interval = kEventPollInterval) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!condition()) {
    if (std::chrono::steady_clock::now() >= deadline) return condition();
    std::this_thread::sleep_for(poll_interval);
  }
  return true;
}

}  // namespace recog::testing
