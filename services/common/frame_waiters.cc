#include "frame_waiters.h"

#include <utility>
#include <vector>

#include "absl/time/time.h"

namespace transtick {

FrameWaiters::FrameWaiters(size_t max_parked, std::chrono::milliseconds patience)
    : max_parked_(max_parked), patience_(patience), expiry_([this] { Expire(); }) {}

FrameWaiters::~FrameWaiters() {
  Close();
  expiry_.join();
}

void FrameWaiters::Close() {
  std::vector<Resume> left;
  {
    absl::MutexLock lock(&mu_);
    stopping_ = true;
    for (auto& [deadline, w] : waiting_) left.push_back(std::move(w.resume));
    waiting_.clear();
  }
  for (Resume& r : left) r(false);
}

bool FrameWaiters::Park(uint64_t id, Resume resume) {
  absl::MutexLock lock(&mu_);
  if (stopping_ || waiting_.size() >= max_parked_) return false;
  waiting_.emplace(Clock::now() + patience_, Waiter{id, std::move(resume)});
  return true;
}

void FrameWaiters::Notify(uint64_t id) {
  std::vector<Resume> came;
  {
    absl::MutexLock lock(&mu_);
    for (auto it = waiting_.begin(); it != waiting_.end();) {
      if (it->second.id == id) {
        came.push_back(std::move(it->second.resume));
        it = waiting_.erase(it);
      } else {
        ++it;
      }
    }
  }
  for (Resume& r : came) r(true);
}

size_t FrameWaiters::parked() const {
  absl::MutexLock lock(&mu_);
  return waiting_.size();
}

void FrameWaiters::Expire() {
  for (;;) {
    std::vector<Resume> overdue;
    {
      absl::MutexLock lock(&mu_);
      // Wakes at the first deadline, when a stream parks (its deadline may
      // be the first) or when stopping.
      const size_t seen = waiting_.size();
      const auto first = waiting_.empty() ? Clock::time_point::max() : waiting_.begin()->first;
      auto changed = [&]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
        return stopping_ || waiting_.size() > seen;
      };
      if (first == Clock::time_point::max()) {
        mu_.Await(absl::Condition(&changed));
      } else {
        mu_.AwaitWithTimeout(absl::Condition(&changed), absl::FromChrono(first - Clock::now()));
      }
      if (stopping_) return;
      const auto now = Clock::now();
      // Woken more than a second past the deadline waited for: the process
      // did not run meanwhile (a paused or stalled machine), and neither did
      // the calls that would have added the frames. That time is not the
      // streams' wait: their deadlines move on by it.
      if (first != Clock::time_point::max() && now - first > std::chrono::seconds(1)) {
        const auto late = now - first;
        std::multimap<Clock::time_point, Waiter> moved;
        for (auto& [deadline, w] : waiting_) moved.emplace(deadline + late, std::move(w));
        waiting_.swap(moved);
        continue;
      }
      while (!waiting_.empty() && waiting_.begin()->first <= now) {
        overdue.push_back(std::move(waiting_.begin()->second.resume));
        waiting_.erase(waiting_.begin());
      }
    }
    for (Resume& r : overdue) r(false);
  }
}

}  // namespace transtick
