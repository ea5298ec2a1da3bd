// transtick: the command-line client.
//
//   transtick render --volume FILE [--materials FILE | --transfer FILE] ...
//   transtick info --volume FILE
//
// Run `transtick help` for every flag.

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <thread>

#include "absl/strings/escaping.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "client.h"
#include "clock.h"
#include "cluster.grpc.pb.h"
#include "convert.h"
#include "flags.h"
#include "local_cluster.h"
#include "rpc_channel.h"
#include "rpc_status.h"
#include "transtick/camera.h"
#include "transtick/image_io.h"
#include "transtick/render.h"
#include "transtick/scene.h"
#include "transtick/volume_io.h"

namespace transtick {
namespace {

constexpr char kUsage[] = R"(transtick: a volume ray tracer (sticks, ray dataflow)

usage:
  transtick render --volume FILE [options]     render one image (embedded cluster by default)
  transtick submit JOB.json --root HOST:PORT [--out-dir DIR] [--stats FILE.json]
  transtick status --root HOST:PORT            jobs and workers of a running cluster
  transtick cancel JOB_ID --root HOST:PORT
  transtick health --addr HOST:PORT[,...]      exit 0 when every daemon reports SERVING
  transtick info --volume FILE [raw options]   describe a volume

render options:
  --materials FILE       surfaces mode classification (JSON, see docs/formats.md)
  --transfer FILE        dvr mode transfer function (JSON)
  --mode surfaces|dvr    default: surfaces with --materials, dvr with --transfer
  --surface smooth|voxel surfaces on the trilinear field, hit exactly (default), or the
                         paper's voxel faces (overrides the materials file's "surface")
  --azimuth DEG          rotation about the volume's Y axis (0 looks along -Z)
  --elevation DEG        tilt toward +Y
  --zoom F               1 frames the whole volume (default 1)
  --projection perspective|orthographic   (default perspective)
  --fov DEG              perspective field of view (default 30)
  --eye X,Y,Z --target X,Y,Z [--up X,Y,Z]  explicit view (world units, volume centred at 0)
  --size WxH             image size, at most 8192x8192 (default 400x400)
  --shadows on|off       shadow rays in surfaces mode (default on)
  --samples N            primary rays per pixel, 1-64, at a fixed stratified pattern
                         (anti-aliasing; default 1)
  --background R,G,B     background colour in [0, 1] (default 0,0,0)
  --step S               dvr sample step in world units (default half the smallest spacing)
  --local N              render on an embedded cluster of N workers (default: one per
                         core); 0 renders in this process without gRPC (the reference)
  --rings R              rings of the embedded cluster (default 1)
  --balance off|test-rays|previous-frame   static load balancing of the slabs on a
                         cluster (default off; docs/balancing.md)
  --balance-grid N       test rays per side of the image for test-rays (default 32)
  --balance-rule cost|paper   how cuts follow from costs (default cost)
  --root HOST:PORT       render on a running cluster; --volume is then relative to
                         the root's data directory
  --threads N            tracing threads of --local 0, and of each worker of --local N
                         (default: one per core)
  --out FILE             .png/.jpg (8-bit), .tif/.exr/.hdr (float) (default transtick.png)
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
  // In double: a float volume's range may span nearly all of float, and
  // its NaN and infinite values (outside Range()) are counted apart.
  std::vector<uint64_t> hist(kBins, 0);
  uint64_t not_finite = 0;
  const double lo = range[0], hi = range[1];
  const double width = hi > lo ? (hi - lo) / kBins : 1;
  for (float v : volume->values) {
    if (!std::isfinite(v)) {
      ++not_finite;
      continue;
    }
    const double x = (v - lo) / width;
    ++hist[x < 0 ? 0 : std::min<int>(kBins - 1, static_cast<int>(std::min(x, double{kBins})))];
  }
  for (int b = 0; b < kBins; ++b) {
    std::printf("  [%10.1f, %10.1f)  %6.2f%%\n", lo + b * width, lo + (b + 1) * width,
                100.0 * hist[b] / volume->values.size());
  }
  if (not_finite > 0) {
    std::printf("  NaN or infinite        %6.2f%%\n", 100.0 * not_finite / volume->values.size());
  }
  return 0;
}

