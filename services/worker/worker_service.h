// The worker daemon's gRPC service: holds slabs of datasets between frames
// and runs frames (see frame.h). Thread-safe.
#ifndef TRANSTICK_SERVICES_WORKER_WORKER_SERVICE_H_
#define TRANSTICK_SERVICES_WORKER_WORKER_SERVICE_H_

#include <map>
#include <memory>
#include <string>

#include "metrics.h"
#include "absl/base/thread_annotations.h"
#include "absl/synchronization/mutex.h"
#include "cluster.grpc.pb.h"
#include "expiry.h"
#include "frame.h"
#include "frame_table.h"

namespace transtick {

struct WorkerOptions {
  std::string id;       // unique per process
  std::string address;  // as registered with the root (set_address changes it)
  int threads = 1;
  // Ray batches to the neighbours: rays per message and how long a partial
  // batch may wait (FrameOptions; --batch-rays, --linger-us).
  size_t batch_rays = FrameOptions().batch_rays;
  std::chrono::microseconds linger = FrameOptions().linger;
  uint64_t max_slab_bytes = uint64_t{8} << 30;
  FrameLimits frames;  // how many frames, and how long idle ones are kept
  // A neighbour's ray stream for a frame not prepared here yet waits this
  // long for it (the root prepares every worker in one round, and a worker
  // starts as soon as it has prepared); at most `early_streams` wait at once.
  std::chrono::milliseconds early_stream_wait{5000};
  size_t early_streams = 64;
};

// The frame's methods (PrepareFrame, RunFrame, EndFrame and the Rays
// stream that carries ray dataflow) use gRPC's callback API; loading and
// moving slabs, which read and build whole slabs, keep the sync API and
// its thread pool.
class WorkerService final
    : public v1::Worker::WithCallbackMethod_PrepareFrame<
          v1::Worker::WithCallbackMethod_RunFrame<v1::Worker::WithCallbackMethod_EndFrame<
              v1::Worker::WithCallbackMethod_Rays<v1::Worker::Service>>>> {
 public:
  explicit WorkerService(WorkerOptions options);
  ~WorkerService() override;

  void set_address(const std::string& address);
  // Cancels every frame in progress and refuses ray streams that come
  // before their frame (on shutdown).
  void CancelAll();
  // The worker's metrics (docs/formats.md, "Metrics"), for /metrics.
  const std::shared_ptr<Metrics>& metrics() const { return metrics_; }
  // Frames prepared and not yet ended, expired or evicted.
  size_t frames_held() const { return frames_.size(); }
  // Whether frame `id` is held and its left neighbour's stream attached.
  bool LeftAttached(uint64_t id) {
    auto frame = FindFrame(id);
    return frame && frame->left_attached();
  }
  // Rays frame `id` has received from its left neighbour (0 when not held).
  uint64_t RaysReceivedLeft(uint64_t id) {
    auto frame = FindFrame(id);
    return frame ? frame->rays_received_left() : 0;
  }

  grpc::Status LoadSlab(grpc::ServerContext* ctx, grpc::ServerReader<v1::SlabChunk>* reader,
                        v1::LoadReply* reply) override;
  grpc::Status Evict(grpc::ServerContext* ctx, const v1::DatasetRef* req,
                     v1::FrameAck* reply) override;
  grpc::Status Reslab(grpc::ServerContext* ctx, const v1::ReslabRequest* req,
                      v1::LoadReply* reply) override;
  grpc::Status FetchPlanes(grpc::ServerContext* ctx, const v1::PlanesRequest* req,
                           grpc::ServerWriter<v1::SlabChunk>* writer) override;
  grpc::ServerUnaryReactor* PrepareFrame(grpc::CallbackServerContext* ctx,
                                         const v1::FrameSpec* spec, v1::FrameAck* reply) override;
  grpc::ServerUnaryReactor* RunFrame(grpc::CallbackServerContext* ctx, const v1::FrameRef* req,
                                     v1::FrameAck* reply) override;
  grpc::ServerUnaryReactor* EndFrame(grpc::CallbackServerContext* ctx, const v1::FrameRef* req,
                                     v1::WorkerFrameStats* reply) override;
  grpc::ServerBidiReactor<v1::RayBatch, v1::RayBatch>* Rays(
      grpc::CallbackServerContext* ctx) override;

 private:
  std::shared_ptr<Frame> FindFrame(uint64_t id);
  grpc::Status Prepare(const v1::FrameSpec& spec);
  // Starts frame `id` and finishes `reactor` once the stream to the right
  // neighbour is open (`reply->running` set), or at once, NOT_FOUND with
  // `missing`, when the frame is not held.
  void Start(grpc::ServerUnaryReactor* reactor, uint64_t id, v1::FrameAck* reply,
             const char* missing);
  // Ends, cancelled, a frame a limit took out of the table, and says why.
  static void Drop(FrameTable::Dropped dropped);
  // A frame's NOT_FOUND, saying why it is gone when a limit dropped it.
  grpc::Status NotHere(uint64_t id, const char* what) const;
  std::shared_ptr<const Scene> FindDataset(const std::string& key);

  const WorkerOptions options_;  // options_.address is only the first address_
  const std::shared_ptr<Metrics> metrics_;
  absl::Mutex mu_;
  std::string address_ ABSL_GUARDED_BY(mu_);
  std::map<std::string, std::shared_ptr<const Scene>> datasets_ ABSL_GUARDED_BY(mu_);
  FrameTable frames_;  // thread-safe by itself
  // Its frames trace oldest first (thread-safe by itself).
  const std::shared_ptr<TraceOrder> order_ = std::make_shared<TraceOrder>();
  // Ray streams that came before their frame (thread-safe by itself).
  FrameWaiters early_;
  // Sweeps frames_ for idle frames; declared last, so that it stops first.
  Ticker sweeper_;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_WORKER_WORKER_SERVICE_H_
