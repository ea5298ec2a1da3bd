#include "display_service.h"

#include <spdlog/spdlog.h>

#include <bit>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/time/time.h"
#include "convert.h"
#include "refused.h"
#include "rpc_status.h"
#include "security.h"
#include "transtick/camera.h"
#include "transtick/image_io.h"
#include "transtick/ray_codec.h"

namespace transtick {
namespace {

// Image rows per chunk: keeps messages near 1 MB whatever the width.
int RowsPerChunk(int width, int pixel_bytes) {
  return std::max(1, (1 << 20) / (width * pixel_bytes));
}
// Rows complete before the frame go out once there are about 256 KB of
// them, or an eighth of a smaller image (or the image's last rows): a few
// chunks a frame, not one per row or per deposit batch. Each message wakes
// threads in the display, the root, the client and the kernel: a 400x400
// turntable's frames reached the client in 8-13 chunks at 64 KB, 3-5 now.
int EarlyChunkRows(int width, int height, int pixel_bytes) {
  return std::max(1, std::min((1 << 18) / (width * pixel_bytes), height / 8));
}
uint64_t RowBytes(int width, int pixel_bytes) { return static_cast<uint64_t>(width) * pixel_bytes; }

double Mb(uint64_t bytes) { return bytes / 1048576.0; }
double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

}  // namespace

DisplayService::DisplayService(DisplayOptions options)
    : options_(options),
      metrics_(std::make_shared<Metrics>()),
      early_(options.early_streams, options.early_deposit_wait),
      sweeper_(SweepPeriod(options.idle), [this] { ExpireIdle(); }),
      heartbeat_(std::chrono::milliseconds(250), [this] { Heartbeat(); }) {
  using T = Metrics::Type;
  Metrics& m = *metrics_;
  m.Declare("transtick_display_frames_total", T::kCounter,
            "Frames that ended here, by result: complete (every pixel in) or aborted.");
  // What the root's frame_ms holds beyond it is the frame's tail: the image
  // sent to the root and the workers' statistics in (bench/emulated_hosts.sh).
  m.Declare("transtick_display_frame_assembly_seconds", T::kHistogram,
            "From BeginFrame to the deposit that completed the frame.",
            {0.005, 0.01, 0.02, 0.033, 0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 30, 60, 300});
  m.Declare("transtick_display_deposits_total", T::kCounter, "Pixel deposits received.");
  m.Declare("transtick_display_pixel_records_total", T::kCounter,
            "Packed pixel records received (consecutive deposits of a pixel, merged).");
  m.Declare("transtick_display_deposit_bytes_total", T::kCounter,
            "Bytes of deposit batches received.");
  m.Declare("transtick_display_deposits_refused_total", T::kCounter,
            "Deposit batches refused (malformed, or for an aborted or complete frame).");
  m.Declare("transtick_display_frames_open", T::kGauge, "Frames being assembled now.");
  m.Declare("transtick_display_framebuffer_bytes", T::kGauge, "Memory of the open framebuffers.");
  m.OnScrape([this](Metrics& g) {
    g.Set("transtick_display_frames_open", static_cast<double>(open_frames()));
    g.Set("transtick_display_framebuffer_bytes", static_cast<double>(framebuffer_bytes()));
  });
}

size_t DisplayService::open_frames() const {
  absl::MutexLock lock(&mu_);
  return frames_.size();
}

uint64_t DisplayService::framebuffer_bytes() const {
  absl::MutexLock lock(&mu_);
  return OpenBytesLocked() + SpareBytesLocked();
}

uint64_t DisplayService::SpareBytesLocked() const {
  uint64_t bytes = 0;
  for (const Spare& s : spares_) bytes += Framebuffer::MemoryBytes(s.fb->width(), s.fb->height());
  return bytes;
}

std::unique_ptr<Framebuffer> DisplayService::TakeFramebufferLocked(int width, int height,
                                                                   int samples, uint64_t open) {
  // The most recently used of this size (cleared when it was put aside,
  // off this frame's start).
  for (auto it = spares_.rbegin(); it != spares_.rend(); ++it) {
    if (it->fb->width() == width && it->fb->height() == height) {
      std::unique_ptr<Framebuffer> fb = std::move(it->fb);
      spares_.erase(std::next(it).base());
      fb->SetSamples(samples);
      return fb;
    }
  }
  TrimSparesLocked(open + Framebuffer::MemoryBytes(width, height), kMaxSpares);
  return std::make_unique<Framebuffer>(width, height, samples);
}

void DisplayService::TrimSparesLocked(uint64_t held, size_t most) {
  while (!spares_.empty() &&
         (spares_.size() > most || held + SpareBytesLocked() > options_.max_bytes)) {
    spares_.erase(spares_.begin());
  }
}

uint64_t DisplayService::OpenBytesLocked() const {
  uint64_t bytes = 0;
  for (const auto& [id, f] : frames_) bytes += f->bytes;
  return bytes;
}

std::shared_ptr<DisplayService::FrameState> DisplayService::Find(uint64_t id) {
  absl::MutexLock lock(&mu_);
  auto it = frames_.find(id);
  return it == frames_.end() ? nullptr : it->second;
}

bool DisplayService::MayBegin(uint64_t id) {
  absl::MutexLock lock(&mu_);
  return frames_.count(id) == 0 && aborted_.Find(id) == nullptr;
}

grpc::ServerUnaryReactor* DisplayService::BeginFrame(grpc::CallbackServerContext* ctx,
                                                     const v1::DisplayFrame* req, v1::FrameAck*) {
  grpc::ServerUnaryReactor* reactor = ctx->DefaultReactor();
  grpc::Status s = RequireRole(*ctx, "BeginFrame", {Role::kRoot});
  reactor->Finish(s.ok() ? Begin(*req) : s);
  return reactor;
}

grpc::Status DisplayService::Begin(const v1::DisplayFrame& req) {
  if (req.width() < 1 || req.height() < 1 ||
      static_cast<uint64_t>(req.width()) * req.height() > options_.max_frame_pixels) {
    return ToGrpc(absl::InvalidArgumentError(
        absl::StrCat("display: frame size ", req.width(), "x", req.height(), " is out of range")));
  }
  const int samples = req.samples() == 0 ? 1 : req.samples();
  if (samples < 1 || samples > kMaxSamplesPerPixel) {
    return ToGrpc(absl::InvalidArgumentError(absl::StrCat(
        "display: ", req.samples(), " samples per pixel, not in [1, ", kMaxSamplesPerPixel, "]")));
  }
  const uint64_t bytes = Framebuffer::MemoryBytes(req.width(), req.height());
  std::shared_ptr<FrameState> evicted;
  std::string why;
  {
    absl::MutexLock lock(&mu_);
    if (frames_.count(req.frame_id())) {
      return ToGrpc(absl::AlreadyExistsError(
          absl::StrCat("display: frame ", req.frame_id(), " already begun")));
    }
    // Past the count limit the least recently active frame goes, and the
    // byte limit is checked without it.
    const auto now = Clock::now();
    auto victim = frames_.end();
    Clock::time_point victim_at = Clock::time_point::max();
    if (frames_.size() >= options_.max_frames) {
      for (auto it = frames_.begin(); it != frames_.end(); ++it) {
        if (const auto at = LastActive(*it->second, now); at < victim_at) {
          victim = it;
          victim_at = at;
        }
      }
    }
    const bool evict = victim != frames_.end();
    const uint64_t open = OpenBytesLocked() - (evict ? victim->second->bytes : 0);
    if (open + bytes > options_.max_bytes) {
      return ToGrpc(absl::ResourceExhaustedError(absl::StrFormat(
          "display: frame %d needs %.1f MB for its %dx%d framebuffer; %d open frame(s) hold "
          "%.1f MB of the %.1f MB allowed (--max-framebuffer-mb)",
          req.frame_id(), Mb(bytes), req.width(), req.height(), frames_.size() - evict, Mb(open),
          Mb(options_.max_bytes))));
    }
    if (evict) {
      evicted = victim->second;
      why = absl::StrFormat(
          "evicted: the display holds at most %d frames, frame %d began, and this one had "
          "been idle longest (%.1f s)",
          options_.max_frames, req.frame_id(), Seconds(now - victim_at));
      frames_.erase(victim);
      aborted_.Remember(evicted->id, why);
    }
    // A framebuffer of a finished frame of the same size is cleared and used
    // again: faulting in fresh pages for every frame costs more.
    std::unique_ptr<Framebuffer> fb =
        TakeFramebufferLocked(req.width(), req.height(), samples, open);
    frames_[req.frame_id()] = std::make_shared<FrameState>(req.frame_id(), std::move(fb));
  }
  if (evicted) {
    spdlog::warn("display: frame {} {}", evicted->id, why);
    MarkAborted(*evicted, why);
  }
  // Deposits that came first go in now.
  early_.Notify(req.frame_id());
  return grpc::Status::OK;
}

// One worker's deposit stream: every batch is accumulated into its frame's
// framebuffer as it is read. A bad batch ends the stream with an error
// before any of its deposits is added. Deletes itself when done.
class DisplayService::DepositStream : public grpc::ServerReadReactor<v1::DepositBatch> {
 public:
  DepositStream(DisplayService* service, grpc::CallbackServerContext* ctx)
      : service_(service), ctx_(ctx) {
    StartRead(&batch_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      // A worker that went away (or cancelled) before closing its side
      // leaves a frame that cannot complete: it is aborted at once rather
      // than left to the root's frame timeout, and the root retries it.
      if (ctx_->IsCancelled() && frame_) {
        service_->AbortIncomplete(*frame_, "a worker's deposit stream broke");
      }
      Finish(grpc::Status::OK);
      return;
    }
    // Deposits for a frame the root has not begun here yet: it begins the
    // frame in the same round as the workers start it, so they wait for it,
    // and nothing more is read meanwhile. While parked, no reaction of this
    // stream runs.
    const uint64_t id = batch_.frame_id();
    DisplayService* const service = service_;  // once parked, this may be gone
    if (!batch_.packed().empty() && (!frame_ || frame_->id != id) && service->MayBegin(id) &&
        service->early_.Park(id, [this](bool) { Take(); })) {
      // Begun (or aborted) between the look and the parking: its Notify
      // found no one, so this one wakes the stream.
      if (!service->MayBegin(id)) service->early_.Notify(id);
      return;
    }
    Take();
  }

