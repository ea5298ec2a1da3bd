// The root: the client-facing API and the coordinator. It validates and
// queues jobs, loads datasets from its data directory, classifies them and
// encodes their sticks, forms rings from the registered workers, sends each
// worker its slab, drives frames through the workers and the display, and
// gathers per-worker statistics. Thread-safe; one runner thread executes
// jobs in submission order.
#ifndef TRANSTICK_SERVICES_ROOT_ROOT_SERVICE_H_
#define TRANSTICK_SERVICES_ROOT_ROOT_SERVICE_H_

#include <atomic>
#include <condition_variable>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "cluster.grpc.pb.h"
#include "transtick/framebuffer.h"
#include "transtick/partition.h"
#include "transtick/scene.h"

namespace transtick {

struct RootOptions {
  std::string data_dir = "/data";
  std::string display = "127.0.0.1:7002";
  int rings = 1;
  uint64_t max_volume_bytes = uint64_t{8} << 30;
  double frame_timeout_s = 600;
  // How long a job waits for at least one worker to register.
  double worker_wait_s = 120;
  int max_jobs_kept = 32;
};

class RootService final : public v1::Root::Service {
 public:
  // One frame's outcome on the workers: the image and each worker's
  // statistics, ring by ring.
  struct FrameResult {
    uint64_t frame_id = 0;
    double frame_ms = 0;
    Image image;
    std::vector<v1::WorkerFrameStats> workers;
  };

  explicit RootService(RootOptions options);
  ~RootService() override;

  // Cancels the running job, stops the runner. Idempotent.
  void Stop();
  // Workers registered now.
  int WorkerCount();

  grpc::Status Submit(grpc::ServerContext* ctx, const v1::Job* job,
                      v1::SubmitReply* reply) override;
  grpc::Status Watch(grpc::ServerContext* ctx, const v1::JobRef* req,
                     grpc::ServerWriter<v1::JobEvent>* writer) override;
  grpc::Status Status(grpc::ServerContext* ctx, const v1::StatusRequest* req,
                      v1::StatusReply* reply) override;
  grpc::Status Cancel(grpc::ServerContext* ctx, const v1::JobRef* req,
                      v1::CancelReply* reply) override;
  grpc::Status Register(grpc::ServerContext* ctx, const v1::RegisterRequest* req,
                        v1::RegisterReply* reply) override;
  grpc::Status Unregister(grpc::ServerContext* ctx, const v1::RegisterRequest* req,
                          v1::RegisterReply* reply) override;

 private:
  struct WorkerEntry;
  struct JobRecord;
  struct Layout;
  struct LoadedDataset;
  // A slab a worker holds.
  struct HeldSlab {
    std::string key;       // dataset key @ bounds
    std::string data_key;  // the dataset's key
    int y0 = 0, y1 = 0;
    int ring = -1;
  };
  // What balancing did for a frame, for its statistics.
  struct BalanceReport {
    std::string mode;
    std::vector<std::vector<int>> cuts_before, cuts_after;
    std::map<std::string, double> test_ray_ms;  // by worker id
    double balance_ms = 0;
  };

  absl::Status ValidateJob(const v1::Job& job) const;
  void RunnerLoop();
  absl::Status RunJob(JobRecord& job);
  // One view: rings, balancing, slabs, the frame, and its image published.
  absl::Status RunView(JobRecord& job, int dataset_index, int view_index, LoadedDataset& data);
  // Balancing: distributes the layout's slabs, runs a prerender of test
  // rays on them and puts the re-cut slabs in report->cuts_after.
  absl::Status Prerender(JobRecord& job, int dataset_index, int view_index, const v1::View& view,
                         const LoadedDataset& data, Layout& layout, BalanceRule rule,
                         BalanceReport* report);
  // Runs one frame of `view` on the layout (a prerender of test rays when
  // `test`: no progress events).
  absl::StatusOr<FrameResult> RunFrame(JobRecord& job, int dataset_index, int view_index,
                                       const v1::View& view, const LoadedDataset& data,
                                       const Layout& layout, bool test);
  void PublishFrame(JobRecord& job, int dataset_index, int view_index, const v1::View& view,
                    const Layout& layout, const FrameResult& frame, const BalanceReport& balance);
  absl::StatusOr<std::shared_ptr<LoadedDataset>> LoadDataset(const v1::Dataset& dataset);
  // The registered workers split into rings, each ring's slabs cut uniformly.
  absl::StatusOr<Layout> FormRings(const LoadedDataset& data, JobRecord& job);
  // Makes every worker of `layout` hold its slab: workers that hold another
  // slab of the dataset re-cut theirs with planes from their neighbours; the
  // root sends the others theirs.
  absl::Status Distribute(const LoadedDataset& data, Layout& layout);
  absl::Status LoadSlab(const LoadedDataset& data, WorkerEntry& worker, const std::string& key,
                        int y0, int y1);
  void DropWorker(const std::string& id, const std::string& why);
  void Publish(JobRecord& job, v1::JobEvent event);

  const RootOptions options_;
  std::atomic<uint64_t> next_frame_id_;

  std::mutex mu_;
  std::condition_variable cv_;  // jobs queued, workers registered, stop
  bool stopping_ = false;       // guarded by mu_
  uint64_t next_job_ = 1;       // guarded by mu_
  uint64_t next_order_ = 0;     // guarded by mu_
  std::map<std::string, std::shared_ptr<WorkerEntry>> workers_;  // guarded by mu_, by id
  std::deque<std::shared_ptr<JobRecord>> queue_;                 // guarded by mu_
  std::vector<std::shared_ptr<JobRecord>> jobs_;                 // guarded by mu_, newest last
  // What each worker holds, by worker id.
  std::map<std::string, HeldSlab> loaded_;  // guarded by mu_
  std::shared_ptr<LoadedDataset> cache_;       // runner thread only
  std::thread runner_;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_ROOT_SERVICE_H_
