#include "balancer.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"

namespace transtick {
namespace {

// Test rays per side of the image for a balancing prerender. 16 (the
// paper's order) measures too few rays for stable cuts: on bonsai with 8
// workers the tracer CPU max/mean after balancing was 1.22-1.25 with 16,
// 1.09-1.13 with 32 and 48. With smooth surfaces 32 was too few at 8
// workers: at 45 degrees, 1.15-1.17 on cthead and 1.21-1.24 on engine
// against 1.08-1.10 and 1.09-1.11 with 64 (cluster_bench tables, runs
// interleaved, 4 December 2026). 64x64 rays cost about 2.5% of a 400x400
// frame, once per view.
constexpr int kDefaultBalanceGrid = 64;

std::string FormatCuts(const std::vector<std::vector<int>>& cuts) {
  std::string out;
  for (size_t r = 0; r < cuts.size(); ++r) {
    absl::StrAppend(&out, r ? " | " : "", "[", absl::StrJoin(cuts[r], " "), "]");
  }
  return out;
}

// Costs of the workers of each ring (their tracers' CPU time), in ring order.
std::vector<std::vector<double>> RingCosts(const FrameResult& frame,
                                           const std::vector<size_t>& ring_sizes) {
  std::vector<std::vector<double>> costs(ring_sizes.size());
  size_t k = 0;
  for (size_t r = 0; r < ring_sizes.size(); ++r) {
    for (size_t i = 0; i < ring_sizes[r]; ++i, ++k) {
      costs[r].push_back(k < frame.workers.size() ? frame.workers[k].cpu_ms() : 0.0);
    }
  }
  return costs;
}

// The work profiles of the workers of each ring (docs/balancing.md, "The
// work profile"), in ring order; empty for a worker that sent none or one
// that does not fit its slab.
std::vector<std::vector<std::vector<double>>> RingProfiles(const FrameResult& frame,
                                                           const std::vector<size_t>& ring_sizes) {
  std::vector<std::vector<std::vector<double>>> profiles(ring_sizes.size());
  size_t k = 0;
  for (size_t r = 0; r < ring_sizes.size(); ++r) {
    for (size_t i = 0; i < ring_sizes[r]; ++i, ++k) {
      std::vector<double> p;
      // Only a profile of one entry per plane of the worker's slab counts.
      if (k < frame.workers.size()) {
        const v1::WorkerFrameStats& w = frame.workers[k];
        if (w.slab_size() == 2 && w.plane_work_size() == w.slab(1) - w.slab(0)) {
          for (uint64_t x : w.plane_work()) p.push_back(static_cast<double>(x));
        }
      }
      profiles[r].push_back(std::move(p));
    }
  }
  return profiles;
}

std::vector<std::vector<int>> Recut(const Layout& layout, const FrameResult& frame,
                                    BalanceRule rule) {
  const auto sizes = layout.RingSizes();
  auto costs = RingCosts(frame, sizes);
  const auto profiles = RingProfiles(frame, sizes);
  if (rule == BalanceRule::kCost) {
    // A slab's cost is its work profile's total when it sent one: counted,
    // not timed, so the same rays give the same cuts on a busy machine,
    // where a prerender's CPU times (a millisecond or two each) were
    // mostly noise and each thread's fixed costs.
    // A ring some of whose workers sent none keeps its CPU times.
    for (size_t r = 0; r < sizes.size(); ++r) {
      bool profiled = true;
      for (const auto& p : profiles[r]) profiled = profiled && !p.empty();
      if (!profiled) continue;
      for (size_t i = 0; i < costs[r].size(); ++i) {
        double work = 0;
        for (double w : profiles[r][i]) work += w;
        costs[r][i] = work;
      }
    }
  }
  std::vector<std::vector<int>> cuts;
  for (size_t r = 0; r < sizes.size(); ++r) {
    cuts.push_back(BalancedCuts(layout.rings[r].cuts, costs[r], rule, profiles[r]));
  }
  return cuts;
}

int Planes(const Layout& layout) {
  return layout.rings.empty() || layout.rings[0].cuts.empty() ? 0 : layout.rings[0].cuts.back();
}

class Off : public Balancer {
 public:
  absl::Status Plan(const v1::View&, BalanceMemory&, Layout&, const Prerender&,
                    BalanceReport* report) override {
    report->mode = v1::OFF;
    return absl::OkStatus();
  }
};

class TestRays : public Balancer {
 public:
  TestRays(BalanceRule rule, int grid)
      : rule_(rule), grid_(grid > 0 ? grid : kDefaultBalanceGrid) {}

