#include "worker_service.h"

#include <spdlog/spdlog.h>

#include <bit>
#include <cstring>
#include <thread>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "clock.h"
#include "convert.h"
#include "daemon.h"
#include "refused.h"
#include "rpc_status.h"
#include "slab_scalars.h"
#include "transtick/partition.h"

namespace transtick {
namespace {

grpc::Status Invalid(const std::string& message) {
  return ToGrpc(absl::InvalidArgumentError(message));
}

absl::StatusOr<std::shared_ptr<const Scene>> AssembleSlab(const v1::SlabHeader& h,
                                                          std::vector<std::string> blocks,
                                                          std::vector<float> scalars) {
  if (h.dims_size() != 3 || h.spacing_size() != 3 || h.value_range_size() != 2) {
    return absl::InvalidArgumentError("slab header: dims, spacing and value_range incomplete");
  }
  std::array<int, 3> dims = {h.dims(0), h.dims(1), h.dims(2)};
  auto mode = ToRenderMode(h.mode());
  if (!mode.ok()) return absl::InvalidArgumentError(absl::StrCat("slab header: ", mode.status().message()));
  const bool dvr = *mode == RenderMode::kDvr;
  Classification classification;
  TransferFunction transfer;
  int max_material = 1;
  if (dvr) {
    auto tf = ToTransferFunction(h.transfer());
    if (!tf.ok()) return tf.status();
    transfer = *std::move(tf);
  } else {
    auto c = ToClassification(h.materials());
    if (!c.ok()) return c.status();
    classification = *std::move(c);
    max_material = classification.MaxLabel();
  }
  auto sticks = Sticks::FromBlocks(dims, h.y_begin(), h.y_end(), max_material, blocks);
  if (!sticks.ok()) return sticks.status();
  // The reach of the slab's planes, where its walks look it up.
  const bool reach = Scene::WalksBricks(*mode, classification);
  auto bricks =
      BrickMap::FromBytes(dims, std::vector<uint8_t>(h.brick_map().begin(), h.brick_map().end()),
                          reach ? h.y_begin() : 0, reach ? h.y_end() : 0);
  if (!bricks.ok()) return bricks.status();
  FieldSummary summary;
  if (!h.field_summary().empty()) {
    if (dvr) return absl::InvalidArgumentError("slab header: a field summary in dvr");
    auto s = FieldSummary::FromBytes(dims, Bands(classification).size(), h.field_summary());
    if (!s.ok()) return s.status();
    summary = *std::move(s);
  }
  auto scene =
      Scene::FromParts(dvr ? RenderMode::kDvr : RenderMode::kSurfaces, dims,
                       {h.spacing(0), h.spacing(1), h.spacing(2)},
                       {h.value_range(0), h.value_range(1)}, *std::move(sticks), std::move(scalars),
                       *std::move(bricks), std::move(classification), std::move(transfer),
                       std::move(summary));
  if (!scene.ok()) return scene.status();
  return std::shared_ptr<const Scene>(std::make_shared<Scene>(*std::move(scene)));
}

}  // namespace

WorkerService::WorkerService(WorkerOptions options)
    : options_(std::move(options)),
      metrics_(std::make_shared<Metrics>()),
      address_(options_.address),
      frames_(options_.frames),
      early_(options_.early_streams, options_.early_stream_wait),
      sweeper_(SweepPeriod(std::min(options_.frames.prepared_idle, options_.frames.running_idle)),
               [this] {
                 // Time the worker did not run is not a frame's idleness.
                 auto paused = [this](Clock::time_point t) { return sweeper_.PausedSince(t); };
                 for (FrameTable::Dropped& d : frames_.TakeExpired(Clock::now(), paused)) {
                   metrics_->Add("transtick_worker_frames_dropped_total", 1);
                   Drop(std::move(d));
                 }
               }) {
  using T = Metrics::Type;
  Metrics& m = *metrics_;
  m.Declare("transtick_worker_frames_total", T::kCounter, "Frames this worker ended, by result.");
  m.Declare("transtick_worker_frames_dropped_total", T::kCounter,
            "Frames let go of because nobody ended them in time.");
  m.Declare("transtick_worker_frame_seconds", T::kHistogram,
            "A frame's elapsed time on this worker, from its tracers starting to its end.",
            {0.005, 0.01, 0.02, 0.033, 0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 30, 60, 300});
  m.Declare("transtick_worker_rays_traced_total", T::kCounter, "Rays traced here, by kind.");
  m.Declare("transtick_worker_rays_forwarded_total", T::kCounter,
            "Rays sent to a ring neighbour, by direction.");
  m.Declare("transtick_worker_rays_received_total", T::kCounter,
            "Rays received from a ring neighbour, by direction.");
  m.Declare("transtick_worker_rays_rejected_total", T::kCounter,
            "Invalid ray records from a neighbour, dropped (each aborts its frame).");
  m.Declare("transtick_worker_rays_truncated_total", T::kCounter,
            "Rays ended at the tracer's hard bound (0 unless there is a defect).");
  m.Declare("transtick_worker_stream_bytes_total", T::kCounter,
            "Bytes of ray batches on the neighbour streams, by direction (sent, received).");
  m.Declare("transtick_worker_busy_seconds_total", T::kCounter,
            "Time the tracer threads traced (active time, averaged over threads).");
  m.Declare("transtick_worker_idle_seconds_total", T::kCounter,
            "Time within frames the tracer threads waited for rays.");
  m.Declare("transtick_worker_cpu_seconds_total", T::kCounter, "CPU time of the tracer threads.");
  m.Declare("transtick_worker_inbox_high_water_rays", T::kGauge,
            "The most rays that waited in the inbox at once during the last frame.");
  m.Declare("transtick_worker_frames_held", T::kGauge, "Frames prepared or running now.");
  m.Declare("transtick_worker_datasets_held", T::kGauge, "Slabs of datasets held in memory.");
  m.Declare("transtick_worker_threads", T::kGauge, "Tracer threads.");
  m.OnScrape([this](Metrics& g) {
    g.Set("transtick_worker_frames_held", static_cast<double>(frames_.size()));
    size_t datasets = 0;
    {
      absl::MutexLock lock(&mu_);
      datasets = datasets_.size();
    }
    g.Set("transtick_worker_datasets_held", static_cast<double>(datasets));
    g.Set("transtick_worker_threads", options_.threads);
  });
}

WorkerService::~WorkerService() { CancelAll(); }

namespace {

// One frame's statistics into the worker's counters.
void CountFrame(Metrics& m, const v1::WorkerFrameStats& s, bool cancelled) {
  m.Add("transtick_worker_frames_total", 1, {{"result", cancelled ? "cancelled" : "done"}});
  m.Observe("transtick_worker_frame_seconds", s.elapsed_ms() / 1e3);
  const double other = static_cast<double>(s.rays_traced()) - s.primary_traced() - s.shadow_traced();
  m.Add("transtick_worker_rays_traced_total", s.primary_traced(), {{"kind", "primary"}});
  m.Add("transtick_worker_rays_traced_total", s.shadow_traced(), {{"kind", "shadow"}});
  if (other > 0) m.Add("transtick_worker_rays_traced_total", other, {{"kind", "other"}});
  m.Add("transtick_worker_rays_forwarded_total", s.sent_left(), {{"direction", "left"}});
  m.Add("transtick_worker_rays_forwarded_total", s.sent_right(), {{"direction", "right"}});
  m.Add("transtick_worker_rays_received_total", s.received_left(), {{"direction", "left"}});
  m.Add("transtick_worker_rays_received_total", s.received_right(), {{"direction", "right"}});
  m.Add("transtick_worker_rays_rejected_total", s.rays_rejected());
  m.Add("transtick_worker_rays_truncated_total", s.rays_truncated());
  m.Add("transtick_worker_stream_bytes_total", s.bytes_sent(), {{"direction", "sent"}});
  m.Add("transtick_worker_stream_bytes_total", s.bytes_received(), {{"direction", "received"}});
  m.Add("transtick_worker_busy_seconds_total", s.active_ms() / 1e3);
  m.Add("transtick_worker_idle_seconds_total", std::max(0.0, s.elapsed_ms() - s.active_ms()) / 1e3);
  m.Add("transtick_worker_cpu_seconds_total", s.cpu_ms() / 1e3);
  m.Set("transtick_worker_inbox_high_water_rays", s.buffer_high_water());
}

}  // namespace

void WorkerService::set_address(const std::string& address) {
  absl::MutexLock lock(&mu_);
  address_ = address;
}

void WorkerService::CancelAll() {
  early_.Close();
  for (auto& f : frames_.TakeAll()) f->End(/*cancel=*/true);
}

void WorkerService::Drop(FrameTable::Dropped dropped) {
  spdlog::warn("frame {} {}; its tracers stop and its streams are cancelled", dropped.frame->id(),
               dropped.why);
  // Never blocks: the tracers stop within one ray, and the frame is freed
  // when the last of them and of its streams lets go of it.
  dropped.frame->EndAsync(/*cancel=*/true, [](v1::WorkerFrameStats) {});
}

grpc::Status WorkerService::NotHere(uint64_t id, const char* what) const {
  return ToGrpc(absl::NotFoundError(absl::StrCat("frame ", id, " ", what, frames_.WhyGone(id))));
}

grpc::Status WorkerService::LoadSlab(grpc::ServerContext* ctx,
                                     grpc::ServerReader<v1::SlabChunk>* reader,
                                     v1::LoadReply* reply) {
  if (grpc::Status s = RequireRole(*ctx, "LoadSlab", {Role::kRoot}); !s.ok()) return s;
  v1::SlabChunk chunk;
  if (!reader->Read(&chunk) || !chunk.has_header()) {
    return Invalid("LoadSlab: the first message must carry the slab header");
  }
  const v1::SlabHeader header = chunk.header();
  if (header.dataset_key().empty()) return Invalid("LoadSlab: empty dataset_key");
  // Compared as samples: a hostile count times 4 could wrap around.
  if (header.scalar_count() > options_.max_slab_bytes / sizeof(float)) {
    return ToGrpc(absl::ResourceExhaustedError(
        absl::StrCat("LoadSlab: ", header.scalar_count(),
                     " scalars (4 bytes each held) exceed this worker's limit of ",
                     options_.max_slab_bytes, " bytes")));
  }
  std::vector<std::string> blocks;
  // Each message's scalars decoded as they arrive, in their coding
  // (docs/formats.md, "Slab scalars").
  std::vector<float> scalars(header.scalar_count());
  size_t filled = 0;
  do {
    for (auto& b : *chunk.mutable_blocks()) blocks.push_back(std::move(b));
    if (absl::Status s = TakeSlabScalars(chunk, scalars.data(), scalars.size(), &filled); !s.ok()) {
      return Invalid(absl::StrCat("LoadSlab: ", s.message(), " (the header announced ",
                                  header.scalar_count(), " samples)"));
    }
  } while (reader->Read(&chunk));
  if (filled != scalars.size()) {
    return Invalid(absl::StrCat("LoadSlab: ", filled, " scalars arrived, header said ",
                                header.scalar_count()));
  }
  auto scene = AssembleSlab(header, std::move(blocks), std::move(scalars));
  if (!scene.ok()) return ToGrpc(scene.status());
  reply->set_memory_bytes((*scene)->MemoryBytes());
  spdlog::info("loaded {} slab [{}, {}): {:.1f} MB", header.dataset_key(), header.y_begin(),
               header.y_end(), (*scene)->MemoryBytes() / 1e6);
  absl::MutexLock lock(&mu_);
  datasets_[header.dataset_key()] = *std::move(scene);
  return grpc::Status::OK;
}

grpc::Status WorkerService::Evict(grpc::ServerContext* ctx, const v1::DatasetRef* req,
                                  v1::FrameAck*) {
  if (grpc::Status s = RequireRole(*ctx, "Evict", {Role::kRoot}); !s.ok()) return s;
  // An empty key used to mean "everything": one stray call wiped every slab
  // while the root believed them loaded, and later frames on them failed.
  if (req->dataset_key().empty()) {
    return ToGrpc(absl::InvalidArgumentError("Evict: a dataset_key is required"));
  }
  absl::MutexLock lock(&mu_);
  if (datasets_.erase(req->dataset_key()) == 0) {
    return ToGrpc(absl::NotFoundError(
        absl::StrCat("Evict: dataset ", req->dataset_key(), " is not loaded here")));
  }
  return grpc::Status::OK;
}

std::shared_ptr<const Scene> WorkerService::FindDataset(const std::string& key) {
  absl::MutexLock lock(&mu_);
  auto it = datasets_.find(key);
  return it == datasets_.end() ? nullptr : it->second;
}

grpc::Status WorkerService::FetchPlanes(grpc::ServerContext* ctx, const v1::PlanesRequest* req,
                                        grpc::ServerWriter<v1::SlabChunk>* writer) {
  // A worker re-slabbing fetches planes from another.
  if (grpc::Status s = RequireRole(*ctx, "FetchPlanes", {Role::kWorker}); !s.ok()) return s;
  std::shared_ptr<const Scene> scene = FindDataset(req->dataset_key());
  if (!scene) {
    return ToGrpc(absl::NotFoundError(
        absl::StrCat("FetchPlanes: dataset ", req->dataset_key(), " is not here")));
  }
  const int sb = scene->scalar_y_begin(), se = scene->scalar_y_end();
  // An empty range asks for nothing of that kind.
  const bool sticks_ok = req->y_begin() == req->y_end() ||
                         (req->y_begin() >= scene->y_begin() && req->y_end() <= scene->y_end() &&
                          req->y_begin() < req->y_end());
  const bool scalars_ok = req->scalar_begin() == req->scalar_end() ||
                          (req->scalar_begin() >= sb && req->scalar_end() <= se &&
                           req->scalar_begin() < req->scalar_end());
  if (!sticks_ok || !scalars_ok) {
    return Invalid(absl::StrCat(
        "FetchPlanes: asked for sticks [", req->y_begin(), ", ", req->y_end(), ") and scalars [",
        req->scalar_begin(), ", ", req->scalar_end(), "); this worker holds sticks [",
        scene->y_begin(), ", ", scene->y_end(), ") and scalars [", sb, ", ", se, ")"));
  }
  constexpr size_t kChunkBytes = 1 << 20;
  v1::SlabChunk chunk;
  size_t pending = 0;
  auto flush = [&] {
    const bool ok = writer->Write(chunk);
    chunk.Clear();
    pending = 0;
    return ok;
  };
  if (req->y_begin() < req->y_end()) {
    for (std::string& b : scene->sticks().EncodeRows(req->y_begin(), req->y_end())) {
      pending += b.size();
      chunk.add_blocks(std::move(b));
      if (pending >= kChunkBytes && !flush()) return ToGrpc(absl::CancelledError("reader left"));
    }
  }
  if (req->scalar_begin() < req->scalar_end()) {
    // Each z's rows asked for, straight from the slab's planes (in the order
    // CopyScalars gives them), as the root sends a slab.
    const auto& dims = scene->dims();
    const size_t row = static_cast<size_t>(req->scalar_end() - req->scalar_begin()) * dims[0];
    for (int z = 0; z < dims[2]; ++z) {
      const float* first =
          scene->scalars().data() +
          (static_cast<size_t>(z) * (se - sb) + (req->scalar_begin() - sb)) * dims[0];
      if (!AppendSlabScalars(first, row, chunk, pending, kChunkBytes, flush)) {
        return ToGrpc(absl::CancelledError("reader left"));
      }
    }
  }
  if ((chunk.blocks_size() > 0 || !chunk.scalars().empty()) && !flush()) {
    return ToGrpc(absl::CancelledError("reader left"));
  }
  return grpc::Status::OK;
}

namespace {

// Planes of a new slab that its worker fetches from one other worker.
struct Fetch {
  const v1::PlaneSource* source;
  int y_begin, y_end;            // sticks
  int scalar_begin, scalar_end;  // scalars
  std::vector<std::string> blocks;
  ScalarPlanes scalars;
  absl::Status status;
};

// Parts of [lo, hi) outside [held_lo, held_hi): at most two intervals.
std::vector<std::pair<int, int>> Missing(int lo, int hi, int held_lo, int held_hi) {
  std::vector<std::pair<int, int>> out;
  if (held_lo >= held_hi) return {{lo, hi}};
  if (lo < std::min(hi, held_lo)) out.push_back({lo, std::min(hi, held_lo)});
  if (std::max(lo, held_hi) < hi) out.push_back({std::max(lo, held_hi), hi});
  return out;
}

void RunFetch(Fetch& f, const std::array<int, 3>& dims) {
  auto stub = v1::Worker::NewStub(MakeChannel(f.source->address(), Role::kWorker));
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(120));
  v1::PlanesRequest req;
  req.set_dataset_key(f.source->dataset_key());
  req.set_y_begin(f.y_begin);
  req.set_y_end(f.y_end);
  req.set_scalar_begin(f.scalar_begin);
  req.set_scalar_end(f.scalar_end);
  auto reader = stub->FetchPlanes(&ctx, req);
  // The planes asked for, decoded as they arrive (docs/formats.md, "Slab
  // scalars").
  f.scalars.values.resize(static_cast<size_t>(f.scalar_end - f.scalar_begin) * dims[0] * dims[2]);
  size_t filled = 0;
  absl::Status decoded;
  v1::SlabChunk chunk;
  while (reader->Read(&chunk)) {
    for (auto& b : *chunk.mutable_blocks()) f.blocks.push_back(std::move(b));
    if (decoded.ok()) {
      decoded = TakeSlabScalars(chunk, f.scalars.values.data(), f.scalars.values.size(), &filled);
      if (!decoded.ok()) ctx.TryCancel();
    }
  }
  grpc::Status s = reader->Finish();
  if (!decoded.ok()) {
    f.status = absl::AbortedError(
        absl::StrCat("planes from ", f.source->address(), ": ", decoded.message()));
    return;
  }
  if (!s.ok()) {
    // ABORTED, whatever the source said: this worker is fine, a source is not.
    f.status = absl::AbortedError(
        absl::StrCat("fetching planes from ", f.source->address(), ": ", s.error_message()));
    return;
  }
  f.scalars.y_begin = f.scalar_begin;
  f.scalars.y_end = f.scalar_end;
  if (filled != f.scalars.values.size()) {
    f.status = absl::AbortedError(absl::StrCat("planes from ", f.source->address(), ": ", filled,
                                               " scalars, expected ", f.scalars.values.size()));
  }
}

}  // namespace

