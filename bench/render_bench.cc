// render_bench: times RenderLocal on a real volume.
//
//   render_bench [--volume FILE] [--materials FILE | --transfer FILE [--step S]
//                [--skip on|off]] [--size WxH] [--repeat N] [--azimuth DEG[,DEG...]]
//                [--elevation DEG] [--shadows on|off] [--etr on|off] [--threads N]
//
// Loads the volume and builds the surfaces scene (or, with --transfer, the
// dvr scene of that transfer function, sampled every S world units) once, then for each view
// (frontal = azimuth 0, and azimuth 45; or the views --azimuth names) and for 1 thread
// and one per core (or only --threads N), renders once to warm up and then
// `repeat` timed frames. Prints a table of median and minimum frame times,
// rays per second (primary + shadow, from the tracer's counters) and the
// speed-up of all cores over one thread. In dvr the steps are the walk's
// segments, and the samples a frame shades are printed too.
//
// What the dvr walk's savings are worth: --skip off renders a scene whose
// every voxel is labelled visible (no empty space is skipped: the walk
// samples the whole volume), --etr off lets rays go on however opaque they
// have become (no early ray termination). Skipping must not change a bit of
// the image; the bench checks that against the scene that skips.
//
// Every frame of a view must equal the first bit for bit, whatever the
// thread count: the framebuffer sums in fixed point, so the thread schedule
// must not show. Any difference is reported and the exit status is 1.
//
// Defaults: cthead.nrrd in $TRANSTICK_DATA_DIR (else the repository's
// ../shared/data), examples/cthead_materials.json, 400x400, 5 repeats,
// shadows on.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "bench_util.h"
#include "convert.h"
#include "transtick/camera.h"
#include "transtick/parallel.h"
#include "transtick/render.h"
#include "transtick/scene.h"
#include "transtick/volume_io.h"