  void OnDone() override { delete this; }

 private:
  // Adds the batch just read and reads the next.
  void Take() {
    grpc::Status s = service_->Accumulate(batch_, &frame_);
    if (!s.ok()) {
      Finish(s);
      return;
    }
    StartRead(&batch_);
  }

  DisplayService* const service_;
  grpc::CallbackServerContext* const ctx_;
  v1::DepositBatch batch_;
  std::shared_ptr<FrameState> frame_;  // of the last batch
};

grpc::ServerReadReactor<v1::DepositBatch>* DisplayService::Deposits(
    grpc::CallbackServerContext* ctx, v1::FrameAck*) {
  if (grpc::Status s = RequireRole(*ctx, "Deposits", {Role::kWorker}); !s.ok()) {
    return new RefusedRead<v1::DepositBatch>(s);
  }
  return new DepositStream(this, ctx);
}

grpc::Status DisplayService::Accumulate(const v1::DepositBatch& batch,
                                        std::shared_ptr<FrameState>* frame_cache) {
  std::shared_ptr<FrameState>& frame = *frame_cache;
  if (!frame || batch.frame_id() != frame->id) frame = Find(batch.frame_id());
  // A worker's first message names its frame and carries nothing: it may
  // come after the other workers have completed the frame.
  if (!batch.records().empty()) {
    metrics_->Add("transtick_display_deposits_refused_total", 1);
    return ToGrpc(absl::InvalidArgumentError(
        "display: deposits as 20-byte records, from a worker older than this display; it takes "
        "them packed (docs/formats.md, \"Packed deposits\"): run workers of this version"));
  }
  if (batch.packed().empty()) {
    if (frame) {
      absl::MutexLock lock(&frame->mu);
      frame->last_activity = Clock::now();
    }
    return grpc::Status::OK;
  }
  if (!frame) {
    return ToGrpc(
        absl::NotFoundError(absl::StrCat("display: frame ", batch.frame_id(), " was not begun")));
  }
  bool wake = false;
  grpc::Status s = AddDeposits(batch, *frame, &wake);
  // The frame's AwaitFrame streams send `complete` and the image, or the
  // rows now complete.
  if (wake) Wake(*frame);
  return s;
}

grpc::Status DisplayService::AddDeposits(const v1::DepositBatch& batch, FrameState& f, bool* wake) {
  absl::MutexLock lock(&f.mu);
  if (f.aborted) {
    metrics_->Add("transtick_display_deposits_refused_total", 1);
    return ToGrpc(absl::FailedPreconditionError(absl::StrCat(
        "display: frame ", f.id, " was aborted (", f.abort_reason, "); its deposits are refused")));
  }
  if (!f.fb) {
    metrics_->Add("transtick_display_deposits_refused_total", 1);
    return ToGrpc(absl::FailedPreconditionError(
        absl::StrCat("display: frame ", f.id, " is complete; deposits after it are refused")));
  }
  f.last_activity = Clock::now();
  auto added = AddPackedDeposits(batch.packed(), *f.fb);
  if (!added.ok()) {
    metrics_->Add("transtick_display_deposits_refused_total", 1);
    return ToGrpc(absl::InvalidArgumentError(absl::StrCat("display: ", added.status().message())));
  }
  f.deposits += added->deposits;
  metrics_->Add("transtick_display_deposits_total", static_cast<double>(added->deposits));
  metrics_->Add("transtick_display_pixel_records_total", static_cast<double>(added->records));
  metrics_->Add("transtick_display_deposit_bytes_total",
                static_cast<double>(batch.packed().size()));
  if (f.fb->Complete()) {
    *wake = true;
    metrics_->Add("transtick_display_frames_total", 1, {{"result", "complete"}});
    metrics_->Observe("transtick_display_frame_assembly_seconds", Seconds(Clock::now() - f.begun));
  } else if (const int rows = f.fb->CompleteRows();
             rows >= f.woken_rows + EarlyChunkRows(f.width, f.height, f.pixel_bytes)) {
    // Enough rows complete for an early chunk.
    f.woken_rows = rows;
    *wake = true;
  }
  return grpc::Status::OK;
}

namespace {

grpc::Status Aborted(uint64_t id, const std::string& why) {
  return ToGrpc(absl::AbortedError(
      absl::StrCat("display: frame ", id, " was aborted", why.empty() ? "" : ": ", why)));
}

}  // namespace

grpc::Status DisplayService::ImageStatus(const FrameState& f) {
  if (f.aborted) return Aborted(f.id, f.abort_reason);
  if (!f.fb) {
    return ToGrpc(absl::FailedPreconditionError(
        absl::StrCat("display: frame ", f.id, " was complete and its image already sent")));
  }
  return grpc::Status::OK;
}

// One AwaitFrame call: progress while the frame traces, and the image's
// first rows as they complete, up to the bytes asked for; then `complete`
// (the root ends the workers' frame on it), then the rest of the image in
// chunks of rows, each resolved from the framebuffer when the previous one
// is out. Step() decides the next message under the frame's lock and
// starts it after unlocking; no reaction ever waits. Owns itself until
// OnDone.
class DisplayService::AwaitStream : public grpc::ServerWriteReactor<v1::FrameProgress> {
 public:
  AwaitStream(DisplayService* service, std::shared_ptr<FrameState> frame, bool no_image,
              uint64_t early_bytes, v1::ImageEncoding encoding)
      : service_(service),
        frame_(std::move(frame)),
        no_image_(no_image),
        rgb8_(encoding == v1::RGB8),
        pixel_bytes_(PixelBytes(encoding)),
        early_left_(no_image ? 0 : early_bytes) {}

