// The root's balancing policies on frames whose costs are known: when
// "previous-frame" re-cuts the slabs and when it keeps them, and when
// "test-rays" refines a view's cuts from its measured frames.
#include "balancer.h"

#include <cmath>
#include <limits>
#include <random>

#include "gtest/gtest.h"

namespace transtick {
namespace {

// One ring of workers over `planes` planes, and a frame of `frame_ms` in
// which worker i spent cpu[i] ms tracing; its work profile counts
// work[i] spread evenly over its planes (cpu[i] when no work is given).
struct Case {
  Layout layout;
  FrameResult frame;
};

FrameResult MakeFrame(const std::vector<int>& cuts, const std::vector<double>& cpu,
                      const std::vector<double>& work, double frame_ms) {
  FrameResult frame;
  frame.frame_ms = frame_ms;
  for (size_t i = 0; i < cpu.size(); ++i) {
    v1::WorkerFrameStats w;
    w.set_cpu_ms(cpu[i]);
    w.add_slab(cuts[i]);
    w.add_slab(cuts[i + 1]);
    const int n = cuts[i + 1] - cuts[i];
    const double total = work.empty() ? cpu[i] : work[i];
    for (int k = 0; k < n; ++k) w.add_plane_work(static_cast<uint64_t>(total * 1000 / n));
    frame.workers.push_back(w);
  }
  return frame;
}

Case MakeCase(const std::vector<double>& cpu, int planes, double frame_ms,
              const std::vector<double>& work = {}) {
  Case c;
  Layout::Ring ring;
  ring.workers.resize(cpu.size());
  for (size_t i = 0; i <= cpu.size(); ++i) {
    ring.cuts.push_back(static_cast<int>(planes * i / cpu.size()));
  }
  c.layout.rings.push_back(ring);
  c.frame = MakeFrame(ring.cuts, cpu, work, frame_ms);
  return c;
}

std::vector<std::vector<int>> Learn(Case& c, BalanceMemory& memory) {
  auto balancer = MakeBalancer(v1::PREVIOUS_FRAME, BalanceRule::kCost, 0);
  BalanceReport report;
  balancer->Learn(v1::View(), c.frame, c.layout, memory, &report);
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

TEST(PreviousFrameTest, CutsMoveHalfwayToTheMeasuredTimesAFrame) {
  // The profile counts every plane alike; the first 50 planes really cost
  // 3 ms each and the others 1 ms. Each frame moves each plane's
  // calibration halfway to what its slab measured, so the cuts approach
  // the balance (33.3: 100 ms each side) over the frames, never past it.
  std::vector<double> truth(100, 1.0);
  for (int p = 0; p < 50; ++p) truth[p] = 3;
  BalanceMemory memory;
  std::vector<int> cuts = {0, 50, 100};
  std::vector<int> seen;
  for (int f = 0; f < 6; ++f) {
    Case c = MakeCase({1, 1}, 100, 1000);
    ASSERT_TRUE(c.layout.SetCuts({cuts}, 100));
    std::vector<double> cpu, work;
    for (int i = 0; i < 2; ++i) {
      double ms = 0;
      for (int p = cuts[i]; p < cuts[i + 1]; ++p) ms += truth[p];
      cpu.push_back(ms);
      work.push_back(cuts[i + 1] - cuts[i]);
    }
    c.frame = MakeFrame(cuts, cpu, work, 1000);
    cuts = Learn(c, memory)[0];
    seen.push_back(cuts[1]);
  }
  EXPECT_EQ(seen[0], 40);  // 125 ms over 50 planes, 75 over 50
  for (size_t f = 1; f < seen.size(); ++f) {
    EXPECT_LE(seen[f], seen[f - 1]) << f;
    EXPECT_GE(seen[f], 33) << f;
  }
  EXPECT_LE(seen.back(), 35);
}

TEST(PreviousFrameTest, AWorkerWithoutATimeLeavesTheProfileToDecide) {
  // A worker that failed to report has no CPU time: the profile's totals
  // cut, rather than a slab that looks free.
  Case c = MakeCase({150, 0}, 100, 200, {100, 300});
  BalanceMemory memory;
  const auto cuts = Learn(c, memory);
  EXPECT_GT(cuts[0][1], 50);  // toward the slab the profile says is dearer
}

TEST(PreviousFrameTest, ATimeThatIsNoNumberTeachesNothing) {
  // A worker reporting an infinite or NaN CPU time (a defect, or a hostile
  // peer) must not leave the calibration NaN, which would freeze the cuts.
  for (double bad : {std::numeric_limits<double>::infinity(), std::nan("")}) {
    Case c = MakeCase({bad, 50}, 100, 200, {100, 100});
    BalanceMemory memory;
    Learn(c, memory);
    ASSERT_EQ(memory.plane_scale.size(), 1u);
    for (double x : memory.plane_scale[0]) ASSERT_EQ(x, 1.0) << bad;
    // A sound frame after it is learned from as usual.
    Case next = MakeCase({150, 50}, 100, 200, {100, 100});
    EXPECT_EQ(Learn(next, memory)[0][1], 40) << bad;
  }
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

// "test-rays": a prerender whose profile spreads `work` evenly over the
// slabs of `planes` planes cut uniformly among `cpu.size()` workers.
struct TestRaysCase {
  std::unique_ptr<Balancer> balancer = MakeBalancer(v1::TEST_RAYS, BalanceRule::kCost, 16);
  BalanceMemory memory;
  Layout layout;
  v1::View view;
  int planes = 0;
};

TestRaysCase PlanTestRays(size_t workers, int planes, const std::vector<double>& work) {
  TestRaysCase t;
  t.planes = planes;
  Layout::Ring ring;
  ring.workers.resize(workers);
  for (size_t i = 0; i <= workers; ++i) ring.cuts.push_back(static_cast<int>(planes * i / workers));
  t.layout.rings.push_back(ring);
  t.view.set_width(64);
  t.view.set_height(64);
  BalanceReport report;
  const absl::Status s = t.balancer->Plan(
      t.view, t.memory, t.layout,
      [&](const v1::View&, Layout& probe) -> absl::StatusOr<FrameResult> {
        return MakeFrame(probe.rings[0].cuts, work, work, 1);
      },
      &report);
  EXPECT_TRUE(s.ok()) << s;
  return t;
}

// A frame of the view on the cuts the plan set, in which worker i spent
// cpu[i] ms; its planes moved for `move_ms` when given.
std::vector<std::vector<int>> Frame(TestRaysCase& t, const std::vector<double>& cpu,
                                    double frame_ms, double move_ms = -1) {
  Layout layout = t.layout;
  const auto cached = t.memory.view_cuts.at(ViewKey(t.view));
  EXPECT_TRUE(layout.SetCuts(cached, t.planes));
  if (move_ms >= 0) {
    layout.planes_moved = 1;
    layout.load_ms = move_ms;
  }
  BalanceReport report;
  t.balancer->Learn(t.view, MakeFrame(layout.rings[0].cuts, cpu, {}, frame_ms), layout, t.memory,
                    &report);
  EXPECT_EQ(t.memory.next_cuts, layout.Cuts());
  return t.memory.view_cuts.at(ViewKey(t.view));
}

TEST(TestRaysTest, ThePrerendersProfileCutsTheFirstFrame) {
  TestRaysCase t = PlanTestRays(2, 100, {300, 100});
  EXPECT_LT(t.memory.view_cuts.at(ViewKey(t.view))[0][1], 50);
}

TEST(TestRaysTest, RefinesOnceImbalanceHasCostAMove) {
  // The profile says the slabs cost alike; the frames measure 120 and 80
  // ms, in frames of 100 ms: 100 * (1 - 100/120) = 16.7 ms lost a frame.
  // The move to these cuts took 60 ms, so the fourth frame (66.7 ms lost)
  // refines the cuts, from the four frames' times.
  TestRaysCase t = PlanTestRays(2, 100, {100, 100});
  const auto first = t.memory.view_cuts.at(ViewKey(t.view));
  ASSERT_EQ(first[0][1], 50);
  EXPECT_EQ(Frame(t, {120, 80}, 100, 60), first);
  EXPECT_EQ(Frame(t, {120, 80}, 100), first);
  EXPECT_EQ(Frame(t, {120, 80}, 100), first);
  const auto refined = Frame(t, {120, 80}, 100);
  EXPECT_EQ(refined[0][1], 42);  // 120 ms over 50 planes, 80 over 50: 100 each side of 41.7
  // The refined cuts start afresh: a frame on them alone does not move them.
  EXPECT_EQ(Frame(t, {110, 90}, 100, 60), refined);
}

TEST(TestRaysTest, NoiseAveragesOverTheFramesBeforeARefinement) {
  // Frames measure 140/60, then 100/100, then 110/90, 100 ms each, and a
  // move costs 40 ms. The loss is taken from the summed times: 100 * (1 -
  // 100/140) = 28.6 after the first, 200 * (1 - 200/240) = 33.3 after the
  // second (the second frame's balance takes some back), 300 * (1 -
  // 300/350) = 42.9 after the third, which refines from 350/250.
  TestRaysCase t = PlanTestRays(2, 100, {100, 100});
  t.memory.recut_ms = 40;
  EXPECT_EQ(Frame(t, {140, 60}, 100)[0][1], 50);
  EXPECT_EQ(Frame(t, {100, 100}, 100)[0][1], 50);
  EXPECT_EQ(Frame(t, {110, 90}, 100)[0][1], 43);  // 350 over 50 planes, 250 over 50
}

TEST(TestRaysTest, ABalancedViewsNoiseDoesNotAddUp) {
  // Times that scatter around the balance, 10% either way: one frame's
  // imbalance is 5-10%, the sum's falls. A move of 100 ms is not made in
  // 40 frames of 100 ms, though each frame alone "lost" 5-10 ms.
  TestRaysCase t = PlanTestRays(2, 100, {100, 100});
  t.memory.recut_ms = 100;
  for (int f = 0; f < 40; ++f) {
    const double d = f % 2 ? 10 : -10;
    EXPECT_EQ(Frame(t, {100 + d, 100 - d}, 100)[0][1], 50) << f;
  }
  // No re-cut was even tried: all 40 frames are still summed.
  EXPECT_EQ(t.memory.view_costs.at(ViewKey(t.view)).frame_ms, 4000);
}

TEST(TestRaysTest, EachRingIsRefinedByItsOwnProfileAndTimes) {
  // Two rings of two workers over 100 planes: the prerender counts every
  // plane alike in both; the frames measure 120/80 in ring 0 and 80/120 in
  // ring 1 (the rings' rows see different parts of the volume).
  auto balancer = MakeBalancer(v1::TEST_RAYS, BalanceRule::kCost, 16);
  BalanceMemory memory;
  Layout layout;
  for (int r = 0; r < 2; ++r) {
    Layout::Ring ring;
    ring.workers.resize(2);
    ring.cuts = {0, 50, 100};
    layout.rings.push_back(ring);
  }
  v1::View view;
  view.set_width(64);
  view.set_height(64);
  auto two_rings = [](const std::vector<double>& ring0, const std::vector<double>& ring1,
                      double frame_ms) {
    FrameResult f = MakeFrame({0, 50, 100}, ring0, {}, frame_ms);
    for (const auto& w : MakeFrame({0, 50, 100}, ring1, {}, frame_ms).workers) {
      f.workers.push_back(w);
    }
    return f;
  };
  BalanceReport report;
  ASSERT_TRUE(balancer
                  ->Plan(
                      view, memory, layout,
                      [&](const v1::View&, Layout&) -> absl::StatusOr<FrameResult> {
                        return two_rings({100, 100}, {100, 100}, 1);
                      },
                      &report)
                  .ok());
  ASSERT_EQ(memory.view_cuts.at(ViewKey(view)),
            (std::vector<std::vector<int>>{{0, 50, 100}, {0, 50, 100}}));
  memory.recut_ms = 10;
  balancer->Learn(view, two_rings({120, 80}, {80, 120}, 100), layout, memory, &report);
  EXPECT_EQ(memory.view_cuts.at(ViewKey(view)),
            (std::vector<std::vector<int>>{{0, 42, 100}, {0, 58, 100}}));
}

TEST(TestRaysTest, RemembersABoundedNumberOfViewsForgettingTheOldest) {
  TestRaysCase t = PlanTestRays(2, 100, {300, 100});
  for (size_t v = 1; v < kMaxBalancedViews + 100; ++v) {
    v1::View view = t.view;
    view.set_azimuth(static_cast<double>(v));
    Layout layout = t.layout;
    BalanceReport report;
    ASSERT_TRUE(t.balancer
                    ->Plan(
                        view, t.memory, layout,
                        [&](const v1::View&, Layout& probe) -> absl::StatusOr<FrameResult> {
                          return MakeFrame(probe.rings[0].cuts, {300, 100}, {300, 100}, 1);
                        },
                        &report)
                    .ok());
  }
  EXPECT_EQ(t.memory.view_cuts.size(), kMaxBalancedViews);
  EXPECT_EQ(t.memory.view_profiles.size(), kMaxBalancedViews);
  EXPECT_EQ(t.memory.view_order.size(), kMaxBalancedViews);
  EXPECT_EQ(t.memory.view_cuts.count(ViewKey(t.view)), 0u);  // the first, forgotten
  v1::View last = t.view;
  last.set_azimuth(static_cast<double>(kMaxBalancedViews + 99));
  EXPECT_EQ(t.memory.view_cuts.count(ViewKey(last)), 1u);
}

TEST(TestRaysTest, FramesOnOtherCutsOrWithoutTimesAreNotCounted) {
  TestRaysCase t = PlanTestRays(2, 100, {100, 100});
  t.memory.recut_ms = 10;
  // A worker that did not report, or reported no number: nothing learned,
  // whatever the imbalance.
  EXPECT_EQ(Frame(t, {300, 0}, 100)[0][1], 50);
  EXPECT_EQ(Frame(t, {300, std::numeric_limits<double>::infinity()}, 100)[0][1], 50);
  EXPECT_EQ(Frame(t, {std::nan(""), 100}, 100)[0][1], 50);
  EXPECT_TRUE(t.memory.view_costs.empty());
  // A frame on other cuts than the view's (a layout of other members, say).
  Layout other = t.layout;
  ASSERT_TRUE(other.SetCuts({{0, 70, 100}}, t.planes));
  BalanceReport report;
  t.balancer->Learn(t.view, MakeFrame({0, 70, 100}, {300, 100}, {}, 100), other, t.memory, &report);
  EXPECT_EQ(t.memory.view_cuts.at(ViewKey(t.view))[0][1], 50);
  EXPECT_TRUE(t.memory.view_costs.empty());
}

TEST(TestRaysTest, MovesNeverCostMoreThanTheImbalanceBeforeThemOverRandomFrames) {
  // Rent or buy: the view's cuts change only once the time lost to
  // imbalance since they were set (by the summed times) exceeds the last
  // move's price, and then to valid cuts.
  std::mt19937 rng(13);
  std::uniform_real_distribution<double> cost(10, 200), price(1, 400);
  int refinements = 0, waits = 0;
  for (int run = 0; run < 200; ++run) {
    const size_t n = 2 + rng() % 4;
    TestRaysCase t = PlanTestRays(n, 120, std::vector<double>(n, 100));
    t.memory.recut_ms = price(rng);
    double frames_ms = 0;
    std::vector<double> sums(n, 0.0);
    auto cuts = t.memory.view_cuts.at(ViewKey(t.view));
    for (int f = 0; f < 30; ++f) {
      std::vector<double> cpu;
      for (size_t k = 0; k < n; ++k) cpu.push_back(cost(rng));
      const double frame_ms = cost(rng);
      frames_ms += frame_ms;
      double sum = 0, max = 0;
      for (size_t k = 0; k < n; ++k) {
        sums[k] += cpu[k];
        sum += sums[k];
        max = std::max(max, sums[k]);
      }
      const bool due = frames_ms * (1 - sum / n / max) > t.memory.recut_ms;
      const auto now = Frame(t, cpu, frame_ms);
      if (now != cuts) {
        ASSERT_TRUE(due) << run << " " << f;
        ASSERT_TRUE(ValidCuts(now[0], 120, static_cast<int>(n)));
        ++refinements;
        cuts = now;
      } else if (!due) {
        ++waits;
      }
      if (due) {  // counted afresh from here, refined or not
        frames_ms = 0;
        sums.assign(n, 0.0);
      }
    }
  }
  EXPECT_GT(refinements, 100);
  EXPECT_GT(waits, 100);
}

}  // namespace
}  // namespace transtick