namespace transtick {
namespace {

using bench::Median;
using bench::MsSince;
using bench::ParseInt;
using bench::ParseSize;

constexpr char kUsage[] =
    "usage: render_bench [--volume FILE] [--materials FILE | --transfer FILE [--step S]\n"
    "                    [--skip on|off]] [--size WxH] [--repeat N] [--azimuth DEG[,DEG...]]\n"
    "                    [--elevation DEG] [--shadows on|off] [--etr on|off] [--threads N]\n"
    "  --transfer FILE dvr with this transfer function (JSON, docs/formats.md)\n"
    "  --step S        dvr sample step in world units (default half the smallest spacing)\n"
    "  --skip on|off   dvr: skip empty space (default on; off also checks the image)\n"
    "  --etr on|off    early ray termination (default on)\n"
    "  --azimuth DEG   only this view, or these views: DEG,DEG,... (default: 0 and 45)\n"
    "  --elevation DEG every view from this elevation (default 0; bench/turntable.sh: 15)\n"
    "  --shadows       shadow rays (default on)\n"
    "  --threads N     only N threads, 0 = one per core (default: 1 and one per core)\n";

struct Options {
  std::string volume;
  std::string materials = TRANSTICK_BENCH_MATERIALS;
  std::string transfer;  // dvr when set
  double step = 0;
  bool skip = true;
  bool etr = true;
  int width = 400;
  int height = 400;
  int repeat = 5;
  std::vector<double> azimuths = {0, 45};
  double elevation = 0;
  bool shadows = true;
  std::vector<int> threads;  // filled in Parse
};

std::string DefaultVolume() {
  const char* dir = std::getenv("TRANSTICK_DATA_DIR");
  return std::string(dir && *dir ? dir : TRANSTICK_BENCH_DATA_DIR) + "/cthead.nrrd";
}

// Returns an error message, empty on success.
std::string Parse(int argc, char** argv, Options* o) {
  o->volume = DefaultVolume();
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  o->threads = cores > 1 ? std::vector<int>{1, cores} : std::vector<int>{1};
  for (int i = 1; i < argc; ++i) {
    std::string flag = argv[i];
    if (flag == "--help" || flag == "-h") return "help";
    if (i + 1 >= argc) return flag + " needs a value (or is unknown)";
    std::string value = argv[++i];
    if (flag == "--volume") {
      o->volume = value;
    } else if (flag == "--materials") {
      o->materials = value;
    } else if (flag == "--transfer") {
      o->transfer = value;
    } else if (flag == "--skip" || flag == "--etr") {
      if (value != "on" && value != "off") return flag + " must be on or off";
      (flag == "--skip" ? o->skip : o->etr) = value == "on";
    } else if (flag == "--step") {
      char* end = nullptr;
      o->step = std::strtod(value.c_str(), &end);
      if (value.empty() || *end != '\0' || !(o->step > 0 && o->step < 1e6)) {
        return "--step must be a positive number of world units, got '" + value + "'";
      }
    } else if (flag == "--size") {
      if (!ParseSize(value, CameraSpec::kMaxImageSize, &o->width, &o->height)) {
        return "--size must be WxH with each in [1, 8192], got '" + value + "'";
      }
    } else if (flag == "--repeat") {
      if (!ParseInt(value, 1, 100000, &o->repeat)) {
        return "--repeat must be a positive integer, got '" + value + "'";
      }
    } else if (flag == "--azimuth") {
      o->azimuths.clear();
      for (size_t at = 0; at <= value.size();) {
        size_t comma = value.find(',', at);
        if (comma == std::string::npos) comma = value.size();
        const std::string one = value.substr(at, comma - at);
        char* end = nullptr;
        const double a = std::strtod(one.c_str(), &end);
        if (one.empty() || *end != '\0' || !std::isfinite(a)) {
          return "--azimuth takes numbers separated by commas, got '" + value + "'";
        }
        o->azimuths.push_back(a);
        at = comma + 1;
      }
    } else if (flag == "--elevation") {
      char* end = nullptr;
      o->elevation = std::strtod(value.c_str(), &end);
      if (value.empty() || *end != '\0' || !(o->elevation >= -90 && o->elevation <= 90)) {
        return "--elevation must be a number of degrees in [-90, 90], got '" + value + "'";
      }
    } else if (flag == "--shadows") {
      if (value != "on" && value != "off") return "--shadows must be on or off";
      o->shadows = value == "on";
    } else if (flag == "--threads") {
      int n = 0;
      if (!ParseInt(value, 0, 1024, &n)) return "--threads must be in [0, 1024]";
      o->threads = {n == 0 ? cores : n};
    } else {
      return "unknown flag " + flag;
    }
  }
  return "";
}

// Bit-for-bit equality of two float images (memcmp: -0 vs 0 and NaN payloads
// count as differences, as they would in a file).
bool SameBits(const Image& a, const Image& b, size_t* first_diff) {
  if (a.width != b.width || a.height != b.height || a.rgb.size() != b.rgb.size()) {
    *first_diff = 0;
    return false;
  }
  for (size_t i = 0; i < a.rgb.size(); ++i) {
    if (std::memcmp(&a.rgb[i], &b.rgb[i], sizeof(float)) != 0) {
      *first_diff = i;
      return false;
    }
  }
  return true;
}

bool SameCounters(const TraceCounters& a, const TraceCounters& b) {
  return a.primary == b.primary && a.shadow == b.shadow && a.segments == b.segments &&
         a.surface_hits == b.surface_hits && a.samples == b.samples && a.void_rays == b.void_rays;
}

int Run(const Options& o) {
  const bool dvr = !o.transfer.empty();
  absl::StatusOr<Classification> materials = Classification();
  absl::StatusOr<TransferFunction> transfer = TransferFunction();
  if (dvr) {
    transfer = LoadTransferFunction(o.transfer);
  } else {
    materials = LoadMaterials(o.materials);
  }
  const absl::Status parts = dvr ? transfer.status() : materials.status();
  if (!parts.ok()) {
    std::fprintf(stderr, "render_bench: %s\n", std::string(parts.message()).c_str());
    return 1;
  }
  auto t_load = std::chrono::steady_clock::now();
  auto volume = ReadVolume(o.volume);
  if (!volume.ok()) {
    std::fprintf(stderr, "render_bench: %s\n", std::string(volume.status().message()).c_str());
    return 1;
  }
  const double load_ms = MsSince(t_load);
  auto t_build = std::chrono::steady_clock::now();
  auto scene = dvr ? Scene::ForDvr(*volume, *transfer) : Scene::ForSurfaces(*volume, *materials);
  // Without skipping: the same dvr scene with every voxel visible.
  std::optional<Scene> skipping;
  if (dvr && !o.skip && scene.ok()) {
    const std::vector<uint8_t> visible(volume->values.size(), 1);
    auto all = Scene::FromParts(RenderMode::kDvr, volume->dims, volume->spacing, volume->Range(),
                                Sticks::Encode(visible, volume->dims, 0, volume->dims[1]),
                                volume->values, BrickMap::Build(visible, volume->dims, false),
                                Classification(), *transfer);
    if (!all.ok()) {
      std::fprintf(stderr, "render_bench: %s\n", std::string(all.status().message()).c_str());
      return 1;
    }
    skipping = *std::move(scene);
    scene = *std::move(all);
  }
  if (!scene.ok()) {
    std::fprintf(stderr, "render_bench: %s\n", std::string(scene.status().message()).c_str());
    return 1;
  }
  const double build_ms = MsSince(t_build);
  // The build again on one thread and on every core, alternated (the
  // first build above warmed the caches): the least time of each, and
  // whether both give the same scene.
  std::vector<double> build_ms_by[2];
  bool same_scene = true;
  const Scene& built = skipping ? *skipping : *scene;  // ForDvr's, with --skip off
  for (int round = 0; round < 3; ++round) {
    for (int all_cores = 0; all_cores < 2; ++all_cores) {
      SetBuildThreads(all_cores ? 0 : 1);
      const auto t = std::chrono::steady_clock::now();
      auto again =
          dvr ? Scene::ForDvr(*volume, *transfer) : Scene::ForSurfaces(*volume, *materials);
      build_ms_by[all_cores].push_back(MsSince(t));
      same_scene = same_scene && again.ok() && built.SameParts(*again);
    }
  }
  SetBuildThreads(0);

  const Sticks& sticks = scene->sticks();
  uint64_t encoded = 0;
  for (int by = 0; by < sticks.BlocksY(); ++by) {
    for (int bx = 0; bx < sticks.BlocksX(); ++bx) encoded += sticks.EncodeBlock(bx, by).size();
  }
  const uint64_t raw = volume->VoxelCount() * ScalarTypeSize(volume->source_type);
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));