  // Joins `frame`'s watchers and takes the first step.
  static AwaitStream* Start(DisplayService* service, std::shared_ptr<FrameState> frame,
                            bool no_image, uint64_t early_bytes, v1::ImageEncoding encoding) {
    auto stream = std::make_shared<AwaitStream>(service, frame, no_image, early_bytes, encoding);
    stream->self_ = stream;
    {
      absl::MutexLock lock(&frame->mu);
      frame->watchers.push_back(stream);
      if (!no_image) frame->pixel_bytes = stream->pixel_bytes_;
    }
    stream->Step(/*tick=*/false);
    return stream.get();
  }

  // Looks at the frame again; with `tick`, an incomplete frame's progress
  // is sent (unless a message is on its way already).
  void Step(bool tick) {
    enum class Act { kNone, kWrite, kFinish } act = Act::kNone;
    grpc::Status status;
    bool release = false;
    {
      absl::MutexLock lock(&frame_->mu);
      tick_ = tick_ || tick;
      if (writing_ || finished_) return;
      if (cancelled_) {
        status = ToGrpc(absl::CancelledError("the root cancelled its AwaitFrame"));
        act = Act::kFinish;
      } else if (!sent_complete_) {
        if (frame_->aborted || !frame_->fb) {
          status = ImageStatus(*frame_);
          act = Act::kFinish;
        } else if (!frame_->fb->Complete()) {
          if (const int r1 = EarlyChunkEnd(); r1 > next_row_) {
            early_left_ -=
                static_cast<uint64_t>(r1 - next_row_) * RowBytes(frame_->width, pixel_bytes_);
            Chunk(r1, false);
            act = Act::kWrite;
          } else if (tick_) {
            msg_ = Progress(frame_->fb->complete_pixels(), false);
            act = Act::kWrite;
          }
        } else {
          // Every deposit is in: the root hears it before the image is
          // resolved, so the workers end the frame while it is sent.
          sent_complete_ = true;
          msg_ = Progress(Total(), true);
          act = Act::kWrite;
        }
      } else if (no_image_ || next_row_ == frame_->height) {
        release = true;
        act = Act::kFinish;
      } else if (grpc::Status s = ImageStatus(*frame_); !s.ok()) {
        // Aborted, or its framebuffer released by another AwaitFrame.
        status = s;
        act = Act::kFinish;
      } else {
        Chunk(std::min(frame_->height, next_row_ + RowsPerChunk(frame_->width, pixel_bytes_)),
              true);
        act = Act::kWrite;
      }
      if (act == Act::kWrite) {
        writing_ = true;
        tick_ = false;
      }
      finished_ = act == Act::kFinish;
    }
    if (act == Act::kWrite) StartWrite(&msg_);
    if (act == Act::kFinish) {
      if (release) service_->Release(frame_);
      Finish(status);
    }
  }

