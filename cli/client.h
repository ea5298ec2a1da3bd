// The client side of the cluster: submitting jobs and watching them, saving
// images. The embedded cluster of `transtick render --local N` is
// services/local/local_cluster.h.
#ifndef TRANSTICK_CLI_CLIENT_H_
#define TRANSTICK_CLI_CLIENT_H_

#include <chrono>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "cluster.pb.h"
#include "grpc/health/v1/health.pb.h"
#include "security.h"

namespace transtick {

class Progress;

struct WatchOptions {
  std::string out_dir;           // where images with relative output paths go
  Progress* progress = nullptr;  // told of progress, saved frames, warnings; null: silent
  // How long to keep trying to reach the root again after the watch
  // stream broke, counted from the last event received.
  std::chrono::seconds reconnect{300};
  // Images of views without an output path: out_dir/JOB-dD-vV.png.
};

// Submits `job` to the root; UNAVAILABLE naming the root when it cannot
// be reached.
absl::StatusOr<v1::SubmitReply> SubmitJob(const std::string& root, const v1::Job& job);

// Follows job `job_id` to its end, saving each frame's image to its output
// path (relative paths beneath options.out_dir; a view without one as
// out_dir/JOB-dD-vV.png). Every frame is delivered: those already rendered
// too. When the stream breaks it watches again (the root resumes the job
// from its store and sends the frames not yet saved). Returns the frames'
// statistics, or the job's error. Directories are never created: an output
// whose directory does not exist is an error naming it.
absl::StatusOr<std::vector<v1::ClusterFrameStats>> WatchJob(const std::string& root,
                                                            const std::string& job_id,
                                                            const WatchOptions& options);

// SubmitJob, then WatchJob.
absl::StatusOr<std::vector<v1::ClusterFrameStats>> SubmitAndWatch(const std::string& root,
                                                                  const v1::Job& job,
                                                                  const WatchOptions& options);

// Checks, before a job is sent, that every image it will write lands in a
// directory that exists: `out_dir` itself, and the directory of each view's
// output (beneath out_dir when relative). The error names the view and the
// missing directory.
absl::Status CheckOutputDirectories(const v1::Job& job, const std::string& out_dir);

// Reads a job file (protobuf JSON of transtick.v1.Job). A dataset may name
// "materials_file" or "transfer_file" relative to the job file; they are
// read here and sent inline.
absl::StatusOr<v1::Job> LoadJobFile(const std::string& path);

// What the standard health service of the daemon at `address` reports for
// the whole server, decoded from its HealthCheckResponse; or the call's
// error (UNAVAILABLE when nothing answers there, DEADLINE_EXCEEDED after
// `timeout_s` seconds). With TLS, the daemon's certificate must be of `role`.
absl::StatusOr<grpc::health::v1::HealthCheckResponse::ServingStatus> CheckHealth(
    const std::string& address, Role role, double timeout_s);

}  // namespace transtick

#endif  // TRANSTICK_CLI_CLIENT_H_
