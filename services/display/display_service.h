// The display: gathers deposits from every worker into frame buffers, knows
// when a frame is complete (per-pixel accounting, see Framebuffer), and
// hands the image to the root. Thread-safe.
#ifndef TRANSTICK_SERVICES_DISPLAY_DISPLAY_SERVICE_H_
#define TRANSTICK_SERVICES_DISPLAY_DISPLAY_SERVICE_H_

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/synchronization/mutex.h"
#include "clock.h"
#include "cluster.grpc.pb.h"
#include "expiry.h"
#include "frame_waiters.h"
#include "metrics.h"
#include "transtick/framebuffer.h"

namespace transtick {

// How much the display holds for frames that the root began. A framebuffer
// takes 32 bytes a pixel (2 GiB at the largest size), so a root that begins
// frames and never finishes them, crashed or hostile, must not make the
// display hold them for ever.
struct DisplayOptions {
  // Frames larger than this are refused.
  uint64_t max_frame_pixels = uint64_t{8192} * 8192;
  // Open framebuffers. Beginning one more evicts (aborts) the least recently
  // active: the root traces one frame at a time (two in flight at most),
  // so that one was abandoned.
  size_t max_frames = 4;
  // Bytes of open framebuffers. A BeginFrame that would pass it is refused
  // with RESOURCE_EXHAUSTED naming the sizes. Two frames of the largest size.
  uint64_t max_bytes = uint64_t{4} << 30;
  // A frame with no deposit and no call for this long (and no AwaitFrame
  // waiting for it: the root's deadline governs that) is aborted and its
  // framebuffer freed. Workers flush deposits within milliseconds of
  // tracing them, so a live frame is never this quiet. A spare
  // framebuffer kept for reuse is freed after as long unused.
  std::chrono::milliseconds idle = std::chrono::seconds(60);
  // Deposits for a frame not begun yet wait this long for its BeginFrame
  // (the root begins the frame in the same round as the workers prepare and
  // start it); at most `early_streams` streams wait at once.
  std::chrono::milliseconds early_deposit_wait{5000};
  size_t early_streams = 64;
};

// Every method uses gRPC's callback API, and no reaction waits: a deposit
// that completes a frame or more of its rows, an abort, or the 250 ms
// heartbeat wakes the frame's AwaitFrame streams, and each sends its image
// a chunk at a time, resolving the chunk's rows from the framebuffer as it
// goes.
class DisplayService final
    : public v1::Display::WithCallbackMethod_BeginFrame<v1::Display::WithCallbackMethod_AbortFrame<
          v1::Display::WithCallbackMethod_Deposits<
              v1::Display::WithCallbackMethod_AwaitFrame<v1::Display::Service>>>> {
 public:
  explicit DisplayService(DisplayOptions options = {});

  // Frames begun and neither finished nor aborted.
  size_t open_frames() const;
  // Bytes of framebuffers held: the open frames' and the spares'.
  uint64_t framebuffer_bytes() const;
  // The display's metrics (docs/formats.md, "Metrics"), for /metrics.
  const std::shared_ptr<Metrics>& metrics() const { return metrics_; }

  grpc::ServerUnaryReactor* BeginFrame(grpc::CallbackServerContext* ctx,
                                       const v1::DisplayFrame* req, v1::FrameAck* reply) override;
  grpc::ServerReadReactor<v1::DepositBatch>* Deposits(grpc::CallbackServerContext* ctx,
                                                      v1::FrameAck* reply) override;
  grpc::ServerWriteReactor<v1::FrameProgress>* AwaitFrame(grpc::CallbackServerContext* ctx,
                                                          const v1::FrameRef* req) override;
  grpc::ServerUnaryReactor* AbortFrame(grpc::CallbackServerContext* ctx, const v1::FrameRef* req,
                                       v1::FrameAck* reply) override;

 private:
  class DepositStream;
  class AwaitStream;
  struct FrameState {
    FrameState(uint64_t i, std::unique_ptr<Framebuffer> f)
        : id(i),
          width(f->width()),
          height(f->height()),
          bytes(Framebuffer::MemoryBytes(width, height)),
          begun(Clock::now()),
          fb(std::move(f)) {}
    // Constant after construction.
    const uint64_t id;
    const int width, height;
    const uint64_t bytes;           // of the framebuffer
    const Clock::time_point begun;  // BeginFrame

    // Taken after the service's mu_ when both are held.
    absl::Mutex mu;
    // Null once the image is out or the frame aborted.
    std::unique_ptr<Framebuffer> fb ABSL_GUARDED_BY(mu);
    bool aborted ABSL_GUARDED_BY(mu) = false;
    std::string abort_reason ABSL_GUARDED_BY(mu);
    uint64_t deposits ABSL_GUARDED_BY(mu) = 0;
    // The rows complete from the top when the AwaitFrame streams were last
    // woken for them (early image chunks), and the bytes a pixel of those
    // chunks takes (the encoding the last AwaitFrame asked for).
    int woken_rows ABSL_GUARDED_BY(mu) = 0;
    int pixel_bytes ABSL_GUARDED_BY(mu) = 12;
    // The AwaitFrame streams in progress; each leaves when it is done.
    std::vector<std::weak_ptr<AwaitStream>> watchers ABSL_GUARDED_BY(mu);
    Clock::time_point last_activity ABSL_GUARDED_BY(mu) = Clock::now();
  };
  std::shared_ptr<FrameState> Find(uint64_t id) ABSL_LOCKS_EXCLUDED(mu_);
  // Whether frame `id` may still begin: not begun, and not aborted lately.
  bool MayBegin(uint64_t id) ABSL_LOCKS_EXCLUDED(mu_);
  grpc::Status Begin(const v1::DisplayFrame& req) ABSL_LOCKS_EXCLUDED(mu_);
  void Abort(uint64_t id, const std::string& reason) ABSL_LOCKS_EXCLUDED(mu_);
  // Aborts `frame` unless it is complete (or aborted) already.
  void AbortIncomplete(FrameState& frame, const std::string& why) ABSL_LOCKS_EXCLUDED(mu_);
  // Marks `frame` aborted and frees its framebuffer; with `unless_complete`,
  // not a frame whose deposits are all in. False when it did nothing.
  bool MarkAborted(FrameState& frame, const std::string& why, bool unless_complete = false)
      ABSL_LOCKS_EXCLUDED(frame.mu);
  // When `frame` was last active: now while a root awaits it.
  static Clock::time_point LastActive(FrameState& frame, Clock::time_point now)
      ABSL_LOCKS_EXCLUDED(frame.mu);
  // OK when the frame's framebuffer is still here; else why it is not.
  static grpc::Status ImageStatus(const FrameState& frame) ABSL_EXCLUSIVE_LOCKS_REQUIRED(frame.mu);
  // Lets every AwaitFrame stream of `frame` look at it again; `tick` asks
  // those of an incomplete frame to send their progress.
  static void Wake(FrameState& frame, bool tick = false) ABSL_LOCKS_EXCLUDED(frame.mu);
  // Sends progress on every AwaitFrame stream: the root's sign of life.
  void Heartbeat() ABSL_LOCKS_EXCLUDED(mu_);
  // Drops `frame`, whose image is out, keeping its framebuffer as a spare.
  void Release(const std::shared_ptr<FrameState>& frame) ABSL_LOCKS_EXCLUDED(mu_);
  // Aborts frames idle beyond the limit; frees spares unused as long.
  void ExpireIdle() ABSL_LOCKS_EXCLUDED(mu_);
  uint64_t OpenBytesLocked() const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  uint64_t SpareBytesLocked() const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  // A spare framebuffer of this size, cleared, or a new one, for which
  // spares of other sizes make room (TrimSparesLocked) beside the `open`
  // bytes of open frames.
  std::unique_ptr<Framebuffer> TakeFramebufferLocked(int width, int height, int samples,
                                                     uint64_t open)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  // Frees spares, the oldest first, while more than `most` are kept or they
  // and `held` bytes besides would pass the byte limit.
  void TrimSparesLocked(uint64_t held, size_t most) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  // Adds a batch's deposits to its frame; `frame` caches the frame of the
  // stream's last batch.
  grpc::Status Accumulate(const v1::DepositBatch& batch, std::shared_ptr<FrameState>* frame);
  // Adds a batch's deposits to `frame`; `wake` says whether its AwaitFrame
  // streams have something to send: the frame is complete after them, or
  // rows enough for an early image chunk are.
  grpc::Status AddDeposits(const v1::DepositBatch& batch, FrameState& frame, bool* wake)
      ABSL_LOCKS_EXCLUDED(frame.mu);

  const DisplayOptions options_;
  const std::shared_ptr<Metrics> metrics_;
  mutable absl::Mutex mu_;
  std::map<uint64_t, std::shared_ptr<FrameState>> frames_ ABSL_GUARDED_BY(mu_);
  // Finished frames' framebuffers, cleared for reuse, and since when, the
  // oldest first. Pipelined frames need more than one: the next frame
  // begins when the last has traced, while its image and the one before
  // may still be on their way (to a client that writes them to files).
  // Making a new framebuffer every frame faulted in its pages: a fifth of
  // the display's CPU in a 400x400 turntable (perf: 19.5% in BeginFrame).
  struct Spare {
    std::unique_ptr<Framebuffer> fb;
    Clock::time_point since;
  };
  static constexpr size_t kMaxSpares = 3;
  std::vector<Spare> spares_ ABSL_GUARDED_BY(mu_);
  // Why recently aborted frames were aborted, for an AwaitFrame that comes
  // after the abort.
  RecentReasons aborted_ ABSL_GUARDED_BY(mu_);
  // Deposit streams that came before their frame (thread-safe by itself).
  FrameWaiters early_;
  // Sweeps frames_ for idle frames, and beats for AwaitFrame; declared
  // last, so that they stop first.
  Ticker sweeper_;
  Ticker heartbeat_;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_DISPLAY_DISPLAY_SERVICE_H_
