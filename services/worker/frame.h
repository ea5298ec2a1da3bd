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
#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/status.h"
#include "absl/synchronization/mutex.h"
#include "clock.h"
#include "cluster.grpc.pb.h"
#include "frame_waiters.h"
#include "transtick/camera.h"
#include "transtick/ray.h"
#include "transtick/ring_layout.h"
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
  // Whether rays wait here, read without the lock: a moment old at most.
  bool waiting() const { return waiting_.load(std::memory_order_relaxed); }

 private:
  mutable absl::Mutex mu_;
  std::atomic<bool> waiting_{false};  // size_ > 0, for readers without mu_
  std::deque<std::vector<RayDescriptor>> batches_ ABSL_GUARDED_BY(mu_);
  size_t front_used_ ABSL_GUARDED_BY(mu_) = 0;  // rays of batches_.front() taken
  size_t size_ ABSL_GUARDED_BY(mu_) = 0;        // rays in batches_, less front_used_
  size_t high_water_ ABSL_GUARDED_BY(mu_) = 0;
  bool woken_ ABSL_GUARDED_BY(mu_) = false;
};

// Byte buffers for batches, kept once written for the next batches and
// frames: a batch of 2048 rays is 213 KB and a deposit batch up to 1.3 MB,
// and a fresh buffer for each grew by doubling, copied and faulted its
// pages in anew, frame after frame (bench/turntable.sh). Holds at most
// `max_bytes` of capacity. Thread-safe.
class BufferPool {
 public:
  explicit BufferPool(size_t max_bytes) : max_bytes_(max_bytes) {}
  // The process's pool, of 16 MB: a frame has two buffers or so for each
  // of its three streams in use at once.
  static BufferPool& Shared();

  // An empty buffer of at least `capacity`: a kept one when one is big
  // enough, else a new one.
  std::string Take(size_t capacity);
  // Keeps `buffer` (emptied) when it is at least 64 KB and fits.
  void Give(std::string buffer);
  size_t held_bytes() const;

 private:
  const size_t max_bytes_;
  mutable absl::Mutex mu_;
  std::vector<std::string> free_ ABSL_GUARDED_BY(mu_);
  size_t bytes_ ABSL_GUARDED_BY(mu_) = 0;
};

// Encoded records waiting to go out on one stream, with at most one write
// in flight. Producers append and never block; a batch goes out when the
// stream is free and one is ready: `batch_records` pending, or the oldest
// pending record older than `linger` (looked at whenever records are
// appended or a write completes), or anything pending after Flush or
// Close. Once closed and drained, the stream is half-closed. Thread-safe.
class Outbox {
 public:
  // Starts writing one batch; the stream calls WriteDone when it is written.
  using StartWrite = std::function<void(std::string batch)>;

  Outbox(size_t record_bytes, size_t batch_records, std::chrono::microseconds linger)
      : record_bytes_(record_bytes), batch_records_(batch_records), linger_(linger) {}

  // Connects the stream. `done` half-closes it, called once, after Close
  // and the last write (or after a failed write). With `busy`, a write the
  // stream started itself (its first message) is in flight.
  // REQUIRES: called once.
  void Attach(StartWrite write, std::function<void()> done, bool busy);
  // The stream's write completed; `ok` false means the stream is broken:
  // what is pending and all later records are dropped (and counted).
  // `spent` is the written batch's buffer, back for reuse.
  void WriteDone(bool ok, std::string spent = {});

  void Append(const std::string& records);
  // Sends what is pending as soon as the stream is free, without waiting
  // for a full batch or the linger (when the producers have nothing more
  // to add for a while).
  void Flush();
  void Close();

  // Records dropped because the stream broke.
  uint64_t dropped() const;

 private:
  // Starts the next write, or the half-close, if one is due, and releases
  // mu_ before it calls the stream.
  void Pump() ABSL_UNLOCK_FUNCTION(mu_);

