#include "job_runner.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <thread>

#include "absl/strings/str_cat.h"
#include "clock.h"
#include "convert.h"
#include "daemon.h"
#include "security.h"
#include "transtick/tracer.h"

namespace transtick {
namespace {

// A worker that dies is dropped and the frame runs again on the others; a
// display that went away gets time to come back: the attempts are spaced
// 0.25, 0.5, 1 and 2 s apart (about 4 s in all).
constexpr int kAttempts = 5;
constexpr auto kFirstBackoff = std::chrono::milliseconds(250);

// Sleeps `d`, or less if `cancelled()` turns true.
void SleepUnless(std::chrono::milliseconds d, const std::function<bool()>& cancelled) {
  const auto until = Clock::now() + d;
  while (Clock::now() < until && !cancelled()) {
    std::this_thread::sleep_for(
        std::min<Clock::duration>(std::chrono::milliseconds(20), until - Clock::now()));
  }
}

double PixelsOf(const FrameTask& task) {
  return static_cast<double>(task.request->camera.width) * task.request->camera.height;
}

// What a frame of the task costs: as the dataset's last frame did, for this
// frame's pixels, else as assumed.
FrameCosts CostsFor(const FrameTask& task) ABSL_EXCLUSIVE_LOCKS_REQUIRED(task.data->mu) {
  return task.data->costs_pixels > 0
             ? ScaledCosts(task.data->costs, task.data->costs_pixels, PixelsOf(task))
             : DefaultFrameCosts(PixelsOf(task));
}

}  // namespace

JobRunner::JobRunner(const RunnerOptions& options, JobQueue& queue, Registry& registry,
                     Metrics& metrics)
    : options_(options),
      machine_(MachineId()),
      turns_(options.frames_tracing == 1 ? 1 : 2),
      queue_(queue),
      registry_(registry),
      metrics_(metrics),
      datasets_(options.data_dir, options.max_volume_bytes),
      slabs_(registry),
      driver_(registry, options.display, options.frame_timeout_s) {
  using T = Metrics::Type;
  const std::vector<double> seconds = {0.005, 0.01, 0.02, 0.033, 0.05, 0.1, 0.2, 0.5,
                                       1,     2,    5,    10,    30,   60,  300};
  metrics.Declare("transtick_root_frames_total", T::kCounter, "Frames rendered and published.");
  metrics.Declare("transtick_root_frame_seconds", T::kHistogram,
                  "A frame's time at the root, from its start to its image assembled.", seconds);
  metrics.Declare("transtick_root_job_start_seconds", T::kHistogram,
                  "From a job's submission to the start of its first frame.", seconds);
  metrics.Declare("transtick_root_frame_retries_total", T::kCounter,
                  "Frame attempts that failed (a worker or the display lost) and were rendered again.");
  metrics.Declare("transtick_root_rays_traced_total", T::kCounter,
                  "Rays traced by the workers, summed over the cluster, by kind (a ray crossing "
                  "slabs counts on each).");
  metrics.Declare("transtick_root_rays_forwarded_total", T::kCounter,
                  "Rays the workers passed to a ring neighbour, summed over the cluster.");
  metrics.Declare("transtick_root_ray_bytes_total", T::kCounter,
                  "Bytes of ray batches the workers sent to their neighbours.");
  metrics.Declare("transtick_root_frame_imbalance", T::kGauge,
                  "The last frame's max/mean active time over the workers.");
}

void JobRunner::Start() { thread_ = std::thread([this] { Loop(); }); }

JobRunner::~JobRunner() { Stop(); }

void JobRunner::Stop() {
  queue_.Stop();
  if (thread_.joinable()) thread_.join();
}

void JobRunner::Loop() {
  while (std::shared_ptr<Job> job = queue_.Next()) {
    if (!job->cancelled()) {
      job->SetRunning();
      spdlog::info("{} running", job->id());
    }
    absl::Status status;
    do {
      status = job->cancelled() ? absl::CancelledError("cancelled") : RunJob(*job);
    } while (!job->Complete(status));
    if (status.ok()) {
      spdlog::info("{} done", job->id());
    } else {
      spdlog::warn("{} ended: {}", job->id(), Printable(status.message()));
    }
  }
}

absl::Status JobRunner::RunJob(Job& job) {
  std::shared_ptr<LoadedDataset> data;
  int loaded = -1;
  FrameTask::Chosen chosen;  // the automatic rings of the dataset's frames
  // Frames are pipelined (docs/design.md, "Pipelined frames"): the next
  // frame starts as soon as the one before has traced, while that one's
  // image travels and its workers report. At most two are in flight, and
  // images are published in frame order.
  std::shared_ptr<Flight> last;
  bool said_overlap = false;  // logged once a job
  // Waits for the frame in flight to end (stopping it first when
  // `abandon`); its status.
  auto land = [&](bool abandon) {
    if (!last) return absl::OkStatus();
    if (abandon) last->abandon = true;
    last->thread.join();
    absl::Status s = last->status;
    if (s.ok()) job.FrameRendered(last->frame);
    last.reset();
    return s;
  };
  while (std::optional<int> frame = job.NextFrame()) {
    if (job.cancelled()) {
      land(/*abandon=*/true).IgnoreError();  // the job ends cancelled
      return absl::CancelledError("cancelled");
    }
    const FrameKey key = job.key(*frame);
    if (key.dataset != loaded) {
      if (absl::Status s = land(/*abandon=*/false); !s.ok()) return s;
      auto d = datasets_.Load(job.spec().datasets(key.dataset), job.plan().datasets[key.dataset]);
      if (!d.ok()) return d.status();
      data = *std::move(d);
      loaded = key.dataset;
      chosen = {};
      if (!data->warnings.empty()) {
        v1::JobEvent e;
        e.set_dataset(key.dataset);
        for (const std::string& w : data->warnings) e.add_warnings(w);
        job.Publish(std::move(e));
      }
    }
    // A frame balanced by the one before it plans only once that one's
    // workers have reported and its balancer has learned from them; its
    // image may still be on its way.
    if (last && job.plan().datasets[key.dataset].balance[key.view] == v1::PREVIOUS_FRAME) {
      last->learned.WaitForNotification();
    }
    auto next = std::make_shared<Flight>();
    next->frame = *frame;
    if (last) {
      // With two frames tracing, the next one starts once the last runs on
      // every worker: the workers trace the older first, and the next fills
      // what its tail leaves idle.
      const bool overlap = Overlap();
      if (!said_overlap) {
        said_overlap = true;
        spdlog::info("{}: {}", job.id(),
                     overlap ? "frames overlap (a frame starts once the last one runs)"
                             : "frames one at a time (a frame starts once the last one traced)");
      }
      (overlap ? last->running : last->traced).WaitForNotification();
    }
    next->thread = std::thread([this, &job, data, &chosen, me = next, before = last] {
      me->status = RunView(job, *data, chosen, *me, before.get());
      if (!me->running.HasBeenNotified()) me->running.Notify();
      if (!me->traced.HasBeenNotified()) me->traced.Notify();
      if (!me->learned.HasBeenNotified()) me->learned.Notify();
      if (!me->published.HasBeenNotified()) me->published.Notify();
    });
    if (absl::Status s = land(/*abandon=*/false); !s.ok()) {
      last = std::move(next);
      land(/*abandon=*/true).IgnoreError();  // the job fails with the first error
      return s;
    }
    last = std::move(next);
  }
  return land(/*abandon=*/false);
}

bool JobRunner::Overlap() const {
  if (options_.frames_tracing != kAutoFramesTracing) return options_.frames_tracing > 1;
  return !registry_.AllOn(machine_);
}

bool FrameTurns::Acquire(bool interactive, const std::function<bool()>& cancelled) {
  absl::MutexLock lock(&mu_);
  if (interactive) ++interactive_waiting_;
  auto mine = [&]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    // With frames overlapping, an interactive frame need not wait for a
    // turn: the workers trace it first (FrameSpec.interactive).
    if (interactive) return busy_ < frames_ || (frames_ > 1 && busy_ <= frames_);
    return busy_ < frames_ && interactive_waiting_ == 0;
  };
  // Woken by Release; the timeout only looks at `cancelled` now and then.
  while (!mine() && !cancelled()) {
    mu_.AwaitWithTimeout(absl::Condition(&mine), absl::Milliseconds(50));
  }
  if (interactive) --interactive_waiting_;
  if (!mine()) return false;
  ++busy_;
  return true;
}

