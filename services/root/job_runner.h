// The root's runner: one thread that takes jobs from the queue in order and
// renders their pending frames (Job::NextFrame) view by view: load the dataset, form rings from the
// registered workers, balance, distribute the slabs, drive the frame, and
// pass its image and statistics to the job's watchers. A frame that fails
// because a worker or the display failed runs again (five attempts, backing off).
// Thread-safe: Start once, Stop from any thread.
#ifndef TRANSTICK_SERVICES_ROOT_JOB_RUNNER_H_
#define TRANSTICK_SERVICES_ROOT_JOB_RUNNER_H_

#include <memory>
#include <string>
#include <thread>

#include "balancer.h"
#include "datasets.h"
#include "frame_driver.h"
#include "job_queue.h"
#include "metrics.h"
#include "registry.h"
#include "slabs.h"

namespace transtick {

struct RunnerOptions {
  std::string data_dir = "/data";
  std::string display = "127.0.0.1:7002";
  int rings = 1;
  uint64_t max_volume_bytes = uint64_t{8} << 30;
  double frame_timeout_s = 600;
  double worker_wait_s = 120;  // how long a job waits for a first worker
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
  // Starts the runner's thread. Call once.
  void Start();
  // Stops the queue (cancelling its jobs) and joins the runner. Idempotent.
  void Stop();

 private:
  void Loop();
  absl::Status RunJob(Job& job);
  // Renders the job's frame (on attempt after attempt while workers or the
  // display fail) and publishes its image.
  absl::Status RunView(Job& job, int frame, LoadedDataset& data);
  // The frame's statistics, logged and sent with its last image chunk.
  absl::Status PublishStats(Job& job, int dataset, int view, const LoadedDataset& data,
                            const Layout& layout, const FrameResult& frame,
                            const BalanceReport& balance, v1::JobEvent last_chunk);

  const RunnerOptions options_;
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
