// transtick: the command-line client.
//
//   transtick render --volume FILE [--materials FILE | --transfer FILE] ...
//   transtick info --volume FILE
//
// Run `transtick help` for every flag.

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <string>

#include "absl/strings/str_cat.h"
#include "convert.h"
#include "flags.h"
#include "transtick/camera.h"
#include "transtick/image_io.h"
#include "transtick/render.h"
#include "transtick/scene.h"
#include "transtick/volume_io.h"

namespace transtick {
namespace {

constexpr char kUsage[] = R"(transtick: a volume ray tracer (sticks, ray dataflow)

usage:
  transtick render --volume FILE [options]     render one image in this process
  transtick info --volume FILE [raw options]   describe a volume

render options:
  --materials FILE       surfaces mode classification (JSON, see docs/formats.md)
  --transfer FILE        dvr mode transfer function (JSON)
  --mode surfaces|dvr    default: surfaces with --materials, dvr with --transfer
  --azimuth DEG          rotation about the volume's Y axis (0 looks along -Z)
  --elevation DEG        tilt toward +Y
  --zoom F               1 frames the whole volume (default 1)
  --projection perspective|orthographic   (default perspective)
  --fov DEG              perspective field of view (default 30)
  --eye X,Y,Z --target X,Y,Z [--up X,Y,Z]  explicit view (world units, volume centred at 0)
  --size WxH             image size, at most 8192x8192 (default 400x400)
  --shadows on|off       shadow rays in surfaces mode (default on)
  --background R,G,B     background colour in [0, 1] (default 0,0,0)
  --step S               dvr sample step in world units (default half the smallest spacing)
  --threads N            tracing threads (default: one per core)
  --out FILE             .png (8-bit), .tif/.exr (float) (default transtick.png)
  --stats FILE.json      write frame statistics as JSON
  --max-volume-mb N      refuse volumes larger than N MiB in memory (default 8192)
raw volumes (any other extension, or --raw-dims given):
  --raw-dims XxYxZ --raw-type uint8|int8|uint16|int16|uint32|int32|float
  --raw-endian little|big --raw-spacing X,Y,Z --raw-skip BYTES
)";

absl::StatusOr<Volume> LoadVolume(const Flags& flags) {
  if (!flags.Has("volume")) return absl::InvalidArgumentError("--volume FILE is required");
  ReadOptions options;
  auto mb = flags.GetInt("max-volume-mb", 8192);
  if (!mb.ok()) return mb.status();
  if (*mb < 1) return absl::InvalidArgumentError("--max-volume-mb must be at least 1");
  options.max_bytes = static_cast<uint64_t>(*mb) << 20;
  const std::string path = flags.Get("volume");
  if (!flags.Has("raw-dims")) return ReadVolume(path, options);
  RawSpec spec;
  auto dims = flags.GetDims("raw-dims", 3);
  if (!dims.ok()) return dims.status();
  for (int a = 0; a < 3; ++a) spec.dims[a] = (*dims)[a];
  auto type = ParseScalarType(flags.Get("raw-type", "uint8"));
  if (!type.ok()) return type.status();
  spec.type = *type;
  std::string endian = flags.Get("raw-endian", "little");
  if (endian != "little" && endian != "big") {
    return absl::InvalidArgumentError("--raw-endian must be little or big");
  }
  spec.byte_order = endian == "big" ? ByteOrder::kBig : ByteOrder::kLittle;
  if (flags.Has("raw-spacing")) {
    auto sp = flags.GetTriple("raw-spacing");
    if (!sp.ok()) return sp.status();
    spec.spacing = *sp;
  }
  auto skip = flags.GetInt("raw-skip", 0);
  if (!skip.ok()) return skip.status();
  if (*skip < 0) return absl::InvalidArgumentError("--raw-skip must not be negative");
  spec.header_bytes = static_cast<uint64_t>(*skip);
  return ReadRaw(path, spec, options);
}

double MsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

const std::set<std::string> kRawFlags = {"volume",      "raw-dims", "raw-type",     "raw-endian",
                                         "raw-spacing", "raw-skip", "max-volume-mb"};

int Info(int argc, char** argv) {
  auto flags = Flags::Parse(argc, argv, 2, kRawFlags);
  if (!flags.ok()) {
    std::cerr << "transtick info: " << flags.status().message() << "\n";
    return 2;
  }
  auto volume = LoadVolume(*flags);
  if (!volume.ok()) {
    std::cerr << "transtick info: " << volume.status().message() << "\n";
    return 1;
  }
  auto range = volume->Range();
  std::cout << flags->Get("volume") << ": " << volume->dims[0] << "x" << volume->dims[1] << "x"
            << volume->dims[2] << " " << ScalarTypeName(volume->source_type) << ", spacing "
            << volume->spacing[0] << " " << volume->spacing[1] << " " << volume->spacing[2]
            << ", values " << range[0] << " .. " << range[1] << "\n";
  // A coarse histogram helps choose material intervals.
  constexpr int kBins = 16;
  std::vector<uint64_t> hist(kBins, 0);
  const float width = range[1] > range[0] ? (range[1] - range[0]) / kBins : 1;
  for (float v : volume->values) {
    int b = std::min(kBins - 1, static_cast<int>((v - range[0]) / width));
    ++hist[b];
  }
  for (int b = 0; b < kBins; ++b) {
    std::printf("  [%10.1f, %10.1f)  %6.2f%%\n", range[0] + b * width, range[0] + (b + 1) * width,
                100.0 * hist[b] / volume->values.size());
  }
  return 0;
}

int Render(int argc, char** argv) {
  std::set<std::string> known = kRawFlags;
  for (const char* f :
       {"materials", "transfer", "mode", "azimuth", "elevation", "zoom", "projection", "fov", "eye",
        "target", "up", "size", "shadows", "background", "step", "threads", "out", "stats"}) {
    known.insert(f);
  }
  auto fail = [](const absl::Status& s) {
    std::cerr << "transtick render: " << s.message() << "\n";
    return s.code() == absl::StatusCode::kInvalidArgument ? 2 : 1;
  };
  auto flags = Flags::Parse(argc, argv, 2, known);
  if (!flags.ok()) return fail(flags.status());

  // Everything about the request is checked before the volume is read.
  std::string mode_name = flags->Get("mode", flags->Has("transfer") ? "dvr" : "surfaces");
  if (mode_name != "surfaces" && mode_name != "dvr") {
    return fail(absl::InvalidArgumentError("--mode must be surfaces or dvr"));
  }
  const bool dvr = mode_name == "dvr";
  if (!dvr && !flags->Has("materials")) {
    return fail(absl::InvalidArgumentError("surfaces mode needs --materials FILE"));
  }
  if (dvr && !flags->Has("transfer")) {
    return fail(absl::InvalidArgumentError("dvr mode needs --transfer FILE"));
  }
  CameraSpec cam;
  auto size = flags->GetDims("size", 2);
  if (flags->Has("size")) {
    if (!size.ok()) return fail(size.status());
    cam.width = (*size)[0];
    cam.height = (*size)[1];
  }
  auto az = flags->GetDouble("azimuth", 0);
  auto el = flags->GetDouble("elevation", 0);
  auto zoom = flags->GetDouble("zoom", 1);
  auto fov = flags->GetDouble("fov", 30);
  for (const auto* v : {&az, &el, &zoom, &fov}) {
    if (!v->ok()) return fail(v->status());
  }
  cam.azimuth_deg = *az;
  cam.elevation_deg = *el;
  cam.zoom = *zoom;
  cam.fov_deg = *fov;
  std::string projection = flags->Get("projection", "perspective");
  if (projection != "perspective" && projection != "orthographic") {
    return fail(absl::InvalidArgumentError("--projection must be perspective or orthographic"));
  }
  cam.projection =
      projection == "perspective" ? Projection::kPerspective : Projection::kOrthographic;
  if (flags->Has("eye") || flags->Has("target")) {
    if (!flags->Has("eye") || !flags->Has("target")) {
      return fail(absl::InvalidArgumentError("--eye and --target go together"));
    }
    ExplicitView view;
    auto eye = flags->GetTriple("eye");
    auto target = flags->GetTriple("target");
    if (!eye.ok()) return fail(eye.status());
    if (!target.ok()) return fail(target.status());
    view.eye = {(*eye)[0], (*eye)[1], (*eye)[2]};
    view.target = {(*target)[0], (*target)[1], (*target)[2]};
    if (flags->Has("up")) {
      auto up = flags->GetTriple("up");
      if (!up.ok()) return fail(up.status());
      view.up = {(*up)[0], (*up)[1], (*up)[2]};
    }
    cam.view = view;
  }
  RenderSettings settings;
  auto shadows = flags->GetOnOff("shadows", true);
  if (!shadows.ok()) return fail(shadows.status());
  settings.shadows = *shadows;
  if (flags->Has("background")) {
    auto bg = flags->GetTriple("background");
    if (!bg.ok()) return fail(bg.status());
    for (int c = 0; c < 3; ++c) {
      if ((*bg)[c] < 0 || (*bg)[c] > 1) {
        return fail(absl::InvalidArgumentError("--background components must be in [0, 1]"));
      }
      settings.background[c] = static_cast<float>((*bg)[c]);
    }
  }
  auto step = flags->GetDouble("step", 0);
  if (!step.ok()) return fail(step.status());
  if (*step < 0) return fail(absl::InvalidArgumentError("--step must be positive"));
  settings.step = *step;
  auto threads = flags->GetInt("threads", 0);
  if (!threads.ok()) return fail(threads.status());
  if (*threads < 0 || *threads > 1024) {
    return fail(absl::InvalidArgumentError("--threads must be in [0, 1024]"));
  }
  Classification classification;
  TransferFunction transfer;
  if (dvr) {
    auto tf = LoadTransferFunction(flags->Get("transfer"));
    if (!tf.ok()) return fail(tf.status());
    transfer = *std::move(tf);
  } else {
    auto m = LoadMaterials(flags->Get("materials"));
    if (!m.ok()) return fail(m.status());
    classification = *std::move(m);
  }
  const std::string out = flags->Get("out", "transtick.png");

  auto t_load = std::chrono::steady_clock::now();
  auto volume = LoadVolume(*flags);
  if (!volume.ok()) return fail(volume.status());
  const double load_ms = MsSince(t_load);

  auto t_prepare = std::chrono::steady_clock::now();
  auto scene = dvr ? Scene::ForDvr(*volume, transfer) : Scene::ForSurfaces(*volume, classification);
  if (!scene.ok()) return fail(scene.status());
  const double prepare_ms = MsSince(t_prepare);

  Vec3 extent{volume->dims[0] * volume->spacing[0], volume->dims[1] * volume->spacing[1],
              volume->dims[2] * volume->spacing[2]};
  auto camera = Camera::Create(cam, extent);
  if (!camera.ok()) return fail(camera.status());

  const bool tty = isatty(STDERR_FILENO);
  ProgressFn progress;
  if (tty) {
    progress = [](uint64_t done, uint64_t total) {
      std::fprintf(stderr, "\rrendering %5.1f%%", 100.0 * done / total);
      std::fflush(stderr);
    };
  }
  RenderStats stats;
  auto image = RenderLocal(*scene, *camera, settings, *threads, &stats, progress);
  if (tty) std::fprintf(stderr, "\r\033[K");
  if (!image.ok()) return fail(image.status());
  if (auto s = WriteImage(out, *image); !s.ok()) return fail(s);

  v1::FrameStats fs;
  fs.set_frame_ms(stats.frame_ms);
  fs.set_prepare_ms(prepare_ms);
  fs.set_load_ms(load_ms);
  fs.set_threads(stats.threads);
  fs.set_mode(mode_name);
  fs.set_width(cam.width);
  fs.set_height(cam.height);
  const TraceCounters& c = stats.counters;
  fs.mutable_rays()->set_primary(c.primary);
  fs.mutable_rays()->set_shadow(c.shadow);
  fs.mutable_rays()->set_total(c.primary + c.shadow);
  fs.set_segments(c.segments);
  fs.set_surface_hits(c.surface_hits);
  fs.set_samples(c.samples);
  const Sticks& sticks = scene->sticks();
  uint64_t encoded = 0;
  for (int by = 0; by < sticks.BlocksY(); ++by)
    for (int bx = 0; bx < sticks.BlocksX(); ++bx) encoded += sticks.EncodeBlock(bx, by).size();
  const uint64_t raw = volume->VoxelCount() * ScalarTypeSize(volume->source_type);
  auto* ss = fs.mutable_sticks();
  ss->set_sticks(sticks.StickCount());
  ss->set_encoded_bytes(encoded);
  ss->set_memory_bytes(sticks.MemoryBytes());
  ss->set_raw_volume_bytes(raw);
  ss->set_ratio(raw ? static_cast<double>(encoded) / raw : 0);
  ss->set_scalar_bytes(scene->scalars().size() * sizeof(float));
  for (int a = 0; a < 3; ++a) fs.add_volume_dims(volume->dims[a]);
  fs.set_rays_per_second(stats.frame_ms > 0 ? (c.primary + c.shadow) / (stats.frame_ms / 1e3) : 0);

  std::fprintf(stderr,
               "%s: %dx%d %s in %.1f ms on %d threads (%llu primary + %llu shadow rays); "
               "sticks %.2f MB = %.1f%% of the raw volume\n",
               out.c_str(), cam.width, cam.height, mode_name.c_str(), stats.frame_ms, stats.threads,
               static_cast<unsigned long long>(c.primary),
               static_cast<unsigned long long>(c.shadow), encoded / 1e6, 100.0 * ss->ratio());
  if (flags->Has("stats")) {
    std::ofstream f(flags->Get("stats"));
    f << ToJson(fs);
    if (!f) return fail(absl::UnavailableError(flags->Get("stats") + ": cannot write"));
  }
  return 0;
}

}  // namespace
}  // namespace transtick

int main(int argc, char** argv) {
  std::string cmd = argc > 1 ? argv[1] : "help";
  if (cmd == "render") return transtick::Render(argc, argv);
  if (cmd == "info") return transtick::Info(argc, argv);
  if (cmd == "help" || cmd == "--help" || cmd == "-h") {
    std::cout << transtick::kUsage;
    return 0;
  }
  std::cerr << "transtick: unknown command '" << cmd << "'\n" << transtick::kUsage;
  return 2;
}
