// Frames that a root prepares and never ends, as a crashed or hostile root
// leaves them, on a real worker and a real display over loopback: they are
// dropped after the (here shortened) idle time, their tracer threads stop,
// their memory is returned, and the nodes go on rendering. Past the limits,
// the least recently active frame is evicted, and the display refuses a
// framebuffer that would pass its byte limit.
#include <grpcpp/grpcpp.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <string>
#include <thread>

#include "cluster.grpc.pb.h"
#include "gtest/gtest.h"
#include "nodes_fixture.h"
#include "transtick/framebuffer.h"
#include "transtick/ray_codec.h"

namespace transtick {
namespace {

using std::chrono::milliseconds;
using Clock = std::chrono::steady_clock;
using testing::Eventually;

constexpr milliseconds kPreparedIdle(300), kRunningIdle(800), kDisplayIdle(300);

class ExpiryTest : public testing::NodesTest {
 protected:
  WorkerOptions worker_options() const override {
    WorkerOptions o = NodesTest::worker_options();
    o.frames.prepared_idle = kPreparedIdle;
    o.frames.running_idle = kRunningIdle;
    return o;
  }
  DisplayOptions display_options() const override {
    DisplayOptions o;
    o.idle = kDisplayIdle;
    return o;
  }

  // Renders one whole frame as the root does and checks its image arrived.
  void RenderOne(uint64_t id) {
    ASSERT_TRUE(Prepare(id).ok());
    RunToImage(id);
  }
};

TEST_F(ExpiryTest, PreparedFramesNeverRunAreDroppedAndTheNodesGoOn) {
  const auto t0 = Clock::now();
  for (uint64_t id : {1, 2, 3}) ASSERT_TRUE(Prepare(id).ok());
  if (Clock::now() - t0 < kPreparedIdle) {
    EXPECT_EQ(worker_service_->frames_held(), 3u);
    EXPECT_EQ(Frame::alive(), 3);
  }
  const uint64_t framebuffer = Framebuffer::MemoryBytes(kSize, kSize);
  if (Clock::now() - t0 < kDisplayIdle) {
    EXPECT_EQ(display_service_->framebuffer_bytes(), 3 * framebuffer);
  }

  ASSERT_TRUE(Eventually([&] { return worker_service_->frames_held() == 0; }));
  EXPECT_GE(Clock::now() - t0, kPreparedIdle);
  // The frames themselves are gone, not only their table entries.
  EXPECT_TRUE(Eventually([] { return Frame::alive() == 0; })) << Frame::alive();
  ASSERT_TRUE(Eventually([&] { return display_service_->framebuffer_bytes() == 0; }));
  EXPECT_EQ(display_service_->open_frames(), 0u);

  // Late calls about them say what happened.
  grpc::Status s = Run(2);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(s.error_message().find("expired: prepared"), std::string::npos) << s.error_message();
  s = Await(2);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::ABORTED);
  EXPECT_NE(s.error_message().find("expired: no deposit and no call"), std::string::npos)
      << s.error_message();

