#include "root_service.h"

#include <spdlog/spdlog.h>
#include <sys/stat.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <functional>
#include <numeric>
#include <optional>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "convert.h"
#include "daemon.h"
#include "transtick/framebuffer.h"
#include "transtick/partition.h"
#include "transtick/ray_codec.h"
#include "transtick/volume_io.h"

namespace transtick {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// Test rays per side of the image for a balancing prerender. 16 (the
// paper's order) measures too few rays for stable cuts: on bonsai with 8
// workers the tracer CPU max/mean after balancing was 1.22-1.25 with 16,
// 1.09-1.13 with 32 and 48; 32x32 rays cost about 0.6% of a 400x400 frame.
constexpr int kDefaultBalanceGrid = 32;

double MsSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

grpc::Status Invalid(const std::string& m) {
  return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, m);
}

// Runs fn(i) for i in [0, n) on n threads and returns the first error.
absl::Status ForEachParallel(size_t n, const std::function<absl::Status(size_t)>& fn) {
  std::vector<absl::Status> results(n);
  std::vector<std::thread> threads;
  for (size_t i = 0; i < n; ++i) threads.emplace_back([&, i] { results[i] = fn(i); });
  for (auto& t : threads) t.join();
  for (auto& s : results) {
    if (!s.ok()) return s;
  }
  return absl::OkStatus();
}

// Starts one asynchronous unary call per index, all at once, and waits for
// them all: no thread per call. `start(i, ctx, done)` starts call i on
// `ctx`, whose deadline is set, with `done` as its completion.
using StartCall =
    std::function<void(size_t, grpc::ClientContext*, std::function<void(grpc::Status)>)>;
std::vector<grpc::Status> CallAll(size_t n, int deadline_s, const StartCall& start) {
  std::vector<grpc::Status> results(n);
  std::deque<grpc::ClientContext> contexts(n);
  std::mutex mu;
  std::condition_variable cv;
  size_t pending = n;
  for (size_t i = 0; i < n; ++i) {
    contexts[i].set_deadline(Deadline(deadline_s));
    start(i, &contexts[i], [&, i](grpc::Status s) {
      std::lock_guard<std::mutex> lock(mu);
      results[i] = std::move(s);
      if (--pending == 0) cv.notify_all();
    });
  }
  std::unique_lock<std::mutex> lock(mu);
  cv.wait(lock, [&] { return pending == 0; });
  return results;
}

bool IsWorkerFailure(const grpc::Status& s) {
  return s.error_code() == grpc::StatusCode::UNAVAILABLE ||
         s.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED ||
         s.error_code() == grpc::StatusCode::CANCELLED;
}

bool SupportedOutput(const std::string& path) {
  auto dot = path.rfind('.');
  if (dot == std::string::npos) return false;
  std::string ext = path.substr(dot + 1);
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  return ext == "png" || ext == "tif" || ext == "tiff" || ext == "exr" || ext == "jpg" ||
         ext == "jpeg";
}

}  // namespace

struct RootService::WorkerEntry {
  std::string id, address;
  int threads = 1;
  uint64_t order = 0;
  std::unique_ptr<v1::Worker::Stub> stub;
};

struct RootService::JobRecord {
  std::string id;
  v1::Job job;
  double submitted_unix = 0;
  int frames_total = 0;
  std::atomic<bool> cancel{false};
  std::mutex mu;
  std::condition_variable cv;
  std::vector<v1::JobEvent> events;  // guarded by mu
  v1::JobState state = v1::QUEUED;   // guarded by mu
  int frames_done = 0;               // guarded by mu
  std::string error;                 // guarded by mu
  bool finished = false;             // guarded by mu
};

struct RootService::LoadedDataset {
  std::string key;  // content: file identity + classification
  std::string mode;
  v1::Dataset spec;
  Scene scene;
  double load_ms = 0;
  // Balancing state, for the ring members `members` (Layout::Members).
  std::string members;
  // Cuts the next frame starts from: those of the last frame, or the re-cut
  // from its costs in "previous-frame" mode.
  std::vector<std::vector<int>> next_cuts;
  // "test-rays" cuts by view (ViewKey), reused without a new prerender.
  std::map<std::string, std::vector<std::vector<int>>> view_cuts;
};

struct RootService::Layout {
  struct Ring {
    std::vector<std::shared_ptr<WorkerEntry>> workers;
    std::vector<int> cuts;  // workers.size() + 1 bounds along Y
  };
  std::vector<Ring> rings;
  double load_ms = 0;    // slab transfers done for this layout
  int planes_moved = 0;  // planes fetched between workers for it
  std::string SlabKey(const std::string& data_key, const Ring& ring, size_t i) const {
    return absl::StrCat(data_key, "@", ring.cuts[i], "-", ring.cuts[i + 1]);
  }
  // The workers' ids, ring by ring.
  std::string Members() const;
  std::vector<std::vector<int>> Cuts() const;
  // Takes `cuts` (one list per ring) when they fit the rings; else false.
  bool SetCuts(const std::vector<std::vector<int>>& cuts, int planes);
};

RootService::RootService(RootOptions options) : options_(std::move(options)) {
  // Frame ids unique across root restarts, so a worker never mistakes a
  // stale frame for a new one.
  next_frame_id_ =
      static_cast<uint64_t>(std::chrono::system_clock::now().time_since_epoch().count() / 1000)
      << 8;
  runner_ = std::thread([this] { RunnerLoop(); });
}

RootService::~RootService() { Stop(); }

void RootService::Stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_) return;
    stopping_ = true;
    for (auto& j : queue_) j->cancel = true;
    for (auto& j : jobs_) j->cancel = true;
    cv_.notify_all();
  }
  if (runner_.joinable()) runner_.join();
}

int RootService::WorkerCount() {
  std::lock_guard<std::mutex> lock(mu_);
  return static_cast<int>(workers_.size());
}