  void OnWriteDone(bool ok) override {
    {
      absl::MutexLock lock(&frame_->mu);
      writing_ = false;
      cancelled_ = cancelled_ || !ok;
    }
    Step(/*tick=*/false);
  }

  void OnCancel() override {
    {
      absl::MutexLock lock(&frame_->mu);
      cancelled_ = true;
    }
    Step(/*tick=*/false);
  }

  void OnDone() override {
    {
      FrameState& f = *frame_;
      absl::MutexLock lock(&f.mu);
      std::erase_if(f.watchers, [this](const std::weak_ptr<AwaitStream>& w) {
        auto p = w.lock();
        return !p || p.get() == this;
      });
      f.last_activity = Clock::now();
    }
    // The last reference but the ones Wake may hold for a moment.
    auto self = std::move(self_);
  }

 private:
  uint64_t Total() const { return static_cast<uint64_t>(frame_->width) * frame_->height; }
  // Where an early chunk from next_row_ would end: the rows complete from
  // there, at most a chunk's and what is left of the bytes asked for; at
  // next_row_ when that is too few to send yet.
  int EarlyChunkEnd() ABSL_EXCLUSIVE_LOCKS_REQUIRED(frame_->mu) {
    const uint64_t row_bytes = RowBytes(frame_->width, pixel_bytes_);
    if (no_image_ || early_left_ < row_bytes) return next_row_;
    const int complete = frame_->fb->CompleteRows();
    const uint64_t fit = early_left_ / row_bytes;
    const int r1 = static_cast<int>(std::min<uint64_t>(
        {static_cast<uint64_t>(complete), next_row_ + fit,
         static_cast<uint64_t>(next_row_ + RowsPerChunk(frame_->width, pixel_bytes_))}));
    const bool enough =
        r1 - next_row_ >= EarlyChunkRows(frame_->width, frame_->height, pixel_bytes_) ||
        r1 == frame_->height;
    return enough ? r1 : next_row_;
  }
  // The image's rows [next_row_, r1) into msg_, resolved from the
  // framebuffer, as progress with `complete`.
  void Chunk(int r1, bool complete) ABSL_EXCLUSIVE_LOCKS_REQUIRED(frame_->mu) {
    const int r0 = next_row_;
    msg_ = Progress(complete ? Total() : frame_->fb->complete_pixels(), complete);
    v1::ImageChunk* c = msg_.mutable_image();
    c->set_width(frame_->width);
    c->set_height(frame_->height);
    c->set_row_begin(r0);
    c->set_row_end(r1);
    rows_.resize(static_cast<size_t>(r1 - r0) * frame_->width * 3);
    frame_->fb->ResolveRows(r0, r1, rows_.data());
    if (rgb8_) {
      std::string* out = c->mutable_rgb8();
      out->resize(rows_.size());
      for (size_t i = 0; i < rows_.size(); ++i) (*out)[i] = static_cast<char>(ToByte(rows_[i]));
    } else {
      AppendFloats(rows_.data(), rows_.size(), c->mutable_rgb());
    }
    next_row_ = r1;
  }
  v1::FrameProgress Progress(uint64_t done, bool complete) const {
    v1::FrameProgress p;
    p.set_pixels_done(done);
    p.set_pixels_total(Total());
    p.set_complete(complete);
    return p;
  }

