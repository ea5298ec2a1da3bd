// The workers registered with the root, and which slab each holds. Thread-safe.
//
// What a worker holds is the root's belief, set when a load or re-slab
// succeeds and dropped when the worker fails, re-registers or is replaced.
#ifndef TRANSTICK_SERVICES_ROOT_REGISTRY_H_
#define TRANSTICK_SERVICES_ROOT_REGISTRY_H_

#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "cluster.grpc.pb.h"
#include "expiry.h"

namespace transtick {

// One registered worker. Immutable after registration; shared by the
// registry and the frames that use it.
struct WorkerEntry {
  std::string id, address;
  int threads = 1;
  uint64_t memory_bytes = 0;  // 0: unknown
  bool memory_shared = false;  // memory_bytes is its host's, shared
  // Where it runs (RegisterRequest): boot id ("" unknown), the CPUs it may
  // use and its machine's (0 unknown).
  std::string machine;
  double cpus = 0;
  int machine_cpus = 0;
  uint64_t order = 0;  // registration order: rings are formed in it
  std::shared_ptr<grpc::Channel> channel;  // the stub's
  std::unique_ptr<v1::Worker::Stub> stub;
};

// A slab a worker holds.
struct HeldSlab {
  std::string key;       // the slab's key: dataset key @ bounds
  std::string data_key;  // the dataset's key
  int y0 = 0, y1 = 0;
  int ring = -1;
};

class Registry {
 public:
  // A worker not heard from (Register renews) for `expiry` is dropped.
  // Silence is counted while the root runs: a clock thread looks every
  // 100 ms, and a gap of more than a second between its looks means the
  // root itself did not run (a paused process, a stalled machine) and could
  // not have heard any heartbeat, so the gap is not held against a worker.
  explicit Registry(std::chrono::milliseconds expiry = std::chrono::seconds(5));
  Registry(const Registry&) = delete;
  Registry& operator=(const Registry&) = delete;

  // Registers a worker, or renews one the registry knows at the same
  // address (and then fails ALREADY_EXISTS, as for any known id).
  absl::Status Register(const v1::RegisterRequest& req);
  absl::Status Unregister(const std::string& id);
  // A worker that failed a call: forgotten with what it held. When the
  // call could not reach it (its channel is not connected), it is first
  // given up to `recheck` to take a new connection, and keeps its place if
  // it does: one failed connect on a loaded machine is not a death, while a
  // worker that is gone refuses again. One that was reached and did not
  // answer in time (paused, stalled) goes at once. Blocks up to `recheck`.
  void Drop(const std::string& id, const std::string& why,
            std::chrono::milliseconds recheck = std::chrono::seconds(1));

  // The registered workers in registration order. Waits up to `wait` for
  // at least one; fails UNAVAILABLE when none came, CANCELLED when
  // `cancelled()` turns true (checked at least every 100 ms).
  absl::StatusOr<std::vector<std::shared_ptr<WorkerEntry>>> Workers(
      std::chrono::milliseconds wait, const std::function<bool()>& cancelled);
  int size() const;
  // Whether every registered worker said it runs on `machine` (its boot
  // id); false when one did not say, or `machine` is empty.
  bool AllOn(const std::string& machine) const;
  // Whether the worker is registered and was heard from within the expiry.
  bool Alive(const std::string& id);

  std::map<std::string, HeldSlab> Held() const;  // by worker id
  void SetHeld(const std::string& id, const HeldSlab& slab);
  void ClearHeld(const std::string& id);

  // For Status: every worker with its slab, in registration order (after
  // dropping the expired ones, hence not const).
  void Describe(v1::StatusReply* reply);

 private:
  // Drops workers not heard from within the expiry.
  void ExpireLocked() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  // The clock's look: a gap since the last one that shows the root did not
  // run moves every worker's last heartbeat on by the gap.
  void LookLocked(std::chrono::steady_clock::time_point now) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  const std::chrono::milliseconds expiry_;
  mutable absl::Mutex mu_;
  std::chrono::steady_clock::time_point last_look_ ABSL_GUARDED_BY(mu_);
  uint64_t next_order_ ABSL_GUARDED_BY(mu_) = 0;
  std::map<std::string, std::chrono::steady_clock::time_point> last_seen_ ABSL_GUARDED_BY(mu_);
  std::map<std::string, std::shared_ptr<WorkerEntry>> workers_ ABSL_GUARDED_BY(mu_);  // by id
  std::map<std::string, HeldSlab> held_ ABSL_GUARDED_BY(mu_);  // by worker id
  // The clock: last, so that it stops before the rest goes.
  Ticker clock_;
};

// Whether a failed call means the worker itself is gone (rather than a
// refusal it sent).
bool IsWorkerFailure(const grpc::Status& s);

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_REGISTRY_H_