absl::Status RootService::ValidateJob(const v1::Job& job) const {
  if (job.datasets_size() == 0) return absl::InvalidArgumentError("job: no datasets");
  if (job.balance_grid() < 0 || job.balance_grid() > 256) {
    return absl::InvalidArgumentError("job: balance_grid must be in [0, 256]");
  }
  auto balance_mode = [](const std::string& where, const std::string& mode) {
    if (mode.empty() || mode == "off" || mode == "test-rays" || mode == "previous-frame") {
      return absl::OkStatus();
    }
    return absl::InvalidArgumentError(absl::StrCat(
        where, ": balance '", mode, "' is not 'off', 'test-rays' or 'previous-frame'"));
  };
  if (auto s = balance_mode("job", job.balance()); !s.ok()) return s;
  if (auto r = ParseBalanceRule(job.balance_rule()); !r.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("job: ", r.status().message()));
  }
  int views = 0;
  std::error_code ec;
  const fs::path root = fs::weakly_canonical(options_.data_dir, ec);
  for (int d = 0; d < job.datasets_size(); ++d) {
    const v1::Dataset& ds = job.datasets(d);
    const std::string where = absl::StrCat("datasets[", d, "]");
    if (ds.volume().empty()) return absl::InvalidArgumentError(where + ": no volume given");
    fs::path rel(ds.volume());
    if (rel.is_absolute()) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": volume '", ds.volume(),
                                                     "' must be relative to the data directory"));
    }
    fs::path full = fs::weakly_canonical(root / rel, ec);
    auto mismatch = std::mismatch(root.begin(), root.end(), full.begin(), full.end());
    if (ec || mismatch.first != root.end()) {
      return absl::PermissionDeniedError(
          absl::StrCat(where, ": volume '", ds.volume(), "' lies outside the data directory"));
    }
    if (!fs::is_regular_file(full, ec)) {
      return absl::NotFoundError(
          absl::StrCat(where, ": volume '", ds.volume(), "' not found in the data directory"));
    }
    if (!ds.materials_file().empty() || !ds.transfer_file().empty()) {
      return absl::InvalidArgumentError(
          where + ": materials_file and transfer_file are read by the client; send them inline");
    }
    if (ds.has_materials()) {
      if (auto c = ToClassification(ds.materials()); !c.ok()) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": ", c.status().message()));
      }
    } else if (ds.has_transfer()) {
      if (auto t = ToTransferFunction(ds.transfer()); !t.ok()) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": ", t.status().message()));
      }
    } else {
      return absl::InvalidArgumentError(where + ": needs materials or a transfer function");
    }
    if (ds.has_raw()) {
      if (ds.raw().dims_size() != 3) {
        return absl::InvalidArgumentError(where + ": raw.dims needs 3 sizes");
      }
      if (auto t = ParseScalarType(ds.raw().type()); !t.ok()) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": raw: ", t.status().message()));
      }
    }
    if (ds.views_size() == 0) return absl::InvalidArgumentError(where + ": no views");
    for (int v = 0; v < ds.views_size(); ++v) {
      const v1::View& view = ds.views(v);
      const std::string vw = absl::StrCat(where, ".views[", v, "]");
      if (auto c = ToCameraSpec(view); !c.ok()) {
        return absl::InvalidArgumentError(absl::StrCat(vw, ": ", c.status().message()));
      }
      if (auto s = balance_mode(vw, view.balance()); !s.ok()) return s;
      if (!view.output().empty() && !SupportedOutput(view.output())) {
        return absl::InvalidArgumentError(
            absl::StrCat(vw, ": output '", view.output(), "' is not .png, .jpg, .tif or .exr"));
      }
      ++views;
    }
  }
  if (views > 10000) return absl::InvalidArgumentError("job: more than 10000 views");
  return absl::OkStatus();
}

grpc::Status RootService::Submit(grpc::ServerContext*, const v1::Job* job, v1::SubmitReply* reply) {
  if (auto s = ValidateJob(*job); !s.ok()) return ToGrpc(s);
  auto record = std::make_shared<JobRecord>();
  record->job = *job;
  record->submitted_unix =
      std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  for (const auto& d : job->datasets()) record->frames_total += d.views_size();
  std::lock_guard<std::mutex> lock(mu_);
  if (stopping_) return grpc::Status(grpc::StatusCode::UNAVAILABLE, "root is shutting down");
  record->id = absl::StrCat("job-", next_job_++);
  reply->set_job_id(record->id);
  reply->set_frames(record->frames_total);
  reply->set_queue_position(static_cast<int>(queue_.size()));
  queue_.push_back(record);
  jobs_.push_back(record);
  // Forget the oldest finished jobs beyond the history limit.
  while (static_cast<int>(jobs_.size()) > options_.max_jobs_kept) {
    auto it = std::find_if(jobs_.begin(), jobs_.end(), [](const auto& j) {
      std::lock_guard<std::mutex> l(j->mu);
      return j->finished;
    });
    if (it == jobs_.end()) break;
    jobs_.erase(it);
  }
  spdlog::info("{} queued: '{}', {} frames, {} ahead", record->id, job->name(),
               record->frames_total, queue_.size() - 1);
  cv_.notify_all();
  return grpc::Status::OK;
}

void RootService::Publish(JobRecord& job, v1::JobEvent event) {
  std::lock_guard<std::mutex> lock(job.mu);
  event.set_job_id(job.id);
  event.set_state(job.state);
  event.set_frames_total(job.frames_total);
  event.set_frames_done(job.frames_done);
  if (!job.error.empty()) event.set_error(job.error);
  job.events.push_back(std::move(event));
  job.cv.notify_all();
}

grpc::Status RootService::Watch(grpc::ServerContext* ctx, const v1::JobRef* req,
                                grpc::ServerWriter<v1::JobEvent>* writer) {
  std::shared_ptr<JobRecord> job;
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto& j : jobs_) {
      if (j->id == req->job_id()) job = j;
    }
  }
  if (!job) {
    return grpc::Status(grpc::StatusCode::NOT_FOUND, absl::StrCat("no job '", req->job_id(), "'"));
  }
  size_t next = 0;
  while (true) {
    std::vector<v1::JobEvent> batch;
    bool finished;
    {
      std::unique_lock<std::mutex> lock(job->mu);
      job->cv.wait_for(lock, std::chrono::milliseconds(500),
                       [&] { return job->events.size() > next || job->finished; });
      batch.assign(job->events.begin() + next, job->events.end());
      next = job->events.size();
      finished = job->finished;
    }
    for (const auto& e : batch) {
      if (!writer->Write(e)) return grpc::Status(grpc::StatusCode::CANCELLED, "watcher left");
    }
    if (finished && batch.empty()) return grpc::Status::OK;
    if (ctx->IsCancelled()) return grpc::Status(grpc::StatusCode::CANCELLED, "watcher left");
  }
}