// The view a render's flags describe, as the job API has it, so the
// in-process and cluster renders take their camera from one place.
absl::StatusOr<v1::View> ViewFromFlags(const Flags& flags) {
  v1::View v;
  v.set_width(400);
  v.set_height(400);
  if (flags.Has("size")) {
    auto size = flags.GetDims("size", 2);
    if (!size.ok()) return size.status();
    v.set_width((*size)[0]);
    v.set_height((*size)[1]);
  }
  auto az = flags.GetDouble("azimuth", 0);
  auto el = flags.GetDouble("elevation", 0);
  auto zoom = flags.GetDouble("zoom", 1);
  auto fov = flags.GetDouble("fov", 30);
  auto step = flags.GetDouble("step", 0);
  for (const auto* d : {&az, &el, &zoom, &fov, &step}) {
    if (!d->ok()) return d->status();
  }
  v.set_azimuth(*az);
  v.set_elevation(*el);
  v.set_zoom(*zoom);
  v.set_fov(*fov);
  if (*step < 0) return absl::InvalidArgumentError("--step must be positive");
  v.set_step(*step);
  auto projection = ParseEnum<v1::Projection>(flags.Get("projection", "perspective"), "--projection");
  if (!projection.ok()) return projection.status();
  v.set_projection(*projection);
  if (flags.Has("eye") || flags.Has("target")) {
    if (!flags.Has("eye") || !flags.Has("target")) {
      return absl::InvalidArgumentError("--eye and --target go together");
    }
    for (const char* name : {"eye", "target", "up"}) {
      if (!flags.Has(name)) continue;
      auto t = flags.GetTriple(name);
      if (!t.ok()) return t.status();
      auto* field = std::string(name) == "eye"      ? v.mutable_explicit_view()->mutable_eye()
                    : std::string(name) == "target" ? v.mutable_explicit_view()->mutable_target()
                                                    : v.mutable_explicit_view()->mutable_up();
      for (double x : *t) field->Add(x);
    }
  }
  auto shadows = flags.GetOnOff("shadows", true);
  if (!shadows.ok()) return shadows.status();
  v.set_shadows(*shadows);
  if (flags.Has("samples")) {
    auto samples = flags.GetInt("samples", 1);
    if (!samples.ok()) return samples.status();
    v.set_samples(*samples);
  }
  if (flags.Has("background")) {
    auto bg = flags.GetTriple("background");
    if (!bg.ok()) return bg.status();
    for (double c : *bg) v.add_background(static_cast<float>(c));
  }
  v.set_output(flags.Get("out", "transtick.png"));
  if (!IsSupportedImagePath(v.output())) {
    return absl::InvalidArgumentError(absl::StrCat("--out: '", v.output(),
                                                   "' is not an image format transtick writes (",
                                                   SupportedImageList(), ")"));
  }
  // Checks ranges (image size, zoom, projection, background) up front.
  if (auto c = ToCameraSpec(v); !c.ok()) return c.status();
  return v;
}

// Takes the command's TLS and token flags (security.h) for its channels.
absl::Status UseSecurity(const Flags& flags) {
  auto security = SecurityFromFlags(flags, /*daemon=*/false);
  if (!security.ok()) return security.status();
  SetSecurity(*std::move(security));
  return absl::OkStatus();
}

int Fail(const char* command, const absl::Status& s) {
  std::cerr << "transtick " << command << ": " << s.message() << "\n";
  return s.code() == absl::StatusCode::kInvalidArgument ? 2 : 1;
}

