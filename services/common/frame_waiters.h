// Streams that arrive before their frame. The root prepares a frame on every
// worker and begins it at the display in one round, and a worker starts
// tracing as soon as it has prepared it, so a neighbour's ray stream (or a
// worker's first deposits) can reach a node a moment before the node has
// heard of the frame. Such a stream parks here, holding its first message
// and reading no further (gRPC's flow control holds the sender), until the
// frame is added (Notify) or a deadline passes. No thread waits per stream:
// one thread per FrameWaiters expires the overdue. Time the process did not
// run (a pause of more than a second) does not count against the wait.
#ifndef TRANSTICK_SERVICES_COMMON_FRAME_WAITERS_H_
#define TRANSTICK_SERVICES_COMMON_FRAME_WAITERS_H_

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <thread>

#include "absl/synchronization/mutex.h"

namespace transtick {

// Thread-safe.
class FrameWaiters {
 public:
  using Clock = std::chrono::steady_clock;
  // Called once: true when the frame came, false when the wait ended
  // without it (deadline, or the FrameWaiters going away). Called on the
  // thread of Notify, of the expiry thread or of the destructor, never
  // under the lock, and must not block.
  using Resume = std::function<void(bool came)>;

  // At most `max_parked` streams wait at once, each for at most `patience`.
  FrameWaiters(size_t max_parked, std::chrono::milliseconds patience);
  // Close()s.
  ~FrameWaiters();
  FrameWaiters(const FrameWaiters&) = delete;
  FrameWaiters& operator=(const FrameWaiters&) = delete;

  // Parks a stream until frame `id` is Notified. False, without parking or
  // calling `resume`, when `max_parked` streams already wait.
  bool Park(uint64_t id, Resume resume);
  // Resumes the streams waiting for frame `id` with true.
  void Notify(uint64_t id);
  // Resumes every stream still waiting with false, and parks none from now
  // on (a node shutting down).
  void Close();
  size_t parked() const;
  std::chrono::milliseconds patience() const { return patience_; }

 private:
  struct Waiter {
    uint64_t id;
    Resume resume;
  };
  void Expire();

  const size_t max_parked_;
  const std::chrono::milliseconds patience_;
  mutable absl::Mutex mu_;
  // By deadline; ties in the order parked.
  std::multimap<Clock::time_point, Waiter> waiting_ ABSL_GUARDED_BY(mu_);
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;  // Close()d
  std::thread expiry_;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_COMMON_FRAME_WAITERS_H_
