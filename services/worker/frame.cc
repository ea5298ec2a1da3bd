#include "frame.h"

#include <grpcpp/alarm.h>
#include <pthread.h>
#include <spdlog/spdlog.h>
#include <time.h>

#include <algorithm>
#include <future>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/time/time.h"
#include "clock.h"
#include "convert.h"
#include "daemon.h"
#include "rpc_status.h"
#include "transtick/check.h"
#include "transtick/ray_codec.h"

namespace transtick {
namespace {

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
// Rays a tracer traces between looks at whether an older frame has work
// here (TraceOrder): about 50 us of tracing.
constexpr int kOrderLook = 64;
// How long an idle tracer sleeps before looking again (it is woken sooner
// when rays arrive).
constexpr auto kIdleWait = std::chrono::milliseconds(5);
// How long a stream may stay open after End for its peer to close its side.
constexpr auto kCloseWait = std::chrono::seconds(10);

}  // namespace

void Inbox::Push(std::vector<RayDescriptor> rays) {
  if (rays.empty()) return;
  absl::MutexLock lock(&mu_);  // wakes a Wait (its condition is checked on unlock)
  size_ += rays.size();
  high_water_ = std::max(high_water_, size_);
  batches_.push_back(std::move(rays));
  waiting_.store(true, std::memory_order_relaxed);
}

bool Inbox::TryPop(size_t max, std::vector<RayDescriptor>* out) {
  absl::MutexLock lock(&mu_);
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
  waiting_.store(size_ > 0, std::memory_order_relaxed);
  return taken > 0;
}

uint64_t TraceOrder::Join(const Member* member, bool interactive) {
  absl::MutexLock lock(&mu_);
  const uint64_t place = next_++;
  frames_.push_back({place, interactive, member});
  members_.store(static_cast<int>(frames_.size()), std::memory_order_relaxed);
  return place;
}

void TraceOrder::Leave(uint64_t place) {
  absl::MutexLock lock(&mu_);  // the frames behind look again on unlock
  std::erase_if(frames_, [place](const Entry& e) { return e.place == place; });
  members_.store(static_cast<int>(frames_.size()), std::memory_order_relaxed);
  ++generation_;
}

bool TraceOrder::BehindLocked(uint64_t place) const {
  bool interactive = false;
  for (const Entry& e : frames_) {
    if (e.place == place) interactive = e.interactive;
  }
  for (const Entry& e : frames_) {
    const bool ahead = e.interactive != interactive ? e.interactive : e.place < place;
    if (ahead && e.member->HasWork()) return true;
  }
  return false;
}

bool TraceOrder::Behind(uint64_t place) const {
  // One frame (as between a job's frames, or with no job overlapping) is
  // behind nobody: no lock.
  if (members_.load(std::memory_order_relaxed) < 2) return false;
  absl::MutexLock lock(&mu_);
  return BehindLocked(place);
}

void TraceOrder::Wait(uint64_t place, std::chrono::milliseconds timeout) {
  absl::MutexLock lock(&mu_);
  waiting_.fetch_add(1, std::memory_order_relaxed);
  const uint64_t seen = generation_;
  auto go = [&]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    return generation_ != seen || !BehindLocked(place);
  };
  mu_.AwaitWithTimeout(absl::Condition(&go), absl::FromChrono(timeout));
  waiting_.fetch_sub(1, std::memory_order_relaxed);
}

void TraceOrder::Notify() {
  if (waiting_.load(std::memory_order_relaxed) == 0) return;
  absl::MutexLock lock(&mu_);
  ++generation_;
}

void Inbox::Wait(std::chrono::milliseconds timeout) {
  absl::MutexLock lock(&mu_);
  auto ready = [this]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) { return size_ > 0 || woken_; };
  mu_.AwaitWithTimeout(absl::Condition(&ready), absl::FromChrono(timeout));
}

void Inbox::Wake() {
  absl::MutexLock lock(&mu_);
  woken_ = true;
}

size_t Inbox::high_water() const {
  absl::MutexLock lock(&mu_);
  return high_water_;
}

BufferPool& BufferPool::Shared() {
  static BufferPool* pool = new BufferPool(size_t{16} << 20);
  return *pool;
}

std::string BufferPool::Take(size_t capacity) {
  {
    absl::MutexLock lock(&mu_);
    for (size_t i = 0; i < free_.size(); ++i) {
      if (free_[i].capacity() < capacity) continue;
      std::string buffer = std::move(free_[i]);
      free_[i] = std::move(free_.back());
      free_.pop_back();
      bytes_ -= buffer.capacity();
      return buffer;
    }
  }
  std::string buffer;
  buffer.reserve(capacity);
  return buffer;
}