  RenderOne(4);
  // The finished frame's framebuffer, kept for reuse, goes too when unused.
  EXPECT_TRUE(Eventually([&] { return display_service_->framebuffer_bytes() == 0; }));
}

// Finished frames' framebuffers are kept for the next frames (pipelined
// frames need more than one), at most three, and freed when unused.
TEST_F(ExpiryTest, FinishedFramebuffersAreKeptAtMostThreeUntilIdle) {
  const uint64_t framebuffer = Framebuffer::MemoryBytes(kSize, kSize);
  const auto t0 = Clock::now();
  for (uint64_t id : {41, 42, 43, 44}) ASSERT_TRUE(Begin(id).ok());
  for (uint64_t id : {41, 42, 43, 44}) {
    ASSERT_TRUE(PrepareOnly(Spec(id)).ok());
    RunToImage(id);
  }
  EXPECT_EQ(display_service_->open_frames(), 0u);
  // Unless the spares were idle long enough to go already.
  if (Clock::now() - t0 < kDisplayIdle) {
    EXPECT_EQ(display_service_->framebuffer_bytes(), 3 * framebuffer);
  }
  EXPECT_TRUE(Eventually([&] { return display_service_->framebuffer_bytes() == 0; }));
}

// Run, traced out, and never ended or awaited: the worker stops the frame
// once it has been silent for the running limit; the display drops the
// completed framebuffer nobody came for.
TEST_F(ExpiryTest, RunningFramesThatFallSilentAreDropped) {
  ASSERT_TRUE(Prepare(5).ok());
  const auto run = Clock::now();  // before RunFrame, which marks the frame active
  ASSERT_TRUE(Run(5).ok());
  ASSERT_TRUE(Eventually([&] { return worker_service_->frames_held() == 0; }));
  EXPECT_GE(Clock::now() - run, kRunningIdle);
  EXPECT_TRUE(Eventually([] { return Frame::alive() == 0; })) << Frame::alive();
  EXPECT_TRUE(Eventually([&] { return display_service_->framebuffer_bytes() == 0; }));
  auto stats = End(5);
  EXPECT_EQ(stats.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(stats.status().message().find("expired: running"), std::string::npos) << stats.status();
  RenderOne(6);
}

// A running frame that goes on receiving rays is not idle, however long it
// runs: only silence expires a frame.
TEST_F(ExpiryTest, ARunningFrameThatReceivesRaysIsKept) {
  ASSERT_TRUE(Prepare(7).ok());
  ASSERT_TRUE(Run(7).ok());
  v1::RayBatch batch;
  batch.set_frame_id(7);
  std::string records;
  AppendRay(CentreRay(), &records);
  PackRays(records, batch.mutable_packed());

  // A left neighbour that sends a ray every 100 ms, for 2.5 running limits.
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(30));
  auto stream = worker_stub_->Rays(&ctx);
  const auto t0 = Clock::now();
  while (Clock::now() - t0 < 2.5 * kRunningIdle) {
    ASSERT_TRUE(stream->Write(batch));
    std::this_thread::sleep_for(milliseconds(100));
    ASSERT_EQ(worker_service_->frames_held(), 1u);
  }
  auto stats = End(7, /*cancel=*/true);
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_GE(stats->received_left(), 10u);
  stream->WritesDone();
  stream->Finish();
}

// Stops this process (every thread) for `d`, as a debugger or a stalled
// machine would: a child sends SIGSTOP, then SIGCONT.
void PauseThisProcess(milliseconds d) {
  const pid_t self = getpid();
  const pid_t child = fork();
  if (child == 0) {
    kill(self, SIGSTOP);
    usleep(static_cast<useconds_t>(d.count() * 1000));
    kill(self, SIGCONT);
    _exit(0);
  }
  ASSERT_GT(child, 0);
  waitpid(child, nullptr, 0);  // the child ends after SIGCONT
}

// Time the worker did not run is not a frame's idleness: a paused worker
// keeps the frames it held, and they expire after their own silence.
TEST_F(ExpiryTest, TimeTheWorkerWasPausedIsNotIdleness) {
  ASSERT_TRUE(Prepare(9).ok());
  ASSERT_TRUE(Run(9).ok());
  PauseThisProcess(2 * kRunningIdle + milliseconds(500));
  // The sweeper runs every 200 ms; give it two looks.
  std::this_thread::sleep_for(milliseconds(450));
  EXPECT_EQ(worker_service_->frames_held(), 1u) << "the pause was counted as the frame's silence";
  ASSERT_TRUE(Eventually([&] { return worker_service_->frames_held() == 0; }));
}

// A root that waits for a frame keeps it: its own deadline governs.
TEST_F(ExpiryTest, AFrameARootAwaitsDoesNotExpire) {
  ASSERT_TRUE(Begin(8).ok());
  const auto t0 = Clock::now();
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(3 * kDisplayIdle.count() / 1e3));
  v1::FrameRef ref;
  ref.set_frame_id(8);
  auto reader = display_stub_->AwaitFrame(&ctx, ref);
  v1::FrameProgress p;
  while (reader->Read(&p)) {
  }
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  EXPECT_GE(Clock::now() - t0, 2 * kDisplayIdle);
  // The waiter is gone: now the frame expires.
  ASSERT_TRUE(Eventually([&] { return display_service_->open_frames() == 0; }));
  EXPECT_EQ(display_service_->framebuffer_bytes(), 0u);
}

