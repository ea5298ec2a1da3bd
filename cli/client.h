// The client side of the cluster: submitting jobs and watching them, saving
// images, and an embedded cluster for `transtick render --local N`.
#ifndef TRANSTICK_CLI_CLIENT_H_
#define TRANSTICK_CLI_CLIENT_H_

#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "cluster.pb.h"

namespace transtick {

class DisplayService;
class RootNode;
class Server;
class WorkerNode;

struct WatchOptions {
  std::string out_dir;    // where images with relative output paths go
  bool progress = false;  // a progress line on stderr
  // Images of views without an output path: out_dir/JOB-dD-vV.png.
};

// Submits `job` to the root and follows it to the end, saving each frame's
// image to its output path. Returns the frames' statistics, or the job's
// error.
absl::StatusOr<std::vector<v1::ClusterFrameStats>> SubmitAndWatch(const std::string& root,
                                                                  const v1::Job& job,
                                                                  const WatchOptions& options);

// Reads a job file (protobuf JSON of transtick.v1.Job). A dataset may name
// "materials_file" or "transfer_file" relative to the job file; they are
// read here and sent inline.
absl::StatusOr<v1::Job> LoadJobFile(const std::string& path);

// A root, a display and N workers in this process, each a real gRPC server
// on 127.0.0.1. Stops everything on destruction.
class LocalCluster {
 public:
  struct Options {
    int workers = 1;
    int rings = 1;
    int threads_per_worker = 1;
    std::string data_dir;
  };
  static absl::StatusOr<std::unique_ptr<LocalCluster>> Start(const Options& options);
  ~LocalCluster();

  std::string root_address() const;

 private:
  LocalCluster() = default;
  std::unique_ptr<DisplayService> display_service_;
  std::unique_ptr<Server> display_server_;
  std::unique_ptr<RootNode> root_;
  std::vector<std::unique_ptr<WorkerNode>> workers_;
};

}  // namespace transtick

#endif  // TRANSTICK_CLI_CLIENT_H_