void BufferPool::Give(std::string buffer) {
  if (buffer.capacity() < (64 << 10)) return;
  buffer.clear();
  absl::MutexLock lock(&mu_);
  if (bytes_ + buffer.capacity() > max_bytes_) return;
  bytes_ += buffer.capacity();
  free_.push_back(std::move(buffer));
}

size_t BufferPool::held_bytes() const {
  absl::MutexLock lock(&mu_);
  return bytes_;
}

void Outbox::Attach(StartWrite write, std::function<void()> done, bool busy) {
  mu_.Lock();
  write_ = std::move(write);
  done_ = std::move(done);
  in_flight_ = busy;
  Pump();
}

void Outbox::WriteDone(bool ok, std::string spent) {
  BufferPool::Shared().Give(std::move(spent));
  mu_.Lock();
  in_flight_ = false;
  if (!ok && !failed_) {
    failed_ = true;
    dropped_ += pending_.size() / record_bytes_;
    pending_.clear();
  }
  Pump();
}

void Outbox::Append(const std::string& records) {
  if (records.empty()) return;
  mu_.Lock();
  if (failed_ || closed_) {
    dropped_ += records.size() / record_bytes_;
    mu_.Unlock();
    return;
  }
  if (pending_.empty()) {
    first_pending_ = Clock::now();
    // A buffer for a whole batch, so appends do not grow it.
    const size_t batch = batch_records_ * record_bytes_;
    if (pending_.capacity() < batch) {
      pending_ = BufferPool::Shared().Take(std::max(records.size(), batch + (16 << 10)));
    }
  }
  pending_ += records;
  Pump();
}

void Outbox::Flush() {
  mu_.Lock();
  if (pending_.empty()) {
    mu_.Unlock();
    return;
  }
  flush_ = true;
  Pump();
}

void Outbox::Close() {
  mu_.Lock();
  closed_ = true;
  Pump();
}

uint64_t Outbox::dropped() const {
  absl::MutexLock lock(&mu_);
  return dropped_;
}

void Outbox::Pump() {
  if (!write_ || in_flight_) {
    mu_.Unlock();
    return;
  }
  const size_t limit = batch_records_ * record_bytes_;
  const bool due =
      pending_.size() >= limit ||
      (!pending_.empty() && (flush_ || closed_ || Clock::now() - first_pending_ >= linger_));
  if (due) {
    std::string batch;
    if (pending_.size() <= limit) {
      // The usual case: everything pending is one batch, handed over whole.
      batch.swap(pending_);
    } else {
      batch = BufferPool::Shared().Take(limit);
      batch.assign(pending_, 0, limit);
      pending_.erase(0, limit);
    }
    if (pending_.empty()) {
      flush_ = false;
    } else {
      first_pending_ = Clock::now();
    }
    in_flight_ = true;
    mu_.Unlock();
    write_(std::move(batch));
    return;
  }
  const bool finished = (closed_ || failed_) && pending_.empty() && !done_called_;
  if (finished) done_called_ = true;
  mu_.Unlock();
  if (finished) done_();
}

struct Frame::Link {
  explicit Link(const FrameOptions& o) : outbox(kRayRecordBytes, o.batch_rays, o.linger) {}
  Outbox outbox;
  std::atomic<uint64_t> rays_sent{0}, bytes_sent{0}, rays_received{0}, bytes_received{0};

  // The write of one batch on this link's stream, for Outbox::Attach: the
  // outbox's records packed into `out` (docs/formats.md, "Packed rays"),
  // their buffer kept until the write is done (Written).
  void Pack(std::string records, v1::RayBatch* out) {
    std::string* packed = out->mutable_packed();
    packed->clear();
    rays_sent += PackRays(records, packed);
    bytes_sent += out->ByteSizeLong();
    records_ = std::move(records);
  }
  // The write is done: the records' buffer goes back to the outbox.
  void Written(bool ok) { outbox.WriteDone(ok, std::move(records_)); }

 private:
  std::string records_;  // the batch being written (one at a time), as the outbox made it
};

