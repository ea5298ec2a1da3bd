#include "job_store.h"

#include <fcntl.h>
#include <sqlite3.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "absl/strings/str_cat.h"

namespace transtick {
namespace {

constexpr const char* kSchemaVersion = "1";

constexpr const char* kSchema = R"sql(
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS jobs (
  seq            INTEGER PRIMARY KEY AUTOINCREMENT,
  spec           BLOB    NOT NULL,
  owner          TEXT    NOT NULL,
  frames_total   INTEGER NOT NULL,
  pixels_total   INTEGER NOT NULL,
  submitted_unix REAL    NOT NULL,
  state          INTEGER NOT NULL,
  error          TEXT    NOT NULL DEFAULT '',
  cancel         INTEGER NOT NULL DEFAULT 0
);
CREATE TABLE IF NOT EXISTS delivered (
  seq   INTEGER NOT NULL REFERENCES jobs(seq) ON DELETE CASCADE,
  frame INTEGER NOT NULL,
  PRIMARY KEY (seq, frame)
) WITHOUT ROWID;
)sql";

// One prepared statement; finalized when it goes out of scope.
class Statement {
 public:
  Statement(sqlite3* db, const char* sql) {
    rc_ = sqlite3_prepare_v2(db, sql, -1, &stmt_, nullptr);
  }
  ~Statement() { sqlite3_finalize(stmt_); }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  bool ok() const { return rc_ == SQLITE_OK || rc_ == SQLITE_ROW || rc_ == SQLITE_DONE; }
  Statement& Int(int64_t v) {
    if (ok()) rc_ = sqlite3_bind_int64(stmt_, ++bound_, v);
    return *this;
  }
  Statement& Real(double v) {
    if (ok()) rc_ = sqlite3_bind_double(stmt_, ++bound_, v);
    return *this;
  }
  Statement& Text(const std::string& v) {
    if (ok()) rc_ = sqlite3_bind_text(stmt_, ++bound_, v.data(), v.size(), SQLITE_TRANSIENT);
    return *this;
  }
  Statement& Blob(const std::string& v) {
    if (ok()) rc_ = sqlite3_bind_blob(stmt_, ++bound_, v.data(), v.size(), SQLITE_TRANSIENT);
    return *this;
  }
  // Steps once: true while there is a row to read.
  bool Step() {
    if (!ok()) return false;
    rc_ = sqlite3_step(stmt_);
    return rc_ == SQLITE_ROW;
  }
  int64_t ColumnInt(int i) { return sqlite3_column_int64(stmt_, i); }
  double ColumnReal(int i) { return sqlite3_column_double(stmt_, i); }
  std::string ColumnBytes(int i) {
    const void* p = sqlite3_column_blob(stmt_, i);
    const int n = sqlite3_column_bytes(stmt_, i);
    return p == nullptr ? std::string() : std::string(static_cast<const char*>(p), n);
  }

 private:
  sqlite3_stmt* stmt_ = nullptr;
  int rc_;
  int bound_ = 0;
};

}  // namespace

std::string JobId(int64_t seq) { return absl::StrCat("job-", seq); }

