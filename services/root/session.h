// Interactive sessions (docs/formats.md, "Session stream"): a client opens a
// session on a dataset, then streams cameras and classifications; the root
// renders the newest camera whenever the cluster is free for it (before
// batch jobs: FrameTurns), a coarse preview first if asked, and streams the
// frames back. Cameras that arrive while a frame renders supersede one
// another: only the newest is rendered next, so a client dragging the view
// never waits behind stale frames. Thread-safe.
#ifndef TRANSTICK_SERVICES_ROOT_SESSION_H_
#define TRANSTICK_SERVICES_ROOT_SESSION_H_

#include <grpcpp/grpcpp.h>

#include <cstdint>
#include <map>
#include <string>

#include "absl/base/thread_annotations.h"
#include "absl/synchronization/mutex.h"
#include "cluster.pb.h"
#include "job_runner.h"
#include "metrics.h"
#include "security.h"

namespace transtick {

struct SessionLimits {
  int max_sessions = 32;    // open at once on the root
  int max_per_client = 8;   // open at once by one client
};

class Sessions {
 public:
  // REQUIRES: `runner` and `metrics` outlive this.
  Sessions(JobRunner& runner, Metrics& metrics, SessionLimits limits = {});

  // Serves one session to its end: the client closes its side, cancels, or
  // the root stops. The first request must open it; every error of a later
  // request is an event and the session goes on.
  grpc::Status Serve(grpc::ServerContext* ctx,
                     grpc::ServerReaderWriter<v1::SessionEvent, v1::SessionRequest>* stream,
                     const Client& client);

  int open() const;

 private:
  JobRunner& runner_;
  Metrics& metrics_;
  const SessionLimits limits_;
  mutable absl::Mutex mu_;
  int open_ ABSL_GUARDED_BY(mu_) = 0;
  std::map<std::string, int> per_client_ ABSL_GUARDED_BY(mu_);
  uint64_t next_id_ ABSL_GUARDED_BY(mu_) = 1;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_SESSION_H_