grpc::Status RootService::Status(grpc::ServerContext*, const v1::StatusRequest*,
                                 v1::StatusReply* reply) {
  std::lock_guard<std::mutex> lock(mu_);
  for (auto& j : jobs_) {
    std::lock_guard<std::mutex> l(j->mu);
    v1::JobSummary* s = reply->add_jobs();
    s->set_job_id(j->id);
    s->set_name(j->job.name());
    s->set_state(j->state);
    s->set_frames_total(j->frames_total);
    s->set_frames_done(j->frames_done);
    s->set_error(j->error);
    s->set_submitted_unix(j->submitted_unix);
  }
  std::vector<std::shared_ptr<WorkerEntry>> ws;
  for (auto& [id, w] : workers_) ws.push_back(w);
  std::sort(ws.begin(), ws.end(), [](auto& a, auto& b) { return a->order < b->order; });
  for (auto& w : ws) {
    v1::WorkerInfo* info = reply->add_workers();
    info->set_id(w->id);
    info->set_address(w->address);
    info->set_threads(w->threads);
    auto held = loaded_.find(w->id);
    info->set_ring(held == loaded_.end() ? -1 : held->second.ring);
    if (held != loaded_.end()) {
      info->set_slab_begin(held->second.y0);
      info->set_slab_end(held->second.y1);
    }
  }
  reply->set_rings(options_.rings);
  return grpc::Status::OK;
}

grpc::Status RootService::Cancel(grpc::ServerContext*, const v1::JobRef* req,
                                 v1::CancelReply* reply) {
  std::lock_guard<std::mutex> lock(mu_);
  for (auto& j : jobs_) {
    if (j->id != req->job_id()) continue;
    std::lock_guard<std::mutex> l(j->mu);
    if (j->finished) {
      reply->set_cancelled(false);
      return grpc::Status::OK;
    }
    j->cancel = true;
    reply->set_cancelled(true);
    cv_.notify_all();
    spdlog::info("{}: cancel requested", j->id);
    return grpc::Status::OK;
  }
  return grpc::Status(grpc::StatusCode::NOT_FOUND, absl::StrCat("no job '", req->job_id(), "'"));
}

grpc::Status RootService::Register(grpc::ServerContext*, const v1::RegisterRequest* req,
                                   v1::RegisterReply*) {
  if (req->id().empty() || req->address().empty()) {
    return Invalid("Register: a worker needs an id and an address");
  }
  if (req->threads() < 0 || req->threads() > 4096) return Invalid("Register: absurd thread count");
  std::lock_guard<std::mutex> lock(mu_);
  if (workers_.count(req->id())) {
    return grpc::Status(grpc::StatusCode::ALREADY_EXISTS,
                        absl::StrCat("worker ", req->id(), " is already registered (at ",
                                     workers_[req->id()]->address, ")"));
  }
  // A worker restarted at the same address replaces its old entry.
  for (auto it = workers_.begin(); it != workers_.end();) {
    if (it->second->address == req->address()) {
      spdlog::info("worker {} at {} replaces {}", req->id(), req->address(), it->first);
      loaded_.erase(it->first);
      it = workers_.erase(it);
    } else {
      ++it;
    }
  }
  auto w = std::make_shared<WorkerEntry>();
  w->id = req->id();
  w->address = req->address();
  w->threads = std::max(1, req->threads());
  w->order = next_order_++;
  w->stub = v1::Worker::NewStub(MakeChannel(w->address));
  workers_[w->id] = w;
  spdlog::info("worker {} registered at {} ({} threads); {} workers", w->id, w->address, w->threads,
               workers_.size());
  cv_.notify_all();
  return grpc::Status::OK;
}

grpc::Status RootService::Unregister(grpc::ServerContext*, const v1::RegisterRequest* req,
                                     v1::RegisterReply*) {
  std::lock_guard<std::mutex> lock(mu_);
  loaded_.erase(req->id());
  if (workers_.erase(req->id()) == 0) {
    return grpc::Status(grpc::StatusCode::NOT_FOUND,
                        absl::StrCat("worker ", req->id(), " is not registered"));
  }
  spdlog::info("worker {} unregistered; {} workers", req->id(), workers_.size());
  return grpc::Status::OK;
}

void RootService::DropWorker(const std::string& id, const std::string& why) {
  std::lock_guard<std::mutex> lock(mu_);
  loaded_.erase(id);
  if (workers_.erase(id)) {
    spdlog::warn("dropping worker {}: {}; {} workers left", id, why, workers_.size());
  }
}

void RootService::RunnerLoop() {
  while (true) {
    std::shared_ptr<JobRecord> job;
    {
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
      if (stopping_) break;
      job = queue_.front();
      queue_.pop_front();
    }
    {
      std::lock_guard<std::mutex> l(job->mu);
      job->state = job->cancel ? v1::CANCELLED : v1::RUNNING;
    }
    absl::Status status = absl::CancelledError("cancelled before it started");
    if (!job->cancel) {
      Publish(*job, v1::JobEvent());
      spdlog::info("{} running", job->id);
      status = RunJob(*job);
    }
    {
      std::lock_guard<std::mutex> l(job->mu);
      job->state = job->cancel ? v1::CANCELLED : (status.ok() ? v1::DONE : v1::FAILED);
      if (!status.ok()) job->error = std::string(status.message());
    }
    Publish(*job, v1::JobEvent());
    {
      std::lock_guard<std::mutex> l(job->mu);
      job->finished = true;
      job->cv.notify_all();
    }
    if (status.ok()) {
      spdlog::info("{} done", job->id);
    } else {
      spdlog::warn("{} ended: {}", job->id, std::string(status.message()));
    }
  }
}