grpc::Status WorkerService::Reslab(grpc::ServerContext* ctx, const v1::ReslabRequest* req,
                                   v1::LoadReply* reply) {
  // Only the root says where a worker fetches planes from: the addresses
  // of workers it registered.
  if (grpc::Status s = RequireRole(*ctx, "Reslab", {Role::kRoot}); !s.ok()) return s;
  std::shared_ptr<const Scene> old = FindDataset(req->old_key());
  if (!old) {
    return ToGrpc(absl::FailedPreconditionError(
        absl::StrCat("Reslab: dataset ", req->old_key(), " is not loaded here")));
  }
  const auto& dims = old->dims();
  const int y0 = req->y_begin(), y1 = req->y_end();
  if (req->new_key().empty() || y0 < 0 || y0 >= y1 || y1 > dims[1]) {
    return Invalid(absl::StrCat("Reslab: bad slab [", y0, ", ", y1, ") or empty key"));
  }
  const auto started = Clock::now();
  // What this worker has already.
  const int sb = old->ScalarBegin(y0), se = old->ScalarEnd(y1);
  const int own_sb = old->scalar_y_begin(), own_se = old->scalar_y_end();
  std::vector<std::string> blocks;
  std::vector<ScalarPlanes> planes;
  const int keep0 = std::max(y0, old->y_begin()), keep1 = std::min(y1, old->y_end());
  if (keep0 < keep1) blocks = old->sticks().EncodeRows(keep0, keep1);
  if (std::max(sb, own_sb) < std::min(se, own_se)) {
    planes.push_back(old->CopyScalars(std::max(sb, own_sb), std::min(se, own_se)));
  }
  // The rest from the workers whose slabs hold them.
  std::vector<Fetch> fetches;
  auto plan = [&](const std::vector<std::pair<int, int>>& missing, bool sticks) -> grpc::Status {
    for (auto [lo, hi] : missing) {
      while (lo < hi) {
        const v1::PlaneSource* from = nullptr;
        for (const auto& src : req->sources()) {
          if (src.y_begin() <= lo && lo < src.y_end()) {
            from = &src;
            break;
          }
        }
        if (!from) {
          return ToGrpc(
              absl::FailedPreconditionError(absl::StrCat("Reslab: no source holds plane ", lo)));
        }
        const int end = std::min(hi, from->y_end());
        Fetch f{from, 0, 0, 0, 0, {}, {}, {}};
        (sticks ? f.y_begin : f.scalar_begin) = lo;
        (sticks ? f.y_end : f.scalar_end) = end;
        fetches.push_back(std::move(f));
        lo = end;
      }
    }
    return grpc::Status::OK;
  };
  if (auto s = plan(Missing(y0, y1, old->y_begin(), old->y_end()), true); !s.ok()) return s;
  if (auto s = plan(Missing(sb, se, own_sb, own_se), false); !s.ok()) return s;
  std::vector<std::thread> threads;
  for (Fetch& f : fetches) threads.emplace_back([&f, &dims] { RunFetch(f, dims); });
  for (auto& t : threads) t.join();
  const double fetch_ms = MsSince(started);
  for (Fetch& f : fetches) {
    if (!f.status.ok()) return ToGrpc(f.status);
    for (auto& b : f.blocks) blocks.push_back(std::move(b));
    if (f.scalar_begin < f.scalar_end) planes.push_back(std::move(f.scalars));
  }
  auto scene = old->Reslab(y0, y1, blocks, planes);
  if (!scene.ok()) return ToGrpc(scene.status());
  reply->set_memory_bytes(scene->MemoryBytes());
  spdlog::info(
      "re-slabbed {} [{}, {}) -> [{}, {}) with planes from {} neighbour fetch(es): {:.1f} ms, "
      "{:.1f} of them gathering planes",
      req->new_key(), old->y_begin(), old->y_end(), y0, y1, fetches.size(), MsSince(started),
      fetch_ms);
  absl::MutexLock lock(&mu_);
  datasets_[req->new_key()] = std::make_shared<const Scene>(*std::move(scene));
  return grpc::Status::OK;
}

