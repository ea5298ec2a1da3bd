// The root's runner: one thread that takes jobs from the queue in order and
// renders their pending frames (Job::NextFrame) view by view: load the dataset, form rings from the
// registered workers, balance, distribute the slabs, drive the frame, and
// pass its image and statistics to the job's watchers. A frame that fails
// because a worker or the display failed runs again (five attempts, backing off).
// Thread-safe: Start once, Stop from any thread.
#ifndef TRANSTICK_SERVICES_ROOT_JOB_RUNNER_H_
#define TRANSTICK_SERVICES_ROOT_JOB_RUNNER_H_

#include <algorithm>
#include <atomic>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "absl/synchronization/mutex.h"
#include "absl/synchronization/notification.h"
#include "balancer.h"
#include "cluster_model.h"
#include "datasets.h"
#include "frame_driver.h"
#include "job_queue.h"
#include "metrics.h"
#include "registry.h"
#include "slabs.h"

namespace transtick {

constexpr int kAutoFramesTracing = 0;

struct RunnerOptions {
  std::string data_dir = "/data";
  std::string display = "127.0.0.1:7002";
  int rings = 1;            // kAutoRings: the cluster model's choice
  Network network;          // between hosts, for the model
  uint64_t max_volume_bytes = uint64_t{8} << 30;
  double frame_timeout_s = 600;
  double worker_wait_s = 120;  // how long a job waits for a first worker
  // Frames the cluster traces at once (FrameTurns), 1 or 2, or
  // kAutoFramesTracing. With 2 a job's next frame starts as soon as the last
  // one runs on every worker, which trace the older first (TraceOrder); with
  // 1 once the last one has traced. Auto: 2 when a worker runs on another
  // machine than the root, where the frame's hops wait on the network; 1
  // when they share one machine's cores (docs/design.md, "Overlapped
  // frames").
  int frames_tracing = kAutoFramesTracing;
};

// Who traces on the cluster next: `frames` frames at a time (a frame uses
// every worker; it gives up its turn once it has traced, and its image
// travels while the next one traces; a second frame traces where the first
// leaves the workers idle, RunnerOptions::frames_tracing), and an
// interactive session's frame before any batch job's that waits. Batch
// frames go between session frames, so a session that renders without
// pause holds the jobs off until it pauses. With frames overlapping, an
// interactive frame may take one turn more than `frames`: the workers trace
// it before the batch frames they hold. Thread-safe.
class FrameTurns {
 public:
  explicit FrameTurns(int frames = 1) : frames_(frames) {}
  // Blocks until it is the caller's turn; false (no turn) if `cancelled()`
  // turns true first.
  bool Acquire(bool interactive, const std::function<bool()>& cancelled);
  void Release();

 private:
  const int frames_;
  absl::Mutex mu_;
  int busy_ ABSL_GUARDED_BY(mu_) = 0;
  int interactive_waiting_ ABSL_GUARDED_BY(mu_) = 0;
};

// One frame to render on the cluster, and where its progress and image go.
struct FrameTask {
  std::string who;  // "job-3", "session-2": for logs
  const v1::View* view = nullptr;
  const FrameRequest* request = nullptr;  // the view, converted and checked
  Balancer* balancer = nullptr;
  LoadedDataset* data = nullptr;
  std::function<bool()> cancelled;
  FrameDriver::ProgressFn on_progress;
  FrameDriver::ChunkFn on_chunk;
  v1::ImageEncoding image_encoding = v1::FLOAT32;  // of the chunks on_chunk takes
  std::function<void()> on_attempt;  // before each attempt (chunks of a failed one are void)
  // Once the frame has traced (FrameDriver::Run's on_traced), on the
  // rendering thread; again if a later attempt traces.
  std::function<void()> on_traced;
  // Once the frame runs on every worker (FrameDriver::Run's on_running),
  // on the rendering thread; again if a later attempt runs.
  std::function<void()> on_running;
  // Once the balancer has learned from the frame's statistics (the workers
  // have reported; the image may still travel), on another thread; again
  // if a later attempt reports.
  std::function<void()> on_learned;
  bool interactive = false;
  // Rings (kAutoRings: chosen by the model for `frames` frames, once per
  // set of workers, and kept in `chosen` across the task's frames;
  // negative: the root's --rings).
  int rings = -1;
  int frames = 1;
  struct Chosen {
    std::string members;  // the workers it was chosen for
    int rings = 1;
  };
  Chosen* chosen = nullptr;
};

struct RenderedFrame {
  FrameResult result;
  Layout layout;
  BalanceReport report;
  int attempts = 1;  // the attempt that rendered it, counting from 1
};

// A frame's image rows, each passed on once over the frame's attempts. An
// attempt can fail after some of its chunks went out (the display lost in
// the middle of the image); the frame is then traced again, to the same
// bits, and the rows that already went out are dropped from the next
// attempt's chunks. A client that counts the rows it was sent would
// otherwise take the frame as whole before its last rows came.
class RowsOnce {
 public:
  // The part of `chunk` whose rows have not gone out; none when all have.
  // REQUIRES: rows go out in order (chunks of an attempt come in order, and
  // what goes out is a prefix of the image); the chunk's rows fit rgb or
  // rgb8 (ChunkBytesFit).
  std::optional<v1::ImageChunk> Trim(v1::ImageChunk chunk) const;
  // The rows of a chunk that ended at `row_end` went out.
  void Sent(int row_end) { out_ = std::max(out_, row_end); }

