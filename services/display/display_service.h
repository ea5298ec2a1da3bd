// The display: gathers deposits from every worker into frame buffers, knows
// when a frame is complete (per-pixel accounting, see Framebuffer), and
// hands the image to the root. Thread-safe.
#ifndef TRANSTICK_SERVICES_DISPLAY_DISPLAY_SERVICE_H_
#define TRANSTICK_SERVICES_DISPLAY_DISPLAY_SERVICE_H_

#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>

#include "cluster.grpc.pb.h"
#include "transtick/framebuffer.h"

namespace transtick {

class DisplayService final : public v1::Display::Service {
 public:
  // Frames larger than `max_frame_pixels` are refused.
  explicit DisplayService(uint64_t max_frame_pixels = uint64_t{8192} * 8192);

  grpc::Status BeginFrame(grpc::ServerContext* ctx, const v1::DisplayFrame* req,
                          v1::FrameAck* reply) override;
  grpc::Status Deposits(grpc::ServerContext* ctx, grpc::ServerReader<v1::DepositBatch>* reader,
                        v1::FrameAck* reply) override;
  grpc::Status AwaitFrame(grpc::ServerContext* ctx, const v1::FrameRef* req,
                          grpc::ServerWriter<v1::FrameProgress>* writer) override;
  grpc::Status AbortFrame(grpc::ServerContext* ctx, const v1::FrameRef* req,
                          v1::FrameAck* reply) override;

 private:
  struct FrameState {
    explicit FrameState(std::unique_ptr<Framebuffer> f) : fb(std::move(f)) {}
    std::mutex mu;
    std::condition_variable cv;
    std::unique_ptr<Framebuffer> fb;  // guarded by mu; null once the image is out
    bool aborted = false;   // guarded by mu
    uint64_t deposits = 0;  // guarded by mu
  };
  std::shared_ptr<FrameState> Find(uint64_t id);

  const uint64_t max_frame_pixels_;
  std::mutex mu_;
  std::map<uint64_t, std::shared_ptr<FrameState>> frames_;  // guarded by mu_
  std::unique_ptr<Framebuffer> spare_;  // guarded by mu_: a finished frame's, for reuse
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_DISPLAY_DISPLAY_SERVICE_H_