  std::printf("volume     %s: %dx%dx%d %s, spacing %g %g %g\n", o.volume.c_str(), volume->dims[0],
              volume->dims[1], volume->dims[2],
              std::string(ScalarTypeName(volume->source_type)).c_str(), volume->spacing[0],
              volume->spacing[1], volume->spacing[2]);
  if (dvr) {
    std::printf("transfer   %s (dvr), step %g\n", o.transfer.c_str(), o.step);
  } else {
    std::printf("materials  %s\n", o.materials.c_str());
  }
  std::printf("load       %.1f ms\n", load_ms);
  std::printf("scene      built in %.1f ms (%s: labels, sticks, occupancy, scalars)\n", build_ms,
              dvr ? "dvr" : "surfaces");
  {
    const double one = *std::min_element(build_ms_by[0].begin(), build_ms_by[0].end());
    const double all = *std::min_element(build_ms_by[1].begin(), build_ms_by[1].end());
    std::printf("build      %.1f ms on 1 thread, %.1f ms on %d (%.2fx; least of 3, alternated)%s\n",
                one, all, BuildThreads(), one / all,
                same_scene ? "; the same scene" : "; THE SCENES DIFFER");
  }
  std::printf(
      "sticks     %zu sticks; encoded %.3f MB = %.2f%% of raw %.3f MB; "
      "in memory %.3f MB = %.2f%% of raw\n",
      sticks.StickCount(), encoded / 1e6, raw ? 100.0 * encoded / raw : 0.0, raw / 1e6,
      sticks.MemoryBytes() / 1e6, raw ? 100.0 * sticks.MemoryBytes() / raw : 0.0);
  std::printf("scene mem  %.3f MB (sticks, float scalars, brick map, field grid and summary)\n",
              scene->MemoryBytes() / 1e6);
  std::printf(
      "brick map  %zu bytes serialised (%zu bricks and the 2^3 cells of the mixed ones), "
      "%.3f MB in memory%s\n",
      scene->bricks().bytes().size(),
      static_cast<size_t>(scene->bricks().brick_dims()[0]) * scene->bricks().brick_dims()[1] *
          scene->bricks().brick_dims()[2],
      scene->bricks().MemoryBytes() / 1e6,
      scene->bricks().HoldsReach() ? " with its reach"
                                   : ", no reach (smooth surfaces walk the field's grid)");
  std::printf("frames     %dx%d, shadows %s, %d timed after 1 warm-up, %d cores\n\n", o.width,
              o.height, o.shadows ? "on" : "off", o.repeat, cores);

