// The root's jobs: the queue the runner takes them from in submission order,
// each job's state and frames, and its event log for watchers; durable
// through the job store (job_store.h). Thread-safe.
//
// Memory stays bounded: the queue holds at most `max_queued` jobs (and
// `max_jobs_per_client` of one client's), a job at most `max_job_pixels`, finished
// jobs beyond `max_jobs_kept` are forgotten, a job's log keeps at most
// kMaxEvents small events (older progress events are dropped first), and
// image chunks are held only until one watcher has taken them, at most
// `max_pending_image_bytes` per job: a frame's publisher waits for a
// watcher beyond that (Job::PublishImage).
#ifndef TRANSTICK_SERVICES_ROOT_JOB_QUEUE_H_
#define TRANSTICK_SERVICES_ROOT_JOB_QUEUE_H_

#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "cluster.pb.h"
#include "datasets.h"
#include "job.h"
#include "job_store.h"

namespace transtick {

struct JobQueueOptions {
  int max_queued = 1000;          // jobs waiting to run
  int max_jobs_kept = 32;         // finished jobs kept for Status and late watchers
  int max_jobs_per_client = 100;  // a client's jobs queued or running at once
  uint64_t max_job_pixels = uint64_t{2048} << 20;  // width x height summed over a job's views
  uint64_t max_pending_image_bytes = uint64_t{256} << 20;
  // How long a frame's image may wait for a watcher once the budget is
  // full before the job fails.
  std::chrono::seconds image_wait{600};
};

class JobQueue {
 public:
  // REQUIRES: `store` outlives this.
  JobQueue(JobQueueOptions options, JobStore& store) : options_(options), store_(store) {}

  using Planner = std::function<absl::StatusOr<JobPlan>(const v1::Job&)>;
  // Takes up the jobs recorded in the store: unfinished ones are planned
  // again and queued in submission order (one that no longer plans, say
  // its volume is gone, fails with the reason), finished ones are history.
  // Call once, before the runner starts.
  absl::Status Recover(const Planner& plan);
  // Queues a job from `owner` with its plan. Fails when the queue, the
  // owner's share of it or the job's pixels are over their limits, or the
  // root is stopping, or the store cannot record it.
  absl::StatusOr<std::shared_ptr<Job>> Submit(const v1::Job& spec, JobPlan plan,
                                               const std::string& owner, int* queue_position);
  // Queues a finished job again (Job::Resume said so).
  void Requeue(std::shared_ptr<Job> job);
  // The next job to run; null once stopping.
  std::shared_ptr<Job> Next();
  std::shared_ptr<Job> Find(const std::string& id) const;
  std::vector<v1::JobSummary> Summaries() const;
  // Stops every job (their stored state stays) and wakes Next. Idempotent.
  void Stop();
  // Anything that may end a wait of the runner's (used by the registry's
  // waits for workers): the queue stopping.
  bool stopping() const;

  const JobQueueOptions& options() const { return options_; }

 private:
  // Forgets the oldest finished jobs beyond the history limit.
  void TrimHistory() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  const JobQueueOptions options_;
  JobStore& store_;
  mutable absl::Mutex mu_;
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;
  std::deque<std::shared_ptr<Job>> queue_ ABSL_GUARDED_BY(mu_);
  std::vector<std::shared_ptr<Job>> jobs_ ABSL_GUARDED_BY(mu_);  // oldest first
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_JOB_QUEUE_H_