  absl::Status Plan(const v1::View& view, BalanceMemory& memory, Layout& layout,
                    const Prerender& prerender, BalanceReport* report) override {
    report->mode = v1::TEST_RAYS;
    const int planes = Planes(layout);
    auto cached = memory.view_cuts.find(ViewKey(view));
    if (cached != memory.view_cuts.end()) {
      layout.SetCuts(cached->second, planes);
      report->cuts_before = report->cuts_after = cached->second;
      return absl::OkStatus();
    }
    // Start from the cuts the workers hold when they are this ring's.
    if (!memory.next_cuts.empty()) layout.SetCuts(memory.next_cuts, planes);
    report->cuts_before = layout.Cuts();
    // A grid of test rays through the same camera: a small image of the
    // view, never more rays than the view itself has.
    const int grid = std::min(view.width(), grid_);
    v1::View test = view;
    test.clear_output();
    test.set_width(grid);
    test.set_height(std::max(1, static_cast<int>(std::lround(static_cast<double>(grid) *
                                                             view.height() / view.width()))));
    auto probe = prerender(test, layout);
    if (!probe.ok()) return probe.status();
    report->cuts_after = Recut(layout, *probe, rule_);
    for (const auto& w : probe->workers) report->test_ray_ms[w.id()] = w.cpu_ms();
    std::vector<std::string> times;
    for (const auto& c : RingCosts(*probe, layout.RingSizes())) {
      times.push_back(absl::StrJoin(c, " ", [](std::string* o, double x) {
        absl::StrAppend(o, absl::StrFormat("%.2f", x));
      }));
    }
    spdlog::info("{} balance ({}x{} test rays, rule {}): test-ray CPU ms [{}]; cuts {} -> {}",
                 report->job_id, test.width(), test.height(),
                 rule_ == BalanceRule::kPaper ? "paper" : "cost", absl::StrJoin(times, " | "),
                 FormatCuts(report->cuts_before), FormatCuts(report->cuts_after));
    layout.SetCuts(report->cuts_after, planes);
    memory.view_cuts[ViewKey(view)] = report->cuts_after;
    return absl::OkStatus();
  }

 private:
  const BalanceRule rule_;
  const int grid_;
};

// The largest share of a ring's frame its slowest worker spends beyond the
// mean, 1 - mean / max of its workers' tracer CPU: what perfect cuts
// would save of the frame.
double MaxImbalanceShare(const FrameResult& frame, const Layout& layout) {
  double share = 0;
  for (const auto& ring : RingCosts(frame, layout.RingSizes())) {
    if (ring.empty()) continue;
    double sum = 0, max = 0;
    for (double c : ring) sum += c, max = std::max(max, c);
    if (max > 0) share = std::max(share, 1 - sum / ring.size() / max);
  }
  return share;
}

// A re-cut must pay for itself within this many frames.
constexpr int kPaybackFrames = 3;

class PreviousFrame : public Balancer {
 public:
  explicit PreviousFrame(BalanceRule rule) : rule_(rule) {}

  absl::Status Plan(const v1::View&, BalanceMemory& memory, Layout& layout, const Prerender&,
                    BalanceReport* report) override {
    report->mode = v1::PREVIOUS_FRAME;
    if (!memory.next_cuts.empty()) layout.SetCuts(memory.next_cuts, Planes(layout));
    report->cuts_before = report->cuts_after = layout.Cuts();
    return absl::OkStatus();
  }
  bool LearnsFromProfiles() const override { return true; }
  void Learn(const FrameResult& frame, const Layout& layout, BalanceMemory& memory,
             BalanceReport* report) override {
    // What this frame's cut moves cost: the price of the next move.
    if (layout.planes_moved > 0) memory.recut_ms = layout.load_ms;
    // This frame's costs cut the slabs of the next one, when that pays: the
    // frame would have ended when its slowest worker's share of the work
    // was the mean share, and so should the next, much like it, if re-cut.
    // Re-cutting moves planes and rebuilds the slabs of the workers whose
    // cuts move (measured on cthead, 2 workers: about 200 ms, more than a
    // whole frame, for a move of one or two planes), so the slabs are
    // re-cut only when the time the next kPaybackFrames frames would gain
    // exceeds what the last move took. Until a move has been measured, the
    // first re-cut is made.
    const double gain_ms = frame.frame_ms * MaxImbalanceShare(frame, layout);
    const bool pays = memory.recut_ms < 0 || gain_ms * kPaybackFrames > memory.recut_ms;
    memory.next_cuts = pays ? Recut(layout, frame, rule_) : layout.Cuts();
    report->cuts_after = memory.next_cuts;
    if (!pays) {
      spdlog::debug("{} balance previous-frame: cuts kept (gain {:.1f} ms a frame, a re-cut took {:.0f} ms)",
                    report->job_id, gain_ms, memory.recut_ms);
    }
  }

 private:
  const BalanceRule rule_;
};

}  // namespace

void Balancer::Learn(const FrameResult&, const Layout& layout, BalanceMemory& memory,
                     BalanceReport*) {
  memory.next_cuts = layout.Cuts();
}

std::unique_ptr<Balancer> MakeBalancer(v1::BalanceMode mode, BalanceRule rule, int grid) {
  switch (mode) {
    case v1::TEST_RAYS:
      return std::make_unique<TestRays>(rule, grid);
    case v1::PREVIOUS_FRAME:
      return std::make_unique<PreviousFrame>(rule);
    default:
      return std::make_unique<Off>();
  }
}

std::string ViewKey(const v1::View& view) {
  v1::View k = view;
  k.clear_output();
  k.clear_balance();
  return k.SerializeAsString();
}

}  // namespace transtick