  const size_t record_bytes_;
  const size_t batch_records_;
  const std::chrono::microseconds linger_;
  mutable absl::Mutex mu_;
  std::string pending_ ABSL_GUARDED_BY(mu_);
  Clock::time_point first_pending_ ABSL_GUARDED_BY(mu_);
  bool flush_ ABSL_GUARDED_BY(mu_) = false;
  bool closed_ ABSL_GUARDED_BY(mu_) = false;
  bool in_flight_ ABSL_GUARDED_BY(mu_) = false;
  bool failed_ ABSL_GUARDED_BY(mu_) = false;
  bool done_called_ ABSL_GUARDED_BY(mu_) = false;
  uint64_t dropped_ ABSL_GUARDED_BY(mu_) = 0;
  // Empty until Attach sets them, under mu_, once; then never changed, and
  // called without mu_ (Pump calls them only once it saw them set, under
  // mu_). Not annotated: the compiler cannot express "written once".
  StartWrite write_;
  std::function<void()> done_;
};

// The frames one worker traces at once share its cores in order
// (docs/design.md, "Overlapped frames"): interactive frames first, then in
// the order they started here. A frame's tracers trace only while no frame
// ahead of it has work on this worker: rays in its inbox, primary rays not
// yet made, or a tracer in the middle of a unit of work. The root can so
// start a job's next frame while the last one still traces: the next one
// fills what the last one's tail leaves idle (rays in flight to and from
// its neighbours, the display and the root ending it), and gives the cores
// back within a few rays when the last one's rays come. Thread-safe.
class TraceOrder {
 public:
  class Member {
   public:
    // Whether it has work here that the frames behind it wait for.
    virtual bool HasWork() const = 0;

   protected:
    ~Member() = default;
  };

  // A frame that starts tracing joins; its place, which Leave takes.
  // REQUIRES: `member` stays valid until Leave.
  uint64_t Join(const Member* member, bool interactive);
  void Leave(uint64_t place);
  // Whether a frame ahead of `place` has work now.
  bool Behind(uint64_t place) const;
  // Returns once nothing is ahead of `place`, on Notify or Leave, or after
  // `timeout`.
  void Wait(uint64_t place, std::chrono::milliseconds timeout);
  // A frame's work here ran out (or it ends): the frames behind it look
  // again.
  void Notify();
  int frames() const { return members_.load(std::memory_order_relaxed); }

 private:
  struct Entry {
    uint64_t place;
    bool interactive;
    const Member* member;
  };
  bool BehindLocked(uint64_t place) const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  mutable absl::Mutex mu_;
  uint64_t next_ ABSL_GUARDED_BY(mu_) = 0;
  std::vector<Entry> frames_ ABSL_GUARDED_BY(mu_);
  uint64_t generation_ ABSL_GUARDED_BY(mu_) = 0;  // moved on by Notify and Leave
  std::atomic<int> members_{0};                   // frames_.size(), read without mu_
  std::atomic<int> waiting_{0};                   // tracers in Wait
};

struct FrameOptions {
  int threads = 1;
  // Shared by the frames of one worker; none: the frame traces whenever
  // it has work.
  std::shared_ptr<TraceOrder> order;
  // Ray batches to a neighbour: a neighbour may be waiting for these rays.
  size_t batch_rays = 2048;
  std::chrono::microseconds linger{1000};
  // Deposit batches to the display (20-byte records, so at most 1.3 MB per
  // message). They are only needed by the end of the frame, when idle
  // tracers flush them at once; fewer, larger messages cost less. Measured
  // on cthead 400x400 with 2 workers: 65536 records and 5 ms against 4096
  // and 1 ms made the frame 3.5-4.5% faster.
  size_t deposit_batch = 65536;
  std::chrono::microseconds deposit_linger{5000};
};