// What the frame's client streams share: each keeps its frame, and itself,
// until its OnDone (the frame may have ended by then, since a stream winds
// down on its own), and can be cancelled now or after a wait.
template <typename Stream>
class Frame::ClientCall {
 public:
  void Cancel() { ctx_.TryCancel(); }
  // Cancels the call if it is still open after `patience` (a peer that
  // never closes its side).
  static void CancelAfter(const std::shared_ptr<Stream>& stream,
                          std::chrono::steady_clock::duration patience) {
    std::weak_ptr<Stream> weak = stream;
    stream->closer_.Set(std::chrono::system_clock::now() + patience, [weak](bool fired) {
      if (auto self = weak.lock(); self && fired) self->Cancel();
    });
  }

 protected:
  explicit ClientCall(std::shared_ptr<Frame> frame) : frame_(std::move(frame)) {}

  void Own(std::shared_ptr<Stream> self) { self_ = std::move(self); }
  // From OnDone: logs how a call that was not cancelled ended badly, then
  // lets go of the frame and of this stream.
  void Done(const grpc::Status& s, const char* what, const std::string& peer) {
    if (!s.ok() && !frame_->cancelled_) {
      spdlog::warn("frame {}: the {} stream to {} ended with: {}", frame_->id(), what, peer,
                   s.error_message());
    }
    auto frame = std::move(frame_);
    auto self = std::move(self_);  // may delete this: nothing after
  }

  std::shared_ptr<Frame> frame_;
  grpc::ClientContext ctx_;

 private:
  std::shared_ptr<Stream> self_;
  grpc::Alarm closer_;
};

// The client side of the stream to the right neighbour: the right link's
// outbox writes on it, and the neighbour's rays coming back are read into
// the inbox.
class Frame::RightStream : public grpc::ClientBidiReactor<v1::RayBatch, v1::RayBatch>,
                           public Frame::ClientCall<Frame::RightStream> {
 public:
  explicit RightStream(std::shared_ptr<Frame> frame)
      : ClientCall(std::move(frame)),
        stub_(v1::Worker::NewStub(SharedChannel(frame_->spec_.right(), Role::kWorker, "rays"))) {}

  // `opened` hears whether the first message went out.
  void Begin(std::shared_ptr<RightStream> self, std::function<void(absl::Status)> opened) {
    Own(std::move(self));
    opened_ = std::move(opened);
    stub_->async()->Rays(&ctx_, this);
    AddHold();                        // writes come from the outbox, outside reactions
    out_.set_frame_id(frame_->id());  // the first message, with no rays, names the frame
    StartWrite(&out_);
    StartRead(&in_);
    Link& link = *frame_->right_;
    link.outbox.Attach(
        [this, &link](std::string batch) {
          link.Pack(std::move(batch), &out_);
          StartWrite(&out_);
        },
        [this] {
          StartWritesDone();
          RemoveHold();
        },
        /*busy=*/true);
    StartCall();
  }

  void OnWriteDone(bool ok) override {
    if (opened_) Opened(ok);  // the first write is the only one before opened_ is cleared
    frame_->right_->Written(ok);
  }
  void OnReadDone(bool ok) override {
    if (!ok) return;  // the neighbour closed its side
    frame_->ReceiveBatch(in_, *frame_->right_);
    StartRead(&in_);
  }
  void OnDone(const grpc::Status& s) override {
    if (opened_) Opened(false);
    Done(s, "ray", frame_->spec_.right());
  }

 private:
  const std::unique_ptr<v1::Worker::Stub> stub_;
  v1::RayBatch out_, in_;
  std::function<void(absl::Status)> opened_;  // until the first write completes

  void Opened(bool ok) {
    auto opened = std::move(opened_);
    opened_ = nullptr;
    opened(ok ? absl::OkStatus()
              : absl::UnavailableError(absl::StrCat(
                    "cannot open the ray stream to the right neighbour ", frame_->spec_.right())));
  }
};

