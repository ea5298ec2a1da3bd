// One frame on the cluster, driven from the root: every worker of the
// layout prepares it while the display begins it, then the workers run it,
// the display reports progress and completion and streams the image, and
// the workers end it and report their statistics. Each call has its
// deadline; a failure aborts the frame everywhere. Thread-safe (frames may
// run concurrently).
#ifndef TRANSTICK_SERVICES_ROOT_FRAME_DRIVER_H_
#define TRANSTICK_SERVICES_ROOT_FRAME_DRIVER_H_

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "cluster.grpc.pb.h"
#include "datasets.h"
#include "registry.h"
#include "slabs.h"

namespace transtick {

// What one frame gave: the workers' statistics, in ring order.
struct FrameResult {
  uint64_t frame_id = 0;
  double frame_ms = 0;
  double started_unix = 0;  // when Run began, in seconds since the Unix epoch
  std::vector<v1::WorkerFrameStats> workers;
};

class FrameDriver {
 public:
  // Called with (pixels done, pixels total) while the frame runs.
  using ProgressFn = std::function<void(uint64_t, uint64_t)>;
  // Called with each chunk of the image as it arrives from the display, in
  // order, in Run's `image_encoding`; the bytes are the display's, passed
  // on without decoding. A non-OK return aborts the frame with that status.
  using ChunkFn = std::function<absl::Status(v1::ImageChunk chunk)>;

  // REQUIRES: `registry` outlives this. A frame fails when the display
  // sends nothing for `stall_timeout`, or a member's registration expires.
  FrameDriver(Registry& registry, std::string display, double frame_timeout_s,
              std::chrono::milliseconds stall_timeout = std::chrono::seconds(10));

  // Runs one frame of `view`. Without `on_chunk` (a balancing prerender)
  // the display sends no image, only completion. `on_traced`, when set, is
  // called once, on the calling thread, as soon as the display holds every
  // deposit (before the image comes and the workers report): the cluster's
  // tracers are free for the next frame from then on. The workers count
  // their work profiles (FrameSpec.work_profile) for a prerender and when
  // `work_profile` is set. `on_reported`, when set, is called once the
  // workers have ended the frame and reported, on another thread, while the
  // image may still be on its way: with the statistics Run would return
  // and the frame's time until then. It is not called when the frame
  // fails before every deposit is in. `on_running`, when set, is called
  // once every worker runs the frame, on the calling thread. An
  // `interactive` frame goes first on workers that trace several at once
  // (FrameSpec.interactive). Fails UNAVAILABLE
  // when a worker or the display failed (a failed worker is dropped from
  // the registry), CANCELLED when `cancelled()` turned true.
  absl::StatusOr<FrameResult> Run(
      const v1::View& view, const LoadedDataset& data, const Layout& layout,
      const std::function<bool()>& cancelled, const ProgressFn& on_progress,
      const ChunkFn& on_chunk, const std::function<void()>& on_traced = nullptr,
      bool work_profile = false,
      const std::function<void(const FrameResult&)>& on_reported = nullptr,
      v1::ImageEncoding image_encoding = v1::FLOAT32,
      const std::function<void()>& on_running = nullptr, bool interactive = false);

 private:
  Registry& registry_;
  const std::string display_;
  const double frame_timeout_s_;
  const std::chrono::milliseconds stall_timeout_;
  std::atomic<uint64_t> next_frame_id_;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_FRAME_DRIVER_H_
