// An embedded cluster: a root, a display and N workers in this process, each
// a real gRPC server on 127.0.0.1, as `transtick render --local N`, the
// cluster tests and the benchmarks run them.
#ifndef TRANSTICK_SERVICES_LOCAL_LOCAL_CLUSTER_H_
#define TRANSTICK_SERVICES_LOCAL_LOCAL_CLUSTER_H_

#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace transtick {

class DisplayNode;
class RootNode;
class WorkerNode;

// Stops everything on destruction. Not copyable; root_address() may be
// called from any thread.
class LocalCluster {
 public:
  struct Options {
    int workers = 1;
    int rings = 1;
    int threads_per_worker = 1;
    std::string data_dir;  // the root's data directory
    bool metrics = false;  // each node serves /metrics on a port of 127.0.0.1
    // The root's RunnerOptions::frames_tracing: 0 auto (1 here: one
    // machine), 1 or 2.
    int frames_tracing = 0;
  };
  // Returns once every worker has registered with the root.
  static absl::StatusOr<std::unique_ptr<LocalCluster>> Start(const Options& options);
  ~LocalCluster();

  LocalCluster(const LocalCluster&) = delete;
  LocalCluster& operator=(const LocalCluster&) = delete;

  // "127.0.0.1:PORT" of the root, for clients.
  std::string root_address() const;
  // The ports of the nodes' /metrics (Options::metrics), and each worker's
  // gRPC address.
  int root_metrics_port() const;
  int display_metrics_port() const;
  std::vector<int> worker_metrics_ports() const;
  std::vector<std::string> worker_addresses() const;

 private:
  LocalCluster() = default;
  std::unique_ptr<DisplayNode> display_;
  std::unique_ptr<RootNode> root_;
  std::vector<std::unique_ptr<WorkerNode>> workers_;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_LOCAL_LOCAL_CLUSTER_H_
