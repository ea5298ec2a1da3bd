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

// Times per ring and worker, ring after ring, for the log.
std::string FormatTimes(const std::vector<std::vector<double>>& ring_times,
                        const absl::FormatSpec<double>& format) {
  std::vector<std::string> times;
  for (const auto& c : ring_times) {
    times.push_back(absl::StrJoin(
        c, " ", [&](std::string* o, double x) { absl::StrAppend(o, absl::StrFormat(format, x)); }));
  }
  return absl::StrJoin(times, " | ");
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

// Whether every worker of a ring sent its profile.
bool Profiled(const std::vector<std::vector<double>>& ring_profiles) {
  for (const auto& p : ring_profiles) {
    if (p.empty()) return false;
  }
  return true;
}

// Where a slab's cost comes from under the cost rule: its work profile's
// total (counted: the same rays give the same cuts on a busy machine), or
// its tracers' measured CPU time, spread over its planes by the profile.
enum class Costs { kProfile, kMeasured };

// New cuts for every ring from each slab's cost (per ring and worker) and
// the profiles to spread it over the slab's planes by.
std::vector<std::vector<int>> Recut(const Layout& layout, std::vector<std::vector<double>> costs,
                                    const std::vector<std::vector<std::vector<double>>>& profiles,
                                    BalanceRule rule, Costs from) {
  if (rule == BalanceRule::kCost) {
    // A ring some of whose workers sent no profile keeps its CPU times; one
    // some of whose workers sent no CPU time (they failed to report) its
    // profile's totals.
    for (size_t r = 0; r < costs.size(); ++r) {
      bool timed = true;
      for (double c : costs[r]) timed = timed && c > 0;
      if (!Profiled(profiles[r]) || (from == Costs::kMeasured && timed)) continue;
      for (size_t i = 0; i < costs[r].size(); ++i) {
        double work = 0;
        for (double w : profiles[r][i]) work += w;
        costs[r][i] = work;
      }
    }
  }
  std::vector<std::vector<int>> cuts;
  for (size_t r = 0; r < costs.size(); ++r) {
    cuts.push_back(BalancedCuts(layout.rings[r].cuts, costs[r], rule, profiles[r]));
  }
  return cuts;
}

// The same from a frame's statistics alone.
std::vector<std::vector<int>> Recut(const Layout& layout, const FrameResult& frame,
                                    BalanceRule rule, Costs from) {
  const auto sizes = layout.RingSizes();
  return Recut(layout, RingCosts(frame, sizes), RingProfiles(frame, sizes), rule, from);
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

// The largest share of a ring's frame its slowest worker spends beyond the
// mean, 1 - mean / max of its workers' tracer CPU: what perfect cuts
// would save of the frame.
double MaxShare(const std::vector<std::vector<double>>& ring_costs) {
  double share = 0;
  for (const auto& ring : ring_costs) {
    if (ring.empty()) continue;
    double sum = 0, max = 0;
    for (double c : ring) sum += c, max = std::max(max, c);
    if (max > 0) share = std::max(share, 1 - sum / ring.size() / max);
  }
  return share;
}

double MaxImbalanceShare(const FrameResult& frame, const Layout& layout) {
  return MaxShare(RingCosts(frame, layout.RingSizes()));
}

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
    report->cuts_after = Recut(layout, *probe, rule_, Costs::kProfile);
    // The profile, plane by plane, for refining the cuts from the view's
    // frames (Learn): whole, or not at all.
    const std::string key = ViewKey(view);
    std::vector<std::vector<double>> per_plane;
    for (const auto& ring : RingProfiles(*probe, layout.RingSizes())) {
      std::vector<double> planes_work;
      for (const auto& p : ring) planes_work.insert(planes_work.end(), p.begin(), p.end());
      if (static_cast<int>(planes_work.size()) != planes) {
        per_plane.clear();
        break;
      }
      per_plane.push_back(std::move(planes_work));
    }
    if (per_plane.empty()) {
      memory.view_profiles.erase(key);
    } else {
      memory.view_profiles[key] = std::move(per_plane);
    }
    memory.view_costs.erase(key);
    for (const auto& w : probe->workers) report->test_ray_ms[w.id()] = w.cpu_ms();
    spdlog::info("{} balance ({}x{} test rays, rule {}): test-ray CPU ms [{}]; cuts {} -> {}",
                 report->job_id, test.width(), test.height(),
                 rule_ == BalanceRule::kPaper ? "paper" : "cost",
                 FormatTimes(RingCosts(*probe, layout.RingSizes()), "%.2f"),
                 FormatCuts(report->cuts_before), FormatCuts(report->cuts_after));
    layout.SetCuts(report->cuts_after, planes);
    memory.view_cuts[key] = report->cuts_after;
    // At most kMaxBalancedViews views remembered, the oldest forgotten
    // first: a service that renders ever new views (a session's camera,
    // say) keeps a bounded memory, and a view forgotten costs a prerender
    // again.
    memory.view_order.push_back(key);
    while (memory.view_order.size() > kMaxBalancedViews) {
      const std::string& oldest = memory.view_order.front();
      memory.view_cuts.erase(oldest);
      memory.view_profiles.erase(oldest);
      memory.view_costs.erase(oldest);
      memory.view_order.pop_front();
    }
    return absl::OkStatus();
  }

  // Refined by measured frames: the test rays' profile is counted, and
  // the kinds of work it counts cost a little more or less in some slabs
  // than its weights say (docs/balancing.md). The view's frames measure
  // what each slab really costs. Once the time they have lost to imbalance
  // since the view's cuts were set (their summed frame time, times the
  // share perfect cuts would save by their summed CPU times) exceeds what a
  // move of planes costs (rent or buy: never more spent on moves than
  // imbalance has cost), the cuts are re-cut from the summed CPU times,
  // each slab's spread over its planes by the prerender's profile.
  void Learn(const v1::View& view, const FrameResult& frame, const Layout& layout,
             BalanceMemory& memory, BalanceReport* report) override {
    memory.next_cuts = layout.Cuts();
    if (layout.planes_moved > 0) memory.recut_ms = layout.load_ms;
    const std::string key = ViewKey(view);
    const auto profile = memory.view_profiles.find(key);
    const auto cached = memory.view_cuts.find(key);
    if (profile == memory.view_profiles.end() || cached == memory.view_cuts.end() ||
        cached->second != layout.Cuts() || profile->second.size() != layout.rings.size()) {
      return;
    }
    // Only frames every worker reported on, with a time that is one (a
    // worker's report is not trusted to be finite), count.
    const auto costs = RingCosts(frame, layout.RingSizes());
    for (const auto& ring : costs) {
      for (double c : ring) {
        if (!(c > 0 && std::isfinite(c))) return;
      }
    }
    ViewCosts& measured = memory.view_costs[key];
    if (measured.cpu_ms.size() != costs.size()) {
      measured = ViewCosts{std::vector<std::vector<double>>(costs.size()), 0, 0};
    }
    for (size_t r = 0; r < costs.size(); ++r) {
      measured.cpu_ms[r].resize(costs[r].size(), 0.0);
      for (size_t i = 0; i < costs[r].size(); ++i) measured.cpu_ms[r][i] += costs[r][i];
    }
    measured.frame_ms += frame.frame_ms;
    ++measured.frames;
    // The loss from the summed times: what is noise in one frame's times
    // averages out over several, and a view already balanced stops adding
    // to it.
    if (memory.recut_ms >= 0 && measured.frame_ms * MaxShare(measured.cpu_ms) <= memory.recut_ms) {
      return;
    }
    std::vector<std::vector<std::vector<double>>> shapes(layout.rings.size());
    for (size_t r = 0; r < layout.rings.size(); ++r) {
      const std::vector<int>& cuts = layout.rings[r].cuts;
      const std::vector<double>& planes_work = profile->second[r];
      for (size_t i = 0; i + 1 < cuts.size(); ++i) {
        shapes[r].emplace_back(planes_work.begin() + cuts[i], planes_work.begin() + cuts[i + 1]);
      }
    }
    const auto refined = Recut(layout, measured.cpu_ms, shapes, rule_, Costs::kMeasured);
    const int frames = measured.frames;
    const ViewCosts summed = std::move(measured);
    memory.view_costs.erase(key);
    if (refined == layout.Cuts()) return;
    auto mean = summed.cpu_ms;
    for (auto& ring : mean) {
      for (double& ms : ring) ms /= frames;
    }
    spdlog::info("{} balance refined from {} frames' tracer CPU ms [{}] a frame: cuts {} -> {}",
                 report->job_id, frames, FormatTimes(mean, "%.1f"), FormatCuts(layout.Cuts()),
                 FormatCuts(refined));
    memory.view_cuts[key] = refined;
  }

 private:
  const BalanceRule rule_;
  const int grid_;
};

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
  void Learn(const v1::View&, const FrameResult& frame, const Layout& layout, BalanceMemory& memory,
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
    Calibrate(frame, layout, memory);
    const double gain_ms = frame.frame_ms * MaxImbalanceShare(frame, layout);
    const bool pays = memory.recut_ms < 0 || gain_ms * kPaybackFrames > memory.recut_ms;
    memory.next_cuts = pays ? CalibratedCuts(frame, layout, memory) : layout.Cuts();
    report->cuts_after = memory.next_cuts;
    if (!pays) {
      spdlog::debug("{} balance previous-frame: cuts kept (gain {:.1f} ms a frame, a re-cut took {:.0f} ms)",
                    report->job_id, gain_ms, memory.recut_ms);
    }
  }

 private:
  // How far one frame moves the calibration: halfway. A frame's times on
  // a shared machine scatter by 5-10% a worker (docs/balancing.md), about
  // as much as the profile errs in its dearest slabs.
  static constexpr double kCalibrationStep = 0.5;

  // Each plane's calibration: how much more or less than its profile says
  // its work has cost, from the slab it was in, per frame the measured
  // share of the ring's CPU time over the profile's share, averaged over
  // the frames (each moves it kCalibrationStep of the way). A ring with a
  // worker that sent no profile or no time is left as it was.
  void Calibrate(const FrameResult& frame, const Layout& layout, BalanceMemory& memory) const {
    const auto sizes = layout.RingSizes();
    const auto costs = RingCosts(frame, sizes);
    const auto profiles = RingProfiles(frame, sizes);
    if (memory.plane_scale.size() != sizes.size()) memory.plane_scale.assign(sizes.size(), {});
    for (size_t r = 0; r < sizes.size(); ++r) {
      const std::vector<int>& cuts = layout.rings[r].cuts;
      std::vector<double>& scale = memory.plane_scale[r];
      if (scale.size() != static_cast<size_t>(cuts.back())) scale.assign(cuts.back(), 1.0);
      double cpu = 0, work = 0;
      std::vector<double> totals;
      bool usable = true;
      for (size_t i = 0; i < costs[r].size(); ++i) {
        usable = usable && costs[r][i] > 0 && std::isfinite(costs[r][i]) && !profiles[r][i].empty();
        double t = 0;
        for (double w : profiles[r][i]) t += w;
        totals.push_back(t);
        cpu += costs[r][i];
        work += t;
      }
      if (!usable || !(work > 0) || !std::isfinite(cpu)) continue;
      for (size_t i = 0; i < totals.size(); ++i) {
        if (!(totals[i] > 0)) continue;
        const double ratio = (costs[r][i] / cpu) / (totals[i] / work);
        for (int p = cuts[i]; p < cuts[i + 1]; ++p) {
          scale[p] += kCalibrationStep * (ratio - scale[p]);
        }
      }
    }
  }

  // The cuts of the frame's profile with each plane's calibration: each
  // slab's cost its calibrated profile's total. A ring without a
  // calibration, or whose workers did not all send a profile, is cut by
  // the frame's measured times (Recut).
  std::vector<std::vector<int>> CalibratedCuts(const FrameResult& frame, const Layout& layout,
                                               const BalanceMemory& memory) const {
    std::vector<std::vector<int>> cuts = Recut(layout, frame, rule_, Costs::kMeasured);
    if (rule_ != BalanceRule::kCost) return cuts;
    auto profiles = RingProfiles(frame, layout.RingSizes());
    for (size_t r = 0; r < profiles.size(); ++r) {
      const std::vector<int>& ring_cuts = layout.rings[r].cuts;
      if (r >= memory.plane_scale.size() ||
          memory.plane_scale[r].size() != static_cast<size_t>(ring_cuts.back())) {
        continue;
      }
      if (!Profiled(profiles[r])) continue;
      std::vector<double> costs;
      for (size_t i = 0; i < profiles[r].size(); ++i) {
        double total = 0;
        for (size_t k = 0; k < profiles[r][i].size(); ++k) {
          profiles[r][i][k] *= memory.plane_scale[r][ring_cuts[i] + k];
          total += profiles[r][i][k];
        }
        costs.push_back(total);
      }
      cuts[r] = BalancedCuts(ring_cuts, costs, rule_, profiles[r]);
    }
    return cuts;
  }

  const BalanceRule rule_;
};

}  // namespace

void Balancer::Learn(const v1::View&, const FrameResult&, const Layout& layout,
                     BalanceMemory& memory, BalanceReport*) {
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
