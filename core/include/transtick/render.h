// Renders one image in this process with a pool of threads: the reference
// every distributed render must equal bit for bit.
#ifndef TRANSTICK_RENDER_H_
#define TRANSTICK_RENDER_H_

#include <cstdint>
#include <functional>

#include "absl/status/statusor.h"
#include "transtick/camera.h"
#include "transtick/framebuffer.h"
#include "transtick/scene.h"
#include "transtick/tracer.h"

namespace transtick {

// One frame asked of the renderer: where the camera is and how to render.
// The services convert a view from the API into this once, at each edge
// (api/convert.h, ToFrameRequest), and pass it on.
struct FrameRequest {
  CameraSpec camera;
  RenderSettings settings;
};

struct RenderStats {
  double frame_ms = 0;
  int threads = 0;
  TraceCounters counters;
};

// Called now and then from the calling thread with (pixels done, total).
using ProgressFn = std::function<void(uint64_t, uint64_t)>;

// threads = 0 uses one per core.
absl::StatusOr<Image> RenderLocal(const Scene& scene, const Camera& camera,
                                  const RenderSettings& settings, int threads, RenderStats* stats,
                                  const ProgressFn& progress = {});

// Traces every ray of the pixels in rows [row_begin, row_end) to completion
// in a scene that holds the whole volume, depositing into `fb`, which holds
// the image's rows from `fb_row` on (pixel p of the image is fb's pixel
// p - fb_row * width): every deposit of a pixel is made here, so a band of
// rows is all a caller needs.
// REQUIRES: fb_row <= row_begin, row_end <= fb_row + fb.height().
void TraceRows(const Tracer& tracer, const Camera& camera, int row_begin, int row_end,
               Framebuffer& fb, int fb_row, TraceCounters& counters);

}  // namespace transtick

#endif  // TRANSTICK_RENDER_H_
