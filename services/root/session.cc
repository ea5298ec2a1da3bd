#include "session.h"

#include <spdlog/spdlog.h>

#include <deque>
#include <optional>
#include <thread>

#include "absl/strings/str_cat.h"
#include "clock.h"
#include "convert.h"
#include "rpc_status.h"
#include "transtick/tracer.h"

namespace transtick {
namespace {

// What the client sent and the render loop has not taken yet.
struct Inbox {
  absl::Mutex mu;
  std::optional<v1::SessionRequest> view ABSL_GUARDED_BY(mu);            // the newest camera
  double view_arrived ABSL_GUARDED_BY(mu) = 0;                            // when (Unix seconds)
  std::optional<v1::SessionRequest> classification ABSL_GUARDED_BY(mu);  // the newest one
  std::deque<v1::SessionEvent> notices ABSL_GUARDED_BY(mu);              // errors to send
  bool closed ABSL_GUARDED_BY(mu) = false;
  uint64_t superseded ABSL_GUARDED_BY(mu) = 0;
};

v1::SessionEvent ErrorEvent(uint64_t seq, const std::string& error) {
  v1::SessionEvent e;
  e.set_seq(seq);
  e.set_error(error);
  return e;
}

}  // namespace

Sessions::Sessions(JobRunner& runner, Metrics& metrics, SessionLimits limits)
    : runner_(runner), metrics_(metrics), limits_(limits) {
  using T = Metrics::Type;
  metrics_.Declare("transtick_root_sessions", T::kGauge, "Interactive sessions open now.");
  metrics_.Declare("transtick_root_session_frames_total", T::kCounter,
                   "Frames rendered for sessions, by kind (preview, full).");
  metrics_.Declare("transtick_root_session_superseded_total", T::kCounter,
                   "Session cameras never rendered: a newer one came before their turn.");
  metrics_.Declare("transtick_root_session_latency_seconds", T::kHistogram,
                   "From a session camera's arrival to its full frame sent.",
                   {0.01, 0.02, 0.033, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.5, 1, 2, 5, 10});
  metrics_.OnScrape([this](Metrics& g) { g.Set("transtick_root_sessions", open()); });
}

int Sessions::open() const {
  absl::MutexLock lock(&mu_);
  return open_;
}

grpc::Status Sessions::Serve(grpc::ServerContext* ctx,
                             grpc::ServerReaderWriter<v1::SessionEvent, v1::SessionRequest>* stream,
                             const Client& client) {
  std::string id;
  {
    absl::MutexLock lock(&mu_);
    if (open_ >= limits_.max_sessions) {
      return grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                          absl::StrCat("the root has ", open_, " sessions open, its limit"));
    }
    if (per_client_[client.name] >= limits_.max_per_client) {
      return grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                          absl::StrCat("client '", client.name, "' has ",
                                       per_client_[client.name], " sessions open, its limit"));
    }
    ++open_;
    ++per_client_[client.name];
    id = absl::StrCat("session-", next_id_++);
  }
  struct Leave {
    Sessions& s;
    const std::string& name;
    ~Leave() {
      absl::MutexLock lock(&s.mu_);
      --s.open_;
      if (--s.per_client_[name] == 0) s.per_client_.erase(name);
    }
  } leave{*this, client.name};

  v1::SessionRequest first;
  if (!stream->Read(&first)) return grpc::Status(grpc::StatusCode::CANCELLED, "no request");
  if (!first.has_open() || first.open().views_size() != 1) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        "a session's first request opens it: a dataset with exactly one view "
                        "(the first camera) in views");
  }
  if (first.preview() < 0 || first.preview() > 16) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        absl::StrCat("preview ", first.preview(), " is not in [0, 16]"));
  }
  const int preview = first.preview() > 1 ? first.preview() : 0;
  auto encoding = ToImageEncoding(first.image_encoding(), "image_encoding");
  if (!encoding.ok()) return ToGrpc(encoding.status());
  v1::Dataset spec = first.open();
  spec.clear_views();

  // A one-view job of the session's dataset: the job's checks, and the
  // dataset plan, for every camera and classification.
  auto plan_view = [&](const v1::Dataset& dataset,
                       const v1::View& view) -> absl::StatusOr<std::pair<v1::Job, JobPlan>> {
    v1::Job job;
    *job.add_datasets() = dataset;
    *job.mutable_datasets(0)->add_views() = view;
    auto plan = runner_.Plan(job);
    if (!plan.ok()) {
      // The job's paths mean nothing to a session: its dataset and camera.
      std::string message(plan.status().message());
      for (const auto& [from, to] : {std::pair<std::string, std::string>{"datasets[0].views[0]", "the camera"},
                                     {"datasets[0]", "the dataset"}}) {
        if (message.rfind(from, 0) == 0) {
          message = to + message.substr(from.size());
          break;
        }
      }
      return absl::Status(plan.status().code(), message);
    }
    return std::make_pair(std::move(job), *std::move(plan));
  };
  auto load = [&](const v1::Dataset& dataset, const v1::View& view, uint64_t seq)
      -> absl::StatusOr<std::shared_ptr<LoadedDataset>> {
    auto planned = plan_view(dataset, view);
    if (!planned.ok()) return planned.status();
    auto data = runner_.Load(planned->first.datasets(0), planned->second.datasets[0]);
    if (!data.ok()) return data.status();
    v1::SessionEvent e;
    e.set_seq(seq);
    v1::SessionReady* ready = e.mutable_ready();
    ready->set_session_id(id);
    const Scene& scene = (*data)->scene;
    for (int a = 0; a < 3; ++a) {
      ready->add_dims(scene.dims()[a]);
      ready->add_spacing(scene.spacing()[a]);
    }
    ready->set_mode((*data)->mode == RenderMode::kDvr ? v1::DVR : v1::SURFACES);
    for (const std::string& w : (*data)->warnings) ready->add_warnings(w);
    for (float r : (*data)->range) ready->add_range(r);
    for (uint64_t n : (*data)->histogram) ready->add_histogram(n);
    if ((*data)->spec.has_materials()) *ready->mutable_materials() = (*data)->spec.materials();
    if ((*data)->spec.has_transfer()) *ready->mutable_transfer() = (*data)->spec.transfer();
    stream->Write(e);
    return data;
  };
  auto data = load(spec, first.open().views(0), first.seq());
  if (!data.ok()) return ToGrpc(data.status());
  spdlog::info("{} opened by {} on {}", id, client.name, Printable(spec.volume()));

  Inbox inbox;
  {
    absl::MutexLock lock(&inbox.mu);
    v1::SessionRequest r;
    r.set_seq(first.seq());
    *r.mutable_view() = first.open().views(0);
    inbox.view = std::move(r);
    inbox.view_arrived = UnixNow();
  }
  // Requests arrive on their own thread, so that a newer camera replaces
  // an older one while a frame renders.
  std::thread reader([&] {
    v1::SessionRequest r;
    // Errors wait for the render loop; a client that floods bad requests
    // while a frame renders gets the first few back, not unbounded memory.
    constexpr size_t kMaxNotices = 64;
    while (stream->Read(&r)) {
      absl::MutexLock lock(&inbox.mu);
      if (inbox.notices.size() >= kMaxNotices) inbox.notices.pop_front();
      if (r.has_open() || r.preview() != 0 || r.image_encoding() != v1::IMAGE_ENCODING_DEFAULT) {
        inbox.notices.push_back(ErrorEvent(
            r.seq(), "open, preview and image_encoding belong to the session's first request"));
        continue;
      }
      if (r.has_materials() || r.has_transfer()) inbox.classification = r;
      if (r.has_view()) {
        if (inbox.view) ++inbox.superseded;
        inbox.view = r;
        inbox.view_arrived = UnixNow();
      }
      if (!r.has_view() && !r.has_materials() && !r.has_transfer()) {
        inbox.notices.push_back(ErrorEvent(r.seq(), "the request holds no camera or classification"));
      }
    }
    absl::MutexLock lock(&inbox.mu);
    inbox.closed = true;
  });
  auto stopped = [&] { return ctx->IsCancelled() || runner_.stopping(); };
  // Whether a newer camera came while the last one rendered.
  auto newer_view = [&] {
    absl::MutexLock lock(&inbox.mu);
    return inbox.view.has_value();
  };
  grpc::Status status = grpc::Status::OK;
  bool write_failed = false;
  // The root's rings; chosen once for the session's workers when automatic,
  // as for a long job: a session renders frame after frame.
  FrameTask::Chosen chosen;
  // Renders `view` and sends its chunks; the last chunk with the stats.
  // What a camera must pass to render: the job's checks, and its render
  // settings against the scene.
  auto check = [&](const v1::View& view) -> absl::StatusOr<std::pair<v1::Job, JobPlan>> {
    auto planned = plan_view(spec, view);
    if (!planned.ok()) return planned.status();
    const FrameRequest& request = planned->second.datasets[0].views[0];
    if (absl::Status s = CheckRenderSettings(request.settings, (*data)->scene.mode(),
                                             (*data)->scene.dims(), (*data)->scene.spacing(),
                                             int64_t{request.camera.width} * request.camera.height);
        !s.ok()) {
      return s;
    }
    return planned;
  };
  auto render = [&](const v1::View& view, uint64_t seq, bool is_preview,
                    double arrived) -> absl::Status {
    auto planned = check(view);
    if (!planned.ok()) return planned.status();
    const DatasetPlan& plan = planned->second.datasets[0];
    const FrameRequest& request = plan.views[0];
    std::unique_ptr<Balancer> balancer = MakeBalancer(plan.balance[0], planned->second.rule, 32);
    std::optional<v1::SessionEvent> held;
    RowsOnce rows_once;  // over the frame's attempts
    FrameTask task;
    task.who = id;
    task.view = &planned->first.datasets(0).views(0);
    task.request = &request;
    task.balancer = balancer.get();
    task.data = data->get();
    task.interactive = true;
    task.frames = 1000;
    task.chosen = &chosen;
    task.image_encoding = *encoding;
    task.cancelled = stopped;
    task.on_attempt = [&] { held.reset(); };
    task.on_chunk = [&](v1::ImageChunk chunk) -> absl::Status {
      if (held) {
        if (!stream->Write(*held)) {
          write_failed = true;
          return absl::CancelledError("the client left");
        }
        rows_once.Sent(held->image().row_end());
        held.reset();
      }
      std::optional<v1::ImageChunk> fresh = rows_once.Trim(std::move(chunk));
      if (!fresh) return absl::OkStatus();
      held.emplace();
      held->set_seq(seq);
      held->set_preview(is_preview);
      *held->mutable_image() = *std::move(fresh);
      return absl::OkStatus();
    };
    auto rendered = runner_.Render(task);
    if (!rendered.ok()) return rendered.status();
    if (!held) return absl::InternalError("frame ended without its image");
    runner_.Describe(id, absl::StrCat(id, is_preview ? " preview " : " ", seq), *task.view,
                     **data, *rendered, arrived, held->mutable_stats());
    if (!stream->Write(*held)) {
      write_failed = true;
      return absl::CancelledError("the client left");
    }
    metrics_.Add("transtick_root_session_frames_total", 1,
                 {{"kind", is_preview ? "preview" : "full"}});
    if (!is_preview) metrics_.Observe("transtick_root_session_latency_seconds", UnixNow() - arrived);
    return absl::OkStatus();
  };

  while (!stopped() && !write_failed) {
    std::optional<v1::SessionRequest> view, classification;
    double arrived = 0;
    std::deque<v1::SessionEvent> notices;
    bool closed = false;
    {
      absl::MutexLock lock(&inbox.mu);
      auto ready = [&]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(inbox.mu) {
        return inbox.view || inbox.classification || !inbox.notices.empty() || inbox.closed;
      };
      inbox.mu.AwaitWithTimeout(absl::Condition(&ready), absl::Milliseconds(100));
      view.swap(inbox.view);
      arrived = inbox.view_arrived;
      classification.swap(inbox.classification);
      notices.swap(inbox.notices);
      closed = inbox.closed;
      metrics_.Add("transtick_root_session_superseded_total", static_cast<double>(inbox.superseded));
      inbox.superseded = 0;
    }
    for (const v1::SessionEvent& n : notices) stream->Write(n);
    if (classification) {
      v1::Dataset next = spec;
      // The session's mode is its dataset's (a preset's too).
      const bool surfaces = (*data)->mode == RenderMode::kSurfaces;
      if (classification->has_materials() != surfaces) {
        stream->Write(ErrorEvent(classification->seq(),
                                 surfaces ? "a surfaces session takes materials"
                                          : "a dvr session takes a transfer function"));
      } else {
        if (classification->has_materials()) *next.mutable_materials() = classification->materials();
        if (classification->has_transfer()) *next.mutable_transfer() = classification->transfer();
        v1::View camera = view ? view->view() : first.open().views(0);
        auto loaded = load(next, camera, classification->seq());
        if (loaded.ok()) {
          spec = std::move(next);
          data = *std::move(loaded);
          // The image changes with the classification: the camera renders again.
          if (!view) {
            view.emplace();
            arrived = UnixNow();
            view->set_seq(classification->seq());
            *view->mutable_view() = camera;
          }
        } else {
          stream->Write(ErrorEvent(classification->seq(), std::string(loaded.status().message())));
        }
      }
    }
    if (view) {
      first.mutable_open()->mutable_views(0)->CopyFrom(view->view());  // the camera now
      // The camera itself is checked first: an error names it, not its preview.
      absl::Status s = check(view->view()).status();
      if (s.ok() && preview) {
        v1::View small = view->view();
        small.set_width(std::max(1, small.width() / preview));
        small.set_height(std::max(1, small.height() / preview));
        small.clear_samples();
        small.set_balance(v1::OFF);
        s = render(small, view->seq(), /*is_preview=*/true, arrived);
      }
      // A camera that came during the preview supersedes this one's frame.
      if (s.ok() && !(preview && newer_view())) {
        s = render(view->view(), view->seq(), /*is_preview=*/false, arrived);
      }
      if (!s.ok() && !write_failed && !stopped()) {
        stream->Write(ErrorEvent(view->seq(), std::string(s.message())));
      }
      continue;
    }
    if (closed) break;
  }
  if (stopped() && !ctx->IsCancelled()) {
    status = grpc::Status(grpc::StatusCode::UNAVAILABLE, "the root is stopping");
  }
  {
    // Ends the reader's Read if the client has not closed its side (the
    // status of the call is then CANCELLED, which a client that left expects).
    absl::MutexLock lock(&inbox.mu);
    if (!inbox.closed) ctx->TryCancel();
  }
  reader.join();
  spdlog::info("{} closed", id);
  return status;
}

}  // namespace transtick
