// Streams that come before their frame. The root prepares and starts a frame
// on every worker and begins it at the display in one round
// (FrameSpec.run), so a neighbour's rays can reach a worker, and a worker's
// deposits the display, a moment before that node has heard of the frame.
// Such a stream waits for the frame (FrameWaiters) and then goes on as if
// it had come after; one whose frame never comes ends NOT_FOUND after the
// wait, saying so; and no more than a few wait at once. Real worker and
// display servers on 127.0.0.1.
#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "cluster.grpc.pb.h"
#include "frame_waiters.h"
#include "gtest/gtest.h"
#include "nodes_fixture.h"
#include "transtick/framebuffer.h"
#include "transtick/ray_codec.h"

namespace transtick {
namespace {

using Ms = std::chrono::milliseconds;
using testing::Eventually;

double MsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// ---------------------------------------------------------------- FrameWaiters

TEST(FrameWaitersTest, NotifyResumesTheFramesWaitersOnly) {
  FrameWaiters w(8, Ms(10000));
  std::atomic<int> came{0}, gave_up{0};
  auto resume = [&](bool c) { ++(c ? came : gave_up); };
  ASSERT_TRUE(w.Park(1, resume));
  ASSERT_TRUE(w.Park(1, resume));
  ASSERT_TRUE(w.Park(2, resume));
  w.Notify(3);
  EXPECT_EQ(w.parked(), 3u);
  w.Notify(1);
  EXPECT_EQ(came.load(), 2);
  EXPECT_EQ(w.parked(), 1u);
  w.Notify(1);  // no one left for it
  EXPECT_EQ(came.load(), 2);
  w.Notify(2);
  EXPECT_EQ(came.load(), 3);
  EXPECT_EQ(gave_up.load(), 0);
}

TEST(FrameWaitersTest, AWaitEndsAfterItsPatienceAndTheCapHolds) {
  FrameWaiters w(2, Ms(150));
  std::atomic<int> came{0}, gave_up{0};
  auto resume = [&](bool c) { ++(c ? came : gave_up); };
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_TRUE(w.Park(5, resume));
  ASSERT_TRUE(w.Park(6, resume));
  EXPECT_FALSE(w.Park(7, resume));  // two wait already
  ASSERT_TRUE(Eventually([&] { return gave_up.load() == 2; }, Ms(5000)));
  EXPECT_GE(MsSince(t0), 150);
  EXPECT_EQ(came.load(), 0);
  EXPECT_EQ(w.parked(), 0u);
  w.Notify(5);  // too late: nothing happens
  EXPECT_EQ(came.load(), 0);
  EXPECT_TRUE(w.Park(7, resume));  // room again
}

TEST(FrameWaitersTest, CloseResumesEveryoneAndParksNoMore) {
  std::atomic<int> came{0}, gave_up{0};
  auto resume = [&](bool c) { ++(c ? came : gave_up); };
  {
    FrameWaiters w(64, Ms(60000));
    for (uint64_t id = 0; id < 10; ++id) ASSERT_TRUE(w.Park(id, resume));
    w.Close();
    EXPECT_EQ(gave_up.load(), 10);
    EXPECT_FALSE(w.Park(11, resume));
  }
  {
    FrameWaiters w(64, Ms(60000));
    ASSERT_TRUE(w.Park(1, resume));
  }  // the destructor closes
  EXPECT_EQ(gave_up.load(), 11);
  EXPECT_EQ(came.load(), 0);
}

// Many threads park, notify and time out at once; every waiter is resumed
// exactly once, with true exactly when its frame was notified while it
// waited.
TEST(FrameWaitersTest, EveryWaiterIsResumedOnceUnderContention) {
  constexpr int kThreads = 4, kEach = 500;
  FrameWaiters w(kThreads * kEach, Ms(50));
  std::vector<std::atomic<int>> resumed(kThreads * kEach);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < kEach; ++i) {
        const int k = t * kEach + i;
        EXPECT_TRUE(w.Park(static_cast<uint64_t>(k % 97), [&, k](bool) { ++resumed[k]; }));
        if (i % 3 == 0) w.Notify(static_cast<uint64_t>((k * 7) % 97));
      }
    });
  }
  for (auto& th : threads) th.join();
  ASSERT_TRUE(Eventually([&] { return w.parked() == 0; }, Ms(5000)));
  for (int k = 0; k < kThreads * kEach; ++k) EXPECT_EQ(resumed[k].load(), 1) << k;
}

// ---------------------------------------------------------------- the nodes