void FrameTurns::Release() {
  absl::MutexLock lock(&mu_);
  --busy_;
}

int JobRunner::RingsFor(FrameTask& task, const std::vector<std::shared_ptr<WorkerEntry>>& workers) {
  const int setting = task.rings < 0 ? options_.rings : task.rings;
  if (setting != kAutoRings) return setting;
  std::string members;
  for (const auto& w : workers) absl::StrAppend(&members, w->id, ",");
  FrameTask::Chosen fallback;
  FrameTask::Chosen& chosen = task.chosen ? *task.chosen : fallback;
  if (chosen.members == members) return chosen.rings;
  const LoadedDataset& data = *task.data;
  const FrameCosts costs = CostsFor(task);
  std::vector<WorkerSite> sites;
  for (const auto& w : workers) {
    sites.push_back({w->address, w->machine, w->threads, w->cpus, w->machine_cpus,
                     w->memory_bytes, w->memory_shared});
  }
  const Sites where = SitesOf(sites);
  ClusterShape shape = where.shape;
  shape.network = options_.network;
  // What the workers will hold for the whole volume, which the root's own
  // scene (built only to cut) does not.
  // Its scalars travel in their coding, not as the floats held.
  const double scalars = double(data.scene.scalars().size());
  const double bytes = double(data.scene.TracingBytes());
  const VolumeSize volume{bytes, data.scene.dims()[1],
                          bytes - scalars * (sizeof(float) - ScalarsCodingBytes(data.coding))};
  // The rings whose slabs of this dataset the workers hold now: keeping
  // them costs no loading.
  int loaded = 0;
  const auto held = registry_.Held();
  for (const auto& w : workers) {
    auto it = held.find(w->id);
    if (it == held.end() || it->second.data_key != data.key || it->second.ring < 0) {
      loaded = 0;
      break;
    }
    loaded = std::max(loaded, it->second.ring + 1);
  }
  const RingChoice choice =
      ChooseRings(costs, volume, shape, task.frames, where.memory_per_worker, loaded);
  spdlog::info("{}: rings auto: {} ({} costs; {})", task.who, choice.why,
               task.data->costs_pixels > 0 ? "measured" : "assumed", where.why);
  chosen = {members, choice.rings};
  return choice.rings;
}