 private:
  int out_ = 0;  // rows [0, out_) have gone out
};

class JobRunner {
 public:
  // REQUIRES: `queue` and `registry` outlive this.
  // Frames, rays and retries are counted in `metrics`, which also outlives this.
  JobRunner(const RunnerOptions& options, JobQueue& queue, Registry& registry, Metrics& metrics);
  ~JobRunner();
  JobRunner(const JobRunner&) = delete;
  JobRunner& operator=(const JobRunner&) = delete;

  // Checks and converts a job (Datasets::Plan). Thread-safe.
  absl::StatusOr<JobPlan> Plan(const v1::Job& job) const { return datasets_.Plan(job); }
  // The dataset of `dataset`, loaded and classified (Datasets::Load).
  // Thread-safe.
  absl::StatusOr<std::shared_ptr<LoadedDataset>> Load(const v1::Dataset& dataset,
                                                      const DatasetPlan& plan) {
    return datasets_.Load(dataset, plan);
  }
  // Renders `task` on the cluster when it is its turn (FrameTurns): forms
  // the rings from the workers registered then, balances, distributes the
  // slabs and drives the frame, on attempt after attempt while workers or
  // the display fail. Thread-safe.
  absl::StatusOr<RenderedFrame> Render(FrameTask& task);
  // Counts a rendered frame in the metrics, logs it (as `label`) and fills
  // its statistics.
  void Describe(const std::string& who, const std::string& label, const v1::View& view,
                const LoadedDataset& data,
                const RenderedFrame& frame, double submitted_unix, v1::ClusterFrameStats* fs);
  bool stopping() const { return queue_.stopping(); }
  // Starts the runner's thread. Call once.
  void Start();
  // Stops the queue (cancelling its jobs) and joins the runner. Idempotent.
  void Stop();

 private:
  void Loop();
  absl::Status RunJob(Job& job);
  // A frame of a job in flight: RunJob starts the next frame once this one
  // has traced, and publishes images in frame order.
  struct Flight {
    int frame = 0;
    absl::Status status;
    absl::Notification running;    // it runs on every worker, or the frame ended
    absl::Notification traced;     // every deposit is in, or the frame ended
    absl::Notification published;  // its image is out, or the frame ended
    absl::Notification learned;    // its balancer learned from it, or the frame ended
    std::atomic<bool> abandon{false};  // the job ends: stop it
    std::thread thread;
  };
  // Renders the job's frame (on attempt after attempt while workers or the
  // display fail) and publishes its image, after `before`'s (null: none).
  // Whether a job's next frame starts once the last one runs, rather than
  // once it has traced (RunnerOptions::frames_tracing).
  bool Overlap() const;
  absl::Status RunView(Job& job, LoadedDataset& data, FrameTask::Chosen& chosen, Flight& me,
                       const Flight* before);

  // The task's rings for these workers (the model's choice for kAutoRings).
  int RingsFor(FrameTask& task, const std::vector<std::shared_ptr<WorkerEntry>>& workers)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(task.data->mu);

  const RunnerOptions options_;
  const std::string machine_;  // the root's (MachineId)
  FrameTurns turns_;
  JobQueue& queue_;
  Registry& registry_;
  Metrics& metrics_;
  Datasets datasets_;
  Slabs slabs_;
  FrameDriver driver_;
  std::thread thread_;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_JOB_RUNNER_H_