// Thread-safe. Lifecycle: constructed on PrepareFrame, Start on RunFrame,
// the left neighbour's stream attached when it opens (NewLeftStream), End
// once. The streams use gRPC's callback API: their reactions only move
// batches between the network and the inbox and outboxes.
class Frame final : public std::enable_shared_from_this<Frame>, public TraceOrder::Member {
 public:
  // REQUIRES: the scene outlives the frame (the frame shares ownership);
  // spec.cuts() valid for the scene's planes (ValidCuts), with the scene
  // holding slab spec.index() of them (WorkerService::Prepare checks both).
  // `camera` and `settings` are spec.view() converted (and checked).
  Frame(const v1::FrameSpec& spec, std::shared_ptr<const Scene> scene, Camera camera,
        const RenderSettings& settings, const FrameOptions& options);
  ~Frame();
  Frame(const Frame&) = delete;
  Frame& operator=(const Frame&) = delete;

  uint64_t id() const { return spec_.frame_id(); }
  // Whether the left neighbour's stream has attached.
  bool left_attached() const { return left_attached_.load(); }
  // Rays received from the left neighbour so far.
  uint64_t rays_received_left() const;
  // Whether Start was called.
  bool running() const { return started_; }
  // When the frame last saw a call, a ray batch from a neighbour or a unit
  // of traced work: what the worker's expiry of idle frames looks at.
  Clock::time_point last_activity() const {
    return Clock::time_point(Clock::duration(last_activity_.load(std::memory_order_relaxed)));
  }
  // Work here that the frames behind it wait for (TraceOrder): rays in the
  // inbox, primary rays not yet made, or a tracer in a unit.
  bool HasWork() const override;
  // Frame objects alive in this process. An ended frame is destroyed once
  // its tracer threads have stopped and its streams have let go of it.
  static int64_t alive() { return alive_; }

  // Starts tracing, and opens the streams to the display and to the right
  // neighbour; `started` is called once the stream to the neighbour has
  // sent its first message, or failed to.
  void Start(std::function<void(absl::Status)> started);

  // The server side of a Rays stream opened by a left neighbour: its first
  // batch names the frame, which `find` looks up. A frame not found yet
  // may be a moment away (prepared in the same round as the neighbour that
  // sent the batch): the stream then parks in `waiters` until the frame is
  // added there, reading no further meanwhile.
  static grpc::ServerBidiReactor<v1::RayBatch, v1::RayBatch>* NewLeftStream(
      grpc::CallbackServerContext* ctx, std::function<std::shared_ptr<Frame>(uint64_t)> find,
      FrameWaiters* waiters);

  // Stops tracing, closes the streams and calls `done` with this frame's
  // statistics: at once when no tracer runs, else from the last tracer
  // thread to stop, within one ray (every ray is bounded). Never blocks, so
  // a gRPC reaction may call it. With `cancel`, rays still in flight are
  // dropped and every stream cancelled, the left neighbour's included.
  // REQUIRES: called once, End included.
  void EndAsync(bool cancel, std::function<void(v1::WorkerFrameStats)> done);
  // EndAsync, waiting for the statistics. Not from a gRPC reaction.
  v1::WorkerFrameStats End(bool cancel);

 private:
  struct Link;  // one neighbour: outbox, counters
  template <typename Stream>
  class ClientCall;
  class LeftStream;
  class RightStream;
  class DisplayStream;

