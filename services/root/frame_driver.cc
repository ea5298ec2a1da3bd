#include "frame_driver.h"

#include <spdlog/spdlog.h>

#include <atomic>
#include <chrono>
#include <thread>

#include "absl/strings/str_cat.h"
#include "absl/synchronization/notification.h"
#include "clock.h"
#include "convert.h"
#include "daemon.h"
#include "fanout.h"

namespace transtick {
namespace {

// Deadlines of the frame's unary calls, in seconds.
constexpr double kCallDeadline = 30;
// PrepareFrame and RunFrame answer in milliseconds; a member that does not
// answer within this (a paused worker) fails the frame, which is retried
// once its registration has expired. 30 s here made a pause at that moment
// cost 30 s instead of at most 10.
constexpr double kStartDeadline = 10;
constexpr double kAbortDeadline = 10;
// How much of a frame's image the display may send before the frame is
// complete (rows already complete): the transfer overlaps the tracing, and
// the root holds at most this much of a frame not yet complete.
constexpr uint64_t kEarlyImageBytes = 32 << 20;

}  // namespace

FrameDriver::FrameDriver(Registry& registry, std::string display, double frame_timeout_s,
                         std::chrono::milliseconds stall_timeout)
    : registry_(registry),
      display_(std::move(display)),
      frame_timeout_s_(frame_timeout_s),
      stall_timeout_(stall_timeout) {
  // Frame ids unique across root restarts, so a worker never mistakes a
  // stale frame for a new one.
  next_frame_id_ =
      static_cast<uint64_t>(std::chrono::system_clock::now().time_since_epoch().count() / 1000)
      << 8;
}

absl::StatusOr<FrameResult> FrameDriver::Run(
    const v1::View& view, const LoadedDataset& data, const Layout& layout,
    const std::function<bool()>& cancelled, const ProgressFn& on_progress, const ChunkFn& on_chunk,
    const std::function<void()>& on_traced, bool work_profile,
    const std::function<void(const FrameResult&)>& on_reported, v1::ImageEncoding image_encoding,
    const std::function<void()>& on_running, bool interactive) {
  const uint64_t frame_id = next_frame_id_++;
  const auto t0 = Clock::now();
  const double started_unix =
      std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  auto display = v1::Display::NewStub(SharedChannel(display_, Role::kDisplay, "control"));
  struct Member {
    std::shared_ptr<WorkerEntry> worker;
    v1::FrameSpec spec;
    int ring;
  };
  std::vector<Member> members;
  const int rings = static_cast<int>(layout.rings.size());
  for (int r = 0; r < rings; ++r) {
    const auto& ring = layout.rings[r];
    for (size_t i = 0; i < ring.workers.size(); ++i) {
      v1::FrameSpec spec;
      spec.set_frame_id(frame_id);
      spec.set_dataset_key(layout.SlabKey(data.key, ring, i));
      *spec.mutable_view() = view;
      for (int c : ring.cuts) spec.add_cuts(c);
      spec.set_index(static_cast<int>(i));
      if (i > 0) spec.set_left(ring.workers[i - 1]->address);
      if (i + 1 < ring.workers.size()) spec.set_right(ring.workers[i + 1]->address);
      spec.set_display(display_);
      // Rows are interleaved across rings so each ring gets an even share of
      // every part of the image.
      spec.set_row_begin(std::min(r, view.height()));
      spec.set_row_end(view.height());
      spec.set_row_step(rings);
      spec.set_work_profile(work_profile || !on_chunk);
      spec.set_interactive(interactive);
      // Prepared and started in one round (FrameSpec.run): a neighbour's
      // rays or a worker's deposits that come before a node knows the frame
      // wait there for it.
      spec.set_run(true);
      members.push_back({ring.workers[i], std::move(spec), r});
    }
  }
  // The first failure among the members' replies, naming the worker; a
  // worker that cannot be reached is dropped.
  auto check = [&](const char* what, const std::vector<grpc::Status>& results) {
    absl::Status first;
    for (size_t i = 0; i < results.size(); ++i) {
      const grpc::Status& s = results[i];
      if (s.ok()) continue;
      absl::Status why(FromGrpc(s).code(), absl::StrCat(what, " on ", members[i].worker->address,
                                                        ": ", s.error_message()));
      if (IsWorkerFailure(s)) {
        registry_.Drop(members[i].worker->id, s.error_message());
        why = absl::UnavailableError(why.message());
      } else if (s.error_code() == grpc::StatusCode::FAILED_PRECONDITION) {
        // The worker lacks the slab the registry says it holds (evicted,
        // or lost): the belief goes, and the retry sends the slab again.
        spdlog::warn("{} on {}: {}; the root believed it held that slab and sends it again", what,
                     members[i].worker->address, s.error_message());
        registry_.ClearHeld(members[i].worker->id);
        why = absl::UnavailableError(why.message());
      } else if (s.error_code() == grpc::StatusCode::NOT_FOUND) {
        // The worker dropped the frame (its frame table evicted or expired
        // it): the frame runs again.
        why = absl::UnavailableError(why.message());
      }
      if (first.ok()) first = why;
    }
    return first;
  };
  v1::FrameRef ref;
  ref.set_frame_id(frame_id);
  std::vector<v1::FrameAck> acks(members.size() + 1);
  std::vector<v1::WorkerFrameStats> stats(members.size());
  auto end_all = [&](bool cancel) {
    // Statistics of workers that fail to end are simply missing.
    // No frame waits on a member that stopped answering (its registration
    // expired): it would hold the retry, or the image, for the deadline.
    v1::FrameRef end = ref;
    end.set_cancel(cancel);
    CallAll(members.size(), cancel ? kAbortDeadline : kCallDeadline,
            [&](size_t i, grpc::ClientContext* ctx, auto done) {
              if (!registry_.Alive(members[i].worker->id)) {
                done(grpc::Status(grpc::StatusCode::UNAVAILABLE, "not answering"));
                return;
              }
              members[i].worker->stub->async()->EndFrame(ctx, &end, &stats[i], std::move(done));
            });
    for (size_t i = 0; i < members.size(); ++i) stats[i].set_ring(members[i].ring);
  };
  // The frame's result as it stands: its time so far and the reports.
  auto result_now = [&] {
    FrameResult result;
    result.frame_ms = MsSince(t0);
    result.started_unix = started_unix;
    result.frame_id = frame_id;
    result.workers = stats;
    for (size_t i = 0; i < result.workers.size(); ++i) {
      v1::WorkerFrameStats& w = result.workers[i];
      if (w.id().empty()) w.set_id(members[i].worker->id);
      if (w.address().empty()) w.set_address(members[i].worker->address);
    }
    return result;
  };
  auto abort = [&](const absl::Status& why) {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(kAbortDeadline));
    v1::FrameAck ack;
    v1::FrameRef aborted = ref;
    aborted.set_reason(std::string(why.message()));
    display->AbortFrame(&ctx, aborted, &ack);
    end_all(/*cancel=*/true);
    return why;
  };
  // One round: the display begins the frame while the workers prepare and
  // start it (FrameSpec.run). A worker older than `run` only prepares it,
  // and RunFrame then starts it.
  v1::DisplayFrame df;
  df.set_frame_id(frame_id);
  df.set_width(view.width());
  df.set_height(view.height());
  df.set_samples(view.has_samples() ? view.samples() : 1);
  std::vector<grpc::Status> prepared = CallAll(
      members.size() + 1, kStartDeadline, [&](size_t i, grpc::ClientContext* ctx, auto done) {
        if (i == members.size()) {
          display->async()->BeginFrame(ctx, &df, &acks[i], std::move(done));
        } else {
          members[i].worker->stub->async()->PrepareFrame(ctx, &members[i].spec, &acks[i],
                                                         std::move(done));
        }
      });
  const grpc::Status begun = prepared.back();
  prepared.pop_back();
  absl::Status s = check("PrepareFrame", prepared);
  if (!begun.ok()) {
    // A display that is down or not answering may come back: the frame is
    // retried (UNAVAILABLE); a refusal is final.
    const absl::StatusCode code =
        IsWorkerFailure(begun) ? absl::StatusCode::kUnavailable : FromGrpc(begun).code();
    return abort(
        absl::Status(code, absl::StrCat("display ", display_, ": ", begun.error_message())));
  }
  if (!s.ok()) return abort(s);
  s = check(
      "RunFrame",
      CallAll(members.size(), kStartDeadline, [&](size_t i, grpc::ClientContext* ctx, auto done) {
        if (acks[i].running()) {
          done(grpc::Status::OK);
          return;
        }
        members[i].worker->stub->async()->RunFrame(ctx, &ref, &acks[i], std::move(done));
      }));
  if (!s.ok()) return abort(s);
  if (on_running) on_running();

