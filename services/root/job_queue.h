// The root's jobs: the queue the runner takes them from in submission order,
// each job's state, and its event log for watchers. Thread-safe.
//
// Memory stays bounded: the queue holds at most `max_queued` jobs, finished
// jobs beyond `max_jobs_kept` are forgotten, a job's log keeps at most
// kMaxEvents small events (older progress events are dropped first), and
// image chunks are held only until one watcher has taken them, at most
// `max_pending_image_bytes` per job: a frame's publisher waits for a
// watcher beyond that (JobQueue::PublishImage).
#ifndef TRANSTICK_SERVICES_ROOT_JOB_QUEUE_H_
#define TRANSTICK_SERVICES_ROOT_JOB_QUEUE_H_

#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "cluster.pb.h"

namespace transtick {

struct JobQueueOptions {
  int max_queued = 1000;   // jobs waiting to run
  int max_jobs_kept = 32;  // finished jobs kept for Status and late watchers
  uint64_t max_pending_image_bytes = uint64_t{256} << 20;
  // How long a frame's image may wait for a watcher once the budget is
  // full before the job fails.
  std::chrono::seconds image_wait{600};
};

// One job. The runner owns its progress; watchers read its log.
class Job {
 public:
  static constexpr size_t kMaxEvents = 4096;

  Job(std::string id, v1::Job spec, int frames_total, double submitted_unix)
      : id_(std::move(id)),
        spec_(std::move(spec)),
        frames_total_(frames_total),
        submitted_unix_(submitted_unix) {}
  Job(const Job&) = delete;
  Job& operator=(const Job&) = delete;

  const std::string& id() const { return id_; }
  const v1::Job& spec() const { return spec_; }
  int frames_total() const { return frames_total_; }
  bool cancelled() const { return cancel_.load(); }
  void RequestCancel();

  // Appends an event, stamped with the job's id, state and counts.
  void Publish(v1::JobEvent event);
  // Appends an event carrying an image chunk. Blocks while the job's
  // undelivered image bytes exceed `budget`, until a watcher takes some,
  // the job is cancelled, or `wait` passes (then fails: nobody watches).
  absl::Status PublishImage(v1::JobEvent event, uint64_t budget, std::chrono::seconds wait);
  void SetState(v1::JobState state, const std::string& error = "");
  void FrameDone();
  // Marks the job finished: watchers drain the log and end.
  void Finish();

  v1::JobSummary Summary() const;
  bool finished() const;

  // Writes events from the log to `write` as they come, until the job is
  // finished and the log drained, `write` fails, or `cancelled()` says the
  // watcher left. Image chunks are handed over once: to the first watcher
  // that takes them. Returns false if `write` failed or the watcher left.
  bool Stream(const std::function<bool(const v1::JobEvent&)>& write,
              const std::function<bool()>& watcher_gone);

 private:
  void Append(v1::JobEvent event) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  const std::string id_;
  const v1::Job spec_;
  const int frames_total_;
  const double submitted_unix_;
  std::atomic<bool> cancel_{false};

  mutable absl::Mutex mu_;
  std::deque<v1::JobEvent> events_ ABSL_GUARDED_BY(mu_);
  uint64_t first_seq_ ABSL_GUARDED_BY(mu_) = 0;  // sequence number of events_.front()
  uint64_t pending_image_bytes_ ABSL_GUARDED_BY(mu_) = 0;
  v1::JobState state_ ABSL_GUARDED_BY(mu_) = v1::QUEUED;
  int frames_done_ ABSL_GUARDED_BY(mu_) = 0;
  std::string error_ ABSL_GUARDED_BY(mu_);
  bool finished_ ABSL_GUARDED_BY(mu_) = false;
};

class JobQueue {
 public:
  explicit JobQueue(JobQueueOptions options) : options_(options) {}

  // Queues a validated job. Fails when the queue is full or stopping.
  absl::StatusOr<std::shared_ptr<Job>> Submit(const v1::Job& spec, int* queue_position);
  // The next job to run; null once stopping.
  std::shared_ptr<Job> Next();
  std::shared_ptr<Job> Find(const std::string& id) const;
  std::vector<v1::JobSummary> Summaries() const;
  // Cancels every job and wakes Next. Idempotent.
  void Stop();
  // Anything that may end a wait of the runner's (used by the registry's
  // waits for workers): the queue stopping.
  bool stopping() const;

  const JobQueueOptions& options() const { return options_; }

 private:
  const JobQueueOptions options_;
  mutable absl::Mutex mu_;
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;
  uint64_t next_job_ ABSL_GUARDED_BY(mu_) = 1;
  std::deque<std::shared_ptr<Job>> queue_ ABSL_GUARDED_BY(mu_);
  std::vector<std::shared_ptr<Job>> jobs_ ABSL_GUARDED_BY(mu_);  // newest last
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_JOB_QUEUE_H_