  DisplayService* const service_;
  const std::shared_ptr<FrameState> frame_;
  const bool no_image_;
  const bool rgb8_;        // rows as RGB8, not FLOAT32
  const int pixel_bytes_;  // a pixel's bytes in a chunk
  // A chunk's rows, resolved (kept from chunk to chunk).
  std::vector<float> rows_ ABSL_GUARDED_BY(frame_->mu);
  // Bytes of image rows it may still send before the frame is complete.
  uint64_t early_left_ ABSL_GUARDED_BY(frame_->mu);
  std::shared_ptr<AwaitStream> self_;  // set by Start, dropped by OnDone
  v1::FrameProgress msg_ ABSL_GUARDED_BY(frame_->mu);  // the message being written
  bool writing_ ABSL_GUARDED_BY(frame_->mu) = false;
  bool finished_ ABSL_GUARDED_BY(frame_->mu) = false;
  bool cancelled_ ABSL_GUARDED_BY(frame_->mu) = false;
  bool tick_ ABSL_GUARDED_BY(frame_->mu) = false;  // progress asked for
  bool sent_complete_ ABSL_GUARDED_BY(frame_->mu) = false;
  int next_row_ ABSL_GUARDED_BY(frame_->mu) = 0;  // of the image, to send next
};

grpc::ServerWriteReactor<v1::FrameProgress>* DisplayService::AwaitFrame(
    grpc::CallbackServerContext* ctx, const v1::FrameRef* req) {
  if (grpc::Status s = RequireRole(*ctx, "AwaitFrame", {Role::kRoot}); !s.ok()) {
    return new RefusedWrite<v1::FrameProgress>(s);
  }
  std::shared_ptr<FrameState> frame = Find(req->frame_id());
  if (!frame) {
    absl::MutexLock lock(&mu_);
    if (const std::string* why = aborted_.Find(req->frame_id())) {
      return new RefusedWrite<v1::FrameProgress>(Aborted(req->frame_id(), *why));
    }
    return new RefusedWrite<v1::FrameProgress>(ToGrpc(
        absl::NotFoundError(absl::StrCat("display: frame ", req->frame_id(), " was not begun"))));
  }
  auto encoding = ToImageEncoding(req->image_encoding(), "display: image_encoding");
  if (!encoding.ok()) return new RefusedWrite<v1::FrameProgress>(ToGrpc(encoding.status()));
  return AwaitStream::Start(this, std::move(frame), req->no_image(), req->early_image_bytes(),
                            *encoding);
}

void DisplayService::Wake(FrameState& frame, bool tick) {
  std::vector<std::shared_ptr<AwaitStream>> streams;
  {
    absl::MutexLock lock(&frame.mu);
    for (const auto& w : frame.watchers) {
      if (auto p = w.lock()) streams.push_back(std::move(p));
    }
  }
  for (const auto& stream : streams) stream->Step(tick);
}

void DisplayService::Heartbeat() {
  std::vector<std::shared_ptr<FrameState>> frames;
  {
    absl::MutexLock lock(&mu_);
    for (const auto& [id, f] : frames_) frames.push_back(f);
  }
  for (const auto& f : frames) Wake(*f, /*tick=*/true);
}

void DisplayService::Release(const std::shared_ptr<FrameState>& frame) {
  // Workers' deposit streams hold the frame state, not the framebuffer:
  // every deposit is in, so none will touch it again. It is cleared here,
  // outside the locks, so that the next frame's BeginFrame need not.
  std::unique_ptr<Framebuffer> fb;
  {
    absl::MutexLock frame_lock(&frame->mu);
    fb = std::move(frame->fb);
  }
  if (fb) fb->Clear();
  absl::MutexLock lock(&mu_);
  if (auto it = frames_.find(frame->id); it != frames_.end() && it->second == frame) {
    frames_.erase(it);
  }
  if (fb) {
    spares_.push_back({std::move(fb), Clock::now()});
    TrimSparesLocked(OpenBytesLocked(), kMaxSpares);
  }
}

grpc::ServerUnaryReactor* DisplayService::AbortFrame(grpc::CallbackServerContext* ctx,
                                                     const v1::FrameRef* req, v1::FrameAck*) {
  grpc::ServerUnaryReactor* reactor = ctx->DefaultReactor();
  grpc::Status s = RequireRole(*ctx, "AbortFrame", {Role::kRoot});
  if (s.ok()) Abort(req->frame_id(), req->reason());
  reactor->Finish(s);
  return reactor;
}

void DisplayService::AbortIncomplete(FrameState& frame, const std::string& why) {
  if (!MarkAborted(frame, why, /*unless_complete=*/true)) return;
  spdlog::warn("display: frame {} aborted: {}", frame.id, why);
  absl::MutexLock lock(&mu_);
  if (auto it = frames_.find(frame.id); it != frames_.end() && it->second.get() == &frame) {
    frames_.erase(it);
  }
  aborted_.Remember(frame.id, why);
}

bool DisplayService::MarkAborted(FrameState& frame, const std::string& why, bool unless_complete) {
  {
    absl::MutexLock lock(&frame.mu);
    if (frame.aborted || (unless_complete && (!frame.fb || frame.fb->Complete()))) return false;
    frame.aborted = true;
    frame.abort_reason = why;
    metrics_->Add("transtick_display_frames_total", 1, {{"result", "aborted"}});
    // Deposit streams may hold the frame for a while; its memory goes now.
    frame.fb.reset();
  }
  Wake(frame);  // its AwaitFrame streams end with the reason
  return true;
}

Clock::time_point DisplayService::LastActive(FrameState& frame, Clock::time_point now) {
  absl::MutexLock lock(&frame.mu);
  return frame.watchers.empty() ? frame.last_activity : now;
}

void DisplayService::Abort(uint64_t id, const std::string& reason) {
  std::shared_ptr<FrameState> frame;
  {
    absl::MutexLock lock(&mu_);
    auto it = frames_.find(id);
    if (it == frames_.end()) return;
    frame = it->second;
    frames_.erase(it);
    aborted_.Remember(id, reason);
  }
  if (!reason.empty()) spdlog::warn("display: frame {} aborted: {}", id, reason);
  MarkAborted(*frame, reason);
}

void DisplayService::ExpireIdle() {
  const auto now = Clock::now();
  std::vector<std::pair<std::shared_ptr<FrameState>, std::string>> expired;
  {
    absl::MutexLock lock(&mu_);
    for (auto it = frames_.begin(); it != frames_.end();) {
      const Clock::time_point active = LastActive(*it->second, now);
      // Time the display did not run is not the frame's idleness.
      const Clock::duration idle = now - active - sweeper_.PausedSince(active);
      if (idle <= options_.idle) {
        ++it;
        continue;
      }
      std::string why = absl::StrFormat(
          "expired: no deposit and no call for %.1f s (the display's limit is %.1f s)",
          Seconds(idle), Seconds(options_.idle));
      aborted_.Remember(it->first, why);
      expired.emplace_back(std::move(it->second), std::move(why));
      it = frames_.erase(it);
    }
    std::erase_if(spares_, [&](const Spare& s) { return now - s.since > options_.idle; });
  }
  for (auto& [frame, why] : expired) {
    spdlog::warn("display: frame {} {}; its {:.1f} MB framebuffer is freed", frame->id, why,
                 Mb(frame->bytes));
    MarkAborted(*frame, why);
  }
}

}  // namespace transtick