absl::StatusOr<RenderedFrame> JobRunner::Render(FrameTask& task) {
  LoadedDataset& data = *task.data;
  const int planes = data.scene.dims()[1];
  // The workers trace in the volume's frame; the client's view is in world
  // space (ToVolumeFrame). Unchanged for a volume of identity direction.
  const auto& dims = data.scene.dims();
  const auto& spacing = data.scene.spacing();
  auto local_view = ToVolumeFrame(
      *task.view, data.direction,
      Vec3{dims[0] * spacing[0], dims[1] * spacing[1], dims[2] * spacing[2]});
  if (!local_view.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat(task.who, ": ", local_view.status().message()));
  }
  absl::Status status = absl::CancelledError("cancelled");
  for (int attempt = 0; attempt < kAttempts; ++attempt) {
    if (attempt > 0) SleepUnless(kFirstBackoff * (1 << (attempt - 1)), task.cancelled);
    if (task.cancelled()) return absl::CancelledError("cancelled");
    if (!turns_.Acquire(task.interactive, task.cancelled)) return absl::CancelledError("cancelled");
    // The cluster's turn, given up as soon as the frame has traced: its
    // image and the workers' reports then overlap the next frame.
    struct Turn {
      FrameTurns& turns;
      bool held = true;
      void Release() {
        if (held) turns.Release();
        held = false;
      }
      ~Turn() { Release(); }
    } turn{turns_};
    auto workers = registry_.Workers(
        std::chrono::milliseconds(static_cast<int64_t>(options_.worker_wait_s * 1000)),
        task.cancelled);
    if (!workers.ok()) {
      status = workers.status();
      if (status.code() != absl::StatusCode::kUnavailable) return status;
      continue;
    }
    RenderedFrame out;
    out.attempts = attempt + 1;
    Layout& layout = out.layout;
    out.report.job_id = task.who;
    const auto balance_start = Clock::now();
    bool prerendered = false;
    {
      // The layout: a frame still travelling may learn from its result
      // meanwhile, but not while this one plans.
      absl::MutexLock lock(&task.data->mu);
      layout = Slabs::FormRings(*workers, RingsFor(task, *workers), planes);
      // Cuts computed for other ring members mean nothing to these.
      BalanceMemory& memory = task.data->balance;
      if (const std::string members = layout.Members(); members != memory.members) {
        memory = BalanceMemory{};
        memory.members = members;
      }
      status = task.balancer->Plan(
          *local_view, memory, layout,
          [&](const v1::View& test, Layout& probe) -> absl::StatusOr<FrameResult> {
            prerendered = true;
            if (absl::Status s = slabs_.Distribute(data, probe); !s.ok()) return s;
            return driver_.Run(test, data, probe, task.cancelled, nullptr, nullptr, nullptr, false,
                               nullptr, v1::FLOAT32, nullptr, task.interactive);
          },
          &out.report);
      if (status.ok()) status = slabs_.Distribute(data, layout);
    }
    if (!status.ok()) {
      if (status.code() == absl::StatusCode::kUnavailable && !task.cancelled()) continue;
      return status;
    }
    // The prerender and the plane moves it caused.
    if (prerendered) out.report.balance_ms = MsSince(balance_start);
    if (task.on_attempt) task.on_attempt();
    // The balancer learns as soon as the workers report, so that a frame
    // that plans from this one's statistics need not wait for its image.
    bool learned = false;
    auto learn = [&](const FrameResult& result) {
      {
        absl::MutexLock lock(&task.data->mu);
        task.balancer->Learn(*local_view, result, layout, task.data->balance, &out.report);
      }
      learned = true;
      if (task.on_learned) task.on_learned();
    };
    auto result = driver_.Run(
        *local_view, data, layout, task.cancelled, task.on_progress, task.on_chunk,
        [&] {
          turn.Release();
          if (task.on_traced) task.on_traced();
        },
        task.balancer->LearnsFromProfiles(), learn, task.image_encoding, task.on_running,
        task.interactive);
    if (!result.ok()) {
      status = result.status();
      if (status.code() != absl::StatusCode::kUnavailable || task.cancelled()) return status;
      spdlog::warn("{}: frame failed ({}); retrying", task.who, Printable(status.message()));
      metrics_.Add("transtick_root_frame_retries_total", 1);
      continue;
    }
    if (!learned) learn(*result);
    {
      absl::MutexLock lock(&task.data->mu);
      task.data->costs = FrameCostsFrom(result->workers, CostsFor(task));
      task.data->costs_pixels = PixelsOf(task);
    }
    out.result = *std::move(result);
    return out;
  }
  return status;
}

