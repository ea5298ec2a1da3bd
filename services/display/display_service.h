// The display: gathers deposits from every worker into frame buffers, knows
// when a frame is complete (per-pixel accounting, see Framebuffer), and
// hands the image to the root. Thread-safe.
#ifndef TRANSTICK_SERVICES_DISPLAY_DISPLAY_SERVICE_H_
#define TRANSTICK_SERVICES_DISPLAY_DISPLAY_SERVICE_H_

#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "clock.h"
#include "cluster.grpc.pb.h"
#include "expiry.h"
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
  // active: the root runs one frame at a time, so that one was abandoned.
  size_t max_frames = 4;
  // Bytes of open framebuffers. A BeginFrame that would pass it is refused
  // with RESOURCE_EXHAUSTED naming the sizes. Two frames of the largest size.
  uint64_t max_bytes = uint64_t{4} << 30;
  // A frame with no deposit and no call for this long (and no AwaitFrame
  // waiting for it: the root's deadline governs that) is aborted and its
  // framebuffer freed. Workers flush deposits within milliseconds of
  // tracing them, so a live frame is never this quiet. The spare
  // framebuffer kept for reuse is freed after as long unused.
  std::chrono::milliseconds idle = std::chrono::seconds(60);
};

// BeginFrame, AbortFrame and Deposits, the stream every worker sends its
// finished rays on, use gRPC's callback API. AwaitFrame, which waits for a
// frame to complete, keeps the sync API and its thread pool.
class DisplayService final
    : public v1::Display::WithCallbackMethod_BeginFrame<v1::Display::WithCallbackMethod_AbortFrame<
          v1::Display::WithCallbackMethod_Deposits<v1::Display::Service>>> {
 public:
  explicit DisplayService(DisplayOptions options = {});

  // Frames begun and neither finished nor aborted.
  size_t open_frames();
  // Bytes of framebuffers held: the open frames' and the spare one's.
  uint64_t framebuffer_bytes();

  grpc::ServerUnaryReactor* BeginFrame(grpc::CallbackServerContext* ctx,
                                       const v1::DisplayFrame* req, v1::FrameAck* reply) override;
  grpc::ServerReadReactor<v1::DepositBatch>* Deposits(grpc::CallbackServerContext* ctx,
                                                      v1::FrameAck* reply) override;
  grpc::Status AwaitFrame(grpc::ServerContext* ctx, const v1::FrameRef* req,
                          grpc::ServerWriter<v1::FrameProgress>* writer) override;
  grpc::ServerUnaryReactor* AbortFrame(grpc::CallbackServerContext* ctx, const v1::FrameRef* req,
                                       v1::FrameAck* reply) override;

 private:
  class DepositStream;
  struct FrameState {
    FrameState(uint64_t i, std::unique_ptr<Framebuffer> f)
        : id(i),
          width(f->width()),
          height(f->height()),
          bytes(Framebuffer::MemoryBytes(width, height)),
          fb(std::move(f)) {}
    const uint64_t id;
    const int width, height;
    const uint64_t bytes;  // of the framebuffer
    std::mutex mu;
    std::condition_variable cv;
    // Null once the image is out or the frame aborted.
    std::unique_ptr<Framebuffer> fb;                 // guarded by mu
    bool aborted = false;                            // guarded by mu
    std::string abort_reason;                        // guarded by mu
    uint64_t deposits = 0;                           // guarded by mu
    int waiters = 0;                                 // guarded by mu: AwaitFrame calls in progress
    Clock::time_point last_activity = Clock::now();  // guarded by mu
  };
  std::shared_ptr<FrameState> Find(uint64_t id);
  grpc::Status Begin(const v1::DisplayFrame& req);
  void Abort(uint64_t id, const std::string& reason);
  // Aborts `frame` unless it is complete (or aborted) already.
  void AbortIncomplete(FrameState& frame, const std::string& why);
  // Marks `frame` aborted and frees its framebuffer; with `unless_complete`,
  // not a frame whose deposits are all in. False when it did nothing.
  static bool MarkAborted(FrameState& frame, const std::string& why, bool unless_complete = false);
  // Aborts frames idle beyond the limit; frees a spare unused as long.
  void ExpireIdle();
  uint64_t OpenBytesLocked();  // REQUIRES: mu_ held
  // Adds a batch's deposits to its frame; `frame` caches the frame of the
  // stream's last batch.
  grpc::Status Accumulate(const v1::DepositBatch& batch, std::shared_ptr<FrameState>* frame);

  const DisplayOptions options_;
  std::mutex mu_;
  std::map<uint64_t, std::shared_ptr<FrameState>> frames_;  // guarded by mu_
  std::unique_ptr<Framebuffer> spare_;  // guarded by mu_: a finished frame's, for reuse
  Clock::time_point spare_since_;       // guarded by mu_
  // Why recently aborted frames were aborted, for an AwaitFrame that comes
  // after the abort.
  RecentReasons aborted_;  // guarded by mu_
  // Sweeps frames_ for idle frames; declared last, so that it stops first.
  Ticker sweeper_;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_DISPLAY_DISPLAY_SERVICE_H_
