// The root's balancing policies on frames whose costs are known: when
// "previous-frame" re-cuts the slabs and when it keeps them.
#include "balancer.h"

#include <random>

#include "gtest/gtest.h"

namespace transtick {
namespace {

// One ring of workers over `planes` planes, cut uniformly, and a frame of
// `frame_ms` in which worker i spent cpu[i] ms tracing, spread evenly over
// its planes.
struct Case {
  Layout layout;
  FrameResult frame;
};

Case MakeCase(const std::vector<double>& cpu, int planes, double frame_ms) {
  Case c;
  Layout::Ring ring;
  ring.workers.resize(cpu.size());
  for (size_t i = 0; i <= cpu.size(); ++i) {
    ring.cuts.push_back(static_cast<int>(planes * i / cpu.size()));
  }
  c.layout.rings.push_back(ring);
  c.frame.frame_ms = frame_ms;
  for (size_t i = 0; i < cpu.size(); ++i) {
    v1::WorkerFrameStats w;
    w.set_cpu_ms(cpu[i]);
    w.add_slab(ring.cuts[i]);
    w.add_slab(ring.cuts[i + 1]);
    const int n = ring.cuts[i + 1] - ring.cuts[i];
    for (int k = 0; k < n; ++k) w.add_plane_work(static_cast<uint64_t>(cpu[i] * 1000 / n));
    c.frame.workers.push_back(w);
  }
  return c;
}

std::vector<std::vector<int>> Learn(Case& c, BalanceMemory& memory) {
  auto balancer = MakeBalancer(v1::PREVIOUS_FRAME, BalanceRule::kCost, 0);
  BalanceReport report;
  balancer->Learn(c.frame, c.layout, memory, &report);
  EXPECT_EQ(report.cuts_after, memory.next_cuts);
  return memory.next_cuts;
}

TEST(PreviousFrameTest, TheFirstImbalanceIsReCutToLearnWhatAMoveCosts) {
  Case c = MakeCase({150, 50}, 100, 200);
  BalanceMemory memory;
  const auto cuts = Learn(c, memory);
  ASSERT_EQ(cuts.size(), 1u);
  EXPECT_LT(cuts[0][1], 50);  // toward the expensive slab
}

TEST(PreviousFrameTest, ASmallGainDoesNotPayForADearMove) {
  // The last move took 200 ms; perfect cuts would save 1 - 105/110 of a
  // 180 ms frame, 8 ms a frame: the cuts stay.
  Case c = MakeCase({110, 100}, 100, 180);
  c.layout.planes_moved = 2;
  c.layout.load_ms = 200;
  BalanceMemory memory;
  EXPECT_EQ(Learn(c, memory), c.layout.Cuts());
  EXPECT_EQ(memory.recut_ms, 200);
}

TEST(PreviousFrameTest, ALargeGainPaysForTheSameMove) {
  // 1 - 200/300 of a 600 ms frame: 200 ms a frame.
  Case c = MakeCase({300, 100}, 100, 600);
  c.layout.planes_moved = 2;
  c.layout.load_ms = 200;
  BalanceMemory memory;
  const auto cuts = Learn(c, memory);
  EXPECT_NE(cuts, c.layout.Cuts());
  EXPECT_LT(cuts[0][1], 50);
}

TEST(PreviousFrameTest, ACheapMoveIsMadeForASmallGain) {
  // A move of 5 ms is repaid by 8 ms a frame; the price measured by an
  // earlier frame holds while this layout moved nothing.
  Case c = MakeCase({110, 100}, 100, 180);
  BalanceMemory memory;
  memory.recut_ms = 5;
  EXPECT_NE(Learn(c, memory), c.layout.Cuts());
  EXPECT_EQ(memory.recut_ms, 5);
}

TEST(PreviousFrameTest, TheDecisionFollowsGainAgainstPriceOverRandomFrames) {
  // The invariant over many frames: cuts move exactly when three frames'
  // gain exceeds the last move's price (and the new cuts differ at all).
  std::mt19937 rng(14);
  std::uniform_real_distribution<double> cost(1, 400), price(1, 500);
  int kept = 0, moved = 0;
  for (int i = 0; i < 2000; ++i) {
    const int n = 2 + static_cast<int>(rng() % 4);
    std::vector<double> cpu;
    for (int k = 0; k < n; ++k) cpu.push_back(cost(rng));
    const double frame_ms = cost(rng);
    Case c = MakeCase(cpu, 120, frame_ms);
    c.layout.planes_moved = 1;
    c.layout.load_ms = price(rng);
    double sum = 0, max = 0;
    for (double x : cpu) sum += x, max = std::max(max, x);
    const double gain = frame_ms * (1 - sum / n / max);
    BalanceMemory memory;
    const auto cuts = Learn(c, memory);
    if (gain * 3 <= c.layout.load_ms) {
      ASSERT_EQ(cuts, c.layout.Cuts()) << i;
      ++kept;
    } else {
      ++moved;
    }
  }
  // Both outcomes are exercised.
  EXPECT_GT(kept, 200);
  EXPECT_GT(moved, 200);
}

}  // namespace
}  // namespace transtick