absl::Status JobRunner::RunView(Job& job, LoadedDataset& data, FrameTask::Chosen& chosen,
                                Flight& me, const Flight* before) {
  const int frame = me.frame;
  const int d = job.key(frame).dataset, v = job.key(frame).view;
  // The view goes to the workers as the client wrote it; the root's own
  // checks use the plan made when the job was accepted.
  const v1::View& view = job.spec().datasets(d).views(v);
  const DatasetPlan& plan = job.plan().datasets[d];
  const FrameRequest& request = plan.views[v];
  std::unique_ptr<Balancer> balancer =
      MakeBalancer(plan.balance[v], job.plan().rule, job.spec().balance_grid());
  if (absl::Status s = CheckRenderSettings(
          request.settings, data.scene.mode(), data.scene.dims(), data.scene.spacing(),
          int64_t{request.camera.width} * request.camera.height);
      !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("dataset ", d, " view ", v, ": ", s.message()));
  }
  // The image passes through as the display sends it, chunk by chunk; the
  // last chunk waits for the frame's statistics, which go with it.
  std::optional<v1::JobEvent> held;
  RowsOnce rows_once;  // over the frame's attempts
  const uint64_t pixels = static_cast<uint64_t>(view.width()) * view.height();
  const auto& queue_options = queue_.options();
  FrameTask task;
  task.who = job.id();
  task.view = &view;
  task.request = &request;
  task.balancer = balancer.get();
  task.data = &data;
  task.rings = job.plan().rings.value_or(options_.rings);
  task.frames = job.spec().datasets(d).views_size();
  task.chosen = &chosen;
  task.image_encoding = job.spec().image_encoding() == v1::RGB8 ? v1::RGB8 : v1::FLOAT32;
  task.cancelled = [&] { return job.cancelled() || queue_.stopping() || me.abandon.load(); };
  task.on_attempt = [&] { held.reset(); };
  task.on_running = [&] {
    if (!me.running.HasBeenNotified()) me.running.Notify();
  };
  task.on_traced = [&] {
    if (!me.traced.HasBeenNotified()) me.traced.Notify();
  };
  task.on_learned = [&] {
    if (!me.learned.HasBeenNotified()) me.learned.Notify();
  };
  task.on_chunk = [&](v1::ImageChunk chunk) -> absl::Status {
    // Images go out in frame order: the frame before finishes first.
    if (before) before->published.WaitForNotification();
    if (held) {
      const int sent_end = held->image().row_end();
      absl::Status s = job.PublishImage(*std::move(held), queue_options.max_pending_image_bytes,
                                        queue_options.image_wait);
      held.reset();
      if (!s.ok()) return s;
      rows_once.Sent(sent_end);
    }
    std::optional<v1::ImageChunk> fresh = rows_once.Trim(std::move(chunk));
    if (!fresh) return absl::OkStatus();
    v1::JobEvent e;
    e.set_frame(frame);
    e.set_dataset(d);
    e.set_view(v);
    e.set_pixels_done(pixels);
    e.set_pixels_total(pixels);
    fresh->set_output(view.output());
    *e.mutable_image() = *std::move(fresh);
    held = std::move(e);
    return absl::OkStatus();
  };
  task.on_progress = [&](uint64_t done, uint64_t total) {
    // Progress of a frame whose predecessor is still publishing is left
    // out (the next report comes within 200 ms).
    if (before && !before->published.HasBeenNotified()) return;
    v1::JobEvent e;
    e.set_frame(frame);
    e.set_dataset(d);
    e.set_view(v);
    e.set_pixels_done(done);
    e.set_pixels_total(total);
    job.Publish(std::move(e));
  };
  auto rendered = Render(task);
  if (!rendered.ok()) return rendered.status();
  if (!held) return absl::InternalError("frame ended without its image");
  Describe(job.id(), absl::StrCat(job.id(), " ", d, "/", v), view, data, *rendered,
           job.submitted_unix(), held->mutable_stats());
  held->mutable_stats()->set_dataset(d);
  held->mutable_stats()->set_view(v);
  if (frame == 0) {
    metrics_.Observe("transtick_root_job_start_seconds", held->stats().since_submit_ms() / 1e3);
  }
  absl::Status published = job.PublishImage(*std::move(held), queue_options.max_pending_image_bytes,
                                            queue_options.image_wait);
  me.published.Notify();
  return published;
}

