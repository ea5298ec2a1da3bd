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

// A frame of a job: the index over its views in order (dataset 0's views,
// then dataset 1's, ...), as the store and JobEvent.frame number them.
struct FrameKey {
  int dataset = 0, view = 0;
};
std::vector<FrameKey> FrameKeys(const v1::Job& spec);

// One job. The runner owns its progress; watchers read its log. Every
// change that must survive the root (state, cancel, delivered frames) is
// written to the store.
//
// A frame is pending (to render), rendering, published (its image is in
// the log) or delivered (its last chunk was written to a watcher). The
// runner takes pending frames lowest first (NextFrame), so a job whose
// delivered frames were recovered from the store renders only the rest,
// and a frame a resuming watcher lacks but the job no longer holds becomes
// pending again (Resume).
class Job {
 public:
  static constexpr size_t kMaxEvents = 4096;

  // `plan` is the spec converted (Datasets::Plan); empty for a finished
  // job. REQUIRES: `store` outlives this.
  Job(const StoredJob& stored, JobPlan plan, JobStore& store);
  Job(const Job&) = delete;
  Job& operator=(const Job&) = delete;

  const std::string& id() const { return id_; }
  int64_t seq() const { return seq_; }
  const std::string& owner() const { return owner_; }
  const v1::Job& spec() const { return spec_; }
  const JobPlan& plan() const { return plan_; }
  int frames_total() const { return static_cast<int>(keys_.size()); }
  const FrameKey& key(int frame) const { return keys_[frame]; }
  // Cancelled by a client, or the root is stopping.
  bool cancelled() const { return cancel_.load() || stop_.load(); }
  // A client's cancel: recorded in the store.
  void RequestCancel();
  // The root stops: the job ends here, its stored state stays as it was so
  // the next root resumes it.
  void Stop();

  // The runner: the lowest pending frame, now rendering; none when every
  // frame is rendered.
  std::optional<int> NextFrame();
  // The runner published `frame`'s last chunk.
  void FrameRendered(int frame);
  // The runner ends its turn with `status` (ok: no frame was left). False
  // when frames became pending meanwhile: the runner goes on with them.
  // Otherwise the job is finished: watchers drain the log and end.
  bool Complete(const absl::Status& status);

  // Appends an event, stamped with the job's id, state and counts.
  void Publish(v1::JobEvent event);
  // Appends an event carrying an image chunk. Blocks while the job's
  // undelivered image bytes exceed `budget`, until a watcher takes some,
  // the job is cancelled, or `wait` passes (then fails: nobody watches).
  absl::Status PublishImage(v1::JobEvent event, uint64_t budget, std::chrono::seconds wait);
  // The job is running (from queued).
  void SetRunning();

  // A watcher resumes holding the frames `have`: every other frame the job
  // no longer holds whole is rendered again. True when the job had ended
  // and must be queued again.
  bool Resume(const std::set<int>& have);

  v1::JobSummary Summary() const;
  bool finished() const;
  bool active() const;  // queued or running

  // Writes events from the log to `write` as they come, until the job is
  // finished and the log drained, `write` fails, or `watcher_gone()` says
  // the watcher left. Image chunks are handed over once: to the first
  // watcher that takes them; chunks of frames in `have` are dropped unsent.
  // Returns false if `write` failed or the watcher left.
  bool Stream(const std::function<bool(const v1::JobEvent&)>& write,
              const std::function<bool()>& watcher_gone, const std::set<int>& have);

 private:
  enum class FrameState { kPending, kRendering, kPublished, kDelivered };
  void Append(v1::JobEvent event) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  // The last chunk of `frame` has left: the frame is delivered.
  void Delivered(int frame);
  int FramesDone() const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  // Constant after construction.
  const std::string id_;
  const int64_t seq_;
  const std::string owner_;
  const v1::Job spec_;
  const JobPlan plan_;
  const std::vector<FrameKey> keys_;
  const double submitted_unix_;
  JobStore& store_;
  std::atomic<bool> cancel_{false};
  std::atomic<bool> stop_{false};

  // State below is protected by mu_.
  mutable absl::Mutex mu_;
  std::deque<v1::JobEvent> events_ ABSL_GUARDED_BY(mu_);
  uint64_t first_seq_ ABSL_GUARDED_BY(mu_) = 0;  // sequence number of events_.front()
  uint64_t pending_image_bytes_ ABSL_GUARDED_BY(mu_) = 0;
  v1::JobState state_ ABSL_GUARDED_BY(mu_) = v1::QUEUED;
  std::vector<FrameState> frames_ ABSL_GUARDED_BY(mu_);
  std::vector<bool> taken_ ABSL_GUARDED_BY(mu_);  // a chunk of the frame was handed over
  std::vector<bool> redo_ ABSL_GUARDED_BY(mu_);   // render again once rendered
  std::string error_ ABSL_GUARDED_BY(mu_);
  bool finished_ ABSL_GUARDED_BY(mu_) = false;
  bool active_ ABSL_GUARDED_BY(mu_) = true;
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