void WriteStats(const std::string& path, const google::protobuf::Message& m) {
  std::ofstream f(path);
  f << ToJson(m);
  if (!f) std::cerr << "transtick: cannot write " << path << "\n";
}

// --local 0: the reference renderer, in this process without gRPC.
int RenderInProcess(const Flags& flags, const v1::View& view, bool dvr,
                    const Classification& classification, const TransferFunction& transfer) {
  auto fail = [](const absl::Status& s) { return Fail("render", s); };
  auto threads = flags.GetInt("threads", 0);
  if (!threads.ok()) return fail(threads.status());
  if (*threads < 0 || *threads > 1024) {
    return fail(absl::InvalidArgumentError("--threads must be in [0, 1024]"));
  }
  auto t_load = std::chrono::steady_clock::now();
  auto volume = LoadVolume(flags);
  if (!volume.ok()) return fail(volume.status());
  const double load_ms = MsSince(t_load);
  auto t_prepare = std::chrono::steady_clock::now();
  auto scene = dvr ? Scene::ForDvr(*volume, transfer) : Scene::ForSurfaces(*volume, classification);
  if (!scene.ok()) return fail(scene.status());
  const double prepare_ms = MsSince(t_prepare);
  Vec3 extent{volume->dims[0] * volume->spacing[0], volume->dims[1] * volume->spacing[1],
              volume->dims[2] * volume->spacing[2]};
  auto camera = Camera::Create(*ToCameraSpec(view), extent);
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
  auto image = RenderLocal(*scene, *camera, ToRenderSettings(view), *threads, &stats, progress);
  if (tty) std::fprintf(stderr, "\r\033[K");
  if (!image.ok()) return fail(image.status());
  const std::string out = view.output();
  if (auto s = WriteImage(out, *image); !s.ok()) return fail(s);

  v1::FrameStats fs;
  fs.set_frame_ms(stats.frame_ms);
  fs.set_prepare_ms(prepare_ms);
  fs.set_load_ms(load_ms);
  fs.set_threads(stats.threads);
  fs.set_mode(dvr ? v1::DVR : v1::SURFACES);
  fs.set_width(view.width());
  fs.set_height(view.height());
  const TraceCounters& c = stats.counters;
  fs.mutable_rays()->set_primary(c.primary);
  fs.mutable_rays()->set_shadow(c.shadow);
  fs.mutable_rays()->set_total(c.primary + c.shadow);
  fs.set_segments(c.segments);
  fs.set_surface_hits(c.surface_hits);
  fs.set_samples(c.samples);
  fs.set_rays_truncated(c.truncated);
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
               out.c_str(), view.width(), view.height(), dvr ? "dvr" : "surfaces", stats.frame_ms,
               stats.threads, static_cast<unsigned long long>(c.primary),
               static_cast<unsigned long long>(c.shadow), encoded / 1e6, 100.0 * ss->ratio());
  if (flags.Has("stats")) WriteStats(flags.Get("stats"), fs);
  return 0;
}

