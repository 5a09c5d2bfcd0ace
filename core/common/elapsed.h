// MillisecondsSince: the time a step took, as every timing of core, the server, the tools and the
// benchmarks reports it — in milliseconds with their fractions, on the steady clock (which never
// jumps when the system time is set).
#pragma once

#include <chrono>

namespace recog {

// Milliseconds from `start` (a std::chrono::steady_clock::now() taken before the step) to now.
inline double MillisecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

}  // namespace recog
