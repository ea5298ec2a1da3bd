#include "transtick/render.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "transtick/check.h"

namespace transtick {

// Never inlined, so that it stays a symbol: bench/instructions.sh counts
// the instructions inside it (a call per task of two rows costs nothing).
[[gnu::noinline]] void TraceRows(const Tracer& tracer, const Camera& camera, int row_begin,
                                 int row_end, Framebuffer& fb, int fb_row,
                                 TraceCounters& counters) {
  TRANSTICK_CHECK(fb_row <= row_begin && row_end <= fb_row + fb.height() &&
                  fb.width() == camera.width());
  std::vector<RayDescriptor> pending;
  Deposit deposit;
  // Counted here and added once: the threads tracing other rows would
  // otherwise contend for the framebuffer's counter at every pixel.
  uint64_t completed = 0;
  const int width = camera.width();
  const int samples = fb.samples();
  const uint32_t first = static_cast<uint32_t>(fb_row) * width;  // fb's pixel 0
  auto add = [&](Deposit d) {
    d.pixel -= first;
    completed += fb.AddUncounted(d);
  };
  for (int py = row_begin; py < row_end; ++py) {
    for (int px = 0; px < width; ++px) {
      const uint32_t pixel = static_cast<uint32_t>(py) * width + px;
      if (tracer.Void(px, py)) {
        // Rays that would meet nothing are not made (Tracer::Void).
        for (int s = 0; s < samples; ++s) add(tracer.MissDeposit(pixel));
        counters.void_rays += samples;
        continue;
      }
      for (int s = 0; s < samples; ++s) {
        const auto [ox, oy] = SampleOffset(s, samples);
        RayDescriptor ray;
        if (!tracer.MakePrimary(camera.GenerateAt(px, py, ox, oy), pixel, &ray)) {
          add(tracer.MissDeposit(pixel));
          continue;
        }
        ++counters.primary;
        pending.push_back(ray);
        while (!pending.empty()) {
          RayDescriptor r = pending.back();
          pending.pop_back();
          // A whole-volume scene has no slab planes: every ray finishes
          // here, with a deposit for its own pixel, in fb's rows.
          TRANSTICK_CHECK(tracer.Trace(r, pending, deposit, counters) ==
                          Tracer::Outcome::kFinished);
          add(deposit);
        }
      }
    }
  }
  fb.CountCompleted(completed);
}

absl::StatusOr<Image> RenderLocal(const Scene& scene, const Camera& camera,
                                  const RenderSettings& settings, int threads, RenderStats* stats,
                                  const ProgressFn& progress) {
  if (scene.y_begin() != 0 || scene.y_end() != scene.dims()[1]) {
    return absl::InvalidArgumentError("RenderLocal needs a scene holding the whole volume");
  }
  if (auto s = CheckRenderSettings(settings, scene.mode(), scene.dims(), scene.spacing(),
                                   int64_t{camera.width()} * camera.height());
      !s.ok()) {
    return s;
  }
  if (threads <= 0) threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const auto start = std::chrono::steady_clock::now();
  const Tracer tracer(scene, settings, camera);
  const int width = camera.width(), height = camera.height();
  Image image;
  image.width = width;
  image.height = height;
  image.rgb.resize(static_cast<size_t>(width) * height * 3);
  constexpr int kRowsPerTask = 2;
  std::atomic<int> next_row{0};
  std::atomic<int> rows_done{0};
  std::vector<TraceCounters> counters(threads);
  auto work = [&](int id) {
    // Counted on the thread's stack: neighbouring counters in one vector
    // would share a cache line written at every traversal step.
    TraceCounters local;
    // Every deposit of a pixel is made while its row is traced, so each
    // task's rows are summed in a framebuffer of their own, which stays in
    // the cache, and resolved into the image by this thread when they are
    // done. A framebuffer of the whole image (32 bytes a pixel) was cleared
    // and resolved on one thread: a 2048x2048 cthead frame on 2 threads took
    // 1250-1285 ms with it against 1174-1215 now.
    Framebuffer band(width, kRowsPerTask, settings.samples);
    while (true) {
      int r0 = next_row.fetch_add(kRowsPerTask);
      if (r0 >= height) break;
      int r1 = std::min(r0 + kRowsPerTask, height);
      band.Clear(settings.samples);
      TraceRows(tracer, camera, r0, r1, band, r0, local);
      band.ResolveRows(0, r1 - r0, image.rgb.data() + static_cast<size_t>(r0) * width * 3);
      rows_done.fetch_add(r1 - r0);
    }
    counters[id] = local;
  };
  std::mutex mu;
  std::condition_variable done_cv;
  int finished_threads = 0;  // guarded by mu
  std::vector<std::thread> pool;
  for (int i = 0; i < threads; ++i) {
    pool.emplace_back([&, i] {
      work(i);
      std::lock_guard<std::mutex> lock(mu);
      ++finished_threads;
      done_cv.notify_all();
    });
  }
  if (progress) {
    // The calling thread only reports progress while the pool works.
    const uint64_t total = static_cast<uint64_t>(camera.height()) * camera.width();
    std::unique_lock<std::mutex> lock(mu);
    while (!done_cv.wait_for(lock, std::chrono::milliseconds(200),
                             [&] { return finished_threads == threads; })) {
      progress(static_cast<uint64_t>(rows_done.load()) * camera.width(), total);
    }
    progress(total, total);
  }
  for (auto& t : pool) t.join();
  if (stats) {
    stats->frame_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    stats->threads = threads;
    stats->counters = TraceCounters{};
    for (const auto& c : counters) stats->counters.Add(c);
  }
  return image;
}

}  // namespace transtick
