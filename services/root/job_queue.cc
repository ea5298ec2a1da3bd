#include "job_queue.h"

#include <spdlog/spdlog.h>

#include <algorithm>

#include "absl/strings/str_cat.h"

namespace transtick {

absl::Status JobQueue::Recover(const Planner& planner) {
  auto stored = store_.Load();
  if (!stored.ok()) return stored.status();
  absl::MutexLock lock(&mu_);
  int queued = 0;
  for (const StoredJob& s : *stored) {
    const bool unfinished = s.state == v1::QUEUED || s.state == v1::RUNNING;
    absl::StatusOr<JobPlan> plan = unfinished ? planner(s.spec) : JobPlan{};
    auto job = std::make_shared<Job>(s, plan.ok() ? *std::move(plan) : JobPlan{}, store_);
    jobs_.push_back(job);
    if (!job->active()) continue;
    if (s.cancel) {
      job->Complete(absl::CancelledError("cancelled"));
      continue;
    }
    if (!plan.ok()) {
      spdlog::warn("{} recovered but cannot run: {}", job->id(), std::string(plan.status().message()));
      job->Complete(plan.status());
      continue;
    }
    queue_.push_back(job);
    ++queued;
    spdlog::info("{} recovered: {} of {} frames delivered; queued again", job->id(),
                 s.delivered.size(), job->frames_total());
  }
  TrimHistory();
  if (!stored->empty()) {
    spdlog::info("job store {}: {} jobs, {} queued again",
                 store_.path().empty() ? "(memory)" : store_.path(), stored->size(), queued);
  }
  return absl::OkStatus();
}

void JobQueue::TrimHistory() {
  int finished = 0;
  for (const auto& j : jobs_) finished += j->finished() ? 1 : 0;
  for (auto it = jobs_.begin(); it != jobs_.end() && finished > options_.max_jobs_kept;) {
    if (!(*it)->finished()) {
      ++it;
      continue;
    }
    if (absl::Status s = store_.Forget((*it)->seq()); !s.ok()) {
      spdlog::error("{}: {}", (*it)->id(), std::string(s.message()));
    }
    it = jobs_.erase(it);
    --finished;
  }
}

absl::StatusOr<std::shared_ptr<Job>> JobQueue::Submit(const v1::Job& spec, JobPlan plan,
                                                      const std::string& owner,
                                                      int* queue_position) {
  StoredJob stored;
  stored.spec = spec;
  stored.owner = owner;
  for (const auto& d : spec.datasets()) {
    stored.frames_total += d.views_size();
    for (const auto& v : d.views()) {
      stored.pixels_total += static_cast<uint64_t>(std::max(v.width(), 0)) * std::max(v.height(), 0);
    }
  }
  if (stored.pixels_total > options_.max_job_pixels) {
    return absl::InvalidArgumentError(absl::StrCat(
        "the job's views hold ", stored.pixels_total, " pixels in all; a job may hold at most ",
        options_.max_job_pixels, " (split it into several jobs)"));
  }
  stored.submitted_unix =
      std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  absl::MutexLock lock(&mu_);
  if (stopping_) return absl::UnavailableError("root is shutting down");
  if (static_cast<int>(queue_.size()) >= options_.max_queued) {
    return absl::ResourceExhaustedError(
        absl::StrCat("the queue is full (", queue_.size(), " jobs waiting); try again later"));
  }
  const int of_owner = static_cast<int>(std::count_if(
      jobs_.begin(), jobs_.end(), [&](const auto& j) { return j->owner() == owner && j->active(); }));
  if (of_owner >= options_.max_jobs_per_client) {
    return absl::ResourceExhaustedError(
        absl::StrCat("you have ", of_owner, " jobs queued or running, the most one client may; "
                     "wait for some to finish"));
  }
  auto seq = store_.Insert(stored);
  if (!seq.ok()) return absl::UnavailableError(seq.status().message());
  stored.seq = *seq;
  auto job = std::make_shared<Job>(stored, std::move(plan), store_);
  *queue_position = static_cast<int>(queue_.size());
  queue_.push_back(job);
  jobs_.push_back(job);
  TrimHistory();
  return job;
}

void JobQueue::Requeue(std::shared_ptr<Job> job) {
  absl::MutexLock lock(&mu_);
  if (std::find(queue_.begin(), queue_.end(), job) == queue_.end()) queue_.push_back(job);
  if (std::find(jobs_.begin(), jobs_.end(), job) == jobs_.end()) jobs_.push_back(job);
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
  for (auto& j : jobs) j->Stop();
}

bool JobQueue::stopping() const {
  absl::MutexLock lock(&mu_);
  return stopping_;
}

}  // namespace transtick