absl::Status RootService::RunJob(JobRecord& job) {
  for (int d = 0; d < job.job.datasets_size(); ++d) {
    auto data = LoadDataset(job.job.datasets(d));
    if (!data.ok()) return data.status();
    for (int v = 0; v < job.job.datasets(d).views_size(); ++v) {
      if (job.cancel) return absl::CancelledError("cancelled");
      if (auto s = RunView(job, d, v, **data); !s.ok()) return s;
      {
        std::lock_guard<std::mutex> l(job.mu);
        ++job.frames_done;
      }
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<std::shared_ptr<RootService::LoadedDataset>> RootService::LoadDataset(
    const v1::Dataset& ds) {
  const fs::path path = fs::path(options_.data_dir) / ds.volume();
  struct stat st {};
  if (stat(path.c_str(), &st) != 0) {
    return absl::NotFoundError(absl::StrCat(ds.volume(), ": cannot open"));
  }
  v1::Dataset identity = ds;
  identity.clear_views();
  std::string key_text = absl::StrCat(ds.volume(), "|", st.st_size, "|", st.st_mtim.tv_sec, ".",
                                      st.st_mtim.tv_nsec, "|", identity.SerializeAsString());
  const std::string key = absl::StrFormat("%016x", std::hash<std::string>{}(key_text)) + "-" +
                          absl::StrFormat("%08x", static_cast<uint32_t>(key_text.size()));
  if (cache_ && cache_->key == key) return cache_;
  const auto t0 = Clock::now();
  ReadOptions ro;
  ro.max_bytes = options_.max_volume_bytes;
  absl::StatusOr<Volume> volume;
  if (ds.has_raw()) {
    RawSpec spec;
    for (int a = 0; a < 3; ++a) spec.dims[a] = ds.raw().dims(a);
    spec.type = *ParseScalarType(ds.raw().type());
    spec.byte_order = ds.raw().big_endian() ? ByteOrder::kBig : ByteOrder::kLittle;
    for (int a = 0; a < 3 && a < ds.raw().spacing_size(); ++a)
      spec.spacing[a] = ds.raw().spacing(a);
    spec.header_bytes = ds.raw().header_bytes();
    volume = ReadRaw(path.string(), spec, ro);
  } else {
    volume = ReadVolume(path.string(), ro);
  }
  if (!volume.ok()) return volume.status();
  auto data = std::make_shared<LoadedDataset>();
  data->key = key;
  data->spec = identity;
  absl::StatusOr<Scene> scene;
  if (ds.has_materials()) {
    data->mode = "surfaces";
    scene = Scene::ForSurfaces(*volume, *ToClassification(ds.materials()));
  } else {
    data->mode = "dvr";
    scene = Scene::ForDvr(*volume, *ToTransferFunction(ds.transfer()));
  }
  if (!scene.ok())
    return absl::Status(scene.status().code(),
                        absl::StrCat(ds.volume(), ": ", scene.status().message()));
  data->scene = *std::move(scene);
  data->load_ms = MsSince(t0);
  spdlog::info("dataset {} ({}): {}x{}x{}, {} sticks, prepared in {:.0f} ms", ds.volume(),
               data->mode, volume->dims[0], volume->dims[1], volume->dims[2],
               data->scene.sticks().StickCount(), data->load_ms);
  cache_ = data;
  return data;
}

absl::StatusOr<RootService::Layout> RootService::FormRings(const LoadedDataset& data,
                                                           JobRecord& job) {
  std::vector<std::shared_ptr<WorkerEntry>> workers;
  {
    std::unique_lock<std::mutex> lock(mu_);
    const auto until = Clock::now() + std::chrono::milliseconds(
                                          static_cast<int64_t>(options_.worker_wait_s * 1000));
    while (workers_.empty() && !stopping_ && !job.cancel) {
      if (cv_.wait_until(lock, until) == std::cv_status::timeout && workers_.empty()) {
        return absl::UnavailableError(
            absl::StrCat("no worker registered within ", options_.worker_wait_s, " s"));
      }
    }
    if (stopping_ || job.cancel) return absl::CancelledError("cancelled");
    for (auto& [id, w] : workers_) workers.push_back(w);
  }
  std::sort(workers.begin(), workers.end(), [](auto& a, auto& b) { return a->order < b->order; });
  const int ny = data.scene.dims()[1];
  const int n = static_cast<int>(workers.size());
  const int rings = std::max(1, std::min(options_.rings, n));
  Layout layout;
  for (int r = 0; r < rings; ++r) {
    Layout::Ring ring;
    const int begin = r * n / rings, end = (r + 1) * n / rings;
    // A slab holds at least one plane: extra workers stay idle.
    const int k = std::min(end - begin, ny);
    for (int i = 0; i < k; ++i) ring.workers.push_back(workers[begin + i]);
    ring.cuts = UniformCuts(ny, k);
    layout.rings.push_back(std::move(ring));
  }
  return layout;
}

std::string RootService::Layout::Members() const {
  std::string m;
  for (const Ring& ring : rings) {
    for (const auto& w : ring.workers) absl::StrAppend(&m, w->id, ",");
    m += ";";
  }
  return m;
}

std::vector<std::vector<int>> RootService::Layout::Cuts() const {
  std::vector<std::vector<int>> cuts;
  for (const Ring& ring : rings) cuts.push_back(ring.cuts);
  return cuts;
}

bool RootService::Layout::SetCuts(const std::vector<std::vector<int>>& cuts, int planes) {
  if (cuts.size() != rings.size()) return false;
  for (size_t r = 0; r < rings.size(); ++r) {
    if (!ValidCuts(cuts[r], planes, static_cast<int>(rings[r].workers.size()))) return false;
  }
  for (size_t r = 0; r < rings.size(); ++r) rings[r].cuts = cuts[r];
  return true;
}

absl::Status RootService::LoadSlab(const LoadedDataset& data, WorkerEntry& worker,
                                   const std::string& key, int y0, int y1) {
  const Scene& scene = data.scene;
  const auto& dims = scene.dims();
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(300));
  v1::LoadReply reply;
  auto writer = worker.stub->LoadSlab(&ctx, &reply);
  v1::SlabChunk chunk;
  v1::SlabHeader* h = chunk.mutable_header();
  h->set_dataset_key(key);
  h->set_mode(data.mode);
  for (int a = 0; a < 3; ++a) h->add_dims(dims[a]);
  for (int a = 0; a < 3; ++a) h->add_spacing(scene.spacing()[a]);
  h->add_value_range(scene.value_range()[0]);
  h->add_value_range(scene.value_range()[1]);
  if (data.spec.has_materials()) *h->mutable_materials() = data.spec.materials();
  if (data.spec.has_transfer()) *h->mutable_transfer() = data.spec.transfer();
  h->set_y_begin(y0);
  h->set_y_end(y1);
  const auto& bricks = scene.bricks().bytes();
  h->set_brick_map(std::string(bricks.begin(), bricks.end()));
  const int sb = scene.ScalarBegin(y0), se = scene.ScalarEnd(y1);
  h->set_scalar_count(static_cast<uint64_t>(dims[0]) * (se - sb) * dims[2]);
  constexpr size_t kChunkBytes = 1 << 20;
  size_t pending = 0;
  auto send = [&]() -> bool {
    bool ok = writer->Write(chunk);
    chunk.Clear();
    pending = 0;
    return ok;
  };
  bool ok = true;
  for (std::string& block : scene.sticks().EncodeRows(y0, y1)) {
    if (!ok) break;
    pending += block.size();
    chunk.add_blocks(std::move(block));
    if (pending >= kChunkBytes) ok = send();
  }
  const size_t row = static_cast<size_t>(dims[0]) * (se - sb);
  for (int z = 0; ok && z < dims[2]; ++z) {
    const float* plane = scene.scalars().data() + (static_cast<size_t>(z) * dims[1] + sb) * dims[0];
    AppendFloats(plane, row, chunk.mutable_scalars());
    pending += row * 4;
    if (pending >= kChunkBytes) ok = send();
  }
  if (ok && (pending > 0 || chunk.has_header())) ok = send();
  writer->WritesDone();
  grpc::Status s = writer->Finish();
  if (!s.ok()) {
    if (IsWorkerFailure(s)) DropWorker(worker.id, s.error_message());
    return absl::Status(FromGrpc(s).code(), absl::StrCat("loading slab [", y0, ", ", y1, ") on ",
                                                         worker.address, ": ", s.error_message()));
  }
  return absl::OkStatus();
}

absl::Status RootService::Distribute(const LoadedDataset& data, Layout& layout) {
  // What must change: each worker of the layout holds its slab under the
  // slab's key. A worker that holds another slab of the same dataset
  // re-slabs, taking the planes it lacks from the workers that hold them
  // (its neighbours, when cuts move a little); any other is sent its slab.
  struct Move {
    std::shared_ptr<WorkerEntry> worker;
    int ring, y0, y1;
    std::string key;
    HeldSlab old;  // empty key: holds nothing of this dataset
    bool ok = false;
    bool reslabbed = false;
  };
  std::vector<Move> moves;
  std::map<std::string, HeldSlab> held;  // by worker id
  {
    std::lock_guard<std::mutex> lock(mu_);
    held = loaded_;
  }
  for (size_t r = 0; r < layout.rings.size(); ++r) {
    const auto& ring = layout.rings[r];
    for (size_t i = 0; i < ring.workers.size(); ++i) {
      std::string key = layout.SlabKey(data.key, ring, i);
      auto it = held.find(ring.workers[i]->id);
      HeldSlab old = it == held.end() ? HeldSlab{} : it->second;
      if (old.key == key) continue;
      moves.push_back(
          {ring.workers[i], static_cast<int>(r), ring.cuts[i], ring.cuts[i + 1], key, old});
    }
  }
  if (moves.empty()) return absl::OkStatus();
  // Sources of planes: slabs of this dataset held now by workers of the
  // layout (others may be gone), the mover's own ring first (its
  // neighbours hold the planes a moved cut hands over).
  std::map<std::string, std::string> address_of;  // by worker id
  for (const auto& ring : layout.rings)
    for (const auto& w : ring.workers) address_of[w->id] = w->address;
  auto add_sources = [&](const Move& m, v1::ReslabRequest* req) {
    for (bool same_ring : {true, false}) {
      for (const auto& [id, h] : held) {
        auto address = address_of.find(id);
        if (id == m.worker->id || h.data_key != data.key || address == address_of.end() ||
            (h.ring == m.ring) != same_ring) {
          continue;
        }
        v1::PlaneSource* src = req->add_sources();
        src->set_address(address->second);
        src->set_dataset_key(h.key);
        src->set_y_begin(h.y0);
        src->set_y_end(h.y1);
      }
    }
  };
  const auto t0 = Clock::now();
  absl::Status status = ForEachParallel(moves.size(), [&](size_t mi) -> absl::Status {
    Move& m = moves[mi];
    if (!m.old.key.empty() && m.old.data_key == data.key) {
      grpc::ClientContext ctx;
      ctx.set_deadline(Deadline(300));
      v1::ReslabRequest req;
      req.set_old_key(m.old.key);
      req.set_new_key(m.key);
      req.set_y_begin(m.y0);
      req.set_y_end(m.y1);
      add_sources(m, &req);
      v1::LoadReply reply;
      grpc::Status s = m.worker->stub->Reslab(&ctx, req, &reply);
      if (s.ok()) {
        m.ok = m.reslabbed = true;
        return absl::OkStatus();
      }
      // A source that failed comes back as ABORTED; only the mover's own
      // failure drops it.
      if (IsWorkerFailure(s)) {
        DropWorker(m.worker->id, s.error_message());
        return absl::UnavailableError(
            absl::StrCat("re-slabbing on ", m.worker->address, ": ", s.error_message()));
      }
      // A source could not help: the root sends the slab itself.
      spdlog::warn("re-slabbing [{}, {}) on {} failed ({}); sending the slab instead", m.y0, m.y1,
                   m.worker->address, s.error_message());
    }
    absl::Status s = LoadSlab(data, *m.worker, m.key, m.y0, m.y1);
    m.ok = s.ok();
    return s;
  });
  // Old slabs go only now: until every move is done they are sources.
  std::vector<std::pair<std::shared_ptr<WorkerEntry>, std::string>> evictions;
  int reslabbed = 0, planes = 0;
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (const Move& m : moves) {
      if (!m.old.key.empty()) evictions.push_back({m.worker, m.old.key});
      if (m.ok) {
        loaded_[m.worker->id] = HeldSlab{m.key, data.key, m.y0, m.y1, m.ring};
      } else {
        loaded_.erase(m.worker->id);
      }
      if (m.reslabbed) {
        ++reslabbed;
        planes += std::max(0, m.old.y0 - m.y0) + std::max(0, m.y1 - m.old.y1);
      }
    }
  }
  (void)ForEachParallel(evictions.size(), [&](size_t i) -> absl::Status {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    v1::DatasetRef ref;
    ref.set_dataset_key(evictions[i].second);
    v1::FrameAck ack;
    evictions[i].first->stub->Evict(&ctx, ref, &ack);
    return absl::OkStatus();
  });
  if (!status.ok()) return status;
  layout.load_ms = MsSince(t0);
  layout.planes_moved = planes;
  spdlog::info("slabs: {} sent by the root, {} re-cut with {} planes from neighbours, in {:.0f} ms",
               moves.size() - reslabbed, reslabbed, planes, layout.load_ms);
  return absl::OkStatus();
}

namespace {

// The view as it determines the image's rays: what balancing cuts depend on.
std::string ViewKey(const v1::View& view) {
  v1::View k = view;
  k.clear_output();
  k.clear_balance();
  return k.SerializeAsString();
}

std::string FormatCuts(const std::vector<std::vector<int>>& cuts) {
  std::string out;
  for (size_t r = 0; r < cuts.size(); ++r) {
    absl::StrAppend(&out, r ? " | " : "", "[", absl::StrJoin(cuts[r], " "), "]");
  }
  return out;
}

// Costs of the workers of each ring (their tracers' CPU time), in ring order.
std::vector<std::vector<double>> RingCosts(const RootService::FrameResult& frame,
                                           const std::vector<size_t>& ring_sizes) {
  std::vector<std::vector<double>> costs(ring_sizes.size());
  size_t k = 0;
  for (size_t r = 0; r < ring_sizes.size(); ++r) {
    for (size_t i = 0; i < ring_sizes[r]; ++i, ++k) {
      costs[r].push_back(k < frame.workers.size() ? frame.workers[k].cpu_ms() : 0.0);
    }
  }
  return costs;
}

}  // namespace

absl::Status RootService::Prerender(JobRecord& job, int d, int v, const v1::View& view,
                                    const LoadedDataset& data, Layout& layout, BalanceRule rule,
                                    BalanceReport* report) {
  if (auto s = Distribute(data, layout); !s.ok()) return s;
  // A grid of test rays through the same camera: a small image of the view,
  // never more rays than the view itself has.
  const int grid = std::min(
      view.width(), job.job.balance_grid() > 0 ? job.job.balance_grid() : kDefaultBalanceGrid);
  v1::View test = view;
  test.clear_output();
  test.set_width(grid);
  test.set_height(std::max(
      1, static_cast<int>(std::lround(static_cast<double>(grid) * view.height() / view.width()))));
  auto probe = RunFrame(job, d, v, test, data, layout, /*test=*/true);
  if (!probe.ok()) return probe.status();
  std::vector<size_t> sizes;
  for (const auto& ring : layout.rings) sizes.push_back(ring.workers.size());
  const auto costs = RingCosts(*probe, sizes);
  report->cuts_after.clear();
  for (size_t r = 0; r < sizes.size(); ++r) {
    report->cuts_after.push_back(BalancedCuts(layout.rings[r].cuts, costs[r], rule));
  }
  for (const auto& w : probe->workers) report->test_ray_ms[w.id()] = w.cpu_ms();
  std::vector<std::string> times;
  for (const auto& c : costs) {
    times.push_back(absl::StrJoin(
        c, " ", [](std::string* o, double x) { absl::StrAppend(o, absl::StrFormat("%.2f", x)); }));
  }
  spdlog::info("{} balance ({}x{} test rays, rule {}): test-ray CPU ms [{}]; cuts {} -> {}", job.id,
               test.width(), test.height(), rule == BalanceRule::kPaper ? "paper" : "cost",
               absl::StrJoin(times, " | "), FormatCuts(report->cuts_before),
               FormatCuts(report->cuts_after));
  return absl::OkStatus();
}

absl::Status RootService::RunView(JobRecord& job, int d, int v, LoadedDataset& data) {
  const v1::View& view = job.job.datasets(d).views(v);
  const std::string mode = view.balance().empty() ? job.job.balance() : view.balance();
  const BalanceRule rule = *ParseBalanceRule(job.job.balance_rule());
  const int planes = data.scene.dims()[1];
  if (absl::Status s =
          CheckRenderSettings(ToRenderSettings(view), data.scene.mode(), data.scene.dims(),
                              data.scene.spacing(), int64_t{view.width()} * view.height());
      !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("dataset ", d, " view ", v, ": ", s.message()));
  }
  // A worker that dies is dropped and the frame runs again on the others.
  constexpr int kAttempts = 3;
  absl::Status status;
  for (int attempt = 0; attempt < kAttempts; ++attempt) {
    auto layout = FormRings(data, job);
    if (!layout.ok()) {
      status = layout.status();
      if (status.code() != absl::StatusCode::kUnavailable) return status;
      continue;
    }
    // Cuts computed for other ring members mean nothing to these.
    const std::string members = layout->Members();
    if (members != data.members) {
      data.members = members;
      data.view_cuts.clear();
      data.next_cuts.clear();
    }
    std::vector<size_t> sizes;
    for (const auto& ring : layout->rings) sizes.push_back(ring.workers.size());
    BalanceReport report;
    report.mode = mode.empty() ? "off" : mode;
    std::optional<Clock::time_point> balance_start;  // when a prerender began
    if (mode == "test-rays") {
      auto cached = data.view_cuts.find(ViewKey(view));
      if (cached != data.view_cuts.end()) {
        layout->SetCuts(cached->second, planes);
        report.cuts_before = report.cuts_after = cached->second;
      } else {
        // Start from the cuts the workers hold when they are this ring's.
        if (!data.next_cuts.empty()) layout->SetCuts(data.next_cuts, planes);
        report.cuts_before = layout->Cuts();
        balance_start = Clock::now();
        status = Prerender(job, d, v, view, data, *layout, rule, &report);
        if (!status.ok()) {
          if (status.code() == absl::StatusCode::kUnavailable && !job.cancel) continue;
          return status;
        }
        layout->SetCuts(report.cuts_after, planes);
        data.view_cuts[ViewKey(view)] = report.cuts_after;
      }
    } else if (mode == "previous-frame") {
      if (!data.next_cuts.empty()) layout->SetCuts(data.next_cuts, planes);
      report.cuts_before = report.cuts_after = layout->Cuts();
    }
    status = Distribute(data, *layout);
    if (!status.ok()) {
      if (status.code() == absl::StatusCode::kUnavailable && !job.cancel) continue;
      return status;
    }
    // The prerender and the plane moves it caused.
    if (balance_start) report.balance_ms = MsSince(*balance_start);
    auto frame = RunFrame(job, d, v, view, data, *layout, /*test=*/false);
    if (!frame.ok()) {
      status = frame.status();
      if (status.code() != absl::StatusCode::kUnavailable || job.cancel) return status;
      spdlog::warn("{}: frame failed ({}); retrying", job.id, std::string(status.message()));
      continue;
    }
    if (mode == "previous-frame") {
      // This frame's costs cut the slabs of the next one.
      const auto costs = RingCosts(*frame, sizes);
      data.next_cuts.clear();
      for (size_t r = 0; r < sizes.size(); ++r) {
        data.next_cuts.push_back(BalancedCuts(layout->rings[r].cuts, costs[r], rule));
      }
      report.cuts_after = data.next_cuts;
    } else {
      data.next_cuts = layout->Cuts();
    }
    PublishFrame(job, d, v, view, *layout, *frame, report);
    return absl::OkStatus();
  }
  return status;
}

