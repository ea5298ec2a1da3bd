// The worker's TraceOrder: which of the frames a worker traces at once may
// take its cores (docs/design.md, "Overlapped frames"). Frames here are
// stand-ins whose work the test sets; real frames overlap in cluster_test
// (every multi-frame job there runs with two frames tracing) and in the
// daemons and deploy tests.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <random>
#include <thread>
#include <vector>

#include "frame.h"

namespace transtick {
namespace {

using std::chrono::milliseconds;

struct Stub final : TraceOrder::Member {
  std::atomic<bool> work{false};
  bool HasWork() const override { return work.load(); }
};

TEST(TraceOrderTest, OneFrameIsBehindNobody) {
  TraceOrder order;
  Stub a;
  a.work = true;
  const uint64_t pa = order.Join(&a, false);
  EXPECT_FALSE(order.Behind(pa));
  EXPECT_EQ(order.frames(), 1);
  order.Leave(pa);
  EXPECT_EQ(order.frames(), 0);
}

TEST(TraceOrderTest, TheOlderFrameGoesFirstWhileItHasWork) {
  TraceOrder order;
  Stub a, b;
  const uint64_t pa = order.Join(&a, false), pb = order.Join(&b, false);
  a.work = true;
  b.work = true;
  EXPECT_FALSE(order.Behind(pa));
  EXPECT_TRUE(order.Behind(pb));
  a.work = false;  // its tail: rays in flight elsewhere
  EXPECT_FALSE(order.Behind(pb));
  a.work = true;  // its rays came back
  EXPECT_TRUE(order.Behind(pb));
  order.Leave(pa);
  EXPECT_FALSE(order.Behind(pb));
  order.Leave(pb);
}

TEST(TraceOrderTest, AnInteractiveFrameGoesBeforeBatchFramesThatStartedEarlier) {
  TraceOrder order;
  Stub batch1, batch2, session;
  batch1.work = batch2.work = session.work = true;
  const uint64_t p1 = order.Join(&batch1, false), p2 = order.Join(&batch2, false);
  const uint64_t ps = order.Join(&session, true);
  EXPECT_FALSE(order.Behind(ps));
  EXPECT_TRUE(order.Behind(p1));
  EXPECT_TRUE(order.Behind(p2));
  session.work = false;
  EXPECT_FALSE(order.Behind(p1));
  EXPECT_TRUE(order.Behind(p2));
  for (uint64_t p : {p1, p2, ps}) order.Leave(p);
}

// Against a model over random joins, leaves and changes of work: a frame is
// behind exactly when a frame ahead of it (interactive first, then by the
// order of joining) has work.
TEST(TraceOrderTest, BehindMatchesTheModelOverRandomHistories) {
  std::mt19937 rng(20261207);
  for (int history = 0; history < 200; ++history) {
    TraceOrder order;
    struct Live {
      std::unique_ptr<Stub> stub;
      uint64_t place;
      bool interactive;
      int joined;
    };
    std::vector<Live> live;
    int joins = 0;
    for (int op = 0; op < 60; ++op) {
      const int what = std::uniform_int_distribution<int>(0, 3)(rng);
      if ((what == 0 || live.empty()) && live.size() < 6) {
        Live l{std::make_unique<Stub>(), 0, std::bernoulli_distribution(0.25)(rng), joins++};
        l.stub->work = std::bernoulli_distribution(0.5)(rng);
        l.place = order.Join(l.stub.get(), l.interactive);
        live.push_back(std::move(l));
      } else if (what == 1 && !live.empty()) {
        const size_t k = std::uniform_int_distribution<size_t>(0, live.size() - 1)(rng);
        order.Leave(live[k].place);
        live.erase(live.begin() + static_cast<std::ptrdiff_t>(k));
      } else if (!live.empty()) {
        const size_t k = std::uniform_int_distribution<size_t>(0, live.size() - 1)(rng);
        live[k].stub->work = !live[k].stub->work;
      }
      ASSERT_EQ(order.frames(), static_cast<int>(live.size()));
      for (const Live& me : live) {
        bool want = false;
        for (const Live& o : live) {
          const bool ahead = o.interactive != me.interactive ? o.interactive : o.joined < me.joined;
          want = want || (ahead && o.stub->work);
        }
        ASSERT_EQ(order.Behind(me.place), want) << "history " << history << " op " << op;
      }
    }
  }
}

// A frame waiting behind another goes on as soon as that one's work runs
// out and it says so, or it leaves; not after the wait's timeout.
TEST(TraceOrderTest, WaitEndsWhenTheFrameAheadRunsOutOrLeaves) {
  TraceOrder order;
  Stub a, b;
  a.work = b.work = true;
  const uint64_t pa = order.Join(&a, false), pb = order.Join(&b, false);
  const auto long_wait = milliseconds(20'000);
  for (int how = 0; how < 2; ++how) {
    std::thread ahead([&] {
      std::this_thread::sleep_for(milliseconds(50));
      if (how == 0) {
        a.work = false;
        order.Notify();
      } else {
        order.Leave(pa);
      }
    });
    const auto t0 = std::chrono::steady_clock::now();
    while (order.Behind(pb)) order.Wait(pb, long_wait);
    const auto waited = std::chrono::steady_clock::now() - t0;
    ahead.join();
    EXPECT_LT(waited, milliseconds(10'000)) << (how == 0 ? "notified" : "left");
    a.work = true;
  }
  // With nothing ahead, Wait returns at once.
  const auto t0 = std::chrono::steady_clock::now();
  order.Wait(pb, long_wait);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, milliseconds(10'000));
  order.Leave(pb);
}

}  // namespace
}  // namespace transtick
