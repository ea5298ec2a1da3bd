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

#include "cluster.grpc.pb.h"
#include "transtick/framebuffer.h"

namespace transtick {

// BeginFrame, AbortFrame and Deposits, the stream every worker sends its
// finished rays on, use gRPC's callback API. AwaitFrame, which waits for a
// frame to complete, keeps the sync API and its thread pool.
class DisplayService final
    : public v1::Display::WithCallbackMethod_BeginFrame<v1::Display::WithCallbackMethod_AbortFrame<
          v1::Display::WithCallbackMethod_Deposits<v1::Display::Service>>> {
 public:
  // Frames larger than `max_frame_pixels` are refused.
  explicit DisplayService(uint64_t max_frame_pixels = uint64_t{8192} * 8192);

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
    FrameState(uint64_t i, std::unique_ptr<Framebuffer> f) : id(i), fb(std::move(f)) {}
    const uint64_t id;
    std::mutex mu;
    std::condition_variable cv;
    std::unique_ptr<Framebuffer> fb;  // guarded by mu; null once the image is out
    bool aborted = false;             // guarded by mu
    std::string abort_reason;         // guarded by mu
    uint64_t deposits = 0;            // guarded by mu
  };
  std::shared_ptr<FrameState> Find(uint64_t id);
  grpc::Status Begin(const v1::DisplayFrame& req);
  void Abort(uint64_t id, const std::string& reason);
  // Aborts `frame` unless it is complete (or aborted) already.
  void AbortIncomplete(FrameState& frame, const std::string& why);
  // Adds a batch's deposits to its frame; `frame` caches the frame of the
  // stream's last batch.
  grpc::Status Accumulate(const v1::DepositBatch& batch, std::shared_ptr<FrameState>* frame);

  const uint64_t max_frame_pixels_;
  std::mutex mu_;
  std::map<uint64_t, std::shared_ptr<FrameState>> frames_;  // guarded by mu_
  std::unique_ptr<Framebuffer> spare_;  // guarded by mu_: a finished frame's, for reuse
  // Why recently aborted frames were aborted, for an AwaitFrame that comes
  // after the abort; the newest kMaxAborted only.
  static constexpr size_t kMaxAborted = 256;
  std::map<uint64_t, std::string> aborted_;                    // guarded by mu_
  void RememberAbort(uint64_t id, const std::string& reason);  // REQUIRES: mu_ held
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_DISPLAY_DISPLAY_SERVICE_H_
