// The root's durable record of its jobs: an SQLite database in the state
// directory (docs/formats.md, "Root state database"), or in memory when
// there is none. It records what must survive a restart of the root: each
// accepted job's spec and owner, its state, a cancel request, and which
// frames were delivered whole to a watcher. Thread-safe; every write is
// on disk (WAL, synchronous=FULL) when the call returns OK.
#ifndef TRANSTICK_SERVICES_ROOT_JOB_STORE_H_
#define TRANSTICK_SERVICES_ROOT_JOB_STORE_H_

#include <cstdint>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "cluster.pb.h"

struct sqlite3;

namespace transtick {

// A job as the store holds it.
struct StoredJob {
  int64_t seq = 0;  // the job's id is JobId(seq)
  v1::Job spec;
  std::string owner;
  int frames_total = 0;
  uint64_t pixels_total = 0;
  double submitted_unix = 0;
  v1::JobState state = v1::QUEUED;
  std::string error;
  bool cancel = false;
  std::set<int> delivered;
};

std::string JobId(int64_t seq);

class JobStore {
 public:
  // Opens (creating if needed) STATE_DIR/jobs.db and takes STATE_DIR/LOCK;
  // an empty `state_dir` gives a database in memory. Fails when another
  // process holds the lock, the directory cannot be made or written, or
  // the database is corrupt or of another schema; the message names the
  // path.
  static absl::StatusOr<std::unique_ptr<JobStore>> Open(const std::string& state_dir);
  ~JobStore();
  JobStore(const JobStore&) = delete;
  JobStore& operator=(const JobStore&) = delete;

  // Every job, oldest first.
  absl::StatusOr<std::vector<StoredJob>> Load();
  // Records a new job (its seq, state, error and cancel fields are ignored)
  // and returns its seq.
  absl::StatusOr<int64_t> Insert(const StoredJob& job);
  absl::Status SetState(int64_t seq, v1::JobState state, const std::string& error);
  absl::Status SetCancel(int64_t seq);
  absl::Status MarkDelivered(int64_t seq, int frame);
  // Forgets that `frames` were delivered (they will be rendered again).
  absl::Status Undeliver(int64_t seq, const std::vector<int>& frames);
  absl::Status Forget(int64_t seq);

  // Where the database is ("" for memory).
  const std::string& path() const { return path_; }

 private:
  JobStore(std::string path, sqlite3* db, int lock_fd)
      : path_(std::move(path)), lock_fd_(lock_fd), db_(db) {}
  // Runs SQL without parameters (the schema, transactions).
  absl::Status Exec(const char* sql) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  absl::Status Error(const char* what) const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  const std::string path_;
  const int lock_fd_;  // -1 in memory
  absl::Mutex mu_;
  sqlite3* db_ ABSL_GUARDED_BY(mu_);
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_JOB_STORE_H_
