#include "expiry.h"

#include <algorithm>
#include <utility>

#include "absl/time/time.h"

namespace transtick {

Ticker::Ticker(std::chrono::milliseconds period, std::function<void()> tick) {
  thread_ = std::thread([this, period, tick = std::move(tick)] {
    absl::MutexLock lock(&mu_);
    while (!mu_.AwaitWithTimeout(absl::Condition(&stopping_), absl::FromChrono(period))) {
      mu_.Unlock();
      tick();
      mu_.Lock();
    }
  });
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
