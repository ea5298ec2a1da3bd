#include "root_service.h"

#include <spdlog/spdlog.h>

#include "absl/strings/str_cat.h"
#include "daemon.h"

namespace transtick {
namespace {

JobQueueOptions QueueOptions(const RootOptions& o) {
  JobQueueOptions q;
  q.max_queued = o.max_queued_jobs;
  q.max_jobs_kept = o.max_jobs_kept;
  q.max_pending_image_bytes = o.max_pending_image_bytes;
  return q;
}

}  // namespace

RootService::RootService(const RootOptions& options)
    : options_(options), queue_(QueueOptions(options)), runner_(options, queue_, registry_) {}

RootService::~RootService() { Stop(); }

void RootService::Stop() { runner_.Stop(); }

grpc::Status RootService::Submit(grpc::ServerContext*, const v1::Job* job, v1::SubmitReply* reply) {
  if (auto s = runner_.Validate(*job); !s.ok()) return ToGrpc(s);
  int position = 0;
  auto record = queue_.Submit(*job, &position);
  if (!record.ok()) return ToGrpc(record.status());
  reply->set_job_id((*record)->id());
  reply->set_frames((*record)->frames_total());
  reply->set_queue_position(position);
  spdlog::info("{} queued: '{}', {} frames, {} ahead", (*record)->id(), job->name(),
               (*record)->frames_total(), position);
  return grpc::Status::OK;
}

grpc::Status RootService::Watch(grpc::ServerContext* ctx, const v1::JobRef* req,
                                grpc::ServerWriter<v1::JobEvent>* writer) {
  std::shared_ptr<Job> job = queue_.Find(req->job_id());
  if (!job) return ToGrpc(absl::NotFoundError(absl::StrCat("no job '", req->job_id(), "'")));
  const bool done = job->Stream([&](const v1::JobEvent& e) { return writer->Write(e); },
                                [&] { return ctx->IsCancelled(); });
  return done ? grpc::Status::OK : grpc::Status(grpc::StatusCode::CANCELLED, "watcher left");
}

grpc::Status RootService::Status(grpc::ServerContext*, const v1::StatusRequest*,
                                 v1::StatusReply* reply) {
  for (v1::JobSummary& s : queue_.Summaries()) *reply->add_jobs() = std::move(s);
  registry_.Describe(reply);
  reply->set_rings(options_.rings);
  return grpc::Status::OK;
}

grpc::Status RootService::Cancel(grpc::ServerContext*, const v1::JobRef* req,
                                 v1::CancelReply* reply) {
  std::shared_ptr<Job> job = queue_.Find(req->job_id());
  if (!job) return ToGrpc(absl::NotFoundError(absl::StrCat("no job '", req->job_id(), "'")));
  if (job->finished()) {
    reply->set_cancelled(false);
    return grpc::Status::OK;
  }
  job->RequestCancel();
  reply->set_cancelled(true);
  spdlog::info("{}: cancel requested", job->id());
  return grpc::Status::OK;
}

grpc::Status RootService::Register(grpc::ServerContext*, const v1::RegisterRequest* req,
                                   v1::RegisterReply*) {
  return ToGrpc(registry_.Register(*req));
}

grpc::Status RootService::Unregister(grpc::ServerContext*, const v1::RegisterRequest* req,
                                     v1::RegisterReply*) {
  return ToGrpc(registry_.Unregister(req->id()));
}

}  // namespace transtick