void PrintClusterFrame(const v1::ClusterFrameStats& fs) {
  std::fprintf(stderr, "frame %dx%d in %.1f ms on %d workers (%d ring%s), max/mean active %.2f\n",
               fs.width(), fs.height(), fs.frame_ms(), fs.workers_size(), fs.rings(),
               fs.rings() == 1 ? "" : "s", fs.active_imbalance());
  if (fs.balance() != v1::OFF) {
    // Each ring's cuts run from 0 to the number of planes: "[0 64 128] [0 70 128]".
    auto rings = [](const google::protobuf::RepeatedField<int32_t>& cuts) {
      std::string out;
      for (int i = 0; i < cuts.size(); ++i) {
        if (cuts[i] == 0) out += i ? "] [" : "[";
        out += std::to_string(cuts[i]);
        if (i + 1 < cuts.size() && cuts[i + 1] != 0) out += " ";
      }
      return cuts.empty() ? out : out + "]";
    };
    std::fprintf(stderr, "  balance %s: cuts %s -> %s, %.1f ms, %d planes moved\n",
                 EnumName(fs.balance()).c_str(), rings(fs.cuts_before()).c_str(),
                 rings(fs.cuts_after()).c_str(), fs.balance_ms(), fs.planes_moved());
  }
  for (const auto& w : fs.workers()) {
    std::fprintf(stderr,
                 "  ring %d slab [%3d, %3d): elapsed %7.1f ms, active %7.1f ms, traced %8llu, "
                 "sent %7llu, received %7llu\n",
                 w.ring(), w.slab_size() > 0 ? w.slab(0) : -1, w.slab_size() > 1 ? w.slab(1) : -1,
                 w.elapsed_ms(), w.active_ms(), static_cast<unsigned long long>(w.rays_traced()),
                 static_cast<unsigned long long>(w.rays_sent()),
                 static_cast<unsigned long long>(w.rays_received()));
  }
}

