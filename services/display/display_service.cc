#include "display_service.h"

#include <spdlog/spdlog.h>

#include <bit>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/time/time.h"
#include "rpc_status.h"
#include "transtick/ray_codec.h"

namespace transtick {
namespace {

// Image rows per chunk: keeps messages near 1 MB whatever the width.
int RowsPerChunk(int width) { return std::max(1, (1 << 20) / (width * 12)); }

double Mb(uint64_t bytes) { return bytes / 1048576.0; }
double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

}  // namespace

DisplayService::DisplayService(DisplayOptions options)
    : options_(options), sweeper_(SweepPeriod(options.idle), [this] { ExpireIdle(); }) {}

size_t DisplayService::open_frames() const {
  absl::MutexLock lock(&mu_);
  return frames_.size();
}

uint64_t DisplayService::framebuffer_bytes() const {
  absl::MutexLock lock(&mu_);
  return OpenBytesLocked() +
         (spare_ ? Framebuffer::MemoryBytes(spare_->width(), spare_->height()) : 0);
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

grpc::ServerUnaryReactor* DisplayService::BeginFrame(grpc::CallbackServerContext* ctx,
                                                     const v1::DisplayFrame* req, v1::FrameAck*) {
  grpc::ServerUnaryReactor* reactor = ctx->DefaultReactor();
  reactor->Finish(Begin(*req));
  return reactor;
}

grpc::Status DisplayService::Begin(const v1::DisplayFrame& req) {
  if (req.width() < 1 || req.height() < 1 ||
      static_cast<uint64_t>(req.width()) * req.height() > options_.max_frame_pixels) {
    return ToGrpc(absl::InvalidArgumentError(
        absl::StrCat("display: frame size ", req.width(), "x", req.height(), " is out of range")));
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
    // again: faulting in fresh pages for every frame costs more. A spare of
    // another size goes when keeping it would pass the limit.
    std::unique_ptr<Framebuffer> fb;
    if (spare_ && spare_->width() == req.width() && spare_->height() == req.height()) {
      fb = std::move(spare_);
      fb->Clear();
    } else {
      if (spare_ && open + bytes + Framebuffer::MemoryBytes(spare_->width(), spare_->height()) >
                        options_.max_bytes) {
        spare_.reset();
      }
      fb = std::make_unique<Framebuffer>(req.width(), req.height());
    }
    frames_[req.frame_id()] = std::make_shared<FrameState>(req.frame_id(), std::move(fb));
  }
  if (evicted) {
    spdlog::warn("display: frame {} {}", evicted->id, why);
    MarkAborted(*evicted, why);
  }
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
    grpc::Status s = service_->Accumulate(batch_, &frame_);
    if (!s.ok()) {
      Finish(s);
      return;
    }
    StartRead(&batch_);
  }

  void OnDone() override { delete this; }

 private:
  DisplayService* const service_;
  grpc::CallbackServerContext* const ctx_;
  v1::DepositBatch batch_;
  std::shared_ptr<FrameState> frame_;  // of the last batch
};

grpc::ServerReadReactor<v1::DepositBatch>* DisplayService::Deposits(
    grpc::CallbackServerContext* ctx, v1::FrameAck*) {
  return new DepositStream(this, ctx);
}

grpc::Status DisplayService::Accumulate(const v1::DepositBatch& batch,
                                        std::shared_ptr<FrameState>* frame_cache) {
  std::shared_ptr<FrameState>& frame = *frame_cache;
  if (!frame || batch.frame_id() != frame->id) frame = Find(batch.frame_id());
  // A worker's first message names its frame and carries nothing: it may
  // come after the other workers have completed the frame.
  if (batch.deposits().empty()) {
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
  FrameState& f = *frame;
  // An AwaitFrame waiting for completion looks again when this unlocks.
  absl::MutexLock lock(&f.mu);
  if (f.aborted) {
    return ToGrpc(absl::FailedPreconditionError(absl::StrCat(
        "display: frame ", f.id, " was aborted (", f.abort_reason, "); its deposits are refused")));
  }
  if (!f.fb) {
    return ToGrpc(absl::FailedPreconditionError(
        absl::StrCat("display: frame ", f.id, " is complete; deposits after it are refused")));
  }
  f.last_activity = Clock::now();
  const uint32_t limit =
      static_cast<uint32_t>(f.fb->width()) * static_cast<uint32_t>(f.fb->height());
  auto deposits = DecodeDeposits(batch.deposits(), limit);
  if (!deposits.ok()) {
    return ToGrpc(
        absl::InvalidArgumentError(absl::StrCat("display: ", deposits.status().message())));
  }
  for (const Deposit& d : *deposits) f.fb->Add(d);
  f.deposits += deposits->size();
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

grpc::Status DisplayService::WaitUntilOver(FrameState& f, grpc::ServerContext& ctx,
                                           grpc::ServerWriter<v1::FrameProgress>& writer) {
  // fb is null here only when the frame was aborted or another AwaitFrame
  // took the image.
  auto over = [&f]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(f.mu) {
    return f.aborted || !f.fb || f.fb->Complete();
  };
  while (!f.mu.AwaitWithTimeout(absl::Condition(&over), absl::Milliseconds(250))) {
    if (ctx.IsCancelled()) return ToGrpc(absl::CancelledError("cancelled"));
    v1::FrameProgress p;
    p.set_pixels_done(f.fb->complete_pixels());
    p.set_pixels_total(static_cast<uint64_t>(f.width) * f.height);
    f.mu.Unlock();
    writer.Write(p);
    f.mu.Lock();
  }
  return ImageStatus(f);
}

grpc::Status DisplayService::AwaitFrame(grpc::ServerContext* ctx, const v1::FrameRef* req,
                                        grpc::ServerWriter<v1::FrameProgress>* writer) {
  std::shared_ptr<FrameState> frame = Find(req->frame_id());
  if (!frame) {
    absl::MutexLock lock(&mu_);
    if (const std::string* why = aborted_.Find(req->frame_id())) {
      return Aborted(req->frame_id(), *why);
    }
    return ToGrpc(
        absl::NotFoundError(absl::StrCat("display: frame ", req->frame_id(), " was not begun")));
  }
  FrameState& f = *frame;
  const uint64_t total = static_cast<uint64_t>(f.width) * f.height;
  Image image;
  {
    absl::MutexLock lock(&f.mu);
    // While a root waits for the frame it does not expire: the root's own
    // deadline and watchdog govern it.
    ++f.waiters;
    grpc::Status waited = WaitUntilOver(f, *ctx, *writer);
    --f.waiters;
    f.last_activity = Clock::now();
    if (!waited.ok()) return waited;
    // Every deposit is in: the root hears it before the image is resolved,
    // so the workers end the frame while the image is made and sent.
    v1::FrameProgress done;
    done.set_pixels_done(total);
    done.set_pixels_total(total);
    done.set_complete(true);
    f.mu.Unlock();
    writer->Write(done);
    f.mu.Lock();
    // The frame may have been aborted, and its framebuffer freed, meanwhile.
    if (grpc::Status s = ImageStatus(f); !s.ok()) return s;
    // A balancing prerender wants to know the frame is done, not its image.
    if (!req->no_image()) image = f.fb->Resolve();
  }
  {
    absl::MutexLock lock(&mu_);
    frames_.erase(req->frame_id());
    // Workers' deposit streams hold the frame state, not the framebuffer:
    // every deposit is in, so none will touch it again.
    absl::MutexLock frame_lock(&f.mu);
    spare_ = std::move(f.fb);
    spare_since_ = Clock::now();
  }
  if (req->no_image()) return grpc::Status::OK;
  const int rows = RowsPerChunk(image.width);
  for (int r0 = 0; r0 < image.height; r0 += rows) {
    const int r1 = std::min(image.height, r0 + rows);
    v1::FrameProgress p;
    p.set_pixels_done(total);
    p.set_pixels_total(total);
    p.set_complete(true);
    v1::ImageChunk* c = p.mutable_image();
    c->set_width(image.width);
    c->set_height(image.height);
    c->set_row_begin(r0);
    c->set_row_end(r1);
    AppendFloats(image.rgb.data() + static_cast<size_t>(r0) * image.width * 3,
                 static_cast<size_t>(r1 - r0) * image.width * 3, c->mutable_rgb());
    if (!writer->Write(p)) return ToGrpc(absl::CancelledError("root went away"));
  }
  return grpc::Status::OK;
}

grpc::ServerUnaryReactor* DisplayService::AbortFrame(grpc::CallbackServerContext* ctx,
                                                     const v1::FrameRef* req, v1::FrameAck*) {
  Abort(req->frame_id(), req->reason());
  grpc::ServerUnaryReactor* reactor = ctx->DefaultReactor();
  reactor->Finish(grpc::Status::OK);
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
  absl::MutexLock lock(&frame.mu);  // an AwaitFrame waiting looks again when this unlocks
  if (frame.aborted || (unless_complete && (!frame.fb || frame.fb->Complete()))) return false;
  frame.aborted = true;
  frame.abort_reason = why;
  // Deposit streams may hold the frame for a while; its memory goes now.
  frame.fb.reset();
  return true;
}

Clock::time_point DisplayService::LastActive(FrameState& frame, Clock::time_point now) {
  absl::MutexLock lock(&frame.mu);
  return frame.waiters > 0 ? now : frame.last_activity;
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
      const Clock::duration idle = now - LastActive(*it->second, now);
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
    if (spare_ && now - spare_since_ > options_.idle) spare_.reset();
  }
  for (auto& [frame, why] : expired) {
    spdlog::warn("display: frame {} {}; its {:.1f} MB framebuffer is freed", frame->id, why,
                 Mb(frame->bytes));
    MarkAborted(*frame, why);
  }
}

}  // namespace transtick
