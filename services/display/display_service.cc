#include "display_service.h"

#include <spdlog/spdlog.h>

#include <bit>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "rpc_status.h"
#include "transtick/ray_codec.h"

namespace transtick {
namespace {

// Image rows per chunk: keeps messages near 1 MB whatever the width.
int RowsPerChunk(int width) { return std::max(1, (1 << 20) / (width * 12)); }

}  // namespace

DisplayService::DisplayService(uint64_t max_frame_pixels) : max_frame_pixels_(max_frame_pixels) {}

std::shared_ptr<DisplayService::FrameState> DisplayService::Find(uint64_t id) {
  std::lock_guard<std::mutex> lock(mu_);
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
      static_cast<uint64_t>(req.width()) * req.height() > max_frame_pixels_) {
    return ToGrpc(absl::InvalidArgumentError(
        absl::StrCat("display: frame size ", req.width(), "x", req.height(), " is out of range")));
  }
  std::lock_guard<std::mutex> lock(mu_);
  if (frames_.count(req.frame_id())) {
    return ToGrpc(absl::AlreadyExistsError(
        absl::StrCat("display: frame ", req.frame_id(), " already begun")));
  }
  // A framebuffer of a finished frame of the same size is cleared and used
  // again: faulting in fresh pages for every frame costs more.
  std::unique_ptr<Framebuffer> fb;
  if (spare_ && spare_->width() == req.width() && spare_->height() == req.height()) {
    fb = std::move(spare_);
    fb->Clear();
  } else {
    fb = std::make_unique<Framebuffer>(req.width(), req.height());
  }
  frames_[req.frame_id()] = std::make_shared<FrameState>(req.frame_id(), std::move(fb));
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
  if (batch.deposits().empty()) return grpc::Status::OK;
  if (!frame) {
    return ToGrpc(
        absl::NotFoundError(absl::StrCat("display: frame ", batch.frame_id(), " was not begun")));
  }
  std::lock_guard<std::mutex> lock(frame->mu);
  if (!frame->fb) {
    return ToGrpc(absl::FailedPreconditionError(
        absl::StrCat("display: frame ", frame->id, " is complete; deposits after it are refused")));
  }
  const uint32_t limit =
      static_cast<uint32_t>(frame->fb->width()) * static_cast<uint32_t>(frame->fb->height());
  auto deposits = DecodeDeposits(batch.deposits(), limit);
  if (!deposits.ok()) {
    return ToGrpc(
        absl::InvalidArgumentError(absl::StrCat("display: ", deposits.status().message())));
  }
  bool completed = false;
  for (const Deposit& d : *deposits) completed |= frame->fb->Add(d);
  frame->deposits += deposits->size();
  if (completed && frame->fb->Complete()) frame->cv.notify_all();
  return grpc::Status::OK;
}

grpc::Status DisplayService::AwaitFrame(grpc::ServerContext* ctx, const v1::FrameRef* req,
                                        grpc::ServerWriter<v1::FrameProgress>* writer) {
  std::shared_ptr<FrameState> frame = Find(req->frame_id());
  if (!frame) {
    std::lock_guard<std::mutex> lock(mu_);
    if (auto it = aborted_.find(req->frame_id()); it != aborted_.end()) {
      return ToGrpc(
          absl::AbortedError(absl::StrCat("display: frame ", req->frame_id(), " was aborted",
                                          it->second.empty() ? "" : ": ", it->second)));
    }
    return ToGrpc(
        absl::NotFoundError(absl::StrCat("display: frame ", req->frame_id(), " was not begun")));
  }
  const uint64_t total = static_cast<uint64_t>(frame->fb->width()) * frame->fb->height();
  Image image;
  {
    std::unique_lock<std::mutex> lock(frame->mu);
    while (!frame->fb->Complete() && !frame->aborted) {
      frame->cv.wait_for(lock, std::chrono::milliseconds(250));
      if (ctx->IsCancelled()) return ToGrpc(absl::CancelledError("cancelled"));
      if (frame->fb->Complete() || frame->aborted) break;
      v1::FrameProgress p;
      p.set_pixels_done(frame->fb->complete_pixels());
      p.set_pixels_total(total);
      lock.unlock();
      writer->Write(p);
      lock.lock();
    }
    if (frame->aborted) {
      return ToGrpc(absl::AbortedError(
          absl::StrCat("display: frame ", req->frame_id(), " was aborted",
                       frame->abort_reason.empty() ? "" : ": ", frame->abort_reason)));
    }
    // Every deposit is in: the root hears it before the image is resolved,
    // so the workers end the frame while the image is made and sent.
    v1::FrameProgress done;
    done.set_pixels_done(total);
    done.set_pixels_total(total);
    done.set_complete(true);
    lock.unlock();
    writer->Write(done);
    lock.lock();
    // A balancing prerender wants to know the frame is done, not its image.
    if (!req->no_image()) image = frame->fb->Resolve();
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    frames_.erase(req->frame_id());
    // Workers' deposit streams hold the frame state, not the framebuffer:
    // every deposit is in, so none will touch it again.
    std::lock_guard<std::mutex> frame_lock(frame->mu);
    spare_ = std::move(frame->fb);
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
  {
    std::lock_guard<std::mutex> lock(frame.mu);
    if (!frame.fb || frame.fb->Complete() || frame.aborted) return;
    frame.aborted = true;
    frame.abort_reason = why;
    frame.cv.notify_all();
  }
  spdlog::warn("display: frame {} aborted: {}", frame.id, why);
  std::lock_guard<std::mutex> lock(mu_);
  frames_.erase(frame.id);
  RememberAbort(frame.id, why);
}

void DisplayService::RememberAbort(uint64_t id, const std::string& reason) {
  aborted_[id] = reason;
  while (aborted_.size() > kMaxAborted) aborted_.erase(aborted_.begin());
}

void DisplayService::Abort(uint64_t id, const std::string& reason) {
  std::shared_ptr<FrameState> frame;
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = frames_.find(id);
    if (it == frames_.end()) return;
    frame = it->second;
    frames_.erase(it);
    RememberAbort(id, reason);
  }
  if (!reason.empty()) spdlog::warn("display: frame {} aborted: {}", id, reason);
  std::lock_guard<std::mutex> lock(frame->mu);
  frame->aborted = true;
  frame->abort_reason = reason;
  frame->cv.notify_all();
}

}  // namespace transtick