absl::StatusOr<RootService::FrameResult> RootService::RunFrame(JobRecord& job, int d, int v,
                                                               const v1::View& view,
                                                               const LoadedDataset& data,
                                                               const Layout& layout, bool test) {
  const uint64_t frame_id = next_frame_id_++;
  const auto t0 = Clock::now();
  auto display = v1::Display::NewStub(SharedChannel(options_.display, "control"));
  struct Member {
    std::shared_ptr<WorkerEntry> worker;
    v1::FrameSpec spec;
    int ring;
  };
  std::vector<Member> members;
  const int rings = static_cast<int>(layout.rings.size());
  for (int r = 0; r < rings; ++r) {
    const auto& ring = layout.rings[r];
    for (size_t i = 0; i < ring.workers.size(); ++i) {
      v1::FrameSpec spec;
      spec.set_frame_id(frame_id);
      spec.set_dataset_key(layout.SlabKey(data.key, ring, i));
      *spec.mutable_view() = view;
      for (int c : ring.cuts) spec.add_cuts(c);
      spec.set_index(static_cast<int>(i));
      if (i > 0) spec.set_left(ring.workers[i - 1]->address);
      if (i + 1 < ring.workers.size()) spec.set_right(ring.workers[i + 1]->address);
      spec.set_display(options_.display);
      // Rows are interleaved across rings so each ring gets an even share of
      // every part of the image.
      spec.set_row_begin(std::min(r, view.height()));
      spec.set_row_end(view.height());
      spec.set_row_step(rings);
      members.push_back({ring.workers[i], std::move(spec), r});
    }
  }
  // The first failure among the members' replies, naming the worker; a
  // worker that cannot be reached is dropped.
  auto check = [&](const char* what, const std::vector<grpc::Status>& results) {
    absl::Status first;
    for (size_t i = 0; i < results.size(); ++i) {
      const grpc::Status& s = results[i];
      if (s.ok()) continue;
      absl::Status why(FromGrpc(s).code(), absl::StrCat(what, " on ", members[i].worker->address,
                                                        ": ", s.error_message()));
      if (IsWorkerFailure(s)) {
        DropWorker(members[i].worker->id, s.error_message());
        why = absl::UnavailableError(why.message());
      }
      if (first.ok()) first = why;
    }
    return first;
  };
  v1::FrameRef ref;
  ref.set_frame_id(frame_id);
  std::vector<v1::FrameAck> acks(members.size() + 1);
  std::vector<v1::WorkerFrameStats> stats(members.size());
  auto end_all = [&](bool cancel) {
    // Statistics of workers that fail to end are simply missing.
    v1::FrameRef end = ref;
    end.set_cancel(cancel);
    CallAll(members.size(), 30, [&](size_t i, grpc::ClientContext* ctx, auto done) {
      members[i].worker->stub->async()->EndFrame(ctx, &end, &stats[i], std::move(done));
    });
    for (size_t i = 0; i < members.size(); ++i) stats[i].set_ring(members[i].ring);
  };
  auto abort = [&](const absl::Status& why) {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(10));
    v1::FrameAck ack;
    display->AbortFrame(&ctx, ref, &ack);
    end_all(/*cancel=*/true);
    return why;
  };
  // The display learns of the frame while the workers prepare it; both are
  // done before any worker starts, so no deposit comes early.
  v1::DisplayFrame df;
  df.set_frame_id(frame_id);
  df.set_width(view.width());
  df.set_height(view.height());
  std::vector<grpc::Status> prepared =
      CallAll(members.size() + 1, 30, [&](size_t i, grpc::ClientContext* ctx, auto done) {
        if (i == members.size()) {
          display->async()->BeginFrame(ctx, &df, &acks[i], std::move(done));
        } else {
          members[i].worker->stub->async()->PrepareFrame(ctx, &members[i].spec, &acks[i],
                                                         std::move(done));
        }
      });
  const grpc::Status begun = prepared.back();
  prepared.pop_back();
  absl::Status s = check("PrepareFrame", prepared);
  if (!begun.ok()) {
    return abort(absl::Status(FromGrpc(begun).code(), absl::StrCat("display ", options_.display,
                                                                   ": ", begun.error_message())));
  }
  if (!s.ok()) return abort(s);
  s = check("RunFrame",
            CallAll(members.size(), 30, [&](size_t i, grpc::ClientContext* ctx, auto done) {
              members[i].worker->stub->async()->RunFrame(ctx, &ref, &acks[i], std::move(done));
            }));
  if (!s.ok()) return abort(s);

  // Wait for the display, relaying progress, until the image is in.
  Image image;
  image.width = view.width();
  image.height = view.height();
  image.rgb.resize(static_cast<size_t>(image.width) * image.height * 3);
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(options_.frame_timeout_s));
    auto reader = display->AwaitFrame(&ctx, ref);
    v1::FrameProgress p;
    int rows = 0;
    auto last_event = Clock::now() - std::chrono::seconds(1);
    // Every deposit is in once the display says the frame is complete: the
    // workers end the frame (and report) while its image is resolved and
    // its rows arrive here.
    std::thread ender;
    auto join_ender = [&] {
      if (ender.joinable()) ender.join();
    };
    while (reader->Read(&p)) {
      if (job.cancel) ctx.TryCancel();
      if (p.complete() && !ender.joinable()) {
        ender = std::thread([&] { end_all(/*cancel=*/false); });
      }
      if (p.has_image()) {
        if (!ender.joinable()) ender = std::thread([&] { end_all(/*cancel=*/false); });
        const v1::ImageChunk& c = p.image();
        if (c.width() != image.width || c.row_begin() < 0 || c.row_end() > image.height ||
            c.rgb().size() != static_cast<size_t>(c.row_end() - c.row_begin()) * c.width() * 12) {
          ctx.TryCancel();
          break;
        }
        DecodeFloats(c.rgb(),
                     image.rgb.data() + static_cast<size_t>(c.row_begin()) * image.width * 3);
        rows += c.row_end() - c.row_begin();
      } else if (!test && Clock::now() - last_event > std::chrono::milliseconds(200)) {
        last_event = Clock::now();
        v1::JobEvent e;
        e.set_dataset(d);
        e.set_view(v);
        e.set_pixels_done(p.pixels_done());
        e.set_pixels_total(p.pixels_total());
        Publish(job, std::move(e));
      }
    }
    grpc::Status st = reader->Finish();
    const bool ended = ender.joinable();
    join_ender();
    if (job.cancel) return abort(absl::CancelledError("cancelled"));
    if (!st.ok() || rows != image.height) {
      absl::Status why =
          st.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED
              ? absl::DeadlineExceededError(
                    absl::StrCat("frame not complete within ", options_.frame_timeout_s, " s"))
              : absl::UnavailableError(absl::StrCat("display: ", st.error_message()));
      return abort(why);
    }
    if (!ended) end_all(/*cancel=*/false);
  }
  FrameResult result;
  result.frame_ms = MsSince(t0);
  result.frame_id = frame_id;
  result.image = std::move(image);
  for (size_t i = 0; i < stats.size(); ++i) {
    if (stats[i].id().empty()) stats[i].set_id(members[i].worker->id);
    if (stats[i].address().empty()) stats[i].set_address(members[i].worker->address);
  }
  result.workers = std::move(stats);
  return result;
}