int Render(int argc, char** argv) {
  std::set<std::string> known = kRawFlags;
  for (const char* f :
       {"materials",  "transfer",   "mode",  "azimuth", "elevation",    "zoom",
        "projection", "fov",        "eye",   "target",  "up",           "size",
        "shadows",    "background", "step",  "threads", "out",          "stats", "surface", "samples",
        "local",      "root",       "rings", "balance", "balance-grid", "balance-rule"}) {
    known.insert(f);
  }
  auto fail = [](const absl::Status& s) { return Fail("render", s); };
  auto flags = Flags::Parse(argc, argv, 2, WithSecurityFlags(known));
  if (!flags.ok()) return fail(flags.status());
  if (absl::Status s = UseSecurity(*flags); !s.ok()) return fail(s);

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
  auto view = ViewFromFlags(*flags);
  if (!view.ok()) return fail(view.status());
  if (!flags->Has("volume")) return fail(absl::InvalidArgumentError("--volume FILE is required"));
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  auto local = flags->GetInt("local", cores);
  auto rings = flags->GetInt("rings", 1);
  if (!local.ok()) return fail(local.status());
  if (!rings.ok()) return fail(rings.status());
  if (*local < 0 || *local > 64)
    return fail(absl::InvalidArgumentError("--local must be in [0, 64]"));
  if (*rings < 1 || *rings > 64)
    return fail(absl::InvalidArgumentError("--rings must be in [1, 64]"));

  v1::Dataset dataset;
  Classification classification;
  TransferFunction transfer;
  const std::string settings_file = flags->Get(dvr ? "transfer" : "materials");
  auto text = ReadTextFile(settings_file);
  if (!text.ok()) return fail(text.status());
  if (dvr) {
    if (auto s = ParseJson(*text, settings_file, dataset.mutable_transfer()); !s.ok())
      return fail(s);
    auto tf = ToTransferFunction(dataset.transfer());
    if (!tf.ok())
      return fail(
          absl::InvalidArgumentError(absl::StrCat(settings_file, ": ", tf.status().message())));
    transfer = *std::move(tf);
  } else {
    if (auto s = ParseJson(*text, settings_file, dataset.mutable_materials()); !s.ok())
      return fail(s);
    if (flags->Has("surface")) {
      auto surface = ParseEnum<v1::SurfaceModel>(flags->Get("surface"), "--surface");
      if (!surface.ok() || *surface == v1::SURFACE_DEFAULT) {
        return fail(absl::InvalidArgumentError("--surface must be smooth or voxel"));
      }
      dataset.mutable_materials()->set_surface(*surface);
    }
    auto c = ToClassification(dataset.materials());
    if (!c.ok())
      return fail(
          absl::InvalidArgumentError(absl::StrCat(settings_file, ": ", c.status().message())));
    classification = *std::move(c);
  }
  if (*local == 0 && !flags->Has("root")) {
    return RenderInProcess(*flags, *view, dvr, classification, transfer);
  }

  // On a cluster: an embedded one (--local N), or a running one (--root).
  const std::string volume = flags->Get("volume");
  std::unique_ptr<LocalCluster> cluster;
  std::string root = flags->Get("root");
  if (root.empty()) {
    std::error_code ec;
    const std::filesystem::path abs = std::filesystem::absolute(volume, ec);
    if (!std::filesystem::is_regular_file(abs, ec)) {
      return fail(absl::NotFoundError(absl::StrCat(volume, ": cannot open")));
    }
    LocalCluster::Options co;
    co.workers = *local;
    co.rings = *rings;
    // Each worker runs as its daemon would: one tracer thread per core. On
    // one machine the workers then share the cores as their loads need,
    // where a fixed share each would leave a core idle beside a busy slab.
    auto threads = flags->GetInt("threads", cores);
    if (!threads.ok()) return fail(threads.status());
    if (*threads < 1 || *threads > 1024) {
      return fail(absl::InvalidArgumentError("--threads must be in [1, 1024]"));
    }
    co.threads_per_worker = *threads;
    co.data_dir = abs.parent_path().string();
    dataset.set_volume(abs.filename().string());
    auto c = LocalCluster::Start(co);
    if (!c.ok()) return fail(c.status());
    cluster = *std::move(c);
    root = cluster->root_address();
  } else {
    dataset.set_volume(volume);  // relative to the root's data directory
  }
  if (flags->Has("raw-dims")) {
    auto dims = flags->GetDims("raw-dims", 3);
    if (!dims.ok()) return fail(dims.status());
    v1::RawVolume* raw = dataset.mutable_raw();
    for (int d : *dims) raw->add_dims(d);
    raw->set_type(flags->Get("raw-type", "uint8"));
    raw->set_big_endian(flags->Get("raw-endian", "little") == "big");
    if (flags->Has("raw-spacing")) {
      auto sp = flags->GetTriple("raw-spacing");
      if (!sp.ok()) return fail(sp.status());
      for (double x : *sp) raw->add_spacing(x);
    }
    auto skip = flags->GetInt("raw-skip", 0);
    if (!skip.ok()) return fail(skip.status());
    raw->set_header_bytes(static_cast<uint64_t>(std::max(0, *skip)));
  }
  std::string out = view->output();
  if (std::filesystem::path(out).is_relative()) {
    view->set_output((std::filesystem::current_path() / out).string());
  }
  *dataset.add_views() = *view;
  v1::Job job;
  job.set_name("render");
  *job.add_datasets() = dataset;
  auto balance = ParseEnum<v1::BalanceMode>(flags->Get("balance", "off"), "--balance");
  if (!balance.ok()) return fail(balance.status());
  job.set_balance(*balance);
  auto grid = flags->GetInt("balance-grid", 32);
  if (!grid.ok()) return fail(grid.status());
  job.set_balance_grid(*grid);
  auto rule = ParseEnum<v1::BalanceRule>(flags->Get("balance-rule", "cost"), "--balance-rule");
  if (!rule.ok()) return fail(rule.status());
  job.set_balance_rule(*rule);
  WatchOptions wo;
  wo.progress = isatty(STDERR_FILENO);
  auto stats = SubmitAndWatch(root, job, wo);
  if (!stats.ok()) return fail(stats.status());
  if (!stats->empty()) {
    PrintClusterFrame(stats->front());
    std::fprintf(stderr, "%s: %dx%d %s on %d workers\n", out.c_str(), view->width(), view->height(),
                 mode_name.c_str(), stats->front().workers_size());
    if (flags->Has("stats")) WriteStats(flags->Get("stats"), stats->front());
  }
  return 0;
}