grpc::ServerUnaryReactor* WorkerService::PrepareFrame(grpc::CallbackServerContext* ctx,
                                                      const v1::FrameSpec* spec,
                                                      v1::FrameAck* reply) {
  grpc::ServerUnaryReactor* reactor = ctx->DefaultReactor();
  grpc::Status s = RequireRole(*ctx, "PrepareFrame", {Role::kRoot});
  if (s.ok()) s = Prepare(*spec);
  if (!s.ok() || !spec->run()) {
    reactor->Finish(s);
    return reactor;
  }
  // Prepared and started in one call (FrameSpec.run), as RunFrame starts it.
  Start(reactor, spec->frame_id(), reply, "was dropped as soon as it was prepared");
  return reactor;
}

grpc::Status WorkerService::Prepare(const v1::FrameSpec& spec) {
  std::shared_ptr<const Scene> scene;
  {
    absl::MutexLock lock(&mu_);
    auto it = datasets_.find(spec.dataset_key());
    if (it == datasets_.end()) {
      return ToGrpc(absl::FailedPreconditionError(
          absl::StrCat("dataset ", spec.dataset_key(), " is not loaded here")));
    }
    scene = it->second;
  }
  if (frames_.Find(spec.frame_id())) {
    return ToGrpc(
        absl::AlreadyExistsError(absl::StrCat("frame ", spec.frame_id(), " is already prepared")));
  }
  const int n = spec.cuts_size() - 1;
  const std::vector<int> cuts(spec.cuts().begin(), spec.cuts().end());
  if (n < 1 || !ValidCuts(cuts, scene->dims()[1], n)) {
    return Invalid(absl::StrCat("frame ", spec.frame_id(), ": cuts [", absl::StrJoin(cuts, ", "),
                                "] do not cut the volume's ", scene->dims()[1],
                                " planes into increasing slabs from 0"));
  }
  if (spec.index() < 0 || spec.index() >= n || spec.cuts(spec.index()) != scene->y_begin() ||
      spec.cuts(spec.index() + 1) != scene->y_end()) {
    return Invalid(absl::StrCat("frame ", spec.frame_id(), ": slab ", spec.index(),
                                " of the cuts does not match the loaded slab [", scene->y_begin(),
                                ", ", scene->y_end(), ")"));
  }
  // The view is converted here once; the frame keeps the result.
  auto request = ToFrameRequest(spec.view());
  if (!request.ok()) return ToGrpc(request.status());
  const auto& d = scene->dims();
  const auto& sp = scene->spacing();
  auto camera = Camera::Create(request->camera, Vec3{d[0] * sp[0], d[1] * sp[1], d[2] * sp[2]});
  if (!camera.ok()) return ToGrpc(camera.status());
  if (absl::Status s = CheckRenderSettings(request->settings, scene->mode(), d, sp,
                                           int64_t{camera->width()} * camera->height());
      !s.ok()) {
    return ToGrpc(s);
  }
  if (spec.row_step() < 1 || spec.row_begin() < 0 || spec.row_end() > camera->height() ||
      spec.display().empty()) {
    return Invalid("frame: bad row range or no display");
  }
  FrameOptions fo;
  fo.threads = options_.threads;
  fo.batch_rays = options_.batch_rays;
  fo.linger = options_.linger;
  fo.order = order_;
  auto added = frames_.Add(std::make_shared<Frame>(spec, std::move(scene), *std::move(camera),
                                                   request->settings, fo));
  if (!added.ok()) return ToGrpc(added.status());
  if (*added) Drop(**std::move(added));
  // A neighbour's rays that came first go in now.
  early_.Notify(spec.frame_id());
  return grpc::Status::OK;
}