// The client side of the deposit stream to the display, written from the
// deposit outbox.
class Frame::DisplayStream : public grpc::ClientWriteReactor<v1::DepositBatch>,
                             public Frame::ClientCall<Frame::DisplayStream> {
 public:
  explicit DisplayStream(std::shared_ptr<Frame> frame)
      : ClientCall(std::move(frame)),
        stub_(v1::Display::NewStub(SharedChannel(frame_->spec_.display(), Role::kDisplay, "deposits"))) {}

  void Begin(std::shared_ptr<DisplayStream> self) {
    Own(std::move(self));
    stub_->async()->Deposits(&ctx_, &ack_, this);
    AddHold();  // writes come from the outbox, outside reactions
    // The first message, with no deposits, names the frame: should this
    // worker die, the display knows which frame will never complete.
    out_.set_frame_id(frame_->id());
    StartWrite(&out_);
    frame_->deposits_.Attach(
        [this](std::string batch) {
          // Packed per pixel for the wire (docs/formats.md, "Packed
          // deposits"); the records' buffer goes back to the outbox.
          std::string* packed = out_.mutable_packed();
          packed->clear();
          uint64_t deposits = 0;
          PackDeposits(batch, packed, &deposits);
          frame_->deposits_sent_ += deposits;
          frame_->deposit_bytes_sent_ += packed->size();
          records_ = std::move(batch);
          StartWrite(&out_);
        },
        [this] {
          StartWritesDone();
          RemoveHold();
        },
        /*busy=*/true);
    StartCall();
  }

  void OnWriteDone(bool ok) override { frame_->deposits_.WriteDone(ok, std::move(records_)); }
  void OnDone(const grpc::Status& s) override { Done(s, "deposit", frame_->spec_.display()); }

 private:
  const std::unique_ptr<v1::Display::Stub> stub_;
  v1::FrameAck ack_;
  v1::DepositBatch out_;
  std::string records_;  // the batch being written, as the outbox made it
};

// The server side of the stream from the left neighbour: its rays are read
// into the inbox, and the left link's outbox writes on it. It finishes once
// the neighbour has closed its side and the outbox has drained. Deletes
// itself when done.
class Frame::LeftStream : public grpc::ServerBidiReactor<v1::RayBatch, v1::RayBatch> {
 public:
  LeftStream(grpc::CallbackServerContext* ctx, std::function<std::shared_ptr<Frame>(uint64_t)> find,
             FrameWaiters* waiters)
      : ctx_(ctx), find_(std::move(find)), waiters_(waiters) {
    StartRead(&in_);
  }

  void OnReadDone(bool ok) override {
    if (!frame_) {
      if (!ok) {
        Finish(
            ToGrpc(absl::InvalidArgumentError("Rays: the stream closed before its first batch")));
        return;
      }
      const uint64_t id = in_.frame_id();
      std::shared_ptr<Frame> frame = find_(id);
      // The neighbour may have prepared (and started) the frame a moment
      // before this node: the batch waits for it, and nothing more is read
      // meanwhile. While parked, no reaction of this stream runs.
      if (!frame) {
        // Copies: once parked, this stream may be resumed (and done) on
        // another thread at any moment.
        const auto find = find_;
        FrameWaiters* const waiters = waiters_;
        if (waiters->Park(id, [this](bool came) { Resumed(came); })) {
          // Prepared between the look and the parking: its Notify found
          // no one, so this one wakes the stream.
          if (find(id)) waiters->Notify(id);
          return;
        }
      }
      if (!Bind(std::move(frame), /*waited=*/false)) return;
    }
    if (!ok) {
      // The neighbour closed its side (it has ended the frame) or went away:
      // it takes no more rays, so what is pending for it goes out and the
      // stream then finishes, without waiting for this frame's End.
      frame_->left_->outbox.Close();
      Release();
      return;
    }
    frame_->ReceiveBatch(in_, *frame_->left_);
    StartRead(&in_);
  }
  void OnWriteDone(bool ok) override { frame_->left_->Written(ok); }
  // The parked first batch's frame came (or the wait ended without it).
  void Resumed(bool came) {
    if (!Bind(came ? find_(in_.frame_id()) : nullptr, /*waited=*/true)) return;
    frame_->ReceiveBatch(in_, *frame_->left_);
    StartRead(&in_);
  }
  void OnDone() override {
    if (frame_) frame_->DetachLeft();
    delete this;
  }

 private:
  // Attaches the stream to `frame`, the one its first batch names; false
  // (the stream finished with why) when there is none, or it has a left
  // stream already.
  bool Bind(std::shared_ptr<Frame> frame, bool waited) {
    if (!frame) {
      Finish(ToGrpc(absl::NotFoundError(
          waited ? absl::StrCat("Rays: frame ", in_.frame_id(), " was not prepared here within ",
                                waiters_->patience().count(), " ms")
                 : absl::StrCat("Rays: frame ", in_.frame_id(), " is not prepared here"))));
      return false;
    }
    if (!frame->AttachLeft(ctx_)) {
      Finish(ToGrpc(absl::AlreadyExistsError(absl::StrCat(
          "Rays: frame ", in_.frame_id(), " already has a stream from its left neighbour"))));
      return false;
    }
    frame_ = std::move(frame);
    out_.set_frame_id(frame_->id());
    Link& link = *frame_->left_;
    link.outbox.Attach(
        [this, &link](std::string batch) {
          link.Pack(std::move(batch), &out_);
          StartWrite(&out_);
        },
        [this] { Release(); }, /*busy=*/false);
    return true;
  }
  // Reading and writing each release the stream once; the second finishes.
  void Release() {
    if (--holds_ == 0) Finish(grpc::Status::OK);
  }