class EarlyStreamsTest : public testing::NodesTest {
 protected:
  WorkerOptions worker_options() const override {
    WorkerOptions o = NodesTest::worker_options();
    o.early_stream_wait = Ms(300);
    o.early_streams = 2;
    return o;
  }
  DisplayOptions display_options() const override {
    DisplayOptions o;
    o.early_deposit_wait = Ms(300);
    o.early_streams = 2;
    return o;
  }

  // A Rays stream from a left neighbour whose first batch names `frame`
  // and carries `rays` records.
  struct RayStream {
    grpc::ClientContext ctx;
    std::unique_ptr<grpc::ClientReaderWriter<v1::RayBatch, v1::RayBatch>> stream;
  };
  std::unique_ptr<RayStream> OpenRays(uint64_t frame, const std::string& rays) {
    auto s = std::make_unique<RayStream>();
    s->ctx.set_deadline(Deadline(20));
    s->stream = worker_stub_->Rays(&s->ctx);
    v1::RayBatch first;
    first.set_frame_id(frame);
    PackRays(rays, first.mutable_packed());
    EXPECT_TRUE(s->stream->Write(first));
    return s;
  }

  // A worker's deposit stream to the display: the message naming `frame`,
  // then every pixel of a kSize x kSize frame as a miss (a primary deposit
  // with no shadow rays), which completes the frame.
  struct DepositStream {
    grpc::ClientContext ctx;
    v1::FrameAck ack;
    std::unique_ptr<grpc::ClientWriter<v1::DepositBatch>> writer;
  };
  std::unique_ptr<DepositStream> SendMisses(uint64_t frame) {
    auto d = std::make_unique<DepositStream>();
    d->ctx.set_deadline(Deadline(20));
    d->writer = display_stub_->Deposits(&d->ctx, &d->ack);
    v1::DepositBatch batch;
    batch.set_frame_id(frame);
    EXPECT_TRUE(d->writer->Write(batch));
    batch.set_packed(AllMisses());
    d->writer->Write(batch);  // fails when the display has refused the stream
    return d;
  }
  static std::string AllMisses() {
    std::string records, packed;
    for (uint32_t p = 0; p < kSize * kSize; ++p) {
      AppendDeposit(Deposit{p, RayKind::kPrimary, 0, {0.25f, 0.5f, 0.75f}}, &records);
    }
    PackDeposits(records, &packed);
    return packed;
  }
};

TEST_F(EarlyStreamsTest, RaysBeforeTheFrameWaitForItAndAreTaken) {
  constexpr uint64_t kFrame = 31;
  std::string records;
  AppendRay(CentreRay(), &records);
  AppendRay(CentreRay(), &records);
  auto rays = OpenRays(kFrame, records);
  // Nothing is held for the frame yet, and the stream is not refused.
  std::this_thread::sleep_for(Ms(50));
  EXPECT_FALSE(worker_service_->LeftAttached(kFrame));
  ASSERT_TRUE(Prepare(kFrame).ok());
  // Taken once the frame is prepared: the two rays of the first batch, then
  // one more on the same stream.
  ASSERT_TRUE(Eventually([&] { return worker_service_->RaysReceivedLeft(kFrame) == 2; }, Ms(5000)))
      << worker_service_->RaysReceivedLeft(kFrame);
  EXPECT_TRUE(worker_service_->LeftAttached(kFrame));
  v1::RayBatch more;
  more.set_frame_id(kFrame);
  std::string one;
  AppendRay(CentreRay(), &one);
  PackRays(one, more.mutable_packed());
  ASSERT_TRUE(rays->stream->Write(more));
  ASSERT_TRUE(Eventually([&] { return worker_service_->RaysReceivedLeft(kFrame) == 3; }, Ms(5000)));
  rays->stream->WritesDone();
  ASSERT_TRUE(Run(kFrame).ok());
  auto stats = End(kFrame, /*cancel=*/true);
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_EQ(stats->received_left(), 3u);
  EXPECT_EQ(stats->rays_rejected(), 0u);
  rays->stream->Finish();
}

TEST_F(EarlyStreamsTest, RaysForAFrameThatNeverComesEndAfterTheWait) {
  constexpr uint64_t kFrame = 32;
  const auto t0 = std::chrono::steady_clock::now();
  auto rays = OpenRays(kFrame, "");
  rays->stream->WritesDone();
  grpc::Status s = rays->stream->Finish();
  const double ms = MsSince(t0);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND) << s.error_message();
  EXPECT_NE(s.error_message().find("frame 32 was not prepared here within 300 ms"),
            std::string::npos)
      << s.error_message();
  EXPECT_GE(ms, 300);
  EXPECT_LT(ms, 5000);
  // The worker serves on: a frame prepared now runs.
  ASSERT_TRUE(Prepare(33).ok());
  ASSERT_TRUE(Run(33).ok());
  EXPECT_TRUE(Await(33).ok());
  EXPECT_TRUE(End(33).ok());
}