// Small limits: two frames on the worker and at the display, framebuffers
// of two and a half frames of kSize².
class LimitsTest : public testing::NodesTest {
 protected:
  WorkerOptions worker_options() const override {
    WorkerOptions o = NodesTest::worker_options();
    o.frames.max_frames = 2;
    return o;
  }
  DisplayOptions display_options() const override {
    DisplayOptions o;
    o.max_frames = 2;
    o.max_bytes = Framebuffer::MemoryBytes(kSize, kSize) * 5 / 2;
    return o;
  }
};

TEST_F(LimitsTest, TheLeastRecentlyActiveFrameIsEvicted) {
  for (uint64_t id : {11, 12}) {
    ASSERT_TRUE(Prepare(id).ok());
    std::this_thread::sleep_for(milliseconds(20));
  }
  ASSERT_TRUE(Prepare(13).ok());
  EXPECT_EQ(worker_service_->frames_held(), 2u);
  EXPECT_TRUE(Eventually([] { return Frame::alive() == 2; })) << Frame::alive();
  EXPECT_EQ(display_service_->open_frames(), 2u);

  grpc::Status s = Run(11);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(s.error_message().find("evicted: this worker holds at most 2 frames, frame 13 came"),
            std::string::npos)
      << s.error_message();
  s = Await(11);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::ABORTED);
  EXPECT_NE(s.error_message().find("evicted: the display holds at most 2 frames"),
            std::string::npos)
      << s.error_message();

  // The newest frame renders.
  RunToImage(13);
}

TEST_F(LimitsTest, TheDisplayRefusesAFramebufferPastItsByteLimit) {
  ASSERT_TRUE(Begin(21).ok());
  grpc::Status s = Begin(22, 2 * kSize, kSize);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(s.error_message().find("frame 22 needs 0.1 MB for its 96x48 framebuffer; 1 open "
                                   "frame(s) hold 0.1 MB of the 0.2 MB allowed"),
            std::string::npos)
      << s.error_message();
  EXPECT_EQ(display_service_->open_frames(), 1u);  // refused, nothing evicted
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(5));
  v1::FrameRef ref;
  ref.set_frame_id(21);
  v1::FrameAck ack;
  ASSERT_TRUE(display_stub_->AbortFrame(&ctx, ref, &ack).ok());
  EXPECT_EQ(display_service_->framebuffer_bytes(), 0u);
  // Alone, a frame past the limit is refused too; one within it now fits.
  s = Begin(23, 3 * kSize, kSize);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_NE(s.error_message().find("0 open frame(s)"), std::string::npos) << s.error_message();
  EXPECT_TRUE(Begin(22, 2 * kSize, kSize).ok());
}

// Spares count against the byte limit: two frames' framebuffers are kept,
// and a larger frame that needs their room frees them.
TEST_F(LimitsTest, SparesAreKeptWithinTheByteLimit) {
  const uint64_t framebuffer = Framebuffer::MemoryBytes(kSize, kSize);
  for (uint64_t round : {0, 1}) {
    const uint64_t a = 31 + 2 * round, b = a + 1;
    ASSERT_TRUE(Prepare(a).ok());
    ASSERT_TRUE(Prepare(b).ok());
    // The second round's frames take the first round's spares.
    EXPECT_EQ(display_service_->framebuffer_bytes(), 2 * framebuffer);
    for (uint64_t id : {a, b}) RunToImage(id);
    EXPECT_EQ(display_service_->open_frames(), 0u);
    EXPECT_EQ(display_service_->framebuffer_bytes(), 2 * framebuffer);
  }
  // 2 framebuffers' worth: with the two spares it would pass 2.5.
  ASSERT_TRUE(Begin(35, 2 * kSize, kSize).ok());
  EXPECT_EQ(display_service_->framebuffer_bytes(), 2 * framebuffer);
}

}  // namespace
}  // namespace transtick