std::optional<v1::ImageChunk> RowsOnce::Trim(v1::ImageChunk chunk) const {
  if (chunk.row_end() <= out_) return std::nullopt;
  if (chunk.row_begin() < out_) {
    const v1::ImageEncoding encoding = chunk.rgb8().empty() ? v1::FLOAT32 : v1::RGB8;
    const size_t row_bytes = static_cast<size_t>(chunk.width()) * PixelBytes(encoding);
    MutableChunkBytes(&chunk, encoding)
        ->erase(0, static_cast<size_t>(out_ - chunk.row_begin()) * row_bytes);
    chunk.set_row_begin(out_);
  }
  return chunk;
}

void JobRunner::Describe(const std::string& who, const std::string& label, const v1::View& view,
                         const LoadedDataset& data,
                         const RenderedFrame& rendered, double submitted_unix,
                         v1::ClusterFrameStats* out) {
  const FrameResult& frame = rendered.result;
  const Layout& layout = rendered.layout;
  const BalanceReport& balance = rendered.report;
  v1::ClusterFrameStats& fs = *out;
  fs.set_job_id(who);
  fs.set_frame_ms(frame.frame_ms);
  fs.set_since_submit_ms((frame.started_unix - submitted_unix) * 1e3);
  fs.set_attempts(rendered.attempts);
  for (const std::string& w : data.warnings) fs.add_warnings(w);
  fs.set_width(view.width());
  fs.set_height(view.height());
  fs.set_rings(static_cast<int>(layout.rings.size()));
  fs.set_load_ms(layout.load_ms);
  fs.set_planes_moved(layout.planes_moved);
  fs.set_balance(balance.mode);
  fs.set_balance_ms(balance.balance_ms);
  for (const auto& ring : balance.cuts_before)
    for (int c : ring) fs.add_cuts_before(c);
  for (const auto& ring : balance.cuts_after)
    for (int c : ring) fs.add_cuts_after(c);
  double active_sum = 0, active_max = 0;
  uint64_t rays = 0;
  for (const v1::WorkerFrameStats& stats : frame.workers) {
    v1::WorkerFrameStats* w = fs.add_workers();
    *w = stats;
    if (auto t = balance.test_ray_ms.find(w->id()); t != balance.test_ray_ms.end()) {
      w->set_test_ray_ms(t->second);
    }
    active_sum += w->active_ms();
    active_max = std::max(active_max, w->active_ms());
    rays += w->rays_traced();
    spdlog::info(
        "frame {} ring {} worker {} slab [{}, {}): elapsed {:.1f} ms, active {:.1f} ms, CPU {:.1f} "
        "ms, traced {} ({} primary, {} shadow), sent L {} R {}, received L {} R {} ({:.2f} MB out, "
        "{:.2f} MB in), buffer max {}",
        frame.frame_id, w->ring(), w->address(), w->slab_size() > 0 ? w->slab(0) : -1,
        w->slab_size() > 1 ? w->slab(1) : -1, w->elapsed_ms(), w->active_ms(), w->cpu_ms(),
        w->rays_traced(), w->primary_traced(), w->shadow_traced(), w->sent_left(), w->sent_right(),
        w->received_left(), w->received_right(), w->bytes_sent() / 1e6, w->bytes_received() / 1e6,
        w->buffer_high_water());
  }
  const double mean_active = frame.workers.empty() ? 0 : active_sum / frame.workers.size();
  fs.set_active_imbalance(mean_active > 0 ? active_max / mean_active : 0.0);
  uint64_t primary = 0, shadow = 0, forwarded = 0, bytes = 0;
  for (const v1::WorkerFrameStats& w : fs.workers()) {
    primary += w.primary_traced();
    shadow += w.shadow_traced();
    forwarded += w.rays_sent();
    bytes += w.bytes_sent();
  }
  metrics_.Add("transtick_root_frames_total", 1);
  metrics_.Observe("transtick_root_frame_seconds", frame.frame_ms / 1e3);
  metrics_.Add("transtick_root_rays_traced_total", primary, {{"kind", "primary"}});
  metrics_.Add("transtick_root_rays_traced_total", shadow, {{"kind", "shadow"}});
  metrics_.Add("transtick_root_rays_forwarded_total", forwarded);
  metrics_.Add("transtick_root_ray_bytes_total", bytes);
  metrics_.Set("transtick_root_frame_imbalance", fs.active_imbalance());
  spdlog::info(
      "frame {} ({}): {}x{} in {:.1f} ms on {} workers in {} ring(s); {} rays traced; "
      "max/mean active {:.2f}; balance {}",
      frame.frame_id, label, view.width(), view.height(), frame.frame_ms, frame.workers.size(),
      layout.rings.size(), rays, fs.active_imbalance(), EnumName(balance.mode));
}

}  // namespace transtick