absl::StatusOr<std::unique_ptr<JobStore>> JobStore::Open(const std::string& state_dir) {
  std::string path = ":memory:";
  int lock_fd = -1;
  if (!state_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(state_dir, ec);
    if (ec) {
      return absl::FailedPreconditionError(
          absl::StrCat("state directory ", state_dir, ": ", ec.message()));
    }
    const std::string lock = (std::filesystem::path(state_dir) / "LOCK").string();
    lock_fd = open(lock.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (lock_fd < 0) {
      return absl::FailedPreconditionError(absl::StrCat(lock, ": ", std::strerror(errno)));
    }
    if (flock(lock_fd, LOCK_EX | LOCK_NB) != 0) {
      const int err = errno;
      close(lock_fd);
      return absl::FailedPreconditionError(
          absl::StrCat(lock, ": ",
                       err == EWOULDBLOCK ? "another root uses this state directory"
                                          : std::strerror(err)));
    }
    path = (std::filesystem::path(state_dir) / "jobs.db").string();
  }
  sqlite3* db = nullptr;
  const int rc = sqlite3_open_v2(path.c_str(), &db,
                                 SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX,
                                 nullptr);
  auto store = std::unique_ptr<JobStore>(
      new JobStore(state_dir.empty() ? "" : path, db, lock_fd));
  absl::MutexLock lock(&store->mu_);
  if (rc != SQLITE_OK) return store->Error("open");
  sqlite3_busy_timeout(db, 5000);
  for (const char* pragma : {"PRAGMA journal_mode=WAL", "PRAGMA synchronous=FULL",
                             "PRAGMA foreign_keys=ON"}) {
    Statement s(db, pragma);
    s.Step();
    if (!s.ok()) return store->Error(pragma);
  }
  if (absl::Status s = store->Exec(kSchema); !s.ok()) return s;
  {
    Statement get(db, "SELECT value FROM meta WHERE key = 'schema'");
    if (get.Step()) {
      const std::string version = get.ColumnBytes(0);
      if (version != kSchemaVersion) {
        return absl::FailedPreconditionError(absl::StrCat(
            path, ": schema ", version, ", this root reads schema ", kSchemaVersion));
      }
    } else if (!get.ok()) {
      return store->Error("reading the schema version");
    } else {
      Statement put(db, "INSERT INTO meta (key, value) VALUES ('schema', ?)");
      put.Text(kSchemaVersion).Step();
      if (!put.ok()) return store->Error("writing the schema version");
    }
  }
  return store;
}

JobStore::~JobStore() {
  absl::MutexLock lock(&mu_);
  sqlite3_close(db_);
  if (lock_fd_ >= 0) close(lock_fd_);  // releases the flock
}

absl::Status JobStore::Error(const char* what) const {
  return absl::InternalError(absl::StrCat(path_.empty() ? "in-memory job store" : path_, ": ",
                                          what, ": ", sqlite3_errmsg(db_)));
}

absl::Status JobStore::Exec(const char* sql) {
  char* message = nullptr;
  if (sqlite3_exec(db_, sql, nullptr, nullptr, &message) != SQLITE_OK) {
    std::string m = message != nullptr ? message : "unknown error";
    sqlite3_free(message);
    return absl::InternalError(
        absl::StrCat(path_.empty() ? "in-memory job store" : path_, ": ", m));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::vector<StoredJob>> JobStore::Load() {
  absl::MutexLock lock(&mu_);
  std::vector<StoredJob> jobs;
  Statement q(db_,
              "SELECT seq, spec, owner, frames_total, pixels_total, submitted_unix, state, error, "
              "cancel FROM jobs ORDER BY seq");
  while (q.Step()) {
    StoredJob j;
    j.seq = q.ColumnInt(0);
    if (!j.spec.ParseFromString(q.ColumnBytes(1))) {
      return absl::DataLossError(
          absl::StrCat(path_, ": ", JobId(j.seq), ": the stored job spec does not parse"));
    }
    j.owner = q.ColumnBytes(2);
    j.frames_total = static_cast<int>(q.ColumnInt(3));
    j.pixels_total = static_cast<uint64_t>(q.ColumnInt(4));
    j.submitted_unix = q.ColumnReal(5);
    const int64_t state = q.ColumnInt(6);
    if (!v1::JobState_IsValid(static_cast<int>(state)) || state == v1::JOB_STATE_UNSPECIFIED) {
      return absl::DataLossError(
          absl::StrCat(path_, ": ", JobId(j.seq), ": unknown state ", state));
    }
    j.state = static_cast<v1::JobState>(state);
    j.error = q.ColumnBytes(7);
    j.cancel = q.ColumnInt(8) != 0;
    jobs.push_back(std::move(j));
  }
  if (!q.ok()) return Error("reading jobs");
  Statement d(db_, "SELECT seq, frame FROM delivered ORDER BY seq, frame");
  size_t i = 0;
  while (d.Step()) {
    const int64_t seq = d.ColumnInt(0);
    while (i < jobs.size() && jobs[i].seq < seq) ++i;
    if (i < jobs.size() && jobs[i].seq == seq) jobs[i].delivered.insert(static_cast<int>(d.ColumnInt(1)));
  }
  if (!d.ok()) return Error("reading delivered frames");
  return jobs;
}

absl::StatusOr<int64_t> JobStore::Insert(const StoredJob& job) {
  absl::MutexLock lock(&mu_);
  Statement s(db_,
              "INSERT INTO jobs (spec, owner, frames_total, pixels_total, submitted_unix, state) "
              "VALUES (?, ?, ?, ?, ?, ?)");
  s.Blob(job.spec.SerializeAsString())
      .Text(job.owner)
      .Int(job.frames_total)
      .Int(static_cast<int64_t>(job.pixels_total))
      .Real(job.submitted_unix)
      .Int(v1::QUEUED)
      .Step();
  if (!s.ok()) return Error("recording a job");
  return sqlite3_last_insert_rowid(db_);
}

absl::Status JobStore::SetState(int64_t seq, v1::JobState state, const std::string& error) {
  absl::MutexLock lock(&mu_);
  Statement s(db_, "UPDATE jobs SET state = ?, error = ? WHERE seq = ?");
  s.Int(state).Text(error).Int(seq).Step();
  return s.ok() ? absl::OkStatus() : Error("recording a job's state");
}

absl::Status JobStore::SetCancel(int64_t seq) {
  absl::MutexLock lock(&mu_);
  Statement s(db_, "UPDATE jobs SET cancel = 1 WHERE seq = ?");
  s.Int(seq).Step();
  return s.ok() ? absl::OkStatus() : Error("recording a cancel request");
}

absl::Status JobStore::MarkDelivered(int64_t seq, int frame) {
  absl::MutexLock lock(&mu_);
  Statement s(db_, "INSERT OR IGNORE INTO delivered (seq, frame) VALUES (?, ?)");
  s.Int(seq).Int(frame).Step();
  return s.ok() ? absl::OkStatus() : Error("recording a delivered frame");
}

absl::Status JobStore::Undeliver(int64_t seq, const std::vector<int>& frames) {
  absl::MutexLock lock(&mu_);
  if (absl::Status s = Exec("BEGIN"); !s.ok()) return s;
  for (int f : frames) {
    Statement s(db_, "DELETE FROM delivered WHERE seq = ? AND frame = ?");
    s.Int(seq).Int(f).Step();
    if (!s.ok()) {
      absl::Status e = Error("forgetting a delivered frame");
      Exec("ROLLBACK").IgnoreError();
      return e;
    }
  }
  return Exec("COMMIT");
}

absl::Status JobStore::Forget(int64_t seq) {
  absl::MutexLock lock(&mu_);
  Statement s(db_, "DELETE FROM jobs WHERE seq = ?");
  s.Int(seq).Step();
  return s.ok() ? absl::OkStatus() : Error("forgetting a job");
}

}  // namespace transtick
