// The cluster model (services/root/cluster_model.h, docs/cluster-model.md)
// calibrated on emulated runs, checked against them, and extrapolated.
//
// Usage: cluster_model POINTS.jsonl [--cores N] [--bytes-per-voxel B]
//   POINTS.jsonl: bench/emulated_hosts.sh --json (one point per line, each
//   daemon on its own emulated host, all sharing this machine's N cores).
//
// 1. Costs: each point's own tracing (the workers' summed tracer CPU, their
//    imbalance), rays and rays crossing a slab plane, as the model takes them
//    (measured per-slab costs); the network is what it predicts.
// 2. Fit: the model's three free constants (fixed cost of a frame, CPU to
//    forward a ray, ring lengths of the final chain) by least squares of the
//    relative error over the points; prints measured and predicted frame
//    times, the error of each, the RMS error, and the RMS error of each
//    point predicted by a fit without it (leave one out).
// 3. Rings: for each number of workers in the points, the rings the model
//    picks for a long job against the fastest measured.
// 4. Extrapolation with the fitted constants, costs scaled to the volume and
//    image: the paper's Table 2 case (388x388x464, 8, 32, 128 workers) and a
//    1024^3 float volume on a rack of 16 hosts with 1 and 10 Gbit/s links.
#include "cluster_model.h"

#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <string>
#include <vector>