  void TraceLoop(int thread_index);
  void LeaveOrder();  // leaves options_.order, once
  // A tracer thread has left TraceLoop; the last one ends a frame whose end
  // was asked for.
  void TracerStopped();
  // Closes the streams and gathers the statistics. REQUIRES: no tracer runs.
  v1::WorkerFrameStats Finish(bool cancel);
  // Fills `out` with the next primary rays entering this slab, and queues
  // onto `deposits` the misses this slab deposits (RingLayout::Primaries;
  // counted in the work profile `plane_work` when it is not null); false
  // when every pixel has been generated.
  bool NextPrimaries(std::vector<RayDescriptor>* out, std::string* deposits, uint64_t* plane_work);
  void ReceiveBatch(const v1::RayBatch& batch, Link& from);
  // Counts `count` invalid records from the `side` neighbour; the first
  // time, logs why and aborts the frame at the display.
  void Reject(uint64_t count, const char* side, const std::string& why);
  // Claims the left link for a neighbour's stream, whose server context is
  // `ctx`: false when this frame already has one. A frame cancelled by then
  // cancels the stream at once.
  bool AttachLeft(grpc::CallbackServerContext* ctx);
  // The left neighbour's stream is done: its context goes away.
  void DetachLeft();
  void Touch(Clock::time_point now) {
    last_activity_.store(now.time_since_epoch().count(), std::memory_order_relaxed);
  }

  const v1::FrameSpec spec_;
  const std::shared_ptr<const Scene> scene_;
  const Camera camera_;
  const FrameOptions options_;
  const Tracer tracer_;
  const int samples_;  // primary rays per pixel
  const uint32_t pixel_limit_;
  const int64_t pixels_in_rows_;  // pixels of this ring's rows
  // The ring's slabs under this frame's view: which primary rays this
  // worker makes (those of its own slab's footprint that enter its slab)
  // and which neighbour a ray leaving the slab goes to.
  const RingLayout layout_;

  Inbox inbox_;
  std::unique_ptr<Link> left_, right_;
  Outbox deposits_;
  // Deposits packed for the display, and their bytes on the wire.
  std::atomic<uint64_t> deposits_sent_{0}, deposit_bytes_sent_{0};
  std::atomic<int64_t> next_pixel_{0};
  std::atomic<bool> stop_{false};
  std::atomic<bool> started_{false};
  // Tracers between taking work and finishing it.
  std::atomic<int> working_{0};
  // Its place in options_.order once started; left once no tracer runs.
  std::atomic<bool> in_order_{false};
  uint64_t order_place_ = 0;

  std::atomic<bool> cancelled_{false};
  std::atomic<uint64_t> rejected_{0};
  std::atomic<bool> reject_reported_{false};
  std::atomic<bool> left_attached_{false};
  // Written by tracers once per work unit: a line of its own.
  alignas(64) std::atomic<Clock::rep> last_activity_;
  static std::atomic<int64_t> alive_;

  absl::Mutex left_mu_;
  // The left neighbour's stream, while it is open.
  grpc::CallbackServerContext* left_ctx_ ABSL_GUARDED_BY(left_mu_) = nullptr;
  bool left_cancelled_ ABSL_GUARDED_BY(left_mu_) = false;

  // Streams this worker opened. Each owns itself until its OnDone.
  std::weak_ptr<RightStream> right_stream_;
  std::weak_ptr<DisplayStream> display_stream_;

  // How the frame ends: the last tracer to stop calls end_done_.
  absl::Mutex end_mu_;
  int running_tracers_ ABSL_GUARDED_BY(end_mu_) = 0;
  bool end_requested_ ABSL_GUARDED_BY(end_mu_) = false;
  bool end_cancel_ ABSL_GUARDED_BY(end_mu_) = false;
  std::function<void(v1::WorkerFrameStats)> end_done_ ABSL_GUARDED_BY(end_mu_);

  // Written by Start before the tracers start; read by Finish after them.
  Clock::time_point run_start_;
  // Per tracer thread, written by that thread only until joined.
  struct ThreadStats {
    double idle_ms = 0;
    double cpu_ms = 0;  // CPU time (CLOCK_THREAD_CPUTIME_ID) spent tracing
    TraceCounters counters;
    uint64_t primary = 0, shadow = 0;
    // counters.plane_work points here when the frame counts its work
    // profile (FrameSpec.work_profile); empty otherwise.
    std::vector<uint64_t> plane_work;
  };
  std::vector<ThreadStats> thread_stats_;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_WORKER_FRAME_H_