  grpc::CallbackServerContext* const ctx_;
  const std::function<std::shared_ptr<Frame>(uint64_t)> find_;
  FrameWaiters* const waiters_;
  std::shared_ptr<Frame> frame_;  // set by the first read only
  v1::RayBatch in_, out_;
  std::atomic<int> holds_{2};
};

std::atomic<int64_t> Frame::alive_{0};

Frame::Frame(const v1::FrameSpec& spec, std::shared_ptr<const Scene> scene, Camera camera,
             const RenderSettings& settings, const FrameOptions& options)
    : spec_(spec),
      scene_(std::move(scene)),
      camera_(std::move(camera)),
      options_(options),
      tracer_(*scene_, settings, camera_),
      samples_(settings.samples),
      pixel_limit_(static_cast<uint32_t>(camera_.width()) * camera_.height()),
      pixels_in_rows_(
          static_cast<int64_t>((spec.row_end() - spec.row_begin() + spec.row_step() - 1) /
                               std::max(1, spec.row_step())) *
          camera_.width()),
      layout_(std::vector<int>(spec.cuts().begin(), spec.cuts().end()), scene_->dims(),
              scene_->spacing(), camera_),
      left_(std::make_unique<Link>(options)),
      right_(std::make_unique<Link>(options)),
      deposits_(kDepositRecordBytes, options.deposit_batch, options.deposit_linger),
      last_activity_(Clock::now().time_since_epoch().count()),
      thread_stats_(options.threads) {
  ++alive_;
}

Frame::~Frame() {
  // Tracer threads hold the frame, so none runs now: this ends at once.
  if (!end_requested_) End(/*cancel=*/true);
  LeaveOrder();
  --alive_;
}

bool Frame::HasWork() const {
  return !stop_.load(std::memory_order_relaxed) &&
         (working_.load(std::memory_order_relaxed) > 0 || inbox_.waiting() ||
          next_pixel_.load(std::memory_order_relaxed) < pixels_in_rows_);
}

void Frame::LeaveOrder() {
  if (in_order_.exchange(false)) options_.order->Leave(order_place_);
}

void Frame::Start(std::function<void(absl::Status)> started) {
  if (started_.exchange(true)) {
    started(absl::FailedPreconditionError("frame already running"));
    return;
  }
  {
    absl::MutexLock lock(&end_mu_);
    if (end_requested_) {
      started(absl::FailedPreconditionError("frame already ended"));
      return;
    }
    running_tracers_ = options_.threads;
  }
  run_start_ = Clock::now();
  Touch(run_start_);
  if (options_.order) {
    order_place_ = options_.order->Join(this, spec_.interactive());
    in_order_ = true;
  }
  // Tracing starts at once; the outboxes hold what it produces until the
  // streams below are open. Each tracer holds the frame until it stops, and
  // the last one to stop ends the frame (EndAsync): nothing ever joins a
  // tracer, so no gRPC reaction waits for one.
  for (int i = 0; i < options_.threads; ++i) {
    std::thread([self = shared_from_this(), i] {
      self->TraceLoop(i);
      self->TracerStopped();
    }).detach();
  }
  auto deposits = std::make_shared<DisplayStream>(shared_from_this());
  display_stream_ = deposits;
  deposits->Begin(deposits);
  if (spec_.right().empty()) {
    started(absl::OkStatus());
    return;
  }
  auto right = std::make_shared<RightStream>(shared_from_this());
  right_stream_ = right;
  right->Begin(right, std::move(started));
}

grpc::ServerBidiReactor<v1::RayBatch, v1::RayBatch>* Frame::NewLeftStream(
    grpc::CallbackServerContext* ctx, std::function<std::shared_ptr<Frame>(uint64_t)> find,
    FrameWaiters* waiters) {
  return new LeftStream(ctx, std::move(find), waiters);
}

uint64_t Frame::rays_received_left() const { return left_->rays_received.load(); }

