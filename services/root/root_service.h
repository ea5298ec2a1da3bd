// The root's gRPC service: the client API (Submit, Watch, Status, Cancel)
// and the workers' registration. It only translates between protobuf and
// the root's parts, which do the work: the job queue (job_queue.h), the
// worker registry (registry.h) and the runner (job_runner.h), which loads
// datasets (datasets.h), cuts and moves slabs (slabs.h), balances
// (balancer.h) and drives frames (frame_driver.h). Thread-safe.
#ifndef TRANSTICK_SERVICES_ROOT_ROOT_SERVICE_H_
#define TRANSTICK_SERVICES_ROOT_ROOT_SERVICE_H_

#include <memory>
#include <string>

#include "cluster.grpc.pb.h"
#include "job_queue.h"
#include "job_runner.h"
#include "job_store.h"
#include "metrics.h"
#include "registry.h"
#include "session.h"
#include "volumes.h"

namespace transtick {

// The runner's settings (data directory, display, rings, limits, timeouts),
// the queue's limits and where the jobs are kept.
struct RootOptions : RunnerOptions, JobQueueOptions {
  std::string state_dir;  // the job store's directory; "" keeps jobs in memory only
};

class RootService final : public v1::Root::Service {
 public:
  // Opens the job store, takes up the jobs it holds and starts the runner.
  static absl::StatusOr<std::unique_ptr<RootService>> Create(const RootOptions& options);
  ~RootService() override;

  // Cancels the running job, stops the runner. Idempotent.
  void Stop();
  // Workers registered now.
  int WorkerCount() const { return registry_.size(); }
  // The root's metrics (docs/formats.md, "Metrics"), for /metrics.
  const std::shared_ptr<Metrics>& metrics() const { return metrics_; }

  grpc::Status Submit(grpc::ServerContext* ctx, const v1::Job* job,
                      v1::SubmitReply* reply) override;
  grpc::Status Volumes(grpc::ServerContext* ctx, const v1::VolumesRequest* req,
                       v1::VolumesReply* reply) override;
  grpc::Status Session(
      grpc::ServerContext* ctx,
      grpc::ServerReaderWriter<v1::SessionEvent, v1::SessionRequest>* stream) override;
  grpc::Status Watch(grpc::ServerContext* ctx, const v1::WatchRequest* req,
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
  RootService(const RootOptions& options, std::unique_ptr<JobStore> store);

  const RootOptions options_;
  const std::shared_ptr<Metrics> metrics_;
  std::unique_ptr<JobStore> store_;
  JobQueue queue_;
  Registry registry_;
  JobRunner runner_;  // after queue_ and registry_: it uses both
  Sessions sessions_;  // after runner_: it renders through it
  DicomSeriesCache series_cache_;  // what the data directory's DICOM headers said (Volumes)
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_ROOT_SERVICE_H_
