#include "client.h"

#include <unistd.h>

#include <bit>
#include <cstdio>
#include <chrono>
#include <filesystem>
#include <map>
#include <set>
#include <thread>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "cluster.grpc.pb.h"
#include "convert.h"
#include "progress.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "rpc_channel.h"
#include "rpc_status.h"
#include "transtick/camera.h"
#include "transtick/image_io.h"
#include "transtick/ray_codec.h"

namespace transtick {
namespace fs = std::filesystem;

namespace {

// Where a frame's image goes: its view's output, or JOB-dD-vV.png; a
// relative path beneath `out_dir`.
fs::path ImagePath(const std::string& output, const std::string& job_id, int dataset, int view,
                   const std::string& out_dir) {
  std::string out = output;
  if (out.empty()) out = absl::StrCat(job_id, "-d", dataset, "-v", view, ".png");
  fs::path path(out);
  if (path.is_relative() && !out_dir.empty()) path = fs::path(out_dir) / path;
  return path;
}

absl::Status CheckDirectory(const fs::path& dir, const std::string& what) {
  if (dir.empty()) return absl::OkStatus();
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    return absl::NotFoundError(absl::StrCat(what, ": directory '", dir.string(),
                                            "' does not exist (transtick creates none)"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status ImageRows::Add(const v1::ImageChunk& c) {
  if (!sized_) {
    if (c.width() <= 0 || c.height() <= 0 || c.width() > CameraSpec::kMaxImageSize ||
        c.height() > CameraSpec::kMaxImageSize) {
      return absl::DataLossError("the root sent an image chunk of an impossible size");
    }
    image_.width = c.width();
    image_.height = c.height();
    image_.rgb.resize(static_cast<size_t>(c.width()) * c.height() * 3);
    have_.assign(c.height(), false);
    sized_ = true;
  }
  // Rows in either encoding (docs/formats.md, "Image chunks"), exactly.
  auto encoding = ChunkEncoding(c);
  if (c.width() != image_.width || c.height() != image_.height || c.row_begin() < 0 ||
      c.row_end() > image_.height || c.row_end() < c.row_begin() || !encoding.ok()) {
    return absl::DataLossError("the root sent a malformed image chunk");
  }
  float* rows = image_.rgb.data() + static_cast<size_t>(c.row_begin()) * image_.width * 3;
  if (*encoding == v1::RGB8) {
    const std::string& bytes = c.rgb8();
    for (size_t i = 0; i < bytes.size(); ++i) rows[i] = FromByte(static_cast<uint8_t>(bytes[i]));
  } else {
    DecodeFloats(c.rgb(), rows);
  }
  for (int y = c.row_begin(); y < c.row_end(); ++y) {
    rows_ += !have_[y];
    have_[y] = true;
  }
  return absl::OkStatus();
}

void ChooseImageEncoding(v1::Job* job) {
  if (job->image_encoding() != v1::IMAGE_ENCODING_DEFAULT) return;
  bool bytes = true;
  for (int d = 0; d < job->datasets_size(); ++d) {
    for (int v = 0; v < job->datasets(d).views_size(); ++v) {
      bytes = bytes && IsByteImagePath(ImagePath(job->datasets(d).views(v).output(), "job", d, v,
                                                 /*out_dir=*/"")
                                           .string());
    }
  }
  job->set_image_encoding(bytes ? v1::RGB8 : v1::FLOAT32);
}

absl::Status CheckOutputDirectories(const v1::Job& job, const std::string& out_dir) {
  if (absl::Status s = CheckDirectory(out_dir, "--out-dir"); !s.ok()) return s;
  for (int d = 0; d < job.datasets_size(); ++d) {
    for (int v = 0; v < job.datasets(d).views_size(); ++v) {
      const fs::path path = ImagePath(job.datasets(d).views(v).output(), "job", d, v, out_dir);
      absl::Status s = CheckDirectory(path.parent_path(),
                                      absl::StrCat("datasets[", d, "].views[", v, "] output '",
                                                   path.string(), "'"));
      if (!s.ok()) return s;
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<v1::SubmitReply> SubmitJob(const std::string& root, const v1::Job& job) {
  auto stub = v1::Root::NewStub(MakeChannel(root, Role::kRoot));
  v1::SubmitReply submitted;
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(30));
  absl::Status s = FromGrpc(stub->Submit(&ctx, job, &submitted));
  if (absl::IsUnavailable(s)) {
    return absl::UnavailableError(
        absl::StrCat("cannot reach the root at ", root, ": ", s.message()));
  }
  if (!s.ok()) return s;
  return submitted;
}

absl::StatusOr<std::vector<v1::ClusterFrameStats>> SubmitAndWatch(const std::string& root,
                                                                  const v1::Job& job,
                                                                  const WatchOptions& options) {
  auto submitted = SubmitJob(root, job);
  if (!submitted.ok()) return submitted.status();
  if (options.progress) {
    options.progress->Say(absl::StrCat(submitted->job_id(), ": ", submitted->frames(),
                                       " frame", submitted->frames() == 1 ? "" : "s", ", ",
                                       submitted->queue_position(), " job",
                                       submitted->queue_position() == 1 ? "" : "s", " ahead"));
  }
  return WatchJob(root, submitted->job_id(), options);
}

absl::StatusOr<std::vector<v1::ClusterFrameStats>> WatchJob(const std::string& root,
                                                            const std::string& job_id,
                                                            const WatchOptions& options) {
  auto stub = v1::Root::NewStub(MakeChannel(root, Role::kRoot));
  Progress* const progress = options.progress;
  // Watches until the job ends. A stream that breaks (the root restarted,
  // the network failed) is watched again with the frames already saved, so
  // the root sends (and if need be renders again) only the others.
  std::vector<v1::ClusterFrameStats> stats;
  std::set<int> have;
  std::set<int> stats_of;  // frames whose statistics are in `stats`
  std::set<std::string> warned;
  v1::JobState state = v1::QUEUED;
  std::string error;
  absl::Status save_error;
  auto last_contact = std::chrono::steady_clock::now();
  auto backoff = std::chrono::milliseconds(250);
  std::vector<float> spare;  // the image buffer of the frame saved last
  while (true) {
    grpc::ClientContext ctx;
    v1::WatchRequest request;
    request.set_job_id(job_id);
    request.set_resume(true);
    for (int f : have) request.add_have_frames(f);
    auto reader = stub->Watch(&ctx, request);
    std::map<int, ImageRows> images;  // frames being received
    v1::JobEvent e;
    while (reader->Read(&e)) {
      last_contact = std::chrono::steady_clock::now();
      backoff = std::chrono::milliseconds(250);
      state = e.state();
      error = e.error();
      for (const std::string& w : e.warnings()) {
        if (warned.insert(w).second && progress) progress->Warn("warning: " + w);
      }
      if (e.has_image()) {
        const v1::ImageChunk& c = e.image();
        const int frame = e.frame();
        // One statistics record per frame: a frame rendered again for a
        // resuming watcher may bring a second.
        if (e.has_stats() && stats_of.insert(frame).second) {
          stats.push_back(e.stats());
          for (const std::string& w : e.stats().warnings()) {
            if (warned.insert(w).second && progress) progress->Warn("warning: " + w);
          }
        }
        // Rows of a frame already saved (a second rendering's) are left.
        if (have.count(frame)) continue;
        auto [at, fresh] = images.try_emplace(frame);
        if (fresh) {
          at->second = ImageRows(std::move(spare));
          spare = {};
        }
        ImageRows& img = at->second;
        if (absl::Status s = img.Add(c); !s.ok()) return s;
        if (img.whole()) {
          const fs::path path = ImagePath(c.output(), job_id, e.dataset(), e.view(), options.out_dir);
          absl::Status s = CheckDirectory(path.parent_path(), absl::StrCat("frame ", frame));
          if (s.ok()) s = WriteImage(path.string(), img.image());
          if (!s.ok() && save_error.ok()) save_error = s;
          have.insert(frame);
          if (progress) {
            progress->Say(absl::StrFormat("%s: frame %d/%d saved to %s (%.1f ms)", job_id,
                                          have.size(), e.frames_total(), path.string(),
                                          e.has_stats() ? e.stats().frame_ms() : 0.0));
          }
          spare = img.TakeBuffer();
          images.erase(frame);
        }
      } else if (progress && e.pixels_total() > 0 && e.frames_total() > 0) {
        const double frame_part = static_cast<double>(e.pixels_done()) / e.pixels_total();
        progress->Update((have.size() + frame_part) / e.frames_total(),
                         absl::StrFormat("%s frame %d/%d", job_id,
                                         std::min<int>(have.size() + 1, e.frames_total()),
                                         e.frames_total()));
      }
    }
    absl::Status s = FromGrpc(reader->Finish());
    const bool ended = state == v1::DONE || state == v1::FAILED || state == v1::CANCELLED;
    if (s.ok() && ended) break;
    if (absl::IsNotFound(s)) {
      return absl::NotFoundError(
          absl::StrCat("the root does not know ", job_id,
                       " (a wrong id, or it restarted without a state directory)"));
    }
    if (!s.ok() && !absl::IsUnavailable(s) && !absl::IsCancelled(s)) return s;
    // The stream broke, or the root stopped before the job ended.
    if (std::chrono::steady_clock::now() - last_contact > options.reconnect) {
      return absl::UnavailableError(absl::StrCat(
          "lost the root at ", root, " while watching ", job_id, " and could not ",
          "reach it again for ", options.reconnect.count(), " s",
          s.ok() ? "" : absl::StrCat(": ", s.message())));
    }
    if (progress) {
      progress->Say(absl::StrCat(job_id, ": lost the root (",
                                 s.ok() ? "it stopped" : std::string(s.message()),
                                 "); watching again"));
    }
    std::this_thread::sleep_for(backoff);
    backoff = std::min(backoff * 2, std::chrono::milliseconds(2000));
    // A fresh channel: over TLS, the channel whose stream broke when the root
    // was killed never connected again (each TCP connect hung until the
    // attempt's deadline, gRPC 1.51), while a new one connects at once.
    stub = v1::Root::NewStub(MakeChannel(root, Role::kRoot));
  }
  if (progress) progress->Finish();
  if (state == v1::FAILED) return absl::AbortedError(absl::StrCat(job_id, " failed: ", error));
  if (state == v1::CANCELLED)
    return absl::CancelledError(absl::StrCat(job_id, " was cancelled"));
  if (!save_error.ok()) return save_error;
  return stats;
}

absl::StatusOr<std::unique_ptr<SessionClient>> SessionClient::Open(const std::string& root,
                                                                   const v1::Dataset& dataset,
                                                                   int preview,
                                                                   const std::string& bearer,
                                                                   v1::ImageEncoding encoding) {
  auto c = std::unique_ptr<SessionClient>(new SessionClient());
  c->stub_ = v1::Root::NewStub(MakeChannel(root, Role::kRoot));
  if (!bearer.empty()) c->ctx_.AddMetadata("authorization", "Bearer " + bearer);
  c->stream_ = c->stub_->Session(&c->ctx_);
  v1::SessionRequest open;
  *open.mutable_open() = dataset;
  open.set_preview(preview);
  open.set_image_encoding(encoding);
  auto seq = c->Send(std::move(open));
  if (!seq.ok()) {
    // The stream broke before the open went out: its status says why.
    auto why = c->Next();
    return why.ok() ? seq.status() : why.status();
  }
  return c;
}

SessionClient::~SessionClient() {
  {
    absl::MutexLock lock(&mu_);
    if (finished_) return;
  }
  ctx_.TryCancel();
  v1::SessionEvent e;
  while (stream_->Read(&e)) {
  }
  (void)stream_->Finish();
}

absl::StatusOr<uint64_t> SessionClient::Send(v1::SessionRequest request) {
  absl::MutexLock lock(&mu_);
  if (closed_ || finished_) return absl::FailedPreconditionError("the session is closed");
  request.set_seq(next_seq_++);
  if (!stream_->Write(request)) {
    return absl::UnavailableError("the session's stream is broken (see Next for why)");
  }
  return request.seq();
}

absl::StatusOr<uint64_t> SessionClient::SetView(const v1::View& view) {
  v1::SessionRequest r;
  *r.mutable_view() = view;
  return Send(std::move(r));
}

absl::StatusOr<uint64_t> SessionClient::SetMaterials(const v1::MaterialSet& materials) {
  v1::SessionRequest r;
  *r.mutable_materials() = materials;
  return Send(std::move(r));
}

absl::StatusOr<uint64_t> SessionClient::SetTransfer(const v1::TransferFunction& transfer) {
  v1::SessionRequest r;
  *r.mutable_transfer() = transfer;
  return Send(std::move(r));
}

absl::StatusOr<SessionClient::Event> SessionClient::Next() {
  {
    absl::MutexLock lock(&mu_);
    if (finished_) return absl::FailedPreconditionError("the session has ended");
  }
  v1::SessionEvent e;
  while (stream_->Read(&e)) {
    Event out;
    out.seq = e.seq();
    if (e.has_ready()) {
      out.ready = e.ready();
      return out;
    }
    if (!e.error().empty()) {
      out.error = e.error();
      return out;
    }
    if (!e.has_image()) continue;
    ImageRows& img = partial_[{e.seq(), e.preview()}];
    if (absl::Status s = img.Add(e.image()); !s.ok()) return s;
    if (!img.whole()) continue;
    out.has_frame = true;
    out.preview = e.preview();
    out.image = std::move(img.image());
    out.stats = e.stats();
    partial_.erase({e.seq(), e.preview()});
    return out;
  }
  absl::Status s;
  {
    // Not while a request is being written (Send holds the lock).
    absl::MutexLock lock(&mu_);
    s = FromGrpc(stream_->Finish());
    finished_ = true;
  }
  return s.ok() ? absl::OutOfRangeError("the session ended") : s;
}

absl::Status SessionClient::Close() {
  {
    absl::MutexLock lock(&mu_);
    if (closed_ || finished_) return absl::OkStatus();
    closed_ = true;
    stream_->WritesDone();
  }
  while (true) {
    auto e = Next();
    if (!e.ok()) return absl::IsOutOfRange(e.status()) ? absl::OkStatus() : e.status();
  }
}

absl::StatusOr<v1::Job> LoadJobFile(const std::string& path) {
  auto text = ReadTextFile(path);
  if (!text.ok()) return text.status();
  v1::Job job;
  if (auto s = ParseJson(*text, path, &job); !s.ok()) return s;
  const fs::path dir = fs::path(path).parent_path();
  for (int d = 0; d < job.datasets_size(); ++d) {
    v1::Dataset* ds = job.mutable_datasets(d);
    auto resolve = [&](const std::string& f) {
      return fs::path(f).is_absolute() ? f : (dir / f).string();
    };
    if (!ds->materials_file().empty()) {
      std::string f = resolve(ds->materials_file());
      auto t = ReadTextFile(f);
      if (!t.ok()) return t.status();
      if (auto s = ParseJson(*t, f, ds->mutable_materials()); !s.ok()) return s;
      ds->clear_materials_file();
    }
    if (!ds->transfer_file().empty()) {
      std::string f = resolve(ds->transfer_file());
      auto t = ReadTextFile(f);
      if (!t.ok()) return t.status();
      if (auto s = ParseJson(*t, f, ds->mutable_transfer()); !s.ok()) return s;
      ds->clear_transfer_file();
    }
  }
  return job;
}

absl::StatusOr<grpc::health::v1::HealthCheckResponse::ServingStatus> CheckHealth(
    const std::string& address, Role role, double timeout_s) {
  auto stub = grpc::health::v1::Health::NewStub(MakeChannel(address, role));
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(timeout_s));
  grpc::health::v1::HealthCheckRequest request;  // service "": the whole server
  grpc::health::v1::HealthCheckResponse response;
  grpc::Status s = stub->Check(&ctx, request, &response);
  if (!s.ok()) return FromGrpc(s);
  return response.status();
}

}  // namespace transtick