int Submit(int argc, char** argv) {
  auto flags = Flags::Parse(argc, argv, 2, WithSecurityFlags({"root", "out-dir", "stats"}));
  if (!flags.ok()) return Fail("submit", flags.status());
  if (absl::Status s = UseSecurity(*flags); !s.ok()) return Fail("submit", s);
  if (flags->positional().size() != 1) {
    return Fail("submit",
                absl::InvalidArgumentError("usage: transtick submit JOB.json --root HOST:PORT "
                                           "[--out-dir DIR] [--stats FILE.json]"));
  }
  if (!flags->Has("root"))
    return Fail("submit", absl::InvalidArgumentError("--root HOST:PORT is required"));
  auto job = LoadJobFile(flags->positional()[0]);
  if (!job.ok()) return Fail("submit", job.status());
  WatchOptions wo;
  wo.out_dir = flags->Get("out-dir", ".");
  wo.progress = isatty(STDERR_FILENO);
  auto stats = SubmitAndWatch(flags->Get("root"), *job, wo);
  if (!stats.ok()) return Fail("submit", stats.status());
  for (const auto& s : *stats) PrintClusterFrame(s);
  if (flags->Has("stats")) {
    std::ofstream f(flags->Get("stats"));
    f << "[\n";
    for (size_t i = 0; i < stats->size(); ++i)
      f << ToJson((*stats)[i]) << (i + 1 < stats->size() ? ",\n" : "\n");
    f << "]\n";
  }
  return 0;
}

int StatusCommand(int argc, char** argv) {
  auto flags = Flags::Parse(argc, argv, 2, WithSecurityFlags({"root"}));
  if (!flags.ok()) return Fail("status", flags.status());
  if (absl::Status s = UseSecurity(*flags); !s.ok()) return Fail("status", s);
  if (!flags->Has("root"))
    return Fail("status", absl::InvalidArgumentError("--root HOST:PORT is required"));
  auto stub = v1::Root::NewStub(MakeChannel(flags->Get("root"), Role::kRoot));
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(10));
  v1::StatusReply reply;
  grpc::Status s = stub->Status(&ctx, v1::StatusRequest(), &reply);
  if (!s.ok()) return Fail("status", FromGrpc(s));
  std::printf("%d workers, %d ring(s)\n", reply.workers_size(), reply.rings());
  for (const auto& w : reply.workers()) {
    std::printf("  worker %s at %s, %d threads", w.id().c_str(), w.address().c_str(), w.threads());
    if (w.ring() >= 0) {
      std::printf(", ring %d, slab [%d, %d)", w.ring(), w.slab_begin(), w.slab_end());
    }
    std::printf("\n");
  }
  for (const auto& j : reply.jobs()) {
    // Names are other clients' strings (an admin sees every job): escaped,
    // they cannot move the cursor or forge a line.
    std::printf("%-10s %-10s %3d/%-3d %-8s %s%s%s\n", j.job_id().c_str(),
                v1::JobState_Name(j.state()).c_str(), j.frames_done(), j.frames_total(),
                j.owner().c_str(), Printable(j.name()).c_str(),
                j.error().empty() ? "" : "  error: ", Printable(j.error()).c_str());
  }
  return 0;
}

int CancelCommand(int argc, char** argv) {
  auto flags = Flags::Parse(argc, argv, 2, WithSecurityFlags({"root"}));
  if (!flags.ok()) return Fail("cancel", flags.status());
  if (absl::Status s = UseSecurity(*flags); !s.ok()) return Fail("cancel", s);
  if (!flags->Has("root") || flags->positional().size() != 1) {
    return Fail("cancel",
                absl::InvalidArgumentError("usage: transtick cancel JOB_ID --root HOST:PORT"));
  }
  auto stub = v1::Root::NewStub(MakeChannel(flags->Get("root"), Role::kRoot));
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(10));
  v1::JobRef ref;
  ref.set_job_id(flags->positional()[0]);
  v1::CancelReply reply;
  grpc::Status s = stub->Cancel(&ctx, ref, &reply);
  if (!s.ok()) return Fail("cancel", FromGrpc(s));
  std::printf("%s: %s\n", ref.job_id().c_str(),
              reply.cancelled() ? "cancelled" : "already finished");
  return 0;
}

