#include "root_service.h"

#include <spdlog/spdlog.h>

#include "absl/strings/escaping.h"
#include "absl/strings/str_cat.h"
#include "confined_dir.h"
#include "daemon.h"
#include "volumes.h"

namespace transtick {
namespace {


// Who submitted a job when clients are not authenticated: the host part of
// the peer's address ("ipv4:127.0.0.1:5123" -> "ipv4:127.0.0.1").
std::string PeerHost(const std::string& peer) {
  const size_t colon = peer.rfind(':');
  return colon == std::string::npos || colon < peer.find(':') + 1 ? peer : peer.substr(0, colon);
}

absl::StatusOr<Client> Caller(const grpc::ServerContext& ctx) {
  return CallingClient(ctx, PeerHost(ctx.peer()));
}

// The job `id` when `client` may see it: its owner's, or any for an admin.
// Another client's job is refused as if it did not exist, so that job ids
// say nothing about other clients' work.
absl::StatusOr<std::shared_ptr<Job>> JobFor(const JobQueue& queue, const std::string& id,
                                            const Client& client) {
  std::shared_ptr<Job> job = queue.Find(id);
  if (!job || (!client.admin && job->owner() != client.name)) {
    return absl::NotFoundError(absl::StrCat("no job '", Printable(id), "' of client '",
                                            client.name, "'"));
  }
  return job;
}

}  // namespace

absl::StatusOr<std::unique_ptr<RootService>> RootService::Create(const RootOptions& options) {
  auto store = JobStore::Open(options.state_dir);
  if (!store.ok()) return store.status();
  auto service = std::unique_ptr<RootService>(new RootService(options, *std::move(store)));
  RootService& r = *service;
  if (absl::Status s = r.queue_.Recover([&r](const v1::Job& job) { return r.runner_.Plan(job); });
      !s.ok()) {
    return s;
  }
  service->runner_.Start();
  return service;
}

RootService::RootService(const RootOptions& options, std::unique_ptr<JobStore> store)
    : options_(options),
      metrics_(std::make_shared<Metrics>()),
      store_(std::move(store)),
      queue_(options, *store_),
      runner_(options, queue_, registry_, *metrics_),
      sessions_(runner_, *metrics_) {
  Metrics& m = *metrics_;
  m.Declare("transtick_root_jobs", Metrics::Type::kGauge, "Jobs the root holds, by state.");
  m.Declare("transtick_root_jobs_submitted_total", Metrics::Type::kCounter,
            "Jobs accepted by Submit.");
  m.Declare("transtick_root_jobs_refused_total", Metrics::Type::kCounter,
            "Jobs Submit refused (invalid, over a limit, unauthenticated).");
  m.Declare("transtick_root_workers", Metrics::Type::kGauge, "Workers registered now.");
  m.Declare("transtick_root_rings", Metrics::Type::kGauge, "Rings the root forms (--rings).");
  m.OnScrape([this](Metrics& g) {
    std::map<std::string, int> by_state;
    for (const char* s : {"QUEUED", "RUNNING", "DONE", "FAILED", "CANCELLED"}) by_state[s] = 0;
    for (const v1::JobSummary& j : queue_.Summaries()) ++by_state[v1::JobState_Name(j.state())];
    for (const auto& [state, n] : by_state) g.Set("transtick_root_jobs", n, {{"state", state}});
    g.Set("transtick_root_workers", registry_.size());
    g.Set("transtick_root_rings", options_.rings);
  });
}

RootService::~RootService() { Stop(); }

void RootService::Stop() { runner_.Stop(); }

grpc::Status RootService::Submit(grpc::ServerContext* ctx, const v1::Job* job,
                                 v1::SubmitReply* reply) {
  auto refused = [this](const absl::Status& s) {
    metrics_->Add("transtick_root_jobs_refused_total", 1);
    return ToGrpc(s);
  };
  auto client = Caller(*ctx);
  if (!client.ok()) return refused(client.status());
  auto plan = runner_.Plan(*job);
  if (!plan.ok()) return refused(plan.status());
  int position = 0;
  auto record = queue_.Submit(*job, *std::move(plan), client->name, &position);
  if (!record.ok()) return refused(record.status());
  metrics_->Add("transtick_root_jobs_submitted_total", 1);
  reply->set_job_id((*record)->id());
  reply->set_frames((*record)->frames_total());
  reply->set_queue_position(position);
  // The name is the client's: escaped, it cannot forge a line of the log.
  spdlog::info("{} queued: '{}', {} frames, {} ahead, from {}", (*record)->id(),
               Printable(job->name()), (*record)->frames_total(), position, client->name);
  return grpc::Status::OK;
}

grpc::Status RootService::Volumes(grpc::ServerContext* ctx, const v1::VolumesRequest*,
                                  v1::VolumesReply* reply) {
  auto client = Caller(*ctx);
  if (!client.ok()) return ToGrpc(client.status());
  auto dir = ConfinedDir::Open(options_.data_dir);
  if (!dir.ok()) return ToGrpc(absl::UnavailableError("the root's data directory cannot be opened"));
  auto listed = ListVolumes(**dir, {}, &series_cache_);
  if (!listed.ok()) return ToGrpc(listed.status());
  *reply = *std::move(listed);
  return grpc::Status::OK;
}

grpc::Status RootService::Session(
    grpc::ServerContext* ctx,
    grpc::ServerReaderWriter<v1::SessionEvent, v1::SessionRequest>* stream) {
  auto client = Caller(*ctx);
  if (!client.ok()) return ToGrpc(client.status());
  return sessions_.Serve(ctx, stream, *client);
}

grpc::Status RootService::Watch(grpc::ServerContext* ctx, const v1::WatchRequest* req,
                                grpc::ServerWriter<v1::JobEvent>* writer) {
  auto client = Caller(*ctx);
  if (!client.ok()) return ToGrpc(client.status());
  auto found = JobFor(queue_, req->job_id(), *client);
  if (!found.ok()) return ToGrpc(found.status());
  std::shared_ptr<Job> job = *std::move(found);
  const std::set<int> have(req->have_frames().begin(), req->have_frames().end());
  if (req->resume() && job->Resume(have)) queue_.Requeue(job);
  const bool done = job->Stream([&](const v1::JobEvent& e) { return writer->Write(e); },
                                [&] { return ctx->IsCancelled(); }, have);
  return done ? grpc::Status::OK : grpc::Status(grpc::StatusCode::CANCELLED, "watcher left");
}

grpc::Status RootService::Status(grpc::ServerContext* ctx, const v1::StatusRequest*,
                                 v1::StatusReply* reply) {
  auto client = Caller(*ctx);
  if (!client.ok()) return ToGrpc(client.status());
  // A client sees its own jobs; an admin sees every job.
  for (v1::JobSummary& s : queue_.Summaries()) {
    if (client->admin || s.owner() == client->name) *reply->add_jobs() = std::move(s);
  }
  registry_.Describe(reply);
  reply->set_rings(options_.rings);
  return grpc::Status::OK;
}

grpc::Status RootService::Cancel(grpc::ServerContext* ctx, const v1::JobRef* req,
                                 v1::CancelReply* reply) {
  auto client = Caller(*ctx);
  if (!client.ok()) return ToGrpc(client.status());
  auto found = JobFor(queue_, req->job_id(), *client);
  if (!found.ok()) return ToGrpc(found.status());
  std::shared_ptr<Job> job = *std::move(found);
  if (job->finished()) {
    reply->set_cancelled(false);
    return grpc::Status::OK;
  }
  job->RequestCancel();
  reply->set_cancelled(true);
  spdlog::info("{}: cancel requested by {}", job->id(), client->name);
  return grpc::Status::OK;
}

grpc::Status RootService::Register(grpc::ServerContext* ctx, const v1::RegisterRequest* req,
                                   v1::RegisterReply*) {
  if (grpc::Status s = RequireRole(*ctx, "Register", {Role::kWorker}); !s.ok()) return s;
  return ToGrpc(registry_.Register(*req));
}

grpc::Status RootService::Unregister(grpc::ServerContext* ctx, const v1::RegisterRequest* req,
                                     v1::RegisterReply*) {
  if (grpc::Status s = RequireRole(*ctx, "Unregister", {Role::kWorker}); !s.ok()) return s;
  return ToGrpc(registry_.Unregister(req->id()));
}

}  // namespace transtick
