#include "frame_table.h"

#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace transtick {
namespace {

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

}  // namespace

absl::StatusOr<std::optional<FrameTable::Dropped>> FrameTable::Add(std::shared_ptr<Frame> frame) {
  const uint64_t id = frame->id();
  absl::MutexLock lock(&mu_);
  if (frames_.count(id)) {
    return absl::AlreadyExistsError(absl::StrCat("frame ", id, " is already prepared"));
  }
  std::optional<Dropped> evicted;
  if (!frames_.empty() && frames_.size() >= limits_.max_frames) {
    auto oldest = frames_.begin();
    for (auto it = frames_.begin(); it != frames_.end(); ++it) {
      if (it->second->last_activity() < oldest->second->last_activity()) oldest = it;
    }
    evicted = Dropped{
        oldest->second,
        absl::StrFormat("was evicted: this worker holds at most %d frames, frame %d came, and this "
                        "one had been idle longest (%.1f s)",
                        limits_.max_frames, id,
                        Seconds(Clock::now() - oldest->second->last_activity()))};
    dropped_.Remember(oldest->first, evicted->why);
    frames_.erase(oldest);
  }
  frames_[id] = std::move(frame);
  return evicted;
}

std::shared_ptr<Frame> FrameTable::Find(uint64_t id) const {
  absl::MutexLock lock(&mu_);
  auto it = frames_.find(id);
  return it == frames_.end() ? nullptr : it->second;
}

std::shared_ptr<Frame> FrameTable::Take(uint64_t id) {
  absl::MutexLock lock(&mu_);
  auto it = frames_.find(id);
  if (it == frames_.end()) return nullptr;
  std::shared_ptr<Frame> frame = std::move(it->second);
  frames_.erase(it);
  return frame;
}

std::vector<std::shared_ptr<Frame>> FrameTable::TakeAll() {
  absl::MutexLock lock(&mu_);
  std::vector<std::shared_ptr<Frame>> all;
  for (auto& [id, frame] : frames_) all.push_back(std::move(frame));
  frames_.clear();
  return all;
}

std::vector<FrameTable::Dropped> FrameTable::TakeExpired(
    Clock::time_point now, const std::function<Clock::duration(Clock::time_point)>& paused_since) {
  absl::MutexLock lock(&mu_);
  std::vector<Dropped> expired;
  for (auto it = frames_.begin(); it != frames_.end();) {
    const Frame& f = *it->second;
    const bool running = f.running();
    const auto limit = running ? limits_.running_idle : limits_.prepared_idle;
    const Clock::time_point active = f.last_activity();
    const auto idle = now - active - (paused_since ? paused_since(active) : Clock::duration{0});
    if (idle <= limit) {
      ++it;
      continue;
    }
    std::string why;
    if (running) {
      why = absl::StrFormat(
          "expired: running, and no call, ray or traced work for %.1f s (the limit for a running "
          "frame is %.1f s)",
          Seconds(idle), Seconds(limit));
    } else {
      why = absl::StrFormat(
          "expired: prepared %.1f s ago and never run (the limit for a prepared frame is %.1f s)",
          Seconds(idle), Seconds(limit));
    }
    dropped_.Remember(it->first, why);
    expired.push_back({std::move(it->second), std::move(why)});
    it = frames_.erase(it);
  }
  return expired;
}

std::string FrameTable::WhyGone(uint64_t id) const {
  absl::MutexLock lock(&mu_);
  const std::string* why = dropped_.Find(id);
  return why ? absl::StrCat(" (it ", *why, ")") : "";
}

size_t FrameTable::size() const {
  absl::MutexLock lock(&mu_);
  return frames_.size();
}

}  // namespace transtick