  std::printf(
      "%-9s %7s %10s %10s %14s %8s %8s %9s %10s %9s  %s%s\n", "view", "threads", "median ms",
      "min ms", "rays/s", "Mrays/s", "speedup", "Mrays/s/c", "steps/ray", "ns/step",
      "rays/frame (primary + shadow)",
      dvr ? ", samples/frame" : "; smooth surfaces: cells solved, hits; void rays not made");
  std::fflush(stdout);

  Vec3 extent{volume->dims[0] * volume->spacing[0], volume->dims[1] * volume->spacing[1],
              volume->dims[2] * volume->spacing[2]};
  RenderSettings settings;
  settings.shadows = o.shadows;
  settings.step = o.step;
  if (!o.etr) settings.min_transmittance = 0;
  // A build that differs on more threads fails the bench, as a frame that differs does.
  bool all_same = same_scene;
  for (double azimuth : o.azimuths) {
    CameraSpec spec;
    spec.azimuth_deg = azimuth;
    spec.elevation_deg = o.elevation;
    spec.width = o.width;
    spec.height = o.height;
    auto camera = Camera::Create(spec, extent);
    if (!camera.ok()) {
      std::fprintf(stderr, "render_bench: %s\n", std::string(camera.status().message()).c_str());
      return 1;
    }
    char view[32];
    std::snprintf(view, sizeof(view), azimuth == 0 ? "frontal" : "az%g", azimuth);
    Image reference;
    TraceCounters reference_counters;
    bool have_reference = false;
    double one_thread_median = 0;
    for (int threads : o.threads) {
      std::vector<double> ms;
      TraceCounters counters;
      for (int i = 0; i <= o.repeat; ++i) {  // i = 0 is the warm-up
        RenderStats stats;
        auto start = std::chrono::steady_clock::now();
        auto image = RenderLocal(*scene, *camera, settings, threads, &stats);
        const double frame_ms = MsSince(start);
        if (!image.ok()) {
          std::fprintf(stderr, "render_bench: %s\n", std::string(image.status().message()).c_str());
          return 1;
        }
        if (i > 0) ms.push_back(frame_ms);
        counters = stats.counters;
        if (!have_reference) {
          reference = *std::move(image);
          reference_counters = stats.counters;
          have_reference = true;
          if (skipping) {
            // Skipping empty space saves work, never changes a pixel.
            RenderStats skipped;
            auto want = RenderLocal(*skipping, *camera, settings, threads, &skipped);
            size_t diff = 0;
            if (!want.ok() || !SameBits(*want, reference, &diff)) {
              all_same = false;
              std::fprintf(stderr, "render_bench: %s: the image without skipping differs from "
                           "the one with it (value %zu)\n", view, diff);
            } else {
              std::printf("%-9s skipping: %llu samples and %llu steps a frame, without: %llu "
                          "and %llu (the same image)\n", view,
                          static_cast<unsigned long long>(skipped.counters.samples),
                          static_cast<unsigned long long>(skipped.counters.segments),
                          static_cast<unsigned long long>(stats.counters.samples),
                          static_cast<unsigned long long>(stats.counters.segments));
            }
          }
          continue;
        }
        size_t diff = 0;
        if (!SameBits(reference, *image, &diff)) {
          all_same = false;
          const size_t p = diff / 3;
          std::fprintf(stderr,
                       "render_bench: %s, %d threads, frame %d differs from the first frame: "
                       "pixel (%zu, %zu) channel %zu is %.9g, was %.9g\n",
                       view, threads, i, p % o.width, p / o.width, diff % 3,
                       diff < image->rgb.size() ? image->rgb[diff] : 0.0f,
                       diff < reference.rgb.size() ? reference.rgb[diff] : 0.0f);
        }
        if (!SameCounters(reference_counters, stats.counters)) {
          std::fprintf(stderr,
                       "render_bench: %s, %d threads, frame %d: counters differ from the first "
                       "frame (%llu+%llu rays, was %llu+%llu)\n",
                       view, threads, i, static_cast<unsigned long long>(stats.counters.primary),
                       static_cast<unsigned long long>(stats.counters.shadow),
                       static_cast<unsigned long long>(reference_counters.primary),
                       static_cast<unsigned long long>(reference_counters.shadow));
        }
      }
      const double median = Median(ms);
      const double min = *std::min_element(ms.begin(), ms.end());
      const uint64_t rays = counters.primary + counters.shadow;
      const double rays_per_s = median > 0 ? rays / (median / 1e3) : 0;
      if (threads == 1) one_thread_median = median;
      char speedup[16] = "-";
      if (threads != 1 && one_thread_median > 0) {
        std::snprintf(speedup, sizeof(speedup), "%.2fx", one_thread_median / median);
      }
      // Per core, and the whole frame's time (tracing, shading, pixels)
      // spread over its traversal steps.
      const double per_core = rays_per_s / threads;
      const double steps_per_ray = rays ? static_cast<double>(counters.segments) / rays : 0;
      const double ns_per_step =
          counters.segments ? median * 1e6 * threads / static_cast<double>(counters.segments) : 0;
      std::printf("%-9s %7d %10.1f %10.1f %14.0f %8.2f %8s %9.2f %10.1f %9.1f  %llu + %llu",
                  view, threads, median, min, rays_per_s, rays_per_s / 1e6, speedup,
                  per_core / 1e6, steps_per_ray, ns_per_step,
                  static_cast<unsigned long long>(counters.primary),
                  static_cast<unsigned long long>(counters.shadow));
      if (dvr) std::printf(", %llu", static_cast<unsigned long long>(counters.samples));
      if (counters.cells) {
        std::printf("; %llu cells solved, %llu hits; %llu void",
                    static_cast<unsigned long long>(counters.cells),
                    static_cast<unsigned long long>(counters.surface_hits),
                    static_cast<unsigned long long>(counters.void_rays));
      }
      std::printf("\n");
      std::fflush(stdout);
    }
  }
  if (!all_same) {
    std::printf(same_scene ? "\nFAIL: repeated renders are not bit-identical (see stderr)\n"
                           : "\nFAIL: the scene built on every core differs from the one built on "
                             "one thread\n");
    return 1;
  }
  std::printf("\nOK: every frame of a view is bit-identical (all thread counts)\n");
  return 0;
}

}  // namespace
}  // namespace transtick

int main(int argc, char** argv) {
  transtick::Options options;
  std::string error = transtick::Parse(argc, argv, &options);
  if (error == "help") {
    std::fputs(transtick::kUsage, stdout);
    return 0;
  }
  if (!error.empty()) {
    std::fprintf(stderr, "render_bench: %s\n%s", error.c_str(), transtick::kUsage);
    return 2;
  }
  return transtick::Run(options);
}