bool Frame::AttachLeft(grpc::CallbackServerContext* ctx) {
  if (left_attached_.exchange(true)) return false;
  absl::MutexLock lock(&left_mu_);
  left_ctx_ = ctx;
  if (left_cancelled_) ctx->TryCancel();
  return true;
}

void Frame::DetachLeft() {
  absl::MutexLock lock(&left_mu_);
  left_ctx_ = nullptr;
}

void Frame::ReceiveBatch(const v1::RayBatch& batch, Link& from) {
  if (batch.frame_id() != id()) {
    spdlog::warn("frame {}: dropped a batch of frame {}", id(), batch.frame_id());
    return;
  }
  Touch(Clock::now());
  const char* side = &from == left_.get() ? "left" : "right";
  if (!batch.rays().empty()) {
    Reject((batch.rays().size() + kRayRecordBytes - 1) / kRayRecordBytes, side,
           "the batch has unpacked ray records (field 2): the neighbour is older than packed rays");
    return;
  }
  DecodedRays decoded = DecodePackedRays(batch.packed(), pixel_limit_);
  if (decoded.broken) {
    // Nothing of it is kept: what was read, and the broken record.
    Reject(decoded.records + 1, side, std::string(decoded.error.message()));
    return;
  }
  std::vector<RayDescriptor>& rays = decoded.rays;
  size_t rejected = decoded.invalid;
  std::string first_error(decoded.error.message());
  // Every ray must be one this frame's tracer could have made: a record
  // that is not (a neighbour's defect, or a hostile peer) is dropped here,
  // before a tracer sees it.
  size_t kept = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    if (absl::Status s = tracer_.Validate(rays[i]); !s.ok()) {
      if (rejected++ == 0) first_error = absl::StrCat("record ", i, ": ", s.message());
      continue;
    }
    rays[kept++] = rays[i];
  }
  rays.resize(kept);
  // Counted before a rejection is reported, so that whoever hears of the
  // abort and asks for the frame's stats finds the kept rays among them.
  from.rays_received += rays.size();
  from.bytes_received += batch.ByteSizeLong();
  if (rejected > 0) Reject(rejected, side, first_error);
  inbox_.Push(std::move(rays));
}

void Frame::Reject(uint64_t count, const char* side, const std::string& why) {
  rejected_ += count;
  if (reject_reported_.exchange(true)) return;
  const std::string reason =
      absl::StrCat("worker ", spec_.index(), " of the ring dropped ", count,
                   " invalid ray record(s) from its ", side, " neighbour (", why, ")");
  spdlog::error("frame {}: {}", id(), reason);
  // The pixels of dropped rays can never complete: the frame is aborted at
  // the display now, so the root retries or fails it at once instead of
  // waiting for its timeout. The call is asynchronous: this runs in a
  // stream's reaction.
  struct Call {
    std::unique_ptr<v1::Display::Stub> stub;
    grpc::ClientContext ctx;
    v1::FrameRef ref;
    v1::FrameAck ack;
  };
  auto call = std::make_shared<Call>();
  call->stub = v1::Display::NewStub(SharedChannel(spec_.display(), Role::kDisplay, "control"));
  call->ctx.set_deadline(Deadline(10));
  call->ref.set_frame_id(id());
  call->ref.set_reason(reason);
  call->stub->async()->AbortFrame(&call->ctx, &call->ref, &call->ack, [call](grpc::Status s) {
    if (!s.ok())
      spdlog::warn("frame {}: AbortFrame failed: {}", call->ref.frame_id(), s.error_message());
  });
}

bool Frame::NextPrimaries(std::vector<RayDescriptor>* out, std::string* deposits,
                          uint64_t* plane_work) {
  const int64_t k0 = next_pixel_.fetch_add(static_cast<int64_t>(kWorkUnit));
  if (k0 >= pixels_in_rows_) return false;
  const int64_t k1 = std::min<int64_t>(k0 + kWorkUnit, pixels_in_rows_);
  const int width = camera_.width();
  const int me = spec_.index();
  for (int64_t k = k0; k < k1;) {
    // The unit's pixels in one row at a time: columns [col, end).
    const int row = spec_.row_begin() + static_cast<int>(k / width) * spec_.row_step();
    const int col = static_cast<int>(k % width);
    const int end = static_cast<int>(std::min<int64_t>(width, col + (k1 - k)));
    k += end - col;
    // Outside its footprint a slab has nothing to do for a pixel but
    // deposit the misses of pixels in no footprint, which slab 0 does
    // (RingLayout::Primary): the others look at their footprint's columns
    // only. With 8 slabs each had looked at every pixel.
    int from = col, to = end;
    if (me != 0) {
      const auto [first, last] = layout_.Footprint(me).Row(row);
      from = std::max(from, first);
      to = std::min(to, last);
    }
    if (from >= to) continue;
    const uint64_t misses = layout_.Primaries(me, row, from, to, samples_, tracer_, out, deposits);
    // A miss costs its slab little (the first slab's misses of the
    // volume, or the void pixels of its footprint, Tracer::Void): counted
    // at its first plane.
    if (plane_work) plane_work[0] += misses * tracer_.work_weights().ray;
  }
  return true;
}

