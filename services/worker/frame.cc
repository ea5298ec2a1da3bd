#include "frame.h"

#include <spdlog/spdlog.h>

#include <pthread.h>
#include <time.h>

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "convert.h"
#include "daemon.h"
#include "transtick/ray_codec.h"

namespace transtick {
namespace {

using Clock = std::chrono::steady_clock;

double MsBetween(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

// Names the calling thread (for top, perf and gdb); at most 15 characters.
void NameThread(const char* name) { pthread_setname_np(pthread_self(), name); }

// CPU time of the calling thread.
double ThreadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

// Rays a tracer takes from the inbox, or primaries it generates, at a time.
constexpr size_t kWorkUnit = 256;
// How long an idle tracer sleeps before looking again (it is woken sooner
// when rays arrive).
constexpr auto kIdleWait = std::chrono::milliseconds(5);
// How long End waits for a neighbour to close its side before cancelling.
constexpr auto kCloseWait = std::chrono::seconds(10);

// The footprints of the ring's slabs, from the cuts.
std::vector<ImageRect> SlabFootprints(const v1::FrameSpec& spec, const Scene& scene,
                                      const Camera& camera) {
  const auto& d = scene.dims();
  const auto& sp = scene.spacing();
  std::vector<ImageRect> rects;
  for (int i = 0; i + 1 < spec.cuts_size(); ++i) {
    const Vec3 lo{-0.5 * d[0] * sp[0], (spec.cuts(i) - 0.5 * d[1]) * sp[1], -0.5 * d[2] * sp[2]};
    const Vec3 hi{0.5 * d[0] * sp[0], (spec.cuts(i + 1) - 0.5 * d[1]) * sp[1], 0.5 * d[2] * sp[2]};
    rects.push_back(camera.Footprint(lo, hi));
  }
  return rects;
}

}  // namespace

void Inbox::Push(std::vector<RayDescriptor> rays) {
  if (rays.empty()) return;
  std::lock_guard<std::mutex> lock(mu_);
  size_ += rays.size();
  high_water_ = std::max(high_water_, size_);
  batches_.push_back(std::move(rays));
  cv_.notify_one();
}

bool Inbox::TryPop(size_t max, std::vector<RayDescriptor>* out) {
  std::lock_guard<std::mutex> lock(mu_);
  size_t taken = 0;
  while (taken < max && !batches_.empty()) {
    auto& front = batches_.front();
    size_t n = std::min(max - taken, front.size() - front_used_);
    out->insert(out->end(), front.begin() + front_used_, front.begin() + front_used_ + n);
    front_used_ += n;
    taken += n;
    if (front_used_ == front.size()) {
      batches_.pop_front();
      front_used_ = 0;
    }
  }
  size_ -= taken;
  return taken > 0;
}

void Inbox::Wait(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mu_);
  cv_.wait_for(lock, timeout, [this] { return size_ > 0 || woken_; });
}

void Inbox::Wake() {
  std::lock_guard<std::mutex> lock(mu_);
  woken_ = true;
  cv_.notify_all();
}

size_t Inbox::high_water() const {
  std::lock_guard<std::mutex> lock(mu_);
  return high_water_;
}

void Outbox::Append(const std::string& records) {
  if (records.empty()) return;
  std::lock_guard<std::mutex> lock(mu_);
  const bool was_empty = pending_.empty();
  if (was_empty) first_pending_ = Clock::now();
  pending_ += records;
  // The writer sleeps without a deadline while nothing is pending: wake it
  // to start the linger clock, and again when a full batch is ready.
  if (was_empty || pending_.size() >= batch_records_ * record_bytes_) cv_.notify_one();
}

void Outbox::Flush() {
  std::lock_guard<std::mutex> lock(mu_);
  if (pending_.empty()) return;
  flush_ = true;
  cv_.notify_one();
}

bool Outbox::Take(std::string* batch) {
  std::unique_lock<std::mutex> lock(mu_);
  while (true) {
    if (pending_.size() >= batch_records_ * record_bytes_ ||
        ((closed_ || flush_) && !pending_.empty())) {
      break;
    }
    if (closed_) return false;
    if (pending_.empty()) {
      cv_.wait(lock);
      continue;
    }
    auto due = first_pending_ + linger_;
    if (Clock::now() >= due) break;
    cv_.wait_until(lock, due);
  }
  const size_t limit = batch_records_ * record_bytes_;
  if (pending_.size() <= limit) {
    // The usual case: everything pending is one batch, handed over whole.
    batch->clear();
    batch->swap(pending_);
  } else {
    batch->assign(pending_, 0, limit);
    pending_.erase(0, limit);
  }
  if (pending_.empty()) flush_ = false;
  if (!pending_.empty()) first_pending_ = Clock::now();
  return true;
}

void Outbox::Close() {
  std::lock_guard<std::mutex> lock(mu_);
  closed_ = true;
  cv_.notify_all();
}

struct Frame::Link {
  explicit Link(const FrameOptions& o) : outbox(kRayRecordBytes, o.batch_rays, o.linger) {}
  Outbox outbox;
  std::atomic<uint64_t> rays_sent{0}, bytes_sent{0}, rays_received{0}, bytes_received{0};
};

Frame::Frame(const v1::FrameSpec& spec, std::shared_ptr<const Scene> scene, Camera camera,
             const FrameOptions& options)
    : spec_(spec),
      scene_(std::move(scene)),
      camera_(std::move(camera)),
      options_(options),
      tracer_(*scene_, ToRenderSettings(spec.view()), camera_),
      pixel_limit_(static_cast<uint32_t>(camera_.width()) * camera_.height()),
      pixels_in_rows_(
          static_cast<int64_t>((spec.row_end() - spec.row_begin() + spec.row_step() - 1) /
                               std::max(1, spec.row_step())) *
          camera_.width()),
      footprints_(SlabFootprints(spec, *scene_, camera_)),
      left_(std::make_unique<Link>(options)),
      right_(std::make_unique<Link>(options)),
      deposits_(kDepositRecordBytes, options.batch_rays * 2, options.linger),
      thread_stats_(options.threads) {}

Frame::~Frame() {
  if (!stop_) End(/*cancel=*/true);
}

absl::Status Frame::Start() {
  if (started_.exchange(true)) return absl::FailedPreconditionError("frame already running");
  run_start_ = Clock::now();
  // Tracing starts at once; the outboxes hold what it produces until the
  // streams below are open.
  for (int i = 0; i < options_.threads; ++i) tracers_.emplace_back([this, i] { TraceLoop(i); });
  display_stub_ = v1::Display::NewStub(SharedChannel(spec_.display(), "deposits"));
  display_ctx_ = std::make_unique<grpc::ClientContext>();
  display_stream_ = display_stub_->Deposits(display_ctx_.get(), &display_ack_);
  deposit_writer_ = std::thread([this] {
    NameThread("tt-deposits");
    std::string bytes;
    v1::DepositBatch batch;
    batch.set_frame_id(id());
    while (deposits_.Take(&bytes)) {
      batch.set_deposits(std::move(bytes));
      if (!display_stream_->Write(batch)) {
        spdlog::warn("frame {}: display {} closed the deposit stream", id(), spec_.display());
        break;
      }
    }
    display_stream_->WritesDone();
  });
  if (!spec_.right().empty()) {
    right_stub_ = v1::Worker::NewStub(SharedChannel(spec_.right(), "rays"));
    right_ctx_ = std::make_unique<grpc::ClientContext>();
    right_stream_ = right_stub_->Rays(right_ctx_.get());
    v1::RayBatch hello;
    hello.set_frame_id(id());
    if (!right_stream_->Write(hello)) {
      return absl::UnavailableError(
          absl::StrCat("cannot open the ray stream to the right neighbour ", spec_.right()));
    }
    right_writer_ = std::thread([this] {
      NameThread("tt-ray-writer");
      WriterLoop(*right_, [this](const v1::RayBatch& b) { return right_stream_->Write(b); });
      right_stream_->WritesDone();
    });
    right_reader_ = std::thread([this] {
      NameThread("tt-ray-reader");
      v1::RayBatch b;
      while (right_stream_->Read(&b)) ReceiveBatch(b, *right_);
    });
  }
  return absl::OkStatus();
}

void Frame::WriterLoop(Link& link, std::function<bool(const v1::RayBatch&)> write) {
  std::string bytes;
  v1::RayBatch batch;
  batch.set_frame_id(id());
  while (link.outbox.Take(&bytes)) {
    const size_t n = bytes.size() / kRayRecordBytes;
    batch.set_rays(std::move(bytes));
    if (!write(batch)) {
      spdlog::warn("frame {}: a neighbour closed its ray stream with {} rays unsent", id(), n);
      break;
    }
    link.rays_sent += n;
    link.bytes_sent += batch.ByteSizeLong();
    bytes.clear();
  }
}

void Frame::ReceiveBatch(const v1::RayBatch& batch, Link& from) {
  if (batch.frame_id() != id()) {
    spdlog::warn("frame {}: dropped a batch of frame {}", id(), batch.frame_id());
    return;
  }
  auto rays = DecodeRays(batch.rays(), pixel_limit_);
  if (!rays.ok()) {
    spdlog::error("frame {}: bad ray batch from a neighbour: {}", id(),
                  std::string(rays.status().message()));
    return;
  }
  from.rays_received += rays->size();
  from.bytes_received += batch.ByteSizeLong();
  inbox_.Push(*std::move(rays));
}

grpc::Status Frame::ServeLeft(grpc::ServerReaderWriter<v1::RayBatch, v1::RayBatch>* stream) {
  {
    std::lock_guard<std::mutex> lock(left_mu_);
    left_done_ = false;
  }
  std::thread writer([this, stream] {
    WriterLoop(*left_, [stream](const v1::RayBatch& b) { return stream->Write(b); });
  });
  v1::RayBatch b;
  while (stream->Read(&b)) ReceiveBatch(b, *left_);
  writer.join();
  std::lock_guard<std::mutex> lock(left_mu_);
  left_done_ = true;
  left_cv_.notify_all();
  return grpc::Status::OK;
}

bool Frame::NextPrimaries(std::vector<RayDescriptor>* out, std::vector<Deposit>* misses) {
  const int64_t k0 = next_pixel_.fetch_add(static_cast<int64_t>(kWorkUnit));
  if (k0 >= pixels_in_rows_) return false;
  const int64_t k1 = std::min<int64_t>(k0 + kWorkUnit, pixels_in_rows_);
  const int width = camera_.width();
  const int y0 = scene_->y_begin(), y1 = scene_->y_end();
  const int me = spec_.index();
  const ImageRect& mine = footprints_[me];
  // A miss is deposited once: by the first slab whose footprint holds the
  // pixel, or by slab 0 for a pixel in no footprint (its ray meets no slab).
  auto first_footprint = [&](int col, int row) {
    for (size_t i = 0; i < footprints_.size(); ++i) {
      if (footprints_[i].Contains(col, row)) return static_cast<int>(i);
    }
    return -1;
  };
  for (int64_t k = k0; k < k1; ++k) {
    const int row = spec_.row_begin() + static_cast<int>(k / width) * spec_.row_step();
    const int col = static_cast<int>(k % width);
    const uint32_t pixel = static_cast<uint32_t>(row) * width + col;
    if (!mine.Contains(col, row)) {
      // The ray cannot enter this slab.
      if (me == 0 && first_footprint(col, row) < 0) misses->push_back(tracer_.MissDeposit(pixel));
      continue;
    }
    RayDescriptor ray;
    if (!tracer_.MakePrimary(camera_.Generate(col, row), pixel, &ray)) {
      if (first_footprint(col, row) == me) misses->push_back(tracer_.MissDeposit(pixel));
      continue;
    }
    // The paper's distributed policy: keep only rays entering this slab.
    if (ray.cell[1] >= y0 && ray.cell[1] < y1) out->push_back(ray);
  }
  return true;
}

void Frame::TraceLoop(int thread_index) {
  NameThread("tt-tracer");
  ThreadStats& st = thread_stats_[thread_index];
  std::vector<RayDescriptor> work;
  std::vector<Deposit> misses;
  std::string to_left, to_right, deposits;
  const int y0 = scene_->y_begin();
  auto flush = [&] {
    left_->outbox.Append(to_left);
    right_->outbox.Append(to_right);
    deposits_.Append(deposits);
    to_left.clear();
    to_right.clear();
    deposits.clear();
  };
  while (!stop_.load(std::memory_order_relaxed)) {
    const auto t0 = Clock::now();
    const double cpu0 = ThreadCpuMs();
    work.clear();
    // Rays from neighbours first: they free the nodes waiting on them.
    bool got = inbox_.TryPop(kWorkUnit, &work) || NextPrimaries(&work, &misses);
    for (const Deposit& d : misses) AppendDeposit(d, &deposits);
    misses.clear();
    if (!got) {
      // Nothing to trace: what this thread produced goes out now rather
      // than after the linger, since more may not come for a while (the
      // end of a frame, or a neighbour waiting for these rays).
      flush();
      left_->outbox.Flush();
      right_->outbox.Flush();
      deposits_.Flush();
      inbox_.Wait(kIdleWait);
      st.idle_ms += MsBetween(t0, Clock::now());
      continue;
    }
    Deposit deposit;
    while (!work.empty()) {
      RayDescriptor ray = work.back();
      work.pop_back();
      (ray.kind == RayKind::kPrimary ? st.primary : st.shadow) += 1;
      // Spawned shadow rays go onto `work` and are traced here next.
      if (tracer_.Trace(ray, work, deposit, st.counters) == Tracer::Outcome::kFinished) {
        AppendDeposit(deposit, &deposits);
      } else {
        AppendRay(ray, ray.cell[1] < y0 ? &to_left : &to_right);
      }
    }
    flush();
    st.cpu_ms += ThreadCpuMs() - cpu0;
  }
  flush();
}

v1::WorkerFrameStats Frame::End(bool cancel) {
  stop_ = true;
  inbox_.Wake();
  for (auto& t : tracers_) t.join();
  tracers_.clear();
  const auto end = Clock::now();
  left_->outbox.Close();
  right_->outbox.Close();
  deposits_.Close();
  if (cancel) {
    if (right_ctx_) right_ctx_->TryCancel();
    if (display_ctx_) display_ctx_->TryCancel();
  }
  if (deposit_writer_.joinable()) {
    deposit_writer_.join();
    grpc::Status s = display_stream_->Finish();
    if (!s.ok() && !cancel) {
      spdlog::warn("frame {}: deposit stream ended with: {}", id(), s.error_message());
    }
  }
  if (right_writer_.joinable()) right_writer_.join();
  if (right_reader_.joinable()) {
    // The right neighbour closes its side when it ends the frame too; do
    // not wait for ever on one that died.
    std::mutex mu;
    std::condition_variable cv;
    bool done = false;
    std::thread waiter([&] {
      right_reader_.join();
      std::lock_guard<std::mutex> lock(mu);
      done = true;
      cv.notify_all();
    });
    {
      std::unique_lock<std::mutex> lock(mu);
      if (!cv.wait_for(lock, kCloseWait, [&] { return done; })) right_ctx_->TryCancel();
    }
    waiter.join();
    right_stream_->Finish();
  }
  {
    std::unique_lock<std::mutex> lock(left_mu_);
    left_cv_.wait_for(lock, kCloseWait, [this] { return left_done_; });
  }

  v1::WorkerFrameStats stats;
  stats.add_slab(scene_->y_begin());
  stats.add_slab(scene_->y_end());
  const double elapsed = started_ ? MsBetween(run_start_, end) : 0;
  double idle = 0, cpu = 0;
  uint64_t primary = 0, shadow = 0;
  for (const ThreadStats& t : thread_stats_) {
    idle += t.idle_ms;
    cpu += t.cpu_ms;
    primary += t.primary;
    shadow += t.shadow;
  }
  stats.set_elapsed_ms(elapsed);
  stats.set_active_ms(std::max(0.0, elapsed - idle / std::max<size_t>(1, thread_stats_.size())));
  stats.set_cpu_ms(cpu);
  stats.set_primary_traced(primary);
  stats.set_shadow_traced(shadow);
  stats.set_rays_traced(primary + shadow);
  stats.set_sent_left(left_->rays_sent);
  stats.set_sent_right(right_->rays_sent);
  stats.set_received_left(left_->rays_received);
  stats.set_received_right(right_->rays_received);
  stats.set_rays_sent(left_->rays_sent + right_->rays_sent);
  stats.set_rays_received(left_->rays_received + right_->rays_received);
  stats.set_bytes_sent(left_->bytes_sent + right_->bytes_sent);
  stats.set_bytes_received(left_->bytes_received + right_->bytes_received);
  stats.set_buffer_high_water(inbox_.high_water());
  return stats;
}

}  // namespace transtick