namespace transtick {
namespace {

struct Point {
  int workers = 1, rings = 1;
  bool automatic = false;  // the root's --rings auto chose `rings`
  double latency_ms = 0, gbit = 0;
  double frame_ms = 0;       // measured, median
  double tracer_cpu_ms = 0;  // per frame, summed over workers
  double rays = 0;           // per frame
  double deposit_bytes = 0;  // per frame, packed, to the display
  double crossings = 0;      // rays over one slab plane of a ring, per frame, mean
  double imbalance = 0;
  double pixels = 0;
};

double Number(const google::protobuf::Struct& s, const std::string& key) {
  auto it = s.fields().find(key);
  return it == s.fields().end() ? 0 : it->second.number_value();
}

std::vector<Point> Read(const std::string& path) {
  std::vector<Point> points;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) {
    if (line.empty()) continue;
    google::protobuf::Struct s;
    if (!google::protobuf::util::JsonStringToMessage(line, &s).ok()) {
      std::fprintf(stderr, "cluster_model: %s: a line is not JSON\n", path.c_str());
      std::exit(2);
    }
    Point p;
    p.workers = static_cast<int>(Number(s, "workers"));
    p.rings = static_cast<int>(Number(s, "rings"));
    p.latency_ms = Number(s, "latency_ms");
    if (auto it = s.fields().find("auto"); it != s.fields().end()) {
      p.automatic = it->second.bool_value();
    }
    p.gbit = Number(s, "gbit");
    p.frame_ms = Number(s, "frame_ms_median");
    p.tracer_cpu_ms = Number(s, "tracer_cpu_ms");
    const double frames = std::max(1.0, Number(s, "frames"));
    p.rays = Number(s, "rays_traced") / frames;
    // Points of a sweep from before packed deposits have no bytes: those
    // assumed.
    p.deposit_bytes = Number(s, "deposit_bytes") / frames;
    if (!(p.deposit_bytes > 0)) p.deposit_bytes = p.rays * kAssumedDepositBytes;
    p.imbalance = Number(s, "active_imbalance");
    p.pixels = Number(s, "pixels");
    const auto& links = s.fields().find("links");
    double sum = 0;
    int n = 0;
    if (links != s.fields().end()) {
      for (const auto& l : links->second.list_value().values()) {
        sum += Number(l.struct_value(), "rays") / frames;
        ++n;
      }
    }
    p.crossings = n > 0 ? sum / n : 0;
    if (p.workers < 1 || p.rings < 1 || p.frame_ms <= 0 || p.tracer_cpu_ms <= 0) {
      std::fprintf(stderr,
                   "cluster_model: %s: a point lacks workers, rings, frame_ms_median or "
                   "tracer_cpu_ms (an older bench/emulated_hosts.sh?)\n",
                   path.c_str());
      std::exit(2);
    }
    points.push_back(p);
  }
  if (points.empty()) {
    std::fprintf(stderr, "cluster_model: no points in %s\n", path.c_str());
    std::exit(2);
  }
  return points;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : (v[v.size() / 2 - 1] + v[v.size() / 2]) / 2;
}

// What the points share: a frame's work and rays, whatever the cluster.
FrameCosts SharedCosts(const std::vector<Point>& points) {
  std::vector<double> cpu, rays, deposit_bytes, crossings, imbalance;
  for (const Point& p : points) {
    cpu.push_back(p.tracer_cpu_ms);
    rays.push_back(p.rays);
    deposit_bytes.push_back(p.deposit_bytes);
    // Per plane of one ring, for the whole image: a ring of R traces 1/R.
    if (p.crossings > 0) crossings.push_back(p.crossings * p.rings);
    if (p.workers > 1) imbalance.push_back(p.imbalance);
  }
  FrameCosts c;
  c.tracer_cpu_ms = Median(cpu);
  c.rays = Median(rays);
  c.crossings_per_cut = Median(crossings);
  c.imbalance = imbalance.empty() ? 1 : Median(imbalance);
  c.deposit_bytes = Median(deposit_bytes);
  c.image_bytes = points[0].pixels * 4;
  return c;
}

// The point's own measured costs, with the shared ones where it has none
// (a single ring-less point crosses no plane).
FrameCosts CostsOf(const Point& p, const FrameCosts& shared) {
  FrameCosts c = shared;
  c.tracer_cpu_ms = p.tracer_cpu_ms;
  c.rays = p.rays;
  c.deposit_bytes = p.deposit_bytes;
  if (p.crossings > 0) c.crossings_per_cut = p.crossings * p.rings;
  c.imbalance = p.workers > 1 && p.imbalance > 0 ? p.imbalance : 1;
  return c;
}

ClusterShape ShapeOf(const Point& p, double cores) {
  ClusterShape s;
  s.workers = p.workers;
  s.rings = p.rings;
  s.hosts = p.workers;  // each daemon its own namespace
  s.threads = 1;
  // The emulated hosts share this machine's cores (the root and display
  // take little).
  s.cores_per_host = std::max(cores / p.workers, 0.01);
  s.network = {p.latency_ms, p.gbit > 0 ? p.gbit : 100};
  return s;
}

struct Fit {
  double fixed_ms = 0, forward_us = 0, chain = 0;
  double rms = 0;
};

FrameCosts WithFit(FrameCosts c, const Fit& f) {
  c.fixed_ms = f.fixed_ms;
  c.forward_cpu_us = f.forward_us;
  c.chain_rings = f.chain;
  return c;
}

double RelativeError(const FrameCosts& shared, const Point& p, double cores) {
  const double predicted = Predict(CostsOf(p, shared), {1, 1}, ShapeOf(p, cores)).frame_ms;
  return predicted / p.frame_ms - 1;
}

// Least squares of the relative error over `points`, skipping `skip`, on a
// grid fine enough for the noise of a shared machine.
Fit FitConstants(const FrameCosts& base, const std::vector<Point>& points, double cores,
                 int skip = -1) {
  Fit best;
  best.rms = INFINITY;
  for (double fixed = 0; fixed <= 120; fixed += 2) {
    for (double fwd = 0; fwd <= 12; fwd += 0.25) {
      for (double chain = 0; chain <= 8; chain += 0.5) {
        const Fit f{fixed, fwd, chain, 0};
        const FrameCosts c = WithFit(base, f);
        double sum = 0;
        int n = 0;
        for (size_t i = 0; i < points.size(); ++i) {
          if (int(i) == skip) continue;
          const double e = RelativeError(c, points[i], cores);
          sum += e * e;
          ++n;
        }
        const double rms = std::sqrt(sum / std::max(1, n));
        if (rms < best.rms) best = {fixed, fwd, chain, rms};
      }
    }
  }
  return best;
}

void Extrapolate(const char* title, const FrameCosts& c, const VolumeSize& v, ClusterShape shape,
                 const std::vector<int>& workers, const std::vector<double>& gbits, int frames) {
  std::printf("\n%s\n", title);
  std::printf("%8s %6s %5s %10s %10s %10s %10s %9s %7s %10s %7s\n", "workers", "Gbit", "rings",
              "frame_ms", "trace_ms", "link_ms", "deposit_ms", "chain_ms", "effic", "MB/worker",
              "hops");
  for (double g : gbits) {
    for (int w : workers) {
      shape.workers = w;
      shape.hosts = w;
      shape.network.gbits = g;
      for (int r : {1, 2, 4}) {
        if (r > w) continue;
        shape.rings = r;
        const Prediction p = Predict(c, v, shape);
        std::printf("%8d %6g %5d %10.1f %10.1f %10.1f %10.1f %9.1f %7.2f %10.0f %7.2f\n", w, g, r,
                    p.frame_ms, p.trace_ms, p.link_ms, p.deposit_ms, p.chain_ms, p.efficiency,
                    p.memory_per_worker / (1 << 20), p.hops_per_ray);
      }
      const RingChoice auto_choice = ChooseRings(c, v, shape, frames, 64.0 * (1 << 30));
      std::printf("%8d %6g  auto: %d ring(s) for %d frames with 64 GB a host\n", w, g,
                  auto_choice.rings, frames);
    }
  }
}

int Main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: cluster_model POINTS.jsonl [--cores N] [--bytes-per-voxel B]\n");
    return 2;
  }
  double cores = 2, bytes_per_voxel = 5.5;  // cthead's scene: 40.7 MB for 256x256x113
  for (int i = 2; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    if (flag == "--cores") {
      cores = std::atof(argv[i + 1]);
    } else if (flag == "--bytes-per-voxel") {
      bytes_per_voxel = std::atof(argv[i + 1]);
    } else {
      std::fprintf(stderr, "cluster_model: unknown flag %s\n", flag.c_str());
      return 2;
    }
  }
  std::vector<Point> points, automatic;
  for (const Point& p : Read(argv[1])) (p.automatic ? automatic : points).push_back(p);
  if (points.empty()) {
    std::fprintf(stderr, "cluster_model: no fixed-rings points to fit\n");
    return 2;
  }
  const FrameCosts base = SharedCosts(points);
  std::printf(
      "costs of a frame (%.0f pixels), medians over %zu points (each point is "
      "predicted from its own): tracer CPU %.1f ms, "
      "%.0f rays, %.0f rays over a slab plane, imbalance %.2f\n",
      points[0].pixels, points.size(), base.tracer_cpu_ms, base.rays, base.crossings_per_cut,
      base.imbalance);

  const Fit fit = FitConstants(base, points, cores);
  const FrameCosts fitted = WithFit(base, fit);
  std::printf(
      "fit: fixed %.0f ms a frame, forwarding %.2f us a ray, final chain %.1f ring "
      "lengths; RMS relative error %.1f%%\n",
      fit.fixed_ms, fit.forward_us, fit.chain, 100 * fit.rms);
  std::printf("\n%2s %2s %6s %5s %10s %10s %7s %10s\n", "W", "R", "lat_ms", "Gbit", "measured",
              "predicted", "error", "held out");
  double held_sum = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    const Point& p = points[i];
    const double e = RelativeError(fitted, p, cores);
    const Fit without = FitConstants(base, points, cores, static_cast<int>(i));
    const double held = RelativeError(WithFit(base, without), p, cores);
    held_sum += held * held;
    std::printf("%2d %2d %6g %5g %10.1f %10.1f %+6.1f%% %+9.1f%%\n", p.workers, p.rings,
                p.latency_ms, p.gbit, p.frame_ms, p.frame_ms * (1 + e), 100 * e, 100 * held);
  }
  std::printf("RMS error of each point predicted without it: %.1f%%\n",
              100 * std::sqrt(held_sum / points.size()));

  // The model's rings against the fastest measured, per workers and link.
  std::map<std::tuple<int, double, double>, std::vector<const Point*>> groups;
  for (const Point& p : points) groups[{p.workers, p.latency_ms, p.gbit}].push_back(&p);
  // The root's own choice (--rings auto) against the fixed layouts.
  for (const Point& a : automatic) {
    const Point* fastest = nullptr;
    for (const Point& p : points) {
      if (p.workers != a.workers || p.latency_ms != a.latency_ms || p.gbit != a.gbit) continue;
      if (!fastest || p.frame_ms < fastest->frame_ms) fastest = &p;
    }
    std::printf("--rings auto, %d workers, %g ms, %g Gbit/s: the root formed %d ring(s), %.1f ms",
                a.workers, a.latency_ms, a.gbit, a.rings, a.frame_ms);
    if (fastest) {
      std::printf("; fastest fixed %d ring(s), %.1f ms (%+.1f%%)", fastest->rings,
                  fastest->frame_ms, 100 * (a.frame_ms / fastest->frame_ms - 1));
    }
    std::printf("\n");
  }
  std::printf("\nrings for a 1000-frame job, model against measured:\n");
  for (const auto& [key, ps] : groups) {
    if (ps.size() < 2) continue;
    const Point* fastest =
        *std::min_element(ps.begin(), ps.end(),
                          [](const Point* a, const Point* b) { return a->frame_ms < b->frame_ms; });
    const RingChoice choice =
        ChooseRings(CostsOf(*ps[0], fitted), {1, 1}, ShapeOf(*ps[0], cores), 1000, INFINITY);
    const Point* picked = nullptr;
    for (const Point* p : ps) picked = p->rings == choice.rings ? p : picked;
    std::printf(
        "  %d workers, %g ms, %g Gbit/s: model %d ring(s)%s, fastest measured %d "
        "(%.1f ms)\n",
        std::get<0>(key), std::get<1>(key), std::get<2>(key), choice.rings,
        picked ? (" (" + std::to_string(int(picked->frame_ms + 0.5)) + " ms)").c_str()
               : " (not measured)",
        fastest->rings, fastest->frame_ms);
  }

  // Extrapolation: per pixel and per voxel of depth, as measured here, the
  // tracing as one worker alone did it (no sharing of cores).
  FrameCosts alone = fitted;
  for (const Point& p : points) {
    if (p.workers == 1) alone.tracer_cpu_ms = p.tracer_cpu_ms;
  }
  std::printf(
      "\nextrapolated from: tracer CPU %.1f ms a frame of %.0f pixels, %.0f rays over "
      "a plane, imbalance %.2f, and the fit\n",
      alone.tracer_cpu_ms, points[0].pixels, alone.crossings_per_cut, alone.imbalance);
  const double cthead_depth = 256;
  auto scaled = [&](double pixels, double depth) {
    FrameCosts c = ScaledCosts(alone, points[0].pixels, pixels);
    c.tracer_cpu_ms *= depth / cthead_depth;  // a ray's steps grow with the volume's depth
    return c;
  };
  ClusterShape host;
  host.cores_per_host = 8;
  host.threads = 8;
  host.network.latency_ms = 0.05;
  {
    const FrameCosts c = scaled(512.0 * 512, 464);
    const VolumeSize v{388.0 * 388 * 464 * bytes_per_voxel, 388};
    Extrapolate(
        "the paper's Table 2 case: 388x388x464, 512x512, one worker of 8 cores a host, "
        "0.05 ms links",
        c, v, host, {1, 8, 32, 128}, {1, 10}, 1000);
  }
  {
    const FrameCosts c = scaled(1024.0 * 1024, 1024);
    const VolumeSize v{1024.0 * 1024 * 1024 * bytes_per_voxel, 1024};
    host.cores_per_host = host.threads = 32;
    Extrapolate("a 1024^3 float volume, 1024x1024, a rack of 16 hosts of 32 cores, 0.05 ms links",
                c, v, host, {1, 16}, {1, 10}, 360);
  }
  return 0;
}

}  // namespace
}  // namespace transtick

int main(int argc, char** argv) { return transtick::Main(argc, argv); }