void Frame::TraceLoop(int thread_index) {
  NameThread("tt-tracer");
  ThreadStats& st = thread_stats_[thread_index];
  // The work profile, when the root asked for it: counting it costs the
  // walk about 5% of its instructions.
  if (spec_.work_profile()) {
    st.plane_work.assign(scene_->y_end() - scene_->y_begin(), 0);
    st.counters.plane_work = st.plane_work.data();
  }
  std::vector<RayDescriptor> work;
  std::string to_left, to_right, deposits;
  const int me = spec_.index();
  auto flush = [&] {
    left_->outbox.Append(to_left);
    right_->outbox.Append(to_right);
    deposits_.Append(deposits);
    to_left.clear();
    to_right.clear();
    deposits.clear();
  };
  // The thread's CPU time is read when it turns busy and when it turns
  // idle, not for every unit: in a VM the clock is a system call of about
  // 1.6 us, and read twice a unit it made 2,600 calls a 400x400 frame on
  // 2 workers (61 now).
  bool busy = false;
  double cpu0 = 0;
  auto rest = [&] {
    if (busy) st.cpu_ms += ThreadCpuMs() - cpu0;
    busy = false;
  };
  // Nothing to trace for now: what this thread produced goes out at once
  // rather than after the linger, since more may not come for a while (the
  // end of a frame, or a neighbour waiting for these rays).
  auto send = [&] {
    rest();
    flush();
    left_->outbox.Flush();
    right_->outbox.Flush();
    deposits_.Flush();
  };
  TraceOrder* const order = options_.order.get();
  while (!stop_.load(std::memory_order_relaxed)) {
    const auto t0 = Clock::now();
    // A frame that started before this one here goes first (TraceOrder).
    if (order && order->Behind(order_place_)) {
      send();
      order->Wait(order_place_, kIdleWait);
      st.idle_ms += MsBetween(t0, Clock::now());
      continue;
    }
    if (!busy) {
      cpu0 = ThreadCpuMs();
      busy = true;
    }
    work.clear();
    working_.fetch_add(1, std::memory_order_relaxed);
    // Rays from neighbours first: they free the nodes waiting on them.
    bool got =
        inbox_.TryPop(kWorkUnit, &work) || NextPrimaries(&work, &deposits, st.counters.plane_work);
    if (!got) {
      working_.fetch_sub(1, std::memory_order_relaxed);
      send();
      // The frames behind this one may take the cores.
      if (order) order->Notify();
      inbox_.Wait(kIdleWait);
      st.idle_ms += MsBetween(t0, Clock::now());
      continue;
    }
    Touch(t0);
    Deposit deposit;
    // Every Trace call is bounded (Tracer::max_segments), so a frame that
    // ends stops its tracers within one ray.
    int since_look = 0;
    while (!work.empty() && !stop_.load(std::memory_order_relaxed)) {
      // An older frame's rays came meanwhile: the rest of this unit waits
      // in the inbox, and the cores go to them within a few rays.
      if (order && ++since_look == kOrderLook) {
        since_look = 0;
        if (order->Behind(order_place_)) {
          inbox_.Push(std::move(work));
          work = {};
          break;
        }
      }
      RayDescriptor ray = work.back();
      work.pop_back();
      (ray.kind == RayKind::kPrimary ? st.primary : st.shadow) += 1;
      // Spawned shadow rays go onto `work` and are traced here next.
      if (tracer_.Trace(ray, work, deposit, st.counters) == Tracer::Outcome::kFinished) {
        AppendDeposit(deposit, &deposits);
      } else {
        // A ray that left the slab is inside the volume (else it finished).
        const RingLayout::Hop hop = layout_.Route(me, ray.cell);
        TRANSTICK_DCHECK(hop != RingLayout::Hop::kFinished);
        AppendRay(ray, hop == RingLayout::Hop::kLeft ? &to_left : &to_right);
      }
    }
    flush();
    working_.fetch_sub(1, std::memory_order_relaxed);
  }
  flush();
  rest();
}

