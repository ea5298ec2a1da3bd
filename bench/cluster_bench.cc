// cluster_bench: the render cluster measured on loopback.
//
//   cluster_bench scaling [--volume FILE] [--materials FILE] [--size WxH]
//                         [--azimuth DEG] [--repeat N] [--workers 1,2,4]
//                         [--threads N] [--balance MODE] [--grid N]
//   cluster_bench forward [--rays N]
//   cluster_bench tables  [--volume FILE] [--materials FILE] [--size WxH]
//                         [--repeat N] [--grid N]
//   cluster_bench hops    [--volume FILE] [--materials FILE] [--size WxH]
//                         [--workers 2,4,8]
//   cluster_bench primaries [--volume FILE] [--materials FILE] [--size WxH]
//                           [--workers 2,4,8]
//   cluster_bench weights [--volume FILE] [--materials FILE] [--size WxH]
//                         [--workers 2,4] [--repeat N]
//   cluster_bench deposits [--volume FILE] [--materials FILE] [--size WxH]
//                          [--azimuth DEG] [--workers 1,2,4] [--repeat N]
//   cluster_bench rays    [--volume FILE] [--materials FILE] [--size WxH]
//                         [--workers 2,4,8] [--repeat N]
//   cluster_bench converge [--volume FILE] [--materials FILE] [--size WxH]
//                          [--workers 4,8]
//   cluster_bench refine  [--volume FILE] [--materials FILE] [--size WxH]
//                         [--workers 4,8] [--repeat N] [--grid N]
//
// scaling: the in-process render on all cores, then an embedded cluster
//   (root, display and N workers, real gRPC on 127.0.0.1) for each N. Each
//   cluster renders one warm-up frame (it loads the slabs) and then `repeat`
//   frames of the same view; the table gives the median frame time, the
//   summed CPU time of all workers' tracer threads, the CPU time of the
//   whole process (root, display, workers, gRPC) per frame, and the rays
//   that crossed a slab plane. Ratios: summed tracer CPU of N workers over
//   that of 1 (the cost of ray dataflow) and the 2-worker frame over the
//   in-process frame. Every cluster image must equal the in-process image
//   bit for bit, else the exit status is 1.
// forward: one real worker with a prepared frame receives ray batches on
//   its Rays stream, as from its left neighbour, for several batch sizes;
//   prints rays per second and MB per second from the first batch sent
//   until the worker has read the whole stream and finished it; the
//   worker's count of rays received must then equal the rays sent.
// tables: the paper's Table 1 (per worker elapsed and active times, 2 and 4
//   workers, frontal and 45 degree views, without and with balancing) and
//   Table 2 (elapsed time for 2, 4 and 8 workers and the relative
//   efficiency T_2W / ((n/2) T_nW)), plus active and CPU times, and "CPU
//   alone": the max/mean tracer CPU of the same cuts with each slab traced
//   in this process on one thread (the least of max(3, repeat) runs), which
//   the other workers' threads on the same cores do not disturb.
// hops: whether a ray should skip the slabs it only passes through. For N
//   equal slabs, frontal and at 45 degrees, every ray of a frame is traced
//   in this process slab by slab as the ring routes it (RingLayout); a hop
//   is a ray handed to a neighbour, a transit hop one the slab it left did
//   nothing to (no hit, no shadow ray, colour, transmittance, material and
//   band as they came). Prints hops and transit hops per frame, their
//   share, the traversal steps the transits took, and the rays that ended
//   at a slab plane with nothing but their band ahead (field_summary.h).
// primaries: how many primary rays the slabs make only to drop them. A
//   slab makes the rays of the pixels it holds (RingLayout::Holds) that
//   are not void, and keeps those entering the volume in its planes. For N
//   equal slabs and five views (azimuth 0 and 45 at elevation 0 and 15,
//   and 30 at 40), the rays kept (each made by one slab), and the rays made
//   with the footprints in use against the projections of the slabs'
//   boxes (the footprints before 8 December 2026), with the time a ray
//   costs to make (Camera::GenerateAt and Tracer::MakePrimary).
// weights: what the work profile's units cost for smooth surfaces (tracer.h,
//   kFieldWork). For N equal slabs of each view (azimuth 0, 45, 90, 135), of
//   the volume given and of engine.nrrd beside it, every ray of a frame is
//   traced in this process slab by slab as the ring routes it, `repeat`
//   times; each slab's tracer CPU time (the least over the repeats) is
//   fitted by least squares of the relative error to its counts: steps,
//   cells of the field read, shaded points, rays taken. Prints the fitted
//   cost of each in ns, the fit's error per slab, and the error of the
//   weights in use.
// deposits: what a frame's deposits cost on their way to the display. For
//   N equal slabs, every ray of a frame is traced in this process as the
//   ring routes it, each slab's deposits recorded as its worker queues them
//   and cut into batches of a worker's size (FrameOptions::deposit_batch).
//   Then, `repeat` times, each batch is packed as a worker packs it
//   (PackDeposits) and added to a framebuffer as the display adds it
//   (AddPackedDeposits). Prints the deposits, the records packed (pixel
//   records and runs of misses) and their bytes, and
//   ns per deposit of packing and of the display's ingest (the least and
//   the median over the repeats). The framebuffer must complete every
//   pixel and equal, bit for bit, one that took the deposits one at a
//   time, else the exit status is 1.
// converge: how far the work profile's cuts are from balanced, and how
//   fast measured times close the gap. For N slabs, frontal and at 45
//   degrees, every ray is traced in this process slab by slab, one thread,
//   from equal slabs: each slab's CPU time (the least of 3 runs) and work
//   profile; the cuts the profile's totals give (as a test-ray prerender
//   cuts), then four times the cuts that each slab's measured time spread
//   over its planes by its profile gives. Prints each step's max/mean CPU
//   and each slab's share of the profile over its share of the time.
// refine: balancing in the cluster over a long job. For N workers, frontal
//   and at 45 degrees, each on a fresh embedded cluster: a job of `repeat`
//   frames of the view balanced by test rays, and one balanced by the
//   previous frame. Prints the first and the last frame's tracer CPU
//   max/mean, in the cluster and with its cuts traced alone, and the frames
//   whose cuts had moved (docs/balancing.md, "Refined by measured
//   frames"). Every image must equal the in-process one bit for bit.
//
// Defaults: cthead.nrrd in $TRANSTICK_DATA_DIR (else ../shared/data),
// examples/cthead_materials.json, 400x400, azimuth 45, shadows on, 5 repeats.

#include <spdlog/spdlog.h>
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <initializer_list>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "bench_util.h"
#include "client.h"
#include "cluster.grpc.pb.h"
#include "convert.h"
#include "daemon.h"
#include "frame.h"
#include "local_cluster.h"
#include "transtick/camera.h"
#include "transtick/image_io.h"
#include "transtick/partition.h"
#include "transtick/ray_codec.h"
#include "transtick/render.h"
#include "transtick/ring_layout.h"
#include "transtick/scene.h"
#include "transtick/tracer.h"
#include "transtick/volume_io.h"
#include "worker_service.h"

