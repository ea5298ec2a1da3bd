#include "job.h"

#include <spdlog/spdlog.h>

#include <algorithm>

#include "absl/strings/str_cat.h"

namespace transtick {
namespace {

// The bytes of an event's image rows, in either encoding (one is empty).
uint64_t ImageBytes(const v1::JobEvent& e) {
  return e.has_image() ? e.image().rgb().size() + e.image().rgb8().size() : 0;
}

// An event a late watcher can do without: progress since superseded, or
// the shell left by an image chunk already handed over.
bool IsDroppable(const v1::JobEvent& e) {
  if (e.has_image()) return ImageBytes(e) == 0 && !e.has_stats();
  return !e.has_stats() && e.error().empty() && e.pixels_total() > 0;
}

}  // namespace

std::vector<FrameKey> FrameKeys(const v1::Job& spec) {
  std::vector<FrameKey> keys;
  for (int d = 0; d < spec.datasets_size(); ++d) {
    for (int v = 0; v < spec.datasets(d).views_size(); ++v) keys.push_back({d, v});
  }
  return keys;
}

Job::Job(const StoredJob& stored, JobPlan plan, JobStore& store)
    : id_(JobId(stored.seq)),
      seq_(stored.seq),
      owner_(stored.owner),
      spec_(stored.spec),
      plan_(std::move(plan)),
      keys_(FrameKeys(stored.spec)),
      submitted_unix_(stored.submitted_unix),
      store_(store) {
  absl::MutexLock lock(&mu_);
  frames_.assign(keys_.size(), FrameState::kPending);
  taken_.assign(keys_.size(), false);
  redo_.assign(keys_.size(), false);
  for (int f : stored.delivered) {
    if (f >= 0 && f < frames_total()) frames_[f] = FrameState::kDelivered;
  }
  state_ = stored.state;
  error_ = stored.error;
  cancel_ = stored.cancel;
  if (state_ != v1::QUEUED && state_ != v1::RUNNING) {
    finished_ = true;
    active_ = false;
  } else {
    state_ = v1::QUEUED;  // a running job of a former root runs again
  }
}

void Job::RequestCancel() {
  if (absl::Status s = store_.SetCancel(seq_); !s.ok()) {
    spdlog::error("{}: {}", id_, std::string(s.message()));
  }
  absl::MutexLock lock(&mu_);  // wakes waits on cancel_ (they re-check on unlock)
  cancel_ = true;
}

void Job::Stop() {
  absl::MutexLock lock(&mu_);
  stop_ = true;
}

int Job::FramesDone() const {
  return static_cast<int>(std::count_if(frames_.begin(), frames_.end(), [](FrameState s) {
    return s == FrameState::kPublished || s == FrameState::kDelivered;
  }));
}

std::optional<int> Job::NextFrame() {
  absl::MutexLock lock(&mu_);
  for (int f = 0; f < frames_total(); ++f) {
    if (frames_[f] == FrameState::kPending) {
      frames_[f] = FrameState::kRendering;
      taken_[f] = false;
      return f;
    }
  }
  return std::nullopt;
}

void Job::FrameRendered(int frame) {
  absl::MutexLock lock(&mu_);
  if (redo_[frame]) {
    redo_[frame] = false;
    frames_[frame] = FrameState::kPending;
  } else if (frames_[frame] == FrameState::kRendering) {
    frames_[frame] = FrameState::kPublished;
  }
}

void Job::Delivered(int frame) {
  {
    absl::MutexLock lock(&mu_);
    if (frame < 0 || frame >= frames_total() || frames_[frame] == FrameState::kPending) return;
    frames_[frame] = FrameState::kDelivered;
  }
  if (absl::Status s = store_.MarkDelivered(seq_, frame); !s.ok()) {
    spdlog::error("{}: {}", id_, std::string(s.message()));
  }
}

bool Job::Complete(const absl::Status& status) {
  v1::JobState state;
  std::string error;
  {
    absl::MutexLock lock(&mu_);
    const bool more = std::find(frames_.begin(), frames_.end(), FrameState::kPending) !=
                      frames_.end();
    if (status.ok() && more && !cancelled()) return false;
    state = cancel_ ? v1::CANCELLED : (status.ok() ? v1::DONE : v1::FAILED);
    if (stop_ && !cancel_) state = state_;  // the next root takes it up
    error = status.ok() || state == v1::CANCELLED ? "" : std::string(status.message());
    state_ = state;
    if (!error.empty()) error_ = error;
    finished_ = true;
    active_ = false;
    Append(v1::JobEvent());
  }
  if (stop_ && !cancel_) return true;
  if (absl::Status s = store_.SetState(seq_, state, error); !s.ok()) {
    spdlog::error("{}: {}", id_, std::string(s.message()));
  }
  return true;
}

void Job::SetRunning() {
  {
    absl::MutexLock lock(&mu_);
    state_ = v1::RUNNING;
    Append(v1::JobEvent());
  }
  if (absl::Status s = store_.SetState(seq_, v1::RUNNING, ""); !s.ok()) {
    spdlog::error("{}: {}", id_, std::string(s.message()));
  }
}

bool Job::Resume(const std::set<int>& have) {
  std::vector<int> again;
  bool requeue = false;
  {
    absl::MutexLock lock(&mu_);
    if (cancelled() || state_ == v1::FAILED || state_ == v1::CANCELLED) return false;
    for (int f = 0; f < frames_total(); ++f) {
      if (have.count(f) != 0) continue;
      const FrameState s = frames_[f];
      if (s == FrameState::kDelivered || (s == FrameState::kPublished && taken_[f])) {
        frames_[f] = FrameState::kPending;
        again.push_back(f);
      } else if (s == FrameState::kRendering && taken_[f]) {
        redo_[f] = true;
      }
    }
    if (!again.empty() && !active_) {
      finished_ = false;
      active_ = true;
      state_ = v1::QUEUED;
      requeue = true;
    }
  }
  if (!again.empty()) {
    spdlog::info("{}: a watcher lacks {} frame(s) no longer held; rendering them again", id_,
                 again.size());
    if (absl::Status s = store_.Undeliver(seq_, again); !s.ok()) {
      spdlog::error("{}: {}", id_, std::string(s.message()));
    }
    if (requeue) {
      if (absl::Status s = store_.SetState(seq_, v1::QUEUED, ""); !s.ok()) {
        spdlog::error("{}: {}", id_, std::string(s.message()));
      }
    }
  }
  return requeue;
}

void Job::Append(v1::JobEvent event) {
  event.set_job_id(id_);
  event.set_state(state_);
  event.set_frames_total(frames_total());
  event.set_frames_done(FramesDone());
  if (!error_.empty()) event.set_error(error_);
  pending_image_bytes_ += ImageBytes(event);
  events_.push_back(std::move(event));
  // Bounded: old events a late watcher can do without (progress since
  // superseded, shells of delivered images) go from the front.
  while (events_.size() > kMaxEvents && IsDroppable(events_.front())) {
    events_.pop_front();
    ++first_seq_;
  }
}

void Job::Publish(v1::JobEvent event) {
  absl::MutexLock lock(&mu_);
  Append(std::move(event));
}

absl::Status Job::PublishImage(v1::JobEvent event, uint64_t budget, std::chrono::seconds wait) {
  absl::MutexLock lock(&mu_);
  const uint64_t bytes = ImageBytes(event);
  auto room = [&]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    return cancelled() || pending_image_bytes_ == 0 || pending_image_bytes_ + bytes <= budget;
  };
  const bool drained = mu_.AwaitWithTimeout(absl::Condition(&room), absl::FromChrono(wait));
  if (cancelled()) return absl::CancelledError("cancelled");
  if (!drained) {
    return absl::DeadlineExceededError(
        absl::StrCat("no client took this job's images for ", wait.count(), " s (",
                     pending_image_bytes_ >> 20, " MB waiting); watch the job to receive them"));
  }
  Append(std::move(event));
  return absl::OkStatus();
}

