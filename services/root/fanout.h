// Calls to many workers at once, and waiting for them all.
#ifndef TRANSTICK_SERVICES_ROOT_FANOUT_H_
#define TRANSTICK_SERVICES_ROOT_FANOUT_H_

#include <grpcpp/grpcpp.h>

#include <functional>
#include <vector>

#include "absl/status/status.h"

namespace transtick {

// Runs fn(i) for i in [0, n) on n threads and returns the first error (for
// blocking calls such as whole-slab streams).
absl::Status ForEachParallel(size_t n, const std::function<absl::Status(size_t)>& fn);

// Starts one asynchronous unary call per index, all at once, and waits for
// them all: no thread per call. `start(i, ctx, done)` starts call i on
// `ctx`, whose deadline is set to `deadline_s` from now, with `done` as its
// completion.
using StartCall =
    std::function<void(size_t, grpc::ClientContext*, std::function<void(grpc::Status)>)>;
std::vector<grpc::Status> CallAll(size_t n, double deadline_s, const StartCall& start);

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_FANOUT_H_
