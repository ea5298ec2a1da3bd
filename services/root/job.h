// One job of the root: its spec and plan, its frames' states, and its event
// log for watchers; every change that must survive the root is written to
// the job store (job_store.h). Thread-safe.
//
// A job's log keeps at most kMaxEvents small events (older progress events
// are dropped first), and image chunks are held only until one watcher has
// taken them, at most a budget per job: a frame's publisher waits for a
// watcher beyond that (PublishImage).
#ifndef TRANSTICK_SERVICES_ROOT_JOB_H_
#define TRANSTICK_SERVICES_ROOT_JOB_H_

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
  // When Submit accepted it, in seconds since the Unix epoch.
  double submitted_unix() const { return submitted_unix_; }
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

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_JOB_H_
