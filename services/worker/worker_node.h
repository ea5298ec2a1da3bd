// A running worker: its server, its service, and its registration with the
// root: retried until it succeeds, then renewed every heartbeat (so a
// restarted root learns of this worker again by itself, and a root that
// hears nothing for a while drops it), withdrawn on Stop. Used by the
// transtick-worker daemon and by embedded clusters. Thread-safe.
#ifndef TRANSTICK_SERVICES_WORKER_WORKER_NODE_H_
#define TRANSTICK_SERVICES_WORKER_WORKER_NODE_H_

#include <atomic>
#include <memory>
#include <string>
#include <thread>

#include "absl/base/thread_annotations.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "daemon.h"
#include "metrics.h"
#include "worker_service.h"

namespace transtick {

struct WorkerNodeOptions {
  std::string listen = "0.0.0.0:7001";
  std::string root;       // host:port of the root
  std::string advertise;  // empty: this host's name and the bound port
  int threads = 0;        // 0: one per core
  // Ray batches to the neighbours (WorkerOptions).
  size_t batch_rays = FrameOptions().batch_rays;
  std::chrono::microseconds linger = FrameOptions().linger;
  uint64_t memory_bytes = 0;  // for slabs; 0: the container's limit, else the host's memory
  std::chrono::milliseconds heartbeat{1000};
  MetricsEndpoint metrics;  // where /metrics is served (StartMetrics)
  FrameLimits frames;
};

class WorkerNode {
 public:
  static absl::StatusOr<std::unique_ptr<WorkerNode>> Start(const WorkerNodeOptions& options);
  ~WorkerNode();

  const std::string& address() const { return address_; }
  const std::string& id() const { return id_; }
  int metrics_port() const { return metrics_ ? metrics_->port() : 0; }
  // True once the root accepted the registration.
  bool registered() const { return registered_; }
  // Unregisters, cancels frames, stops serving within `grace`.
  void Stop(std::chrono::milliseconds grace);

 private:
  WorkerNode() = default;
  void RegisterLoop();

  // Set by Start, then constant.
  WorkerNodeOptions options_;
  std::string id_, address_;
  int threads_ = 1;
  struct Memory {
    uint64_t bytes = 0;
    bool shared = false;  // the host's, not this worker's own
  } memory_;
  // Where it runs (RegisterRequest): the machine's boot id, the CPUs this
  // process may use, the machine's online CPUs.
  std::string machine_;
  double cpus_ = 0;
  int machine_cpus_ = 0;
  std::unique_ptr<WorkerService> service_;
  std::unique_ptr<Server> server_;
  std::unique_ptr<MetricsServer> metrics_;
  std::thread registrar_;
  std::atomic<bool> registered_{false};
  absl::Mutex mu_;
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;  // set once by Stop; ends the registrar's wait
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_WORKER_WORKER_NODE_H_
