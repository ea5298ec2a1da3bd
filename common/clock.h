// Elapsed-time helpers for logs and statistics: the monotonic clock every
// timing in the services and the command uses.
#ifndef TRANSTICK_COMMON_CLOCK_H_
#define TRANSTICK_COMMON_CLOCK_H_

#include <chrono>

namespace transtick {

using Clock = std::chrono::steady_clock;

inline double MsBetween(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

inline double MsSince(Clock::time_point t) { return MsBetween(t, Clock::now()); }

// Now, in seconds since the Unix epoch (for times compared across hosts).
inline double UnixNow() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace transtick

#endif  // TRANSTICK_COMMON_CLOCK_H_