TEST_F(EarlyStreamsTest, NoMoreThanTheCapWaitAndTheRestAreRefusedAtOnce) {
  auto a = OpenRays(41, ""), b = OpenRays(42, "");
  std::this_thread::sleep_for(Ms(50));  // both parked
  const auto t0 = std::chrono::steady_clock::now();
  auto c = OpenRays(43, "");
  c->stream->WritesDone();
  grpc::Status s = c->stream->Finish();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND) << s.error_message();
  EXPECT_NE(s.error_message().find("frame 43 is not prepared here"), std::string::npos)
      << s.error_message();
  EXPECT_LT(MsSince(t0), 250);  // refused, not waited out
  for (auto* r : {a.get(), b.get()}) {
    r->stream->WritesDone();
    EXPECT_EQ(r->stream->Finish().error_code(), grpc::StatusCode::NOT_FOUND);
  }
}

TEST_F(EarlyStreamsTest, DepositsBeforeBeginFrameWaitAndCompleteTheFrame) {
  constexpr uint64_t kFrame = 51;
  auto deposits = SendMisses(kFrame);
  std::this_thread::sleep_for(Ms(50));
  ASSERT_TRUE(Begin(kFrame).ok());
  deposits->writer->WritesDone();
  grpc::Status s = deposits->writer->Finish();
  EXPECT_TRUE(s.ok()) << s.error_message();
  // Every pixel came before the frame began, and the frame is complete.
  int rows = 0;
  s = Await(kFrame, &rows);
  EXPECT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(rows, kSize);
}

TEST_F(EarlyStreamsTest, DepositsForAFrameNeverBegunOrAbortedAreRefused) {
  const auto send = [&](uint64_t frame) {
    auto deposits = SendMisses(frame);
    deposits->writer->WritesDone();
    return deposits->writer->Finish();
  };
  auto t0 = std::chrono::steady_clock::now();
  grpc::Status s = send(52);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND) << s.error_message();
  EXPECT_NE(s.error_message().find("frame 52 was not begun"), std::string::npos)
      << s.error_message();
  EXPECT_GE(MsSince(t0), 300);
  // An aborted frame is not waited for: its deposits are refused at once.
  ASSERT_TRUE(Begin(53).ok());
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(5));
    v1::FrameRef ref;
    ref.set_frame_id(53);
    ref.set_reason("a test aborts it");
    v1::FrameAck ack;
    ASSERT_TRUE(display_stub_->AbortFrame(&ctx, ref, &ack).ok());
  }
  t0 = std::chrono::steady_clock::now();
  s = send(53);
  EXPECT_FALSE(s.ok());
  EXPECT_LT(MsSince(t0), 250);
}

// A frame prepared with `run` traces without RunFrame, and says so.
TEST_F(EarlyStreamsTest, PrepareWithRunStartsTheFrame) {
  constexpr uint64_t kFrame = 61;
  ASSERT_TRUE(Begin(kFrame).ok());
  v1::FrameSpec spec = Spec(kFrame);
  spec.set_run(true);
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(10));
  v1::FrameAck ack;
  ASSERT_TRUE(worker_stub_->PrepareFrame(&ctx, spec, &ack).ok());
  EXPECT_TRUE(ack.running());
  int rows = 0;
  grpc::Status s = Await(kFrame, &rows);
  EXPECT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(rows, kSize);
  auto stats = End(kFrame);
  ASSERT_TRUE(stats.ok()) << stats.status();
  // Without `run`, it waits for RunFrame.
  ASSERT_TRUE(Begin(kFrame + 1).ok());
  v1::FrameAck plain;
  grpc::ClientContext ctx2;
  ctx2.set_deadline(Deadline(10));
  ASSERT_TRUE(worker_stub_->PrepareFrame(&ctx2, Spec(kFrame + 1), &plain).ok());
  EXPECT_FALSE(plain.running());
  ASSERT_TRUE(Run(kFrame + 1).ok());
  EXPECT_TRUE(Await(kFrame + 1).ok());
  EXPECT_TRUE(End(kFrame + 1).ok());
}

}  // namespace
}  // namespace transtick