namespace transtick {
namespace {

using bench::Median;
// rays: what packing saves the rays handed between neighbours. For N equal
//   slabs, frontal and at 45 degrees, every ray of a frame is traced in
//   this process as the ring routes it, and the rays each slab hands to
//   each neighbour are queued as its worker queues them, in the order
//   made. They are cut into batches of a worker's size
//   (FrameOptions::batch_rays) and of smaller ones (a lingering stream
//   sends what it has), and packed (PackRays): rays, primary and shadow,
//   bytes per ray packed against the 106 of a record, and ns per ray of
//   packing and of decoding (DecodePackedRays; the least of `repeat`).
//   Every decoded batch must give its records back bit for bit, else the
//   exit status is 1.
using bench::MsSince;
using bench::ParseInt;
using bench::ParseSize;

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr char kUsage[] =
    "usage: cluster_bench scaling|forward|tables|hops|primaries|weights|deposits|rays|converge|\n"
    "                     refine\n"
    "                     [--volume FILE] [--materials FILE]\n"
    "                     [--size WxH] [--azimuth DEG] [--repeat N] [--workers 1,2,4]\n"
    "                     [--rays N] [--grid N] [--threads N] [--balance MODE]\n";

struct Options {
  std::string mode;
  std::string volume;
  std::string materials = TRANSTICK_BENCH_MATERIALS;
  int width = 400;
  int height = 400;
  double azimuth = 45;
  int repeat = 5;
  std::vector<int> workers = {1, 2, 4};
  int rays = 1 << 20;
  int grid = 0;                 // test rays per side for balancing, 0 = the root's default
  int threads = 0;              // tracer threads per worker; 0 = one per core, as transtick render
  std::string balance = "off";  // for scaling
};

double ProcessCpuMs() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return (ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) * 1e3 +
         (ru.ru_utime.tv_usec + ru.ru_stime.tv_usec) / 1e3;
}

std::string Parse(int argc, char** argv, Options* o) {
  const char* dir = std::getenv("TRANSTICK_DATA_DIR");
  o->volume = std::string(dir && *dir ? dir : TRANSTICK_BENCH_DATA_DIR) + "/cthead.nrrd";
  if (argc < 2) return "a mode is required";
  o->mode = argv[1];
  if (o->mode == "--help" || o->mode == "-h") return "help";
  if (o->mode != "scaling" && o->mode != "forward" && o->mode != "tables" && o->mode != "hops" &&
      o->mode != "primaries" && o->mode != "weights" && o->mode != "deposits" &&
      o->mode != "rays" && o->mode != "converge" && o->mode != "refine") {
    return "unknown mode '" + o->mode + "'";
  }
  for (int i = 2; i < argc; ++i) {
    std::string flag = argv[i];
    if (flag == "--help" || flag == "-h") return "help";
    if (i + 1 >= argc) return flag + " needs a value (or is unknown)";
    std::string value = argv[++i];
    if (flag == "--volume") {
      o->volume = value;
    } else if (flag == "--materials") {
      o->materials = value;
    } else if (flag == "--size") {
      if (!ParseSize(value, 8192, &o->width, &o->height)) {
        return "--size must be WxH with each in [1, 8192]";
      }
    } else if (flag == "--azimuth") {
      char* end = nullptr;
      o->azimuth = std::strtod(value.c_str(), &end);
      if (value.empty() || *end != '\0') return "--azimuth must be a number";
    } else if (flag == "--repeat") {
      if (!ParseInt(value, 1, 1000, &o->repeat)) return "--repeat must be in [1, 1000]";
    } else if (flag == "--threads") {
      if (!ParseInt(value, 0, 64, &o->threads)) return "--threads must be in [0, 64]";
    } else if (flag == "--balance") {
      o->balance = value;
    } else if (flag == "--grid") {
      if (!ParseInt(value, 1, 256, &o->grid)) return "--grid must be in [1, 256]";
    } else if (flag == "--rays") {
      if (!ParseInt(value, 1, 1 << 26, &o->rays)) return "--rays must be in [1, 2^26]";
    } else if (flag == "--workers") {
      o->workers.clear();
      for (absl::string_view p : absl::StrSplit(value, ',')) {
        int n = 0;
        if (!ParseInt(std::string(p), 1, 64, &n)) return "--workers takes counts in [1, 64]";
        o->workers.push_back(n);
      }
    } else {
      return "unknown flag " + flag;
    }
  }
  return "";
}

int Fail(const absl::Status& s) {
  std::fprintf(stderr, "cluster_bench: %s\n", s.ToString().c_str());
  return 1;
}

// ---------------------------------------------------------------- scaling

struct Setup {
  v1::MaterialSet materials;
  std::unique_ptr<Scene> scene;  // the whole volume, for the in-process render
  Vec3 extent;
  std::string data_dir, file;
};

absl::StatusOr<Setup> Prepare(const Options& o) {
  Setup s;
  auto text = ReadTextFile(o.materials);
  if (!text.ok()) return text.status();
  if (auto st = ParseJson(*text, o.materials, &s.materials); !st.ok()) return st;
  auto volume = ReadVolume(o.volume);
  if (!volume.ok()) return volume.status();
  auto scene = Scene::ForSurfaces(*volume, *ToClassification(s.materials));
  if (!scene.ok()) return scene.status();
  s.scene = std::make_unique<Scene>(*std::move(scene));
  s.extent = {volume->dims[0] * volume->spacing[0], volume->dims[1] * volume->spacing[1],
              volume->dims[2] * volume->spacing[2]};
  fs::path abs = fs::absolute(o.volume);
  s.data_dir = abs.parent_path().string();
  s.file = abs.filename().string();
  return s;
}

// An embedded cluster of n workers for `setup`'s data, each with o.threads
// tracer threads (one per core when 0).
absl::StatusOr<std::unique_ptr<LocalCluster>> StartCluster(const Options& o, const Setup& setup,
                                                           int n) {
  LocalCluster::Options co;
  co.workers = n;
  co.threads_per_worker = o.threads > 0
                              ? o.threads
                              : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  co.data_dir = setup.data_dir;
  return LocalCluster::Start(co);
}

v1::View MakeView(const Options& o, double azimuth) {
  v1::View v;
  v.set_azimuth(azimuth);
  v.set_width(o.width);
  v.set_height(o.height);
  v.set_shadows(true);
  return v;
}

// Runs `frames` frames of `view` on `cluster` and returns their statistics;
// `image` receives the last frame.
absl::StatusOr<std::vector<v1::ClusterFrameStats>> RunFrames(const std::string& root,
                                                             const Setup& s, v1::View view,
                                                             int frames, const std::string& out,
                                                             const std::string& balance = "",
                                                             int grid = 0) {
  v1::Job job;
  job.set_name("bench");
  if (!balance.empty()) job.set_balance(*ParseEnum<v1::BalanceMode>(balance, "--balance"));
  job.set_balance_grid(grid);
  v1::Dataset* d = job.add_datasets();
  d->set_volume(s.file);
  *d->mutable_materials() = s.materials;
  view.set_output(out);
  for (int i = 0; i < frames; ++i) *d->add_views() = view;
  return SubmitAndWatch(root, job, WatchOptions{});
}

int Scaling(const Options& o) {
  auto setup = Prepare(o);
  if (!setup.ok()) return Fail(setup.status());
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const v1::View view = MakeView(o, o.azimuth);
  auto camera = Camera::Create(*ToCameraSpec(view), setup->extent);
  if (!camera.ok()) return Fail(camera.status());
  std::printf(
      "volume %s, %dx%d, azimuth %g, shadows on, %d cores, balance %s\n"
      "%d rounds; each round renders one frame in-process and one on every cluster, so "
      "ratios are taken within a round (this machine is shared and noisy)\n\n",
      o.volume.c_str(), o.width, o.height, o.azimuth, cores, o.balance.c_str(), o.repeat);

  // The clusters, each warmed up with one frame (slab loads, prerender).
  const std::string out = (fs::temp_directory_path() / "cluster_bench.exr").string();
  struct Run {
    int workers = 0, threads = 0;
    std::unique_ptr<LocalCluster> cluster;
    std::vector<double> ms, cpu, proc, ratio;
    uint64_t crossings = 0;
  };
  std::vector<Run> runs;
  for (int n : o.workers) {
    Run run;
    run.workers = n;
    run.threads = o.threads > 0 ? o.threads : cores;
    auto cluster = StartCluster(o, *setup, n);
    if (!cluster.ok()) return Fail(cluster.status());
    run.cluster = *std::move(cluster);
    auto warm = RunFrames(run.cluster->root_address(), *setup, view, 1, out, o.balance, o.grid);
    if (!warm.ok()) return Fail(warm.status());
    runs.push_back(std::move(run));
  }
  Image reference;
  std::vector<double> local_ms, local_cpu;
  bool identical = true;
  for (int round = 0; round <= o.repeat; ++round) {  // round 0 warms up
    RenderStats rs;
    double cpu0 = ProcessCpuMs();
    auto t0 = Clock::now();
    auto image = RenderLocal(*setup->scene, *camera, ToRenderSettings(view), cores, &rs);
    if (!image.ok()) return Fail(image.status());
    const double in_process = MsSince(t0);
    if (round == 0) reference = *std::move(image);
    if (round > 0) {
      local_ms.push_back(in_process);
      local_cpu.push_back(ProcessCpuMs() - cpu0);
    }
    for (Run& run : runs) {
      cpu0 = ProcessCpuMs();
      auto stats = RunFrames(run.cluster->root_address(), *setup, view, 1, out, o.balance, o.grid);
      if (!stats.ok()) return Fail(stats.status());
      if (round == 0) continue;
      run.proc.push_back(ProcessCpuMs() - cpu0);
      const v1::ClusterFrameStats& f = stats->front();
      run.ms.push_back(f.frame_ms());
      run.ratio.push_back(f.frame_ms() / in_process);
      double sum = 0;
      run.crossings = 0;
      for (const auto& w : f.workers()) {
        sum += w.cpu_ms();
        run.crossings += w.rays_sent();
      }
      run.cpu.push_back(sum);
      auto got = ReadImage(out);
      if (!got.ok()) return Fail(got.status());
      if (got->rgb != reference.rgb) {
        identical = false;
        std::fprintf(stderr, "cluster_bench: %d workers: image differs from the in-process one\n",
                     run.workers);
      }
    }
  }
  std::printf("%-22s %9s %12s %13s %11s %14s\n", "renderer", "frame ms", "tracer CPU",
              "process CPU", "crossings", "frame ratio");
  std::printf("%-22s %9.1f %12s %13.1f %11s %14s\n",
              absl::StrCat("in-process, ", cores, " threads").c_str(), Median(local_ms), "-",
              Median(local_cpu), "-", "1");
  for (const Run& run : runs) {
    std::printf("%-22s %9.1f %12.1f %13.1f %11llu %14.2f\n",
                absl::StrCat(run.workers, " worker", run.workers > 1 ? "s" : "", " x ", run.threads,
                             " thread", run.threads > 1 ? "s" : "")
                    .c_str(),
                Median(run.ms), Median(run.cpu), Median(run.proc),
                static_cast<unsigned long long>(run.crossings), Median(run.ratio));
  }
  std::printf(
      "\n(frame ratio: the median over rounds of the cluster frame over the in-process "
      "frame of the same round)\n");
  const Run* one = nullptr;
  for (const Run& run : runs) {
    if (run.workers == 1) one = &run;
  }
  for (const Run& run : runs) {
    if (one && run.workers > 1 && Median(one->cpu) > 0) {
      std::printf("tracer CPU, %d workers / 1 worker:        %.2f\n", run.workers,
                  Median(run.cpu) / Median(one->cpu));
    }
  }
  for (const Run& run : runs) {
    if (run.workers == 2) {
      std::printf("frame, 2 workers / in-process %d threads: %.2f\n", cores, Median(run.ratio));
    }
  }
  std::printf("%s\n", identical ? "OK: every cluster image equals the in-process image bit for bit"
                                : "FAIL: a cluster image differs (see stderr)");
  return identical ? 0 : 1;
}

// ---------------------------------------------------------------- forward

int Forward(const Options& o) {
  // A small real scene: the worker needs a slab to prepare a frame.
  Volume v;
  v.dims = {64, 64, 64};
  v.values.assign(64 * 64 * 64, 0.0f);
  auto scene = Scene::ForSurfaces(v, Classification{{Material{"m", 1, 2}}});
  if (!scene.ok()) return Fail(scene.status());
  WorkerOptions wo;
  wo.id = "bench";
  wo.address = "127.0.0.1";
  WorkerService service(wo);
  auto server = Server::Start("127.0.0.1:0", Role::kWorker, {&service});
  if (!server.ok()) return Fail(server.status());
  const std::string address = absl::StrCat("127.0.0.1:", (*server)->port());
  auto stub = v1::Worker::NewStub(MakeChannel(address, Role::kWorker));
  {
    grpc::ClientContext ctx;
    v1::LoadReply reply;
    auto w = stub->LoadSlab(&ctx, &reply);
    Scene slab = scene->Slab(32, 64);
    v1::SlabChunk chunk;
    v1::SlabHeader* h = chunk.mutable_header();
    h->set_dataset_key("bench");
    h->set_mode(transtick::v1::SURFACES);
    for (int a = 0; a < 3; ++a) h->add_dims(64), h->add_spacing(1);
    h->add_value_range(0);
    h->add_value_range(1);
    v1::Material* m = h->mutable_materials()->add_materials();
    m->set_name("m");
    m->set_min(1);
    m->set_max(2);
    for (int c = 0; c < 3; ++c) m->add_color(1);
    h->set_y_begin(32);
    h->set_y_end(64);
    const std::vector<uint8_t> bricks = slab.bricks().bytes();
    h->set_brick_map(std::string(bricks.begin(), bricks.end()));
    for (int bx = 0; bx < 2; ++bx) chunk.add_blocks(slab.sticks().EncodeBlock(bx, 1));
    h->set_scalar_count(slab.scalars().size());
    AppendFloats(slab.scalars().data(), slab.scalars().size(), chunk.mutable_scalars());
    w->Write(chunk);
    w->WritesDone();
    grpc::Status st = w->Finish();
    if (!st.ok()) return Fail(FromGrpc(st));
  }
  // Rays as a left neighbour would send them: real descriptors.
  v1::View view;
  view.set_width(512);
  view.set_height(512);
  auto camera = Camera::Create(*ToCameraSpec(view), Vec3{64, 64, 64});
  Tracer tracer(*scene, ToRenderSettings(view), *camera);
  std::vector<RayDescriptor> rays;
  for (int p = 0; rays.size() < 4096; ++p) {
    RayDescriptor r;
    if (tracer.MakePrimary(camera->Generate(p % 512, 256), p % 512 + 256 * 512, &r))
      rays.push_back(r);
  }
  std::printf("%d rays of %zu bytes per size, one stream to a real worker on loopback\n\n", o.rays,
              kRayRecordBytes);
  std::printf("%12s %12s %14s %10s\n", "rays/batch", "batches", "rays/s", "MB/s");
  uint64_t frame_id = 1;
  bool ok = true;
  for (int batch : {1, 16, 256, 2048, 8192}) {
    const int n_batches = std::max(1, (batch == 1 ? o.rays / 16 : o.rays) / batch);
    v1::FrameSpec spec;
    spec.set_frame_id(frame_id);
    spec.set_dataset_key("bench");
    *spec.mutable_view() = view;
    for (int c : {0, 32, 64}) spec.add_cuts(c);
    spec.set_index(1);
    spec.set_left("bench");
    spec.set_display("unused:1");
    spec.set_row_end(512);
    spec.set_row_step(1);
    {
      grpc::ClientContext ctx;
      v1::FrameAck ack;
      grpc::Status st = stub->PrepareFrame(&ctx, spec, &ack);
      if (!st.ok()) return Fail(FromGrpc(st));
    }
    std::string records;
    for (int i = 0; i < batch; ++i) AppendRay(rays[i % rays.size()], &records);
    std::string packed;
    PackRays(records, &packed);
    auto t0 = Clock::now();
    grpc::ClientContext ctx;
    auto stream = stub->Rays(&ctx);
    v1::RayBatch msg;
    msg.set_frame_id(frame_id);
    stream->Write(msg);  // the hello
    for (int b = 0; b < n_batches; ++b) {
      msg.set_packed(packed);
      if (!stream->Write(msg)) return Fail(absl::UnavailableError("the worker closed the stream"));
    }
    stream->WritesDone();
    // The worker finishes the stream once it has read all of it.
    grpc::Status st = stream->Finish();
    const double ms = MsSince(t0);
    if (!st.ok()) return Fail(FromGrpc(st));
    v1::FrameRef ref;
    ref.set_frame_id(frame_id);
    v1::WorkerFrameStats ws;
    grpc::ClientContext end_ctx;
    st = stub->EndFrame(&end_ctx, ref, &ws);
    if (!st.ok()) return Fail(FromGrpc(st));
    const uint64_t sent = static_cast<uint64_t>(n_batches) * batch;
    if (ws.received_left() != sent) {
      ok = false;
      std::fprintf(stderr, "cluster_bench: sent %llu rays, the worker received %llu\n",
                   static_cast<unsigned long long>(sent),
                   static_cast<unsigned long long>(ws.received_left()));
    }
    std::printf("%12d %12d %14.0f %10.1f\n", batch, n_batches, sent / (ms / 1e3),
                sent * kRayRecordBytes / 1e6 / (ms / 1e3));
    std::fflush(stdout);
    ++frame_id;
  }
  (*server)->Shutdown(std::chrono::milliseconds(500));
  std::printf("%s\n", ok ? "OK: every ray sent was received" : "FAIL: rays lost (see stderr)");
  return ok ? 0 : 1;
}

// ---------------------------------------------------------------- tables

// `repeat` frames of one view after a warm-up frame (slab loads, and the
// prerender when balancing), on a running cluster.
struct Series {
  std::vector<v1::ClusterFrameStats> frames;  // the timed ones
  bool identical = true;
  double FrameMs() const {
    std::vector<double> ms;
    for (const auto& f : frames) ms.push_back(f.frame_ms());
    return Median(ms);
  }
  // Mean over the frames of each worker's field.
  std::vector<double> PerWorker(double (v1::WorkerFrameStats::*field)() const) const {
    std::vector<double> out(frames.empty() ? 0 : frames.front().workers_size(), 0.0);
    for (const auto& f : frames)
      for (int i = 0; i < f.workers_size() && i < static_cast<int>(out.size()); ++i)
        out[i] += (f.workers(i).*field)() / frames.size();
    return out;
  }
};

absl::StatusOr<Series> RunSeries(const std::string& root, const Setup& s, const v1::View& view,
                                 int repeat, const std::string& balance, int grid,
                                 const Image& want) {
  const std::string out = (fs::temp_directory_path() / "cluster_bench_tables.exr").string();
  auto stats = RunFrames(root, s, view, repeat + 1, out, balance, grid);
  if (!stats.ok()) return stats.status();
  Series series;
  series.frames.assign(stats->begin() + 1, stats->end());
  auto image = ReadImage(out);
  if (!image.ok()) return image.status();
  series.identical = image->rgb == want.rgb;
  return series;
}

double Sum(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return s;
}

double Imbalance(const std::vector<double>& active) {
  if (active.empty()) return 0;
  double mean = Sum(active) / active.size();
  return mean > 0 ? *std::max_element(active.begin(), active.end()) / mean : 0;
}

// ---------------------------------------------------------------- hops

// The slabs of a whole-volume scene at the given cuts (equal ones unless
// given), their tracers and the ring's layout, for tracing a frame slab by
// slab in this process (TraceRing).
struct SlabRing {
  static std::vector<int> Cuts(int planes, int n) {
    std::vector<int> cuts;
    for (int i = 0; i <= n; ++i) cuts.push_back(static_cast<int>(int64_t{planes} * i / n));
    return cuts;
  }
  SlabRing(const Scene& whole, int n, const RenderSettings& settings, const Camera& camera)
      : SlabRing(whole, Cuts(whole.dims()[1], n), settings, camera) {}
  SlabRing(const Scene& whole, std::vector<int> slab_cuts, const RenderSettings& settings,
           const Camera& camera)
      : cuts(std::move(slab_cuts)), layout(cuts, whole.dims(), whole.spacing(), camera) {
    const size_t n = cuts.size() - 1;
    slabs.reserve(n);
    for (size_t i = 0; i < n; ++i) slabs.push_back(whole.Slab(cuts[i], cuts[i + 1]));
    for (const Scene& sc : slabs) tracers.emplace_back(sc, settings, camera);
  }
  SlabRing(const SlabRing&) = delete;
  SlabRing& operator=(const SlabRing&) = delete;
  std::vector<int> cuts;
  RingLayout layout;
  std::vector<Scene> slabs;     // the tracers refer to them
  std::vector<Tracer> tracers;
};

// Calls f(azimuth, camera, ring) for each view of `azimuths` and each
// number of slabs in o.workers that the volume's planes allow, the slabs
// equal. Fails when a view's camera cannot be made.
template <typename F>
absl::Status ForEachEqualRing(const Options& o, const Setup& setup,
                              std::initializer_list<double> azimuths, F f) {
  const Scene& whole = *setup.scene;
  for (double azimuth : azimuths) {
    const v1::View view = MakeView(o, azimuth);
    auto camera = Camera::Create(*ToCameraSpec(view), setup.extent);
    if (!camera.ok()) return camera.status();
    const RenderSettings settings = ToRenderSettings(view);
    for (int n : o.workers) {
      if (n < 1 || n > whole.dims()[1]) continue;
      const SlabRing ring(whole, n, settings, *camera);
      f(azimuth, *camera, ring);
    }
  }
  return absl::OkStatus();
}

// Traces every ray of one frame in this process, slab by slab as the ring
// routes it (RingLayout): each slab makes its primary rays, then each slab
// in turn traces the rays queued for it, until none are left. `timed(i,
// work)` runs slab i's share of the work (making its primaries, or tracing
// its queue) so that a caller may time it; `traced(i, before, ray,
// spawned, counters, outcome)` sees each Trace call.
template <typename Timed, typename Traced>
void TraceRing(const RingLayout& layout, const std::vector<Tracer>& tracers, const Camera& camera,
               Timed timed, Traced traced, std::vector<std::vector<uint64_t>>* profiles = nullptr) {
  const int n = static_cast<int>(tracers.size());
  std::vector<std::vector<RayDescriptor>> queues(n);
  for (int i = 0; i < n; ++i) {
    timed(i, [&] {
      // As a worker makes them (Frame::NextPrimaries): the first slab looks
      // at every pixel, for the misses of pixels in no footprint; the
      // others at their footprint's columns only.
      for (int py = 0; py < camera.height(); ++py) {
        int from = 0, to = camera.width();
        if (i != 0) {
          const auto [first, last] = layout.Footprint(i).Row(py);
          from = std::max(from, first);
          to = std::min(to, last);
        }
        for (int px = from; px < to; ++px) {
          RayDescriptor ray;
          const RingLayout::PrimaryRole role = layout.Primary(i, px, py, 0, 1, tracers[i], &ray);
          if (role == RingLayout::PrimaryRole::kTrace) {
            queues[i].push_back(ray);
          } else if (profiles && role == RingLayout::PrimaryRole::kMiss) {
            (*profiles)[i][0] += tracers[i].work_weights().ray;  // as a worker counts it
          }
        }
      }
    });
  }
  std::vector<RayDescriptor> spawned;
  for (bool busy = true; busy;) {
    busy = false;
    for (int i = 0; i < n; ++i) {
      std::vector<RayDescriptor> queue = std::move(queues[i]);
      queues[i].clear();
      busy = busy || !queue.empty();
      timed(i, [&] {
        for (RayDescriptor& ray : queue) {
          const RayDescriptor before = ray;
          spawned.clear();
          Deposit deposit;
          TraceCounters counters;
          if (profiles) counters.plane_work = (*profiles)[i].data();
          const Tracer::Outcome outcome = tracers[i].Trace(ray, spawned, deposit, counters);
          traced(i, before, ray, spawned, counters, outcome);
          for (const RayDescriptor& r : spawned) queues[i].push_back(r);
          if (outcome != Tracer::Outcome::kLeftSlab) continue;
          const RingLayout::Hop hop = layout.Route(i, ray.cell);
          if (hop != RingLayout::Hop::kFinished)
            queues[RingLayout::Neighbour(i, hop)].push_back(ray);
        }
      });
    }
  }
}

int Hops(const Options& o) {
  auto setup = Prepare(o);
  if (!setup.ok()) return Fail(setup.status());
  std::printf("volume %s, %dx%d, shadows on, equal slabs; per frame\n", o.volume.c_str(), o.width,
              o.height);
  std::printf("%-8s %7s %10s %12s %8s %14s %12s %12s\n", "view", "slabs", "hops", "transit hops",
              "share", "transit steps", "all steps", "ended early");
  const absl::Status status = ForEachEqualRing(
      o, *setup, {0.0, 45.0}, [&](double azimuth, const Camera& camera, const SlabRing& ring) {
        const int n = static_cast<int>(ring.tracers.size());
        const RingLayout& layout = ring.layout;
        uint64_t hops = 0, transit = 0, transit_steps = 0, steps = 0, ended = 0;
        TraceRing(
            layout, ring.tracers, camera, [](int, auto&& share) { share(); },
            [&](int i, const RayDescriptor& before, const RayDescriptor& ray,
                const std::vector<RayDescriptor>& spawned, const TraceCounters& counters,
                Tracer::Outcome outcome) {
              steps += counters.segments;
              ended += counters.ended_early;
              if (outcome != Tracer::Outcome::kLeftSlab ||
                  layout.Route(i, ray.cell) == RingLayout::Hop::kFinished) {
                return;
              }
              ++hops;
              if (spawned.empty() && counters.surface_hits == 0 && ray.color == before.color &&
                  ray.transmittance == before.transmittance && ray.material == before.material &&
                  ray.band == before.band) {
                ++transit;
                transit_steps += counters.segments;
              }
            });
        using ull = unsigned long long;
        std::printf("%-8s %7d %10llu %12llu %7.1f%% %14llu %12llu %12llu\n",
                    azimuth == 0 ? "frontal" : "45 deg", n, static_cast<ull>(hops),
                    static_cast<ull>(transit), hops ? 100.0 * transit / hops : 0.0,
                    static_cast<ull>(transit_steps), static_cast<ull>(steps),
                    static_cast<ull>(ended));
      });
  return status.ok() ? 0 : Fail(status);
}

// ---------------------------------------------------------------- primaries

int Primaries(const Options& o) {
  auto setup = Prepare(o);
  if (!setup.ok()) return Fail(setup.status());
  const Scene& whole = *setup->scene;
  std::printf("volume %s, %dx%d, equal slabs; primary rays per frame (one sample a pixel)\n",
              o.volume.c_str(), o.width, o.height);
  std::printf("%-12s %6s %10s %14s %12s %10s %10s %10s\n", "view", "slabs", "kept", "made (boxes)",
              "made (now)", "boxes/kept", "now/kept", "saved ms");
  const std::pair<double, double> views[] = {{0, 0}, {45, 0}, {0, 15}, {45, 15}, {30, 40}};
  for (const auto& [azimuth, elevation] : views) {
    v1::View view = MakeView(o, azimuth);
    view.set_elevation(elevation);
    auto camera = Camera::Create(*ToCameraSpec(view), setup->extent);
    if (!camera.ok()) return Fail(camera.status());
    const RenderSettings settings = ToRenderSettings(view);
    // What making a ray costs: every pixel's, the least of three passes.
    const Tracer whole_tracer(whole, settings, *camera);
    double ns = HUGE_VAL;
    for (int pass = 0; pass < 3; ++pass) {
      uint64_t made = 0, entered = 0;
      const auto t0 = Clock::now();
      for (int py = 0; py < camera->height(); ++py) {
        for (int px = 0; px < camera->width(); ++px) {
          RayDescriptor ray;
          entered += whole_tracer.MakePrimary(camera->Generate(px, py), 0, &ray);
          ++made;
        }
      }
      ns = std::min(ns, MsSince(t0) * 1e6 / static_cast<double>(made));
      if (entered == 0) return Fail(absl::FailedPreconditionError("no ray enters the volume"));
    }
    for (int n : o.workers) {
      if (n < 1 || n > whole.dims()[1]) continue;
      const SlabRing ring(whole, n, settings, *camera);
      uint64_t kept = 0, made = 0, made_boxes = 0;
      for (int i = 0; i < n; ++i) {
        const Vec3 lo{-0.5 * setup->extent.x,
                      (ring.cuts[i] - 0.5 * whole.dims()[1]) * whole.spacing()[1],
                      -0.5 * setup->extent.z};
        const Vec3 hi{0.5 * setup->extent.x,
                      (ring.cuts[i + 1] - 0.5 * whole.dims()[1]) * whole.spacing()[1],
                      0.5 * setup->extent.z};
        const ImageSpans box = camera->Footprint(lo, hi);
        for (int py = 0; py < camera->height(); ++py) {
          for (int px = 0; px < camera->width(); ++px) {
            if (ring.tracers[i].Void(px, py)) continue;
            made += ring.layout.Holds(i, px, py);
            made_boxes += box.Contains(px, py);
            RayDescriptor ray;
            kept += ring.layout.Primary(i, px, py, 0, 1, ring.tracers[i], &ray) ==
                    RingLayout::PrimaryRole::kTrace;
          }
        }
      }
      char name[32];
      std::snprintf(name, sizeof(name), "az %g el %g", azimuth, elevation);
      using ull = unsigned long long;
      std::printf("%-12s %6d %10llu %14llu %12llu %10.2f %10.2f %10.2f\n", name, n,
                  static_cast<ull>(kept), static_cast<ull>(made_boxes), static_cast<ull>(made),
                  kept ? static_cast<double>(made_boxes) / kept : 0.0,
                  kept ? static_cast<double>(made) / kept : 0.0,
                  (static_cast<double>(made_boxes) - static_cast<double>(made)) * ns / 1e6);
      if (made > made_boxes || kept > made) {
        return Fail(absl::InternalError("a footprint holds more than its box, or too few rays"));
      }
    }
  }
  return 0;
}

// ---------------------------------------------------------------- weights

double ThreadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

// A TraceRing `timed` that adds the thread CPU time of each of slab i's
// shares to ms[i].
auto CpuPerSlab(std::vector<double>& ms) {
  return [&ms](int i, auto&& share) {
    const double t0 = ThreadCpuMs();
    share();
    ms[i] += ThreadCpuMs() - t0;
  };
}

// One slab's frame: its counts and its least tracer CPU time over repeats.
struct SlabWork {
  std::string what;
  double counts[4] = {0, 0, 0, 0};  // steps, cells, shaded points, rays taken
  double ms = 0;
};

// Solves the normal equations of the least squares of the relative error,
// min sum ((w . counts - ms) / ms)^2, for the weights in `use` (the
// others 0).
std::array<double, 4> FitWeights(const std::vector<SlabWork>& rows, unsigned use) {
  double a[4][5] = {};
  for (const SlabWork& r : rows) {
    double x[4];
    for (int k = 0; k < 4; ++k) x[k] = use >> k & 1 ? r.counts[k] / r.ms : 0;
    for (int i = 0; i < 4; ++i) {
      for (int j = 0; j < 4; ++j) a[i][j] += x[i] * x[j];
      a[i][4] += x[i];  // the target, ms / ms
    }
  }
  for (int i = 0; i < 4; ++i) {  // Gauss-Jordan with partial pivoting
    int p = i;
    for (int r = i + 1; r < 4; ++r) {
      if (std::abs(a[r][i]) > std::abs(a[p][i])) p = r;
    }
    std::swap(a[i], a[p]);
    if (a[i][i] == 0) continue;
    for (int r = 0; r < 4; ++r) {
      if (r == i) continue;
      const double f = a[r][i] / a[i][i];
      for (int k = i; k < 5; ++k) a[r][k] -= f * a[i][k];
    }
  }
  std::array<double, 4> w{};
  for (int i = 0; i < 4; ++i) w[i] = a[i][i] != 0 ? a[i][4] / a[i][i] : 0;
  return w;
}

double SquaredRelativeError(const std::vector<SlabWork>& rows, const std::array<double, 4>& w) {
  double sum = 0;
  for (const SlabWork& r : rows) {
    double pred = 0;
    for (int k = 0; k < 4; ++k) pred += w[k] * r.counts[k];
    sum += (pred - r.ms) * (pred - r.ms) / (r.ms * r.ms);
  }
  return sum;
}

// The best fit with no weight below 0: counts that rise together (cells
// with steps) can otherwise trade a negative weight for a larger one. Every
// subset of the four is tried.
std::array<double, 4> FitNonNegative(const std::vector<SlabWork>& rows) {
  std::array<double, 4> best{};
  double best_error = 1e300;
  for (unsigned use = 1; use < 16; ++use) {
    const std::array<double, 4> w = FitWeights(rows, use);
    if (*std::min_element(w.begin(), w.end()) < 0) continue;
    const double e = SquaredRelativeError(rows, w);
    if (e < best_error) best_error = e, best = w;
  }
  return best;
}

int Weights(const Options& o) {
  std::vector<std::pair<std::string, std::string>> inputs = {{o.volume, o.materials}};
  const fs::path engine = fs::path(o.volume).parent_path() / "engine.nrrd";
  const fs::path engine_materials = fs::path(o.materials).parent_path() / "engine_materials.json";
  if (fs::exists(engine) && fs::exists(engine_materials) && engine != fs::path(o.volume)) {
    inputs.push_back({engine.string(), engine_materials.string()});
  }
  std::vector<SlabWork> rows;
  for (const auto& [volume, materials] : inputs) {
    Options vo = o;
    vo.volume = volume;
    vo.materials = materials;
    auto setup = Prepare(vo);
    if (!setup.ok()) return Fail(setup.status());
    const absl::Status status = ForEachEqualRing(
        o, *setup, {0.0, 45.0, 90.0, 135.0},
        [&](double azimuth, const Camera& camera, const SlabRing& ring) {
          const int n = static_cast<int>(ring.tracers.size());
          std::vector<SlabWork> work(n);
          std::vector<double> best(n, 1e300);
          for (int rep = 0; rep < o.repeat; ++rep) {
            std::vector<double> ms(n, 0);
            std::vector<TraceCounters> counters(n);
            std::vector<uint64_t> taken(n, 0);
            TraceRing(
                ring.layout, ring.tracers, camera, CpuPerSlab(ms),
                [&](int i, const RayDescriptor&, const RayDescriptor&,
                    const std::vector<RayDescriptor>&, const TraceCounters& c, Tracer::Outcome) {
                  ++taken[i];
                  counters[i].Add(c);
                });
            for (int i = 0; i < n; ++i) {
              best[i] = std::min(best[i], ms[i]);
              work[i].counts[0] = static_cast<double>(counters[i].segments);
              work[i].counts[1] = static_cast<double>(counters[i].cells);
              work[i].counts[2] = static_cast<double>(counters[i].surface_hits);
              work[i].counts[3] = static_cast<double>(taken[i]);
            }
          }
          for (int i = 0; i < n; ++i) {
            work[i].ms = best[i];
            work[i].what = absl::StrCat(fs::path(volume).filename().string(), " az ", azimuth, " ",
                                        n, " slabs, slab ", i);
            if (work[i].ms > 0.5) rows.push_back(work[i]);
          }
        });
    if (!status.ok()) return Fail(status);
  }
  if (rows.size() < 4) return Fail(absl::FailedPreconditionError("too few slabs to fit"));
  const std::array<double, 4> w = FitNonNegative(rows);
  // A unit of the work profile is about 5 ns: 5e-6 ms.
  const std::array<double, 4> in_use = {kFieldWork.step * 5e-6, kFieldWork.cell * 5e-6,
                                        kFieldWork.hit * 5e-6, kFieldWork.ray * 5e-6};
  auto errors = [&](const std::array<double, 4>& weights, bool print) {
    double sum = 0, worst = 0;
    for (const SlabWork& r : rows) {
      double pred = 0;
      for (int k = 0; k < 4; ++k) pred += weights[k] * r.counts[k];
      const double e = (pred - r.ms) / r.ms;
      sum += std::abs(e);
      worst = std::max(worst, std::abs(e));
      if (print) {
        std::printf("%-36s %9.0f %8.0f %6.0f %8.0f %8.2f %8.2f %+6.1f%%\n", r.what.c_str(),
                    r.counts[0], r.counts[1], r.counts[2], r.counts[3], r.ms, pred, 100 * e);
      }
    }
    return std::pair{sum / rows.size(), worst};
  };
  std::printf("%-36s %9s %8s %6s %8s %8s %8s %7s\n", "slab", "steps", "cells", "hits", "rays",
              "cpu ms", "fit ms", "error");
  const auto [mean, worst] = errors(w, true);
  // Only their proportions cut slabs: the weights in use at their best
  // common scale.
  double sx = 0, sxx = 0;
  for (const SlabWork& r : rows) {
    double pred = 0;
    for (int k = 0; k < 4; ++k) pred += in_use[k] * r.counts[k];
    sx += pred / r.ms;
    sxx += (pred / r.ms) * (pred / r.ms);
  }
  std::array<double, 4> scaled = in_use;
  for (double& x : scaled) x *= sxx > 0 ? sx / sxx : 1;
  const auto [mean_in_use, worst_in_use] = errors(scaled, false);
  std::printf("fitted: a step %.1f ns, a cell %.1f ns, a shaded point %.1f ns, a ray %.1f ns\n",
              w[0] * 1e6, w[1] * 1e6, w[2] * 1e6, w[3] * 1e6);
  std::printf("relative error per slab: mean %.1f%%, worst %.1f%%; with the weights in use "
              "(%d, %d, %d, %d units, at their best scale): mean %.1f%%, worst %.1f%%\n",
              100 * mean, 100 * worst, static_cast<int>(kFieldWork.step),
              static_cast<int>(kFieldWork.cell), static_cast<int>(kFieldWork.hit),
              static_cast<int>(kFieldWork.ray), 100 * mean_in_use, 100 * worst_in_use);
  return 0;
}

// ---------------------------------------------------------------- rays

int PackedRays(const Options& o) {
  auto setup = Prepare(o);
  if (!setup.ok()) return Fail(setup.status());
  const size_t worker_batch = FrameOptions{}.batch_rays;
  std::printf("volume %s, %dx%d, shadows on, equal slabs; rays handed on in a frame; %d repeats\n",
              o.volume.c_str(), o.width, o.height, o.repeat);
  std::printf("%-8s %6s %8s %8s %8s %7s %12s %12s %12s %13s %13s\n", "view", "slabs", "rays",
              "primary", "shadow", "batch", "record B", "packed B/ray", "packed/rec", "pack ns/ray",
              "decode ns/ray");
  bool ok = true;
  const absl::Status status = ForEachEqualRing(
      o, *setup, {0.0, 45.0}, [&](double azimuth, const Camera& camera, const SlabRing& ring) {
        const int n = static_cast<int>(ring.tracers.size());
        if (n < 2) return;
        // Each link's rays (slab i to its left or right neighbour), as queued.
        std::vector<std::string> links(2 * n);
        uint64_t rays = 0, shadows = 0;
        TraceRing(
            ring.layout, ring.tracers, camera, [](int, auto&& share) { share(); },
            [&](int i, const RayDescriptor&, const RayDescriptor& ray,
                const std::vector<RayDescriptor>&, const TraceCounters&, Tracer::Outcome outcome) {
              if (outcome != Tracer::Outcome::kLeftSlab) return;
              const RingLayout::Hop hop = ring.layout.Route(i, ray.cell);
              if (hop == RingLayout::Hop::kFinished) return;
              AppendRay(ray, &links[2 * i + (hop == RingLayout::Hop::kRight)]);
              ++rays;
              shadows += ray.kind == RayKind::kShadow;
            });
        const uint32_t pixels = static_cast<uint32_t>(camera.width() * camera.height());
        for (size_t batch_rays : {worker_batch, size_t{256}, size_t{32}}) {
          std::vector<std::string_view> batches;
          for (const std::string& l : links) {
            const size_t step = batch_rays * kRayRecordBytes;
            for (size_t at = 0; at < l.size(); at += step)
              batches.push_back(std::string_view(l).substr(at, step));
          }
          std::vector<std::string> packed(batches.size());
          std::vector<double> pack_ms, decode_ms;
          uint64_t bytes = 0;
          for (int rep = 0; rep < o.repeat; ++rep) {
            auto t0 = Clock::now();
            for (size_t b = 0; b < batches.size(); ++b) {
              packed[b].clear();
              PackRays(batches[b], &packed[b]);
            }
            pack_ms.push_back(MsSince(t0));
            t0 = Clock::now();
            std::vector<DecodedRays> decoded(batches.size());
            for (size_t b = 0; b < batches.size(); ++b)
              decoded[b] = DecodePackedRays(packed[b], pixels);
            decode_ms.push_back(MsSince(t0));
            bytes = 0;
            for (size_t b = 0; b < batches.size(); ++b) {
              std::string again;
              for (const RayDescriptor& r : decoded[b].rays) AppendRay(r, &again);
              if (!decoded[b].error.ok() || again != batches[b]) {
                std::fprintf(
                    stderr,
                    "cluster_bench: %d slabs: a packed batch does not decode to its rays: %s\n", n,
                    decoded[b].error.ToString().c_str());
                ok = false;
                return;
              }
              bytes += packed[b].size();
            }
          }
          const double per = 1e6 / static_cast<double>(std::max<uint64_t>(1, rays));
          const double per_ray = static_cast<double>(bytes) / std::max<uint64_t>(1, rays);
          std::printf("%-8s %6d %8llu %8llu %8llu %7zu %12zu %12.1f %12.2f %13.1f %13.1f\n",
                      azimuth == 0 ? "frontal" : "45 deg", n, static_cast<unsigned long long>(rays),
                      static_cast<unsigned long long>(rays - shadows),
                      static_cast<unsigned long long>(shadows), batch_rays, kRayRecordBytes,
                      per_ray, per_ray / kRayRecordBytes,
                      *std::min_element(pack_ms.begin(), pack_ms.end()) * per,
                      *std::min_element(decode_ms.begin(), decode_ms.end()) * per);
        }
      });
  if (!status.ok()) return Fail(status);
  std::printf("\n%s\n",
              ok ? "OK: every packed batch decodes to its rays bit for bit" : "FAIL: see stderr");
  return ok ? 0 : 1;
}

// ---------------------------------------------------------------- deposits

int Deposits(const Options& o) {
  auto setup = Prepare(o);
  if (!setup.ok()) return Fail(setup.status());
  const size_t batch_records = FrameOptions{}.deposit_batch;
  std::printf(
      "volume %s, %dx%d, azimuth %g, shadows on, equal slabs, batches of %zu deposits; %d "
      "repeats\n",
      o.volume.c_str(), o.width, o.height, o.azimuth, batch_records, o.repeat);
  std::printf("%-6s %9s %9s %10s %9s %14s %14s %16s %16s\n", "slabs", "deposits", "records",
              "bytes", "batches", "pack ns/dep", "(median)", "ingest ns/dep", "(median)");
  bool ok = true;
  const absl::Status status = ForEachEqualRing(
      o, *setup, {o.azimuth}, [&](double, const Camera& camera, const SlabRing& ring) {
        // Each slab's deposit records in the order its tracer makes them.
        const int n = static_cast<int>(ring.tracers.size());
        std::vector<std::string> records(n);
        std::vector<std::vector<RayDescriptor>> queues(n);
        for (int i = 0; i < n; ++i) {
          for (int py = 0; py < camera.height(); ++py) {
            ring.layout.Primaries(i, py, 0, camera.width(), 1, ring.tracers[i], &queues[i],
                                  &records[i]);
          }
        }
        for (bool busy = true; busy;) {
          busy = false;
          for (int i = 0; i < n; ++i) {
            std::vector<RayDescriptor> work = std::move(queues[i]);
            queues[i].clear();
            busy = busy || !work.empty();
            Deposit deposit;
            TraceCounters counters;
            while (!work.empty()) {
              RayDescriptor ray = work.back();
              work.pop_back();
              if (ring.tracers[i].Trace(ray, work, deposit, counters) ==
                  Tracer::Outcome::kFinished) {
                AppendDeposit(deposit, &records[i]);
              } else {
                const RingLayout::Hop hop = ring.layout.Route(i, ray.cell);
                if (hop != RingLayout::Hop::kFinished)
                  queues[RingLayout::Neighbour(i, hop)].push_back(ray);
              }
            }
          }
        }
        std::vector<std::string_view> batches;
        Framebuffer one_by_one(camera.width(), camera.height());
        uint64_t deposits = 0;
        for (const std::string& r : records) {
          const size_t step = batch_records * kDepositRecordBytes;
          for (size_t at = 0; at < r.size(); at += step) {
            batches.push_back(std::string_view(r).substr(at, step));
          }
          for (const Deposit& d : UnpackDepositRecords(r)) {
            one_by_one.Add(d);
            ++deposits;
          }
        }
        // Packing and ingest, alternated `repeat` times.
        std::vector<std::string> packed(batches.size());
        Framebuffer fb(camera.width(), camera.height());
        std::vector<double> pack_ms, ingest_ms;
        uint64_t pixel_records = 0, bytes = 0;
        for (int rep = 0; rep < o.repeat; ++rep) {
          auto t0 = Clock::now();
          pixel_records = 0;
          for (size_t b = 0; b < batches.size(); ++b) {
            packed[b].clear();
            pixel_records += PackDeposits(batches[b], &packed[b]);
          }
          pack_ms.push_back(MsSince(t0));
          fb.Clear();
          t0 = Clock::now();
          bytes = 0;
          for (const std::string& p : packed) {
            auto added = AddPackedDeposits(p, fb);
            if (!added.ok()) {
              std::fprintf(stderr, "cluster_bench: %s\n", added.status().ToString().c_str());
              ok = false;
              return;
            }
            bytes += p.size();
          }
          ingest_ms.push_back(MsSince(t0));
        }
        if (!fb.Complete() || fb.Resolve().rgb != one_by_one.Resolve().rgb) {
          std::fprintf(stderr, "cluster_bench: %d slabs: the packed deposits give another image\n",
                       n);
          ok = false;
        }
        const double per = 1e6 / static_cast<double>(std::max<uint64_t>(1, deposits));
        std::printf("%-6d %9llu %9llu %10llu %9zu %14.2f %14.2f %16.2f %16.2f\n", n,
                    static_cast<unsigned long long>(deposits),
                    static_cast<unsigned long long>(pixel_records),
                    static_cast<unsigned long long>(bytes), batches.size(),
                    *std::min_element(pack_ms.begin(), pack_ms.end()) * per, Median(pack_ms) * per,
                    *std::min_element(ingest_ms.begin(), ingest_ms.end()) * per,
                    Median(ingest_ms) * per);
      });
  if (!status.ok()) return Fail(status);
  std::printf("\n%s\n",
              ok ? "OK: every framebuffer complete and equal to the deposits added one by one"
                 : "FAIL: see stderr");
  return ok ? 0 : 1;
}

// The cuts a series' last frame ran on, from its workers' slabs; empty
// when they do not form one ring's slabs (several rings).
std::vector<int> SeriesCuts(const Series& s) {
  if (s.frames.empty()) return {};
  std::vector<std::pair<int, int>> slabs;
  for (const auto& w : s.frames.back().workers()) {
    if (w.slab_size() != 2) return {};
    slabs.emplace_back(w.slab(0), w.slab(1));
  }
  std::sort(slabs.begin(), slabs.end());
  std::vector<int> cuts = {0};
  for (const auto& [begin, end] : slabs) {
    if (begin != cuts.back() || end <= begin) return {};
    cuts.push_back(end);
  }
  return cuts;
}

// Each slab's tracer CPU time for one frame at `cuts`, traced in this
// process slab by slab on one thread (TraceRing), the least of `repeat`
// runs: the work the cuts give each worker, without the other workers'
// threads on the same cores. With 8 workers on 2 cores, the cluster's own
// max/mean CPU of the same cuts moves by 0.05-0.1 from one run to the next.
std::vector<double> SlabCpuAlone(const Scene& whole, const std::vector<int>& cuts,
                                 const v1::View& view, const Camera& camera, int repeat) {
  const SlabRing ring(whole, cuts, ToRenderSettings(view), camera);
  const size_t n = ring.tracers.size();
  std::vector<double> least(n, std::numeric_limits<double>::infinity());
  for (int r = 0; r < std::max(1, repeat); ++r) {
    std::vector<double> ms(n, 0.0);
    TraceRing(ring.layout, ring.tracers, camera, CpuPerSlab(ms),
              [](int, const RayDescriptor&, const RayDescriptor&, const std::vector<RayDescriptor>&,
                 const TraceCounters&, Tracer::Outcome) {});
    for (size_t i = 0; i < n; ++i) least[i] = std::min(least[i], ms[i]);
  }
  return least;
}

// Each slab's work profile for one frame at `cuts`, traced in this process
// as TraceRing routes it (per plane, and its total).
struct SlabProfiles {
  std::vector<std::vector<double>> planes;
  std::vector<double> totals;
};

SlabProfiles ProfileAlone(const Scene& whole, const std::vector<int>& cuts, const v1::View& view,
                          const Camera& camera) {
  const SlabRing ring(whole, cuts, ToRenderSettings(view), camera);
  const size_t n = ring.tracers.size();
  std::vector<std::vector<uint64_t>> counted(n);
  for (size_t i = 0; i < n; ++i) counted[i].assign(cuts[i + 1] - cuts[i], 0);
  TraceRing(
      ring.layout, ring.tracers, camera, [](int, auto&& share) { share(); },
      [](int, const RayDescriptor&, const RayDescriptor&, const std::vector<RayDescriptor>&,
         const TraceCounters&, Tracer::Outcome) {},
      &counted);
  SlabProfiles p;
  p.planes.resize(n);
  p.totals.assign(n, 0.0);
  for (size_t i = 0; i < n; ++i) {
    for (uint64_t w : counted[i]) p.planes[i].push_back(static_cast<double>(w)), p.totals[i] += w;
  }
  return p;
}

int Converge(const Options& o) {
  auto setup = Prepare(o);
  if (!setup.ok()) return Fail(setup.status());
  const Scene& whole = *setup->scene;
  const int planes = whole.dims()[1];
  std::printf(
      "volume %s, %dx%d, shadows on; each slab traced alone on one thread (the least of 3 runs)\n"
      "step 0: equal slabs; 1: the cuts of step 0's profile totals (a test-ray prerender's); "
      "2-5: the cuts of the last step's measured times spread by its profile\n\n",
      o.volume.c_str(), o.width, o.height);
  std::printf("%-8s %6s %5s %9s  %-40s %s\n", "view", "slabs", "step", "max/mean", "CPU ms",
              "profile share / CPU share");
  for (double azimuth : {0.0, 45.0}) {
    const v1::View view = MakeView(o, azimuth);
    auto camera = Camera::Create(*ToCameraSpec(view), setup->extent);
    if (!camera.ok()) return Fail(camera.status());
    for (int n : o.workers) {
      if (n < 1 || n > planes) continue;
      std::vector<int> cuts = UniformCuts(planes, n);
      for (int step = 0; step <= 5; ++step) {
        const std::vector<double> ms = SlabCpuAlone(whole, cuts, view, *camera, 3);
        const SlabProfiles p = ProfileAlone(whole, cuts, view, *camera);
        std::string times, shares;
        for (int i = 0; i < n; ++i) {
          absl::StrAppend(&times, i ? " " : "", absl::StrFormat("%.1f", ms[i]));
          absl::StrAppend(
              &shares, i ? " " : "",
              absl::StrFormat("%.2f", (p.totals[i] / Sum(p.totals)) / (ms[i] / Sum(ms))));
        }
        std::printf("%-8s %6d %5d %9.3f  %-40s %s\n", azimuth == 0 ? "frontal" : "45 deg", n, step,
                    Imbalance(ms), times.c_str(), shares.c_str());
        std::fflush(stdout);
        cuts = BalancedCuts(cuts, step == 0 ? p.totals : ms, BalanceRule::kCost, p.planes);
      }
    }
  }
  return 0;
}

// ---------------------------------------------------------------- refine

// For each number of workers and view, each on a fresh embedded cluster: a
// job of `repeat` frames of the view balanced by test rays, and one
// balanced by the previous frame. Per mode: the first and the last frame's tracer
// CPU max/mean in the cluster and of its cuts traced alone, and the frames
// whose cuts moved.
int Refine(const Options& o) {
  auto setup = Prepare(o);
  if (!setup.ok()) return Fail(setup.status());
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  std::printf(
      "volume %s, %dx%d, shadows on, %d cores, %d frames a job; tracer CPU max/mean of the "
      "first and the last frame, in the cluster and traced alone\n\n",
      o.volume.c_str(), o.width, o.height, cores, o.repeat);
  std::printf("%-8s %-8s %-15s %13s %13s %13s %13s  %s\n", "workers", "view", "balance",
              "first, cluster", "first, alone", "last, cluster", "last, alone",
              "cuts moved before frames");
  bool identical = true;
  for (int n : o.workers) {
    for (double azimuth : {0.0, 45.0}) {
      const v1::View view = MakeView(o, azimuth);
      auto camera = Camera::Create(*ToCameraSpec(view), setup->extent);
      if (!camera.ok()) return Fail(camera.status());
      RenderStats rs;
      auto want = RenderLocal(*setup->scene, *camera, ToRenderSettings(view), cores, &rs);
      if (!want.ok()) return Fail(want.status());
      for (const std::string balance : {"test-rays", "previous-frame"}) {
        // Each mode on a fresh cluster: from uniform cuts, nothing learned.
        auto cluster = StartCluster(o, *setup, n);
        if (!cluster.ok()) return Fail(cluster.status());
        const std::string out = (fs::temp_directory_path() / "cluster_bench_refine.exr").string();
        auto stats =
            RunFrames((*cluster)->root_address(), *setup, view, o.repeat, out, balance, o.grid);
        if (!stats.ok()) return Fail(stats.status());
        auto image = ReadImage(out);
        if (!image.ok()) return Fail(image.status());
        identical = identical && image->rgb == want->rgb;
        auto cpu = [](const v1::ClusterFrameStats& f) {
          std::vector<double> ms;
          for (const auto& w : f.workers()) ms.push_back(w.cpu_ms());
          return ms;
        };
        auto alone = [&](const v1::ClusterFrameStats& f) {
          Series one;
          one.frames = {f};
          const std::vector<int> cuts = SeriesCuts(one);
          return cuts.empty() ? 0.0
                              : Imbalance(SlabCpuAlone(*setup->scene, cuts, view, *camera, 3));
        };
        std::string moved;
        for (size_t k = 1; k < stats->size(); ++k) {
          Series a, b;
          a.frames = {(*stats)[k - 1]};
          b.frames = {(*stats)[k]};
          if (SeriesCuts(a) != SeriesCuts(b))
            absl::StrAppend(&moved, moved.empty() ? "" : " ", k + 1);
        }
        std::printf("%-8d %-8s %-15s %13.2f %13.2f %13.2f %13.2f  %s\n", n,
                    azimuth == 0 ? "frontal" : "45 deg", balance.c_str(),
                    Imbalance(cpu(stats->front())), alone(stats->front()),
                    Imbalance(cpu(stats->back())), alone(stats->back()),
                    moved.empty() ? "-" : moved.c_str());
        std::fflush(stdout);
      }
    }
  }
  std::printf("\n%s\n", identical
                            ? "OK: every cluster image equals the in-process image bit for bit"
                            : "FAIL: a cluster image differs");
  return identical ? 0 : 1;
}

int Tables(const Options& o) {
  auto setup = Prepare(o);
  if (!setup.ok()) return Fail(setup.status());
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  struct NamedView {
    const char* name;
    v1::View view;
    Image want;
  };
  std::vector<NamedView> views = {{"frontal", MakeView(o, 0), {}}, {"45 deg", MakeView(o, 45), {}}};
  std::vector<Camera> cameras;
  for (auto& v : views) {
    auto camera = Camera::Create(*ToCameraSpec(v.view), setup->extent);
    if (!camera.ok()) return Fail(camera.status());
    cameras.push_back(*camera);
    RenderStats rs;
    auto image = RenderLocal(*setup->scene, *camera, ToRenderSettings(v.view), cores, &rs);
    if (!image.ok()) return Fail(image.status());
    v.want = *std::move(image);
  }
  std::printf(
      "volume %s, %dx%d, shadows on, %d cores; each figure: mean of %d frames after a "
      "warm-up frame (slab loads, prerender)\n",
      o.volume.c_str(), o.width, o.height, cores, o.repeat);
  bool identical = true;
  // (workers, view, balance) -> series
  std::map<std::tuple<int, int, std::string>, Series> results;
  for (int n : {2, 4, 8}) {
    auto cluster = StartCluster(o, *setup, n);
    if (!cluster.ok()) return Fail(cluster.status());
    for (size_t vi = 0; vi < views.size(); ++vi) {
      for (const std::string balance : {"off", "test-rays"}) {
        auto series = RunSeries((*cluster)->root_address(), *setup, views[vi].view, o.repeat,
                                balance, o.grid, views[vi].want);
        if (!series.ok()) return Fail(series.status());
        if (!series->identical) {
          identical = false;
          std::fprintf(stderr, "cluster_bench: %d workers, %s, balance %s: image differs\n", n,
                       views[vi].name, balance.c_str());
        }
        results[{n, static_cast<int>(vi), balance}] = *std::move(series);
      }
    }
  }

  // The same cuts' balance measured alone (SlabCpuAlone), max/mean; 0
  // when the cuts are not one ring's.
  std::map<std::tuple<int, int, std::string>, double> alone;
  for (const auto& [key, series] : results) {
    const std::vector<int> cuts = SeriesCuts(series);
    const int vi = std::get<1>(key);
    alone[key] = cuts.empty() ? 0.0
                              : Imbalance(SlabCpuAlone(*setup->scene, cuts, views[vi].view,
                                                       cameras[vi], std::max(3, o.repeat)));
  }

  std::printf("\nTable 1: per worker, elapsed / active / tracer CPU in ms\n");
  std::printf("%-8s %-8s %-10s %-7s %-11s %9s %9s %9s %12s %12s %12s\n", "workers", "view",
              "balance", "worker", "slab", "elapsed", "active", "CPU", "max/mean act",
              "max/mean CPU", "CPU alone");
  for (int n : {2, 4}) {
    for (size_t vi = 0; vi < views.size(); ++vi) {
      for (const std::string balance : {"off", "test-rays"}) {
        const Series& s = results[{n, static_cast<int>(vi), balance}];
        const auto elapsed = s.PerWorker(&v1::WorkerFrameStats::elapsed_ms);
        const auto active = s.PerWorker(&v1::WorkerFrameStats::active_ms);
        const auto cpu = s.PerWorker(&v1::WorkerFrameStats::cpu_ms);
        const auto& last = s.frames.back();
        for (size_t i = 0; i < elapsed.size(); ++i) {
          const auto& w = last.workers(static_cast<int>(i));
          std::printf("%-8d %-8s %-10s %-7zu [%3d, %3d) %9.1f %9.1f %9.1f", n, views[vi].name,
                      balance.c_str(), i, w.slab(0), w.slab(1), elapsed[i], active[i], cpu[i]);
          if (i + 1 == elapsed.size()) {
            std::printf(" %12.2f %12.2f %12.2f", Imbalance(active), Imbalance(cpu),
                        alone[{n, static_cast<int>(vi), balance}]);
          }
          std::printf("\n");
        }
      }
    }
  }

  std::printf("\nTable 2: frame time (ms) and relative efficiency T_2W / ((n/2) T_nW)\n");
  std::printf("%-8s %-10s %-8s %9s %10s %11s %12s %12s %12s %12s\n", "view", "balance", "workers",
              "frame", "efficiency", "mean active", "max/mean act", "summed CPU", "max/mean CPU",
              "CPU alone");
  for (size_t vi = 0; vi < views.size(); ++vi) {
    for (const std::string balance : {"off", "test-rays"}) {
      const double t2 = results[{2, static_cast<int>(vi), balance}].FrameMs();
      for (int n : {2, 4, 8}) {
        const Series& s = results[{n, static_cast<int>(vi), balance}];
        const auto active = s.PerWorker(&v1::WorkerFrameStats::active_ms);
        const auto cpu = s.PerWorker(&v1::WorkerFrameStats::cpu_ms);
        const double t = s.FrameMs();
        std::printf("%-8s %-10s %-8d %9.1f %10.2f %11.1f %12.2f %12.1f %12.2f %12.2f\n",
                    views[vi].name, balance.c_str(), n, t, t > 0 ? t2 / ((n / 2.0) * t) : 0.0,
                    active.empty() ? 0.0 : Sum(active) / active.size(), Imbalance(active), Sum(cpu),
                    Imbalance(cpu), alone[{n, static_cast<int>(vi), balance}]);
      }
    }
  }
  std::printf("\n%s\n", identical
                            ? "OK: every cluster image equals the in-process image bit for bit"
                            : "FAIL: a cluster image differs (see stderr)");
  return identical ? 0 : 1;
}

}  // namespace
}  // namespace transtick

int main(int argc, char** argv) {
  transtick::UseReleaseLocking();  // as the daemons it stands for
  // The embedded daemons' per-frame log lines would bury the tables.
  spdlog::set_level(spdlog::level::warn);
  transtick::Options options;
  std::string error = transtick::Parse(argc, argv, &options);
  if (error == "help") {
    std::fputs(transtick::kUsage, stdout);
    return 0;
  }
  if (!error.empty()) {
    std::fprintf(stderr, "cluster_bench: %s\n%s", error.c_str(), transtick::kUsage);
    return 2;
  }
  if (options.mode == "forward") return transtick::Forward(options);
  if (options.mode == "hops") return transtick::Hops(options);
  if (options.mode == "primaries") return transtick::Primaries(options);
  if (options.mode == "weights") return transtick::Weights(options);
  if (options.mode == "deposits") return transtick::Deposits(options);
  if (options.mode == "rays") return transtick::PackedRays(options);
  if (options.mode == "scaling") return transtick::Scaling(options);
  if (options.mode == "converge") return transtick::Converge(options);
  if (options.mode == "refine") return transtick::Refine(options);
  return transtick::Tables(options);
}