void RootService::PublishFrame(JobRecord& job, int d, int v, const v1::View& view,
                               const Layout& layout, const FrameResult& frame,
                               const BalanceReport& balance) {
  const Image& image = frame.image;
  v1::ClusterFrameStats fs;
  fs.set_job_id(job.id);
  fs.set_dataset(d);
  fs.set_view(v);
  fs.set_frame_ms(frame.frame_ms);
  fs.set_width(image.width);
  fs.set_height(image.height);
  fs.set_rings(static_cast<int>(layout.rings.size()));
  fs.set_load_ms(layout.load_ms);
  fs.set_planes_moved(layout.planes_moved);
  fs.set_balance(balance.mode);
  fs.set_balance_ms(balance.balance_ms);
  for (const auto& ring : balance.cuts_before)
    for (int c : ring) fs.add_cuts_before(c);
  for (const auto& ring : balance.cuts_after)
    for (int c : ring) fs.add_cuts_after(c);
  double active_sum = 0, active_max = 0;
  uint64_t rays = 0;
  for (const v1::WorkerFrameStats& stats : frame.workers) {
    v1::WorkerFrameStats* w = fs.add_workers();
    *w = stats;
    if (auto t = balance.test_ray_ms.find(w->id()); t != balance.test_ray_ms.end()) {
      w->set_test_ray_ms(t->second);
    }
    active_sum += w->active_ms();
    active_max = std::max(active_max, w->active_ms());
    rays += w->rays_traced();
    spdlog::info(
        "frame {} ring {} worker {} slab [{}, {}): elapsed {:.1f} ms, active {:.1f} ms, CPU {:.1f} "
        "ms, traced {} ({} primary, {} shadow), sent L {} R {}, received L {} R {} ({:.2f} MB out, "
        "{:.2f} MB in), buffer max {}",
        frame.frame_id, w->ring(), w->address(), w->slab_size() > 0 ? w->slab(0) : -1,
        w->slab_size() > 1 ? w->slab(1) : -1, w->elapsed_ms(), w->active_ms(), w->cpu_ms(),
        w->rays_traced(), w->primary_traced(), w->shadow_traced(), w->sent_left(), w->sent_right(),
        w->received_left(), w->received_right(), w->bytes_sent() / 1e6, w->bytes_received() / 1e6,
        w->buffer_high_water());
  }
  const double mean_active = frame.workers.empty() ? 0 : active_sum / frame.workers.size();
  fs.set_active_imbalance(mean_active > 0 ? active_max / mean_active : 0.0);
  spdlog::info(
      "frame {} ({} {}/{}): {}x{} in {:.1f} ms on {} workers in {} ring(s); {} rays traced; "
      "max/mean active {:.2f}; balance {}",
      frame.frame_id, job.id, d, v, image.width, image.height, frame.frame_ms, frame.workers.size(),
      layout.rings.size(), rays, fs.active_imbalance(), balance.mode);

  // The image to watchers, in chunks of rows; statistics with the last.
  const int chunk_rows = std::max(1, (1 << 20) / (image.width * 12));
  for (int r0 = 0; r0 < image.height; r0 += chunk_rows) {
    const int r1 = std::min(image.height, r0 + chunk_rows);
    v1::JobEvent e;
    e.set_dataset(d);
    e.set_view(v);
    e.set_pixels_done(static_cast<uint64_t>(image.width) * image.height);
    e.set_pixels_total(static_cast<uint64_t>(image.width) * image.height);
    v1::ImageChunk* c = e.mutable_image();
    c->set_width(image.width);
    c->set_height(image.height);
    c->set_row_begin(r0);
    c->set_row_end(r1);
    c->set_output(view.output());
    AppendFloats(image.rgb.data() + static_cast<size_t>(r0) * image.width * 3,
                 static_cast<size_t>(r1 - r0) * image.width * 3, c->mutable_rgb());
    if (r1 == image.height) *e.mutable_stats() = fs;
    Publish(job, std::move(e));
  }
}

}  // namespace transtick
