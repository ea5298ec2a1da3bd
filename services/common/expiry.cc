#include "expiry.h"

#include <algorithm>
#include <utility>

#include "absl/time/time.h"

namespace transtick {

namespace {

// How much later than due a tick must come to count as a pause.
constexpr auto kPauseSlack = std::chrono::seconds(1);
constexpr size_t kPausesKept = 32;

}  // namespace

Ticker::Ticker(std::chrono::milliseconds period, std::function<void()> tick) {
  thread_ = std::thread([this, period, tick = std::move(tick)] {
    absl::MutexLock lock(&mu_);
    auto last = SteadyClock::now();
    while (!mu_.AwaitWithTimeout(absl::Condition(&stopping_), absl::FromChrono(period))) {
      mu_.Unlock();
      const auto now = SteadyClock::now();
      if (now - last > period + kPauseSlack) {
        absl::MutexLock pauses(&pauses_mu_);
        pauses_.push_back({now, now - last - period});
        if (pauses_.size() > kPausesKept) pauses_.pop_front();
      }
      tick();
      last = SteadyClock::now();
      mu_.Lock();
    }
  });
}

Ticker::SteadyClock::duration Ticker::PausedSince(SteadyClock::time_point since) const {
  absl::MutexLock lock(&pauses_mu_);
  SteadyClock::duration paused{0};
  for (const Pause& p : pauses_) {
    if (p.end > since) paused += std::min(p.length, p.end - since);
  }
  return paused;
}

Ticker::~Ticker() {
  {
    absl::MutexLock lock(&mu_);
    stopping_ = true;
  }
  thread_.join();
}

std::chrono::milliseconds SweepPeriod(std::chrono::milliseconds limit) {
  return std::clamp<std::chrono::milliseconds>(limit / 4, std::chrono::milliseconds(10),
                                               std::chrono::seconds(1));
}

void RecentReasons::Remember(uint64_t id, std::string reason) {
  reasons_[id] = std::move(reason);
  while (reasons_.size() > capacity_) reasons_.erase(reasons_.begin());
}

const std::string* RecentReasons::Find(uint64_t id) const {
  auto it = reasons_.find(id);
  return it == reasons_.end() ? nullptr : &it->second;
}

}  // namespace transtick