bool Job::finished() const {
  absl::MutexLock lock(&mu_);
  return finished_;
}

bool Job::active() const {
  absl::MutexLock lock(&mu_);
  return active_;
}

v1::JobSummary Job::Summary() const {
  absl::MutexLock lock(&mu_);
  v1::JobSummary s;
  s.set_job_id(id_);
  s.set_name(spec_.name());
  s.set_state(state_);
  s.set_frames_total(frames_total());
  s.set_frames_done(FramesDone());
  s.set_error(error_);
  s.set_submitted_unix(submitted_unix_);
  s.set_owner(owner_);
  return s;
}

bool Job::Stream(const std::function<bool(const v1::JobEvent&)>& write,
                 const std::function<bool()>& watcher_gone, const std::set<int>& have) {
  uint64_t next = 0;  // sequence number of the next event to send
  while (true) {
    v1::JobEvent event;
    bool have_event = false, finished;
    int skipped_last = -1;  // a frame in `have` whose last chunk was dropped here
    {
      absl::MutexLock lock(&mu_);
      auto ready = [&]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
        return first_seq_ + events_.size() > next || finished_;
      };
      mu_.AwaitWithTimeout(absl::Condition(&ready), absl::Milliseconds(500));
      next = std::max(next, first_seq_);
      finished = finished_;
      while (!have_event && skipped_last < 0 && next < first_seq_ + events_.size()) {
        v1::JobEvent& e = events_[next - first_seq_];
        ++next;
        if (e.has_image()) {
          if (ImageBytes(e) == 0) continue;  // another watcher took it
          // Handed over: the log keeps no image once it is on its way.
          pending_image_bytes_ -= ImageBytes(e);
          const int frame = e.frame();
          if (frame >= 0 && frame < frames_total()) taken_[frame] = true;
          const bool skip = have.count(frame) != 0;
          if (skip && e.has_stats()) skipped_last = frame;
          event = std::move(e);
          e = v1::JobEvent();
          e.set_job_id(id_);
          e.set_frame(frame);
          e.mutable_image()->set_row_begin(event.image().row_begin());
          // A publisher waiting for room re-checks when the lock is released.
          if (skip) continue;
        } else {
          event = e;
        }
        have_event = true;
      }
    }
    if (skipped_last >= 0) {
      Delivered(skipped_last);
      continue;
    }
    if (have_event) {
      if (!write(event)) return false;
      if (event.has_image() && event.has_stats()) Delivered(event.frame());
      continue;
    }
    if (finished) return true;
    if (watcher_gone()) return false;
  }
}

}  // namespace transtick