std::shared_ptr<Frame> WorkerService::FindFrame(uint64_t id) { return frames_.Find(id); }

void WorkerService::Start(grpc::ServerUnaryReactor* reactor, uint64_t id, v1::FrameAck* reply,
                          const char* missing) {
  std::shared_ptr<Frame> frame = FindFrame(id);
  if (!frame) {
    reactor->Finish(NotHere(id, missing));
    return;
  }
  frame->Start([reactor, reply](absl::Status s) {
    reply->set_running(s.ok());
    reactor->Finish(ToGrpc(s));
  });
}

grpc::ServerUnaryReactor* WorkerService::RunFrame(grpc::CallbackServerContext* ctx,
                                                  const v1::FrameRef* req, v1::FrameAck* reply) {
  grpc::ServerUnaryReactor* reactor = ctx->DefaultReactor();
  if (grpc::Status s = RequireRole(*ctx, "RunFrame", {Role::kRoot}); !s.ok()) {
    reactor->Finish(s);
    return reactor;
  }
  Start(reactor, req->frame_id(), reply, "was not prepared");
  return reactor;
}

grpc::ServerUnaryReactor* WorkerService::EndFrame(grpc::CallbackServerContext* ctx,
                                                  const v1::FrameRef* req,
                                                  v1::WorkerFrameStats* reply) {
  grpc::ServerUnaryReactor* reactor = ctx->DefaultReactor();
  if (grpc::Status s = RequireRole(*ctx, "EndFrame", {Role::kRoot}); !s.ok()) {
    reactor->Finish(s);
    return reactor;
  }
  std::shared_ptr<Frame> frame = frames_.Take(req->frame_id());
  if (!frame) {
    reactor->Finish(NotHere(req->frame_id(), "is not running here"));
    return reactor;
  }
  const std::string id = options_.id;
  std::string address;
  {
    absl::MutexLock lock(&mu_);
    address = address_;
  }
  // The reply goes when the tracers have stopped (within one ray), from
  // the last of them; the streams wind down after it.
  frame->EndAsync(req->cancel(), [reactor, reply, id, address, metrics = metrics_,
                                   cancel = req->cancel()](v1::WorkerFrameStats stats) {
    CountFrame(*metrics, stats, cancel);
    *reply = std::move(stats);
    reply->set_id(id);
    reply->set_address(address);
    reactor->Finish(grpc::Status::OK);
  });
  return reactor;
}

grpc::ServerBidiReactor<v1::RayBatch, v1::RayBatch>* WorkerService::Rays(
    grpc::CallbackServerContext* ctx) {
  if (grpc::Status s = RequireRole(*ctx, "Rays", {Role::kWorker}); !s.ok()) {
    return new RefusedBidi<v1::RayBatch, v1::RayBatch>(s);
  }
  return Frame::NewLeftStream(
      ctx, [this](uint64_t id) { return FindFrame(id); }, &early_);
}

}  // namespace transtick