  // Wait for the display, relaying progress and the image's chunks as they
  // come, until the image is through.
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(frame_timeout_s_));
    v1::FrameRef await = ref;
    await.set_no_image(!on_chunk);
    // The image's first rows may come while the frame traces; they wait
    // here until it is complete, for a frame that fails is traced again
    // and its image must reach the job's watchers once.
    if (on_chunk) await.set_early_image_bytes(kEarlyImageBytes);
    await.set_image_encoding(image_encoding);
    std::vector<v1::ImageChunk> early;
    auto reader = display->AwaitFrame(&ctx, await);
    // The watchdog: a member that stops renewing its registration (dead, or
    // paused), or a display that sends nothing (it reports progress every
    // 250 ms), ends the wait within seconds; the frame is then retried on
    // the workers still alive.
    std::atomic<int64_t> last_message{Clock::now().time_since_epoch().count()};
    // It looks every 100 ms and is woken at once when the wait ends, so it
    // adds nothing to a frame's time (it used to sleep its 100 ms out).
    absl::Notification awaited;
    // Every deposit is in once the display says the frame is complete: the
    // image is then the display's alone, so a worker lost (or a machine that
    // stalled past its registration's expiry) costs its statistics, not the
    // frame. The workers end the frame (and report) while its image is
    // resolved and its rows pass through here.
    std::atomic<bool> complete{false};
    std::string stalled;  // written by the watchdog before it cancels
    std::thread watchdog([&] {
      auto last_look = Clock::now();
      while (!awaited.WaitForNotificationWithTimeout(absl::Milliseconds(100))) {
        // A look more than a second after the last means the root did not
        // run meanwhile (paused, or its machine stalled): whatever the
        // display sent then has not been read yet, and is not its silence
        // (the registry forgives the workers' likewise).
        const auto now = Clock::now();
        if (now - last_look > std::chrono::seconds(1)) {
          last_message = now.time_since_epoch().count();
        }
        last_look = now;
        for (const Member& m : members) {
          if (!awaited.HasBeenNotified() && !complete.load() && !registry_.Alive(m.worker->id)) {
            stalled = absl::StrCat("worker ", m.worker->address, " stopped answering");
            ctx.TryCancel();
            return;
          }
        }
        const auto silent = Clock::now() - Clock::time_point(Clock::duration(last_message.load()));
        if (!awaited.HasBeenNotified() && silent > stall_timeout_) {
          stalled = absl::StrCat("the display sent nothing for ",
                                 std::chrono::duration<double>(silent).count(), " s");
          ctx.TryCancel();
          return;
        }
      }
    });
    v1::FrameProgress p;
    int rows = 0;
    auto last_progress = Clock::now() - std::chrono::seconds(1);
    absl::Status relay;
    std::thread ender;
    while (reader->Read(&p)) {
      last_message = Clock::now().time_since_epoch().count();
      if (cancelled()) ctx.TryCancel();
      if (p.complete() && !ender.joinable()) {
        complete = true;
        ender = std::thread([&] {
          end_all(/*cancel=*/false);
          if (on_reported) on_reported(result_now());
        });
        if (on_traced) on_traced();
        for (v1::ImageChunk& c : early) {
          relay = on_chunk(std::move(c));
          if (!relay.ok()) break;
        }
        early.clear();
        if (!relay.ok()) {
          ctx.TryCancel();
          break;
        }
      }
      if (p.has_image()) {
        v1::ImageChunk* c = p.mutable_image();
        if (!on_chunk || c->width() != view.width() || c->row_begin() != rows ||
            c->row_end() > view.height() || c->row_end() <= c->row_begin() ||
            !ChunkBytesFit(*c, image_encoding)) {
          relay = absl::DataLossError(
              absl::StrCat("display: malformed image chunk of frame ", frame_id));
          ctx.TryCancel();
          break;
        }
        rows = c->row_end();
        if (!complete) {
          early.push_back(std::move(*c));
          continue;
        }
        relay = on_chunk(std::move(*c));
        if (!relay.ok()) {
          ctx.TryCancel();
          break;
        }
      } else if (on_progress && Clock::now() - last_progress > std::chrono::milliseconds(200)) {
        last_progress = Clock::now();
        on_progress(p.pixels_done(), p.pixels_total());
      }
    }
    grpc::Status st = reader->Finish();
    awaited.Notify();
    watchdog.join();
    if (ender.joinable()) ender.join();
    if (cancelled()) return abort(absl::CancelledError("cancelled"));
    if (!relay.ok()) return abort(relay);
    if (!stalled.empty()) return abort(absl::UnavailableError(stalled));
    const bool through = complete && (!on_chunk || rows == view.height());
    if (!st.ok() || !through) {
      absl::Status why =
          st.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED
              ? absl::DeadlineExceededError(
                    absl::StrCat("frame not complete within ", frame_timeout_s_, " s"))
              : absl::UnavailableError(absl::StrCat("display: ", st.error_message()));
      return abort(why);
    }
    if (!complete) end_all(/*cancel=*/false);
  }
  return result_now();
}

}  // namespace transtick
