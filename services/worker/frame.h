// One frame on a worker: the paper's Router, Buffer, Prim_Ray and Tracer
// processes. Rays arrive from the ring neighbours into the inbox, which has
// priority over new primary rays; tracer threads trace them through this
// worker's slab, send rays that leave it to the neighbour owning the next
// part of their path, and stream finished rays' deposits to the display. No
// tracer ever waits for a reply: every ray is a self-contained descriptor.
#ifndef TRANSTICK_SERVICES_WORKER_FRAME_H_
#define TRANSTICK_SERVICES_WORKER_FRAME_H_

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/status.h"
#include "cluster.grpc.pb.h"
#include "transtick/camera.h"
#include "transtick/ray.h"
#include "transtick/scene.h"
#include "transtick/tracer.h"

namespace transtick {

// Ray batches waiting to be traced. Thread-safe.
class Inbox {
 public:
  void Push(std::vector<RayDescriptor> rays);
  // Moves up to `max` rays into `out` (appending); false when empty.
  bool TryPop(size_t max, std::vector<RayDescriptor>* out);
  // Returns when rays arrive, on Wake(), or after `timeout`.
  void Wait(std::chrono::milliseconds timeout);
  void Wake();
  size_t high_water() const;

 private:
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::deque<std::vector<RayDescriptor>> batches_;  // guarded by mu_
  size_t front_used_ = 0;                           // guarded by mu_
  size_t size_ = 0;                                 // guarded by mu_
  size_t high_water_ = 0;                           // guarded by mu_
  bool woken_ = false;                              // guarded by mu_
};

// Encoded records waiting to go out on one stream, taken by its writer in
// batches: as soon as `batch_records` are pending, or `linger` after the
// first pending record, so the last partial batch of a frame never waits
// for more. Thread-safe.
class Outbox {
 public:
  Outbox(size_t record_bytes, size_t batch_records, std::chrono::microseconds linger)
      : record_bytes_(record_bytes), batch_records_(batch_records), linger_(linger) {}

  void Append(const std::string& records);
  // Sends what is pending now, without waiting for the linger (when the
  // producers have nothing more to add for a while).
  void Flush();
  // Blocks for the next batch; false once closed and drained.
  bool Take(std::string* batch);
  void Close();

 private:
  const size_t record_bytes_;
  const size_t batch_records_;
  const std::chrono::microseconds linger_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::string pending_;                                  // guarded by mu_
  std::chrono::steady_clock::time_point first_pending_;  // guarded by mu_
  bool flush_ = false;                                   // guarded by mu_
  bool closed_ = false;                                  // guarded by mu_
};

struct FrameOptions {
  int threads = 1;
  size_t batch_rays = 2048;
  std::chrono::microseconds linger{1000};
};

// Thread-safe. Lifecycle: constructed on PrepareFrame, Start on RunFrame,
// ServeLeft for the duration of the left neighbour's stream, End once.
class Frame {
 public:
  // REQUIRES: the scene outlives the frame (the frame shares ownership).
  Frame(const v1::FrameSpec& spec, std::shared_ptr<const Scene> scene, Camera camera,
        const FrameOptions& options);
  ~Frame();
  Frame(const Frame&) = delete;
  Frame& operator=(const Frame&) = delete;

  uint64_t id() const { return spec_.frame_id(); }

  // Connects to the right neighbour and the display, and starts tracing.
  absl::Status Start();

  // Serves the stream opened by the left neighbour (whose first message has
  // been read) until that neighbour closes it.
  grpc::Status ServeLeft(grpc::ServerReaderWriter<v1::RayBatch, v1::RayBatch>* stream);

  // Stops tracing, closes the streams and returns this frame's statistics.
  // With `cancel`, rays still in flight are dropped and streams cancelled.
  v1::WorkerFrameStats End(bool cancel);

 private:
  struct Link;  // one neighbour: outbox, counters

  void TraceLoop(int thread_index);
  // Fills `out` with the next primary rays entering this slab; false when
  // every pixel has been generated.
  bool NextPrimaries(std::vector<RayDescriptor>* out, std::vector<Deposit>* misses);
  void ReceiveBatch(const v1::RayBatch& batch, Link& from);
  void WriterLoop(Link& link, std::function<bool(const v1::RayBatch&)> write);

  const v1::FrameSpec spec_;
  const std::shared_ptr<const Scene> scene_;
  const Camera camera_;
  const FrameOptions options_;
  const Tracer tracer_;
  const uint32_t pixel_limit_;
  const int64_t pixels_in_rows_;  // pixels of this ring's rows
  // Each slab's footprint on the image (Camera::Footprint): the only pixels
  // whose primary rays can enter that slab. This worker generates the rays
  // of its own footprint only.
  const std::vector<ImageRect> footprints_;

  Inbox inbox_;
  std::unique_ptr<Link> left_, right_;
  Outbox deposits_;
  std::atomic<int64_t> next_pixel_{0};
  std::atomic<bool> stop_{false};
  std::atomic<bool> started_{false};

  // Streams this worker opened.
  std::unique_ptr<v1::Worker::Stub> right_stub_;
  std::unique_ptr<grpc::ClientContext> right_ctx_;
  std::unique_ptr<grpc::ClientReaderWriter<v1::RayBatch, v1::RayBatch>> right_stream_;
  std::unique_ptr<v1::Display::Stub> display_stub_;
  std::unique_ptr<grpc::ClientContext> display_ctx_;
  v1::FrameAck display_ack_;
  std::unique_ptr<grpc::ClientWriter<v1::DepositBatch>> display_stream_;

  std::vector<std::thread> tracers_;
  std::thread right_reader_, right_writer_, deposit_writer_;
  std::mutex left_mu_;
  std::condition_variable left_cv_;
  bool left_done_ = true;  // guarded by left_mu_: no left stream being served

  std::chrono::steady_clock::time_point run_start_;
  // Per tracer thread, written by that thread only until joined.
  struct ThreadStats {
    double idle_ms = 0;
    double cpu_ms = 0;  // CPU time (CLOCK_THREAD_CPUTIME_ID) spent tracing
    TraceCounters counters;
    uint64_t primary = 0, shadow = 0;
  };
  std::vector<ThreadStats> thread_stats_;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_WORKER_FRAME_H_