void Frame::EndAsync(bool cancel, std::function<void(v1::WorkerFrameStats)> done) {
  stop_ = true;
  inbox_.Wake();
  // Its tracers, and the frames behind it, look again.
  if (options_.order) options_.order->Notify();
  {
    absl::MutexLock lock(&end_mu_);
    if (end_requested_) return;  // REQUIRES says once; a second call is ignored
    end_requested_ = true;
    end_cancel_ = cancel;
    if (running_tracers_ > 0) {
      end_done_ = std::move(done);  // the last tracer to stop calls it
      return;
    }
  }
  done(Finish(cancel));
}

void Frame::TracerStopped() {
  std::function<void(v1::WorkerFrameStats)> done;
  bool cancel;
  {
    absl::MutexLock lock(&end_mu_);
    if (--running_tracers_ > 0 || !end_done_) return;
    done = std::move(end_done_);
    end_done_ = nullptr;
    cancel = end_cancel_;
  }
  done(Finish(cancel));
}

v1::WorkerFrameStats Frame::End(bool cancel) {
  std::promise<v1::WorkerFrameStats> stats;
  auto got = stats.get_future();
  EndAsync(cancel, [&stats](v1::WorkerFrameStats s) { stats.set_value(std::move(s)); });
  return got.get();
}

v1::WorkerFrameStats Frame::Finish(bool cancel) {
  const auto end = Clock::now();
  LeaveOrder();
  // Closing the outboxes half-closes every stream once its last batch is
  // written (when the frame is complete, nothing is left to write). The
  // streams then wind down on their own: the frame's statistics do not
  // wait for the display's and the neighbours' replies.
  if (cancel) {
    cancelled_ = true;
    // The left neighbour's stream holds this frame until it ends: a peer
    // that never closes its side must not keep a cancelled frame alive.
    absl::MutexLock lock(&left_mu_);
    left_cancelled_ = true;
    if (left_ctx_) left_ctx_->TryCancel();
  }
  left_->outbox.Close();
  right_->outbox.Close();
  deposits_.Close();
  auto right = right_stream_.lock();
  auto deposits = display_stream_.lock();
  if (cancel) {
    if (right) right->Cancel();
    if (deposits) deposits->Cancel();
  } else {
    // Do not hold a stream open for ever for a peer that hangs.
    if (right) RightStream::CancelAfter(right, kCloseWait);
    if (deposits) DisplayStream::CancelAfter(deposits, kCloseWait);
  }
  const uint64_t dropped = left_->outbox.dropped() + right_->outbox.dropped() + deposits_.dropped();
  if (dropped > 0 && !cancel) {
    spdlog::warn("frame {}: {} rays or deposits could not be sent (a stream broke)", id(), dropped);
  }

  v1::WorkerFrameStats stats;
  stats.add_slab(scene_->y_begin());
  stats.add_slab(scene_->y_end());
  const double elapsed = started_ ? MsBetween(run_start_, end) : 0;
  double idle = 0, cpu = 0;
  uint64_t primary = 0, shadow = 0, truncated = 0;
  for (const ThreadStats& t : thread_stats_) {
    idle += t.idle_ms;
    cpu += t.cpu_ms;
    primary += t.primary;
    shadow += t.shadow;
    truncated += t.counters.truncated;
  }
  if (truncated > 0) {
    spdlog::error("frame {}: {} rays reached the tracer's bound and were ended early", id(),
                  truncated);
  }
  stats.set_rays_truncated(truncated);
  stats.set_rays_rejected(rejected_);
  if (spec_.work_profile()) {
    // A tracer that never started has no profile yet: its planes count 0.
    std::vector<uint64_t> work(scene_->y_end() - scene_->y_begin(), 0);
    for (const ThreadStats& t : thread_stats_) {
      for (size_t y = 0; y < t.plane_work.size() && y < work.size(); ++y) {
        work[y] += t.plane_work[y];
      }
    }
    for (uint64_t w : work) stats.add_plane_work(w);
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
  stats.set_deposits(deposits_sent_);
  stats.set_deposit_bytes(deposit_bytes_sent_);
  return stats;
}

}  // namespace transtick
