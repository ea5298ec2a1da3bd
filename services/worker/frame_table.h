// The frames a worker holds between PrepareFrame and EndFrame, by id, and
// how long it holds them. A root that crashes, or one that never ends what it
// prepares, must not leave a worker with frames (tracer threads, streams,
// and a share of a slab the root may evict) for ever. Thread-safe.
#ifndef TRANSTICK_SERVICES_WORKER_FRAME_TABLE_H_
#define TRANSTICK_SERVICES_WORKER_FRAME_TABLE_H_

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "clock.h"
#include "expiry.h"
#include "frame.h"

namespace transtick {

// A frame expires when it has seen nothing for its idle limit: no call, no
// ray batch from a neighbour, no traced work. A working root runs a frame
// within milliseconds of preparing it (its own deadline for that is 10 s),
// so a prepared frame's limit is short. A running frame may wait, traced out,
// for the rest of its ring for as long as the root's frame timeout (600 s by
// default). A busy frame never expires.
//
// At most `max_frames` are held. Preparing one more evicts the least
// recently active: the root traces one frame at a time on a worker (and
// ends the last while the next traces), so that one was abandoned, unless something floods the worker (then a frame is lost,
// and the root retries it). Refusing instead would leave a worker whose root
// crashed unusable until its leftovers expired.
struct FrameLimits {
  size_t max_frames = 4;
  std::chrono::milliseconds prepared_idle = std::chrono::seconds(60);
  std::chrono::milliseconds running_idle = std::chrono::seconds(600);
};

class FrameTable {
 public:
  // A frame a limit took out of the table, and why, for the caller to end.
  struct Dropped {
    std::shared_ptr<Frame> frame;
    std::string why;
  };

  explicit FrameTable(FrameLimits limits) : limits_(limits) {}

  const FrameLimits& limits() const { return limits_; }

  // Adds `frame`, evicting the least recently active frame if the table is
  // full; fails ALREADY_EXISTS when its id is held.
  absl::StatusOr<std::optional<Dropped>> Add(std::shared_ptr<Frame> frame);
  // The frame, or null. Shared: the caller may use it after it is removed.
  std::shared_ptr<Frame> Find(uint64_t id) const;
  // Removes the frame and returns it (null when absent).
  std::shared_ptr<Frame> Take(uint64_t id);
  std::vector<std::shared_ptr<Frame>> TakeAll();
  // Removes the frames idle beyond their limit at `now`, not counting the
  // time `paused_since(t)` says the process did not run after t.
  std::vector<Dropped> TakeExpired(
      Clock::time_point now,
      const std::function<Clock::duration(Clock::time_point)>& paused_since = {});
  // Why frame `id` is not held: " (it expired: ...)" when a limit dropped
  // it recently, else empty. For error messages.
  std::string WhyGone(uint64_t id) const;
  size_t size() const;

 private:
  const FrameLimits limits_;
  mutable absl::Mutex mu_;
  std::map<uint64_t, std::shared_ptr<Frame>> frames_ ABSL_GUARDED_BY(mu_);
  RecentReasons dropped_ ABSL_GUARDED_BY(mu_);
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_WORKER_FRAME_TABLE_H_
