// What the worker and the display use to let go of frames nobody finishes:
// a thread that sweeps now and then, and a short memory of why frames went,
// so that a late call about one says what happened to it. A root that
// crashes, or a hostile one, must not make a daemon hold frames for ever.
#ifndef TRANSTICK_SERVICES_COMMON_EXPIRY_H_
#define TRANSTICK_SERVICES_COMMON_EXPIRY_H_

#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <string>
#include <thread>

#include "absl/base/thread_annotations.h"
#include "absl/synchronization/mutex.h"

namespace transtick {

// Calls `tick` every `period` on a thread of its own, from construction
// until destruction; the destructor waits for a tick in progress. Declare it
// after what `tick` uses, so that it stops first. Thread-safe.
//
// It also notices when its process did not run: a tick that comes more than
// a second later than due means the process (or its machine) was paused,
// for the excess. Nothing could touch a frame meanwhile, so an expiry sweep
// does not count that time as the frame's idleness (PausedSince).
class Ticker {
 public:
  using SteadyClock = std::chrono::steady_clock;

  Ticker(std::chrono::milliseconds period, std::function<void()> tick);
  ~Ticker();
  Ticker(const Ticker&) = delete;
  Ticker& operator=(const Ticker&) = delete;

  // How long the process was paused after `since`, as far as this ticker
  // saw (its last 32 pauses), before the tick in progress.
  SteadyClock::duration PausedSince(SteadyClock::time_point since) const;

 private:
  struct Pause {
    SteadyClock::time_point end;
    SteadyClock::duration length;
  };
  absl::Mutex mu_;
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;
  mutable absl::Mutex pauses_mu_;
  std::deque<Pause> pauses_ ABSL_GUARDED_BY(pauses_mu_);
  std::thread thread_;
};

// How often to look for things idle beyond `limit`: a quarter of it, so
// that they go within 1.25 × the limit, but no more than every 10 ms and at
// least once a second.
std::chrono::milliseconds SweepPeriod(std::chrono::milliseconds limit);

// Why the newest `capacity` frames that were dropped went, by frame id. Not
// thread-safe: its owner's mutex guards it.
class RecentReasons {
 public:
  explicit RecentReasons(size_t capacity = 256) : capacity_(capacity) {}
  void Remember(uint64_t id, std::string reason);
  // The reason given for `id`, or null when it is not remembered. The
  // pointer is valid until the next Remember.
  const std::string* Find(uint64_t id) const;

 private:
  const size_t capacity_;
  std::map<uint64_t, std::string> reasons_;  // frame ids grow: the smallest is the oldest
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_COMMON_EXPIRY_H_
