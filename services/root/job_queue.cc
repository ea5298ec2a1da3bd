#include "job_queue.h"

#include <spdlog/spdlog.h>

#include <algorithm>

#include "absl/strings/str_cat.h"

namespace transtick {
namespace {

uint64_t ImageBytes(const v1::JobEvent& e) { return e.has_image() ? e.image().rgb().size() : 0; }

// An event a late watcher can do without: progress since superseded, or
// the shell left by an image chunk already handed over.
bool IsDroppable(const v1::JobEvent& e) {
  if (e.has_image()) return e.image().rgb().empty() && !e.has_stats();
  return !e.has_stats() && e.error().empty() && e.pixels_total() > 0;
}

}  // namespace

void Job::RequestCancel() {
  absl::MutexLock lock(&mu_);  // wakes waits on cancel_ (they re-check on unlock)
  cancel_ = true;
}

void Job::Append(v1::JobEvent event) {
  event.set_job_id(id_);
  event.set_state(state_);
  event.set_frames_total(frames_total_);
  event.set_frames_done(frames_done_);
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
    return cancel_ || pending_image_bytes_ == 0 || pending_image_bytes_ + bytes <= budget;
  };
  const bool drained = mu_.AwaitWithTimeout(absl::Condition(&room), absl::FromChrono(wait));
  if (cancel_) return absl::CancelledError("cancelled");
  if (!drained) {
    return absl::DeadlineExceededError(
        absl::StrCat("no client took this job's images for ", wait.count(), " s (",
                     pending_image_bytes_ >> 20, " MB waiting); watch the job to receive them"));
  }
  Append(std::move(event));
  return absl::OkStatus();
}

void Job::SetState(v1::JobState state, const std::string& error) {
  absl::MutexLock lock(&mu_);
  state_ = state;
  if (!error.empty()) error_ = error;
}

void Job::FrameDone() {
  absl::MutexLock lock(&mu_);
  ++frames_done_;
}

void Job::Finish() {
  absl::MutexLock lock(&mu_);
  finished_ = true;
}

bool Job::finished() const {
  absl::MutexLock lock(&mu_);
  return finished_;
}

v1::JobSummary Job::Summary() const {
  absl::MutexLock lock(&mu_);
  v1::JobSummary s;
  s.set_job_id(id_);
  s.set_name(spec_.name());
  s.set_state(state_);
  s.set_frames_total(frames_total_);
  s.set_frames_done(frames_done_);
  s.set_error(error_);
  s.set_submitted_unix(submitted_unix_);
  return s;
}

bool Job::Stream(const std::function<bool(const v1::JobEvent&)>& write,
                 const std::function<bool()>& watcher_gone) {
  uint64_t next = 0;  // sequence number of the next event to send
  while (true) {
    v1::JobEvent event;
    bool have = false, finished;
    {
      absl::MutexLock lock(&mu_);
      auto ready = [&]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
        return first_seq_ + events_.size() > next || finished_;
      };
      mu_.AwaitWithTimeout(absl::Condition(&ready), absl::Milliseconds(500));
      next = std::max(next, first_seq_);
      finished = finished_;
      while (!have && next < first_seq_ + events_.size()) {
        v1::JobEvent& e = events_[next - first_seq_];
        ++next;
        if (e.has_image()) {
          if (e.image().rgb().empty()) continue;  // another watcher took it
          // Handed over: the log keeps no image once it is on its way.
          pending_image_bytes_ -= e.image().rgb().size();
          event = std::move(e);
          e = v1::JobEvent();
          e.set_job_id(id_);
          e.mutable_image()->set_row_begin(event.image().row_begin());
          // A publisher waiting for room re-checks when the lock is released.
        } else {
          event = e;
        }
        have = true;
      }
    }
    if (have) {
      if (!write(event)) return false;
      continue;
    }
    if (finished) return true;
    if (watcher_gone()) return false;
  }
}

absl::StatusOr<std::shared_ptr<Job>> JobQueue::Submit(const v1::Job& spec, int* queue_position) {
  int frames = 0;
  for (const auto& d : spec.datasets()) frames += d.views_size();
  const double now =
      std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  absl::MutexLock lock(&mu_);
  if (stopping_) return absl::UnavailableError("root is shutting down");
  if (static_cast<int>(queue_.size()) >= options_.max_queued) {
    return absl::ResourceExhaustedError(
        absl::StrCat("the queue is full (", queue_.size(), " jobs waiting); try again later"));
  }
  auto job = std::make_shared<Job>(absl::StrCat("job-", next_job_++), spec, frames, now);
  *queue_position = static_cast<int>(queue_.size());
  queue_.push_back(job);
  jobs_.push_back(job);
  // Forget the oldest finished jobs beyond the history limit.
  while (static_cast<int>(jobs_.size()) > options_.max_jobs_kept) {
    auto it = std::find_if(jobs_.begin(), jobs_.end(), [](const auto& j) { return j->finished(); });
    if (it == jobs_.end()) break;
    jobs_.erase(it);
  }
  return job;
}

std::shared_ptr<Job> JobQueue::Next() {
  absl::MutexLock lock(&mu_);
  auto ready = [this]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) { return stopping_ || !queue_.empty(); };
  mu_.Await(absl::Condition(&ready));
  if (stopping_) return nullptr;
  auto job = queue_.front();
  queue_.pop_front();
  return job;
}

std::shared_ptr<Job> JobQueue::Find(const std::string& id) const {
  absl::MutexLock lock(&mu_);
  for (const auto& j : jobs_) {
    if (j->id() == id) return j;
  }
  return nullptr;
}

std::vector<v1::JobSummary> JobQueue::Summaries() const {
  std::vector<std::shared_ptr<Job>> jobs;
  {
    absl::MutexLock lock(&mu_);
    jobs = jobs_;
  }
  std::vector<v1::JobSummary> out;
  for (const auto& j : jobs) out.push_back(j->Summary());
  return out;
}

void JobQueue::Stop() {
  std::vector<std::shared_ptr<Job>> jobs;
  {
    absl::MutexLock lock(&mu_);
    stopping_ = true;
    jobs = jobs_;
  }
  for (auto& j : jobs) j->RequestCancel();
}

bool JobQueue::stopping() const {
  absl::MutexLock lock(&mu_);
  return stopping_;
}

}  // namespace transtick