// Exit 0 when every daemon at --addr reports SERVING (container probes), with
// one line per daemon: its state on stdout, or why it could not be asked on
// stderr.
int Health(int argc, char** argv) {
  using grpc::health::v1::HealthCheckResponse;
  auto flags = Flags::Parse(argc, argv, 2, WithSecurityFlags({"addr", "timeout", "role"}));
  if (!flags.ok()) return Fail("health", flags.status());
  if (absl::Status s = UseSecurity(*flags); !s.ok()) return Fail("health", s);
  const std::string role_name = flags->Get("role", "root");
  std::optional<Role> role;
  for (Role r : {Role::kRoot, Role::kWorker, Role::kDisplay}) {
    if (RoleName(r) == absl::StrCat("transtick-", role_name)) role = r;
  }
  if (!role) {
    return Fail("health", absl::InvalidArgumentError("--role must be root, worker or display"));
  }
  auto timeout = flags->GetDouble("timeout", 3);
  if (!timeout.ok()) return Fail("health", timeout.status());
  if (*timeout <= 0)
    return Fail("health", absl::InvalidArgumentError("--timeout must be positive"));
  std::vector<std::string> addresses = absl::StrSplit(flags->Get("addr", "127.0.0.1:7000"), ',');
  for (const std::string& address : addresses) {
    if (address.empty()) {
      return Fail("health", absl::InvalidArgumentError("--addr: an empty address"));
    }
  }
  bool all_serving = true;
  for (const std::string& address : addresses) {
    auto status = CheckHealth(address, *role, *timeout);
    if (!status.ok()) {
      all_serving = false;
      const absl::Status& e = status.status();
      std::string why;
      if (absl::IsUnavailable(e)) {
        why = absl::StrCat("no daemon answers (", e.message(), ")");
      } else if (absl::IsDeadlineExceeded(e)) {
        why = absl::StrCat("no answer within ", *timeout, " s");
      } else if (absl::IsUnimplemented(e)) {
        why = "it does not serve the grpc.health.v1 health service";
      } else {
        why = absl::StrCat(absl::StatusCodeToString(e.code()), ": ", e.message());
      }
      std::fprintf(stderr, "transtick health: %s: %s\n", address.c_str(), why.c_str());
      continue;
    }
    std::printf("%s: %s\n", address.c_str(),
                HealthCheckResponse::ServingStatus_Name(*status).c_str());
    all_serving &= *status == HealthCheckResponse::SERVING;
  }
  return all_serving ? 0 : 1;
}

}  // namespace
}  // namespace transtick

int main(int argc, char** argv) {
  // The embedded cluster logs only warnings unless asked for more.
  spdlog::set_level(spdlog::level::warn);
  if (const char* level = std::getenv("TRANSTICK_LOG_LEVEL")) {
    spdlog::set_level(spdlog::level::from_str(level));
  }
  std::string cmd = argc > 1 ? argv[1] : "help";
  if (cmd == "render") return transtick::Render(argc, argv);
  if (cmd == "info") return transtick::Info(argc, argv);
  if (cmd == "submit") return transtick::Submit(argc, argv);
  if (cmd == "status") return transtick::StatusCommand(argc, argv);
  if (cmd == "cancel") return transtick::CancelCommand(argc, argv);
  if (cmd == "health") return transtick::Health(argc, argv);
  if (cmd == "help" || cmd == "--help" || cmd == "-h") {
    std::cout << transtick::kUsage;
    return 0;
  }
  std::cerr << "transtick: unknown command '" << cmd << "'\n" << transtick::kUsage;
  return 2;
}
