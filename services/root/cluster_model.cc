#include "cluster_model.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace transtick {
namespace {

// Workers on one host pass rays and slabs through the kernel's loopback:
// about this fast through gRPC (bench/cluster_bench, slab loads).
constexpr double kLoopbackGbits = 16;
// A worker builds its slab (sticks, brick map) from the bytes it receives.
constexpr double kBuildMsPerMb = 2.0;
// Buffers of a running frame, beside the slab.
constexpr double kFrameBytes = 32.0 * (1 << 20);
// As the root's --rings.
constexpr int kMaxRings = 64;

double TransferMs(double bytes, double gbits) { return bytes * 8 / (gbits * 1e6); }

// The frame on `shape`, without the efficiency.
Prediction PredictFrame(const FrameCosts& c, const VolumeSize& v, const ClusterShape& s) {
  Prediction p;
  const int n_min = s.workers / s.rings;                  // the smallest ring's workers
  const int n_max = (s.workers + s.rings - 1) / s.rings;  // the largest ring's
  const int per_host = (s.workers + s.hosts - 1) / s.hosts;
  const double cores = std::min<double>(s.threads, s.cores_per_host / per_host);
  const bool spread = s.hosts > 1;
  const double ring_gbits = spread ? s.network.gbits : kLoopbackGbits;

  // Each ring traces 1/R of the image's rows, so a ring of n workers gives
  // each 1/(R n) of the work: the smallest ring's workers have the most. A
  // ring of one worker has no slabs to be uneven and no plane to forward
  // over; a worker inside a longer ring forwards over two planes, one at an
  // end over one. The slowest of the two ring sizes sets the frame.
  const double crossings = c.crossings_per_cut / s.rings;  // per plane of a ring
  auto worker_ms = [&](int n) {
    if (n <= 1) return c.tracer_cpu_ms / s.rings;
    return c.tracer_cpu_ms / (s.rings * n) * c.imbalance +
           std::min(2, n - 1) * crossings * c.forward_cpu_us / 1e3;
  };
  p.trace_ms = std::max(worker_ms(n_min), worker_ms(n_max)) / cores;

  // Ring neighbours are packed on hosts, so a host's link carries the planes
  // at the edges of its block of workers, in both directions, for every ring
  // that crosses it; full duplex, so one direction's half of each.
  p.bytes_per_link = n_max > 1 ? crossings * c.bytes_per_ray : 0;
  if (spread && n_max > 1) {
    const int blocks_per_ring = std::min(s.hosts, n_max);
    const double edges_per_host = std::min(2.0, 2.0 * (blocks_per_ring - 1) / blocks_per_ring);
    const double rings_per_host = std::max(1.0, double(s.rings) * blocks_per_ring / s.hosts);
    p.link_ms = TransferMs(p.bytes_per_link / 2 * edges_per_host * rings_per_host, s.network.gbits);
  }
  // Every worker streams its deposits to the display as it traces: they
  // all come in through the display's one link.
  p.deposit_ms = spread ? TransferMs(c.deposit_bytes, s.network.gbits) : 0;
  const double body_ms = std::max({p.trace_ms, p.link_ms, p.deposit_ms});

  // At the frame's end the last rays go hop by hop.
  const double hop_ms = (spread ? s.network.latency_ms : 0) + c.linger_ms;
  p.chain_ms = n_max > 1 ? c.chain_rings * (n_max - 1) * hop_ms : 0;

  const double latency = spread ? s.network.latency_ms : 0;
  p.fixed_ms = c.fixed_ms + c.rounds * 2 * latency + TransferMs(c.image_bytes, ring_gbits);
  p.frame_ms = body_ms + p.chain_ms + p.fixed_ms;

  p.hops_per_ray = c.rays > 0 ? c.crossings_per_cut * (n_max - 1) / c.rays : 0;
  const double slab = v.bytes / n_min + 2 * v.bytes / std::max(1, v.planes);  // and ghost planes
  p.memory_per_worker = 2 * slab + kFrameBytes;
  // The root sends each ring a whole copy, through its own link; the
  // workers build their slabs at once.
  const double sent = v.wire_bytes > 0 ? v.wire_bytes : v.bytes;
  p.load_ms = TransferMs(sent * s.rings, ring_gbits) + kBuildMsPerMb * slab / (1 << 20);
  return p;
}

}  // namespace

Prediction Predict(const FrameCosts& costs, const VolumeSize& volume, const ClusterShape& shape) {
  Prediction p = PredictFrame(costs, volume, shape);
  ClusterShape one = shape;
  one.workers = one.rings = one.hosts = 1;
  const double alone = PredictFrame(costs, volume, one).frame_ms;
  p.efficiency = p.frame_ms > 0 ? alone / (shape.workers * p.frame_ms) : 0;
  return p;
}

FrameCosts FrameCostsFrom(const std::vector<v1::WorkerFrameStats>& workers,
                          const FrameCosts& fallback) {
  FrameCosts c = fallback;
  double cpu = 0, rays = 0, sent = 0, bytes = 0, deposit_bytes = 0;
  // Per ring: workers, slowest and summed active time. Rings of unequal
  // sizes finish apart by their layout, which the model sees itself; the
  // imbalance is the slabs' within a ring.
  std::vector<int> ring_size;
  std::vector<double> max_active, sum_active;
  for (const v1::WorkerFrameStats& w : workers) {
    cpu += w.cpu_ms();
    rays += w.rays_traced();
    sent += w.rays_sent();
    bytes += w.bytes_sent();
    deposit_bytes += w.deposit_bytes();
    const size_t ring = static_cast<size_t>(std::max(0, w.ring()));
    if (ring_size.size() <= ring) {
      ring_size.resize(ring + 1);
      max_active.resize(ring + 1);
      sum_active.resize(ring + 1);
    }
    ++ring_size[ring];
    max_active[ring] = std::max(max_active[ring], w.active_ms());
    sum_active[ring] += w.active_ms();
  }
  int planes = 0;  // slab planes crossed: one fewer than a ring's workers
  for (int n : ring_size) planes += std::max(0, n - 1);
  if (cpu > 0) c.tracer_cpu_ms = cpu;
  if (rays > 0) {
    c.rays = rays;
    c.deposit_bytes = deposit_bytes > 0 ? deposit_bytes : rays * kAssumedDepositBytes;
  }
  // Rays crossing one plane of one ring, scaled to the whole image.
  if (planes > 0 && sent > 0) {
    c.crossings_per_cut = sent / planes * std::max<size_t>(1, ring_size.size());
    c.bytes_per_ray = bytes / sent;
  }
  double imbalance = 0;
  for (size_t r = 0; r < ring_size.size(); ++r) {
    if (ring_size[r] > 1 && sum_active[r] > 0) {
      imbalance = std::max(imbalance, max_active[r] / (sum_active[r] / ring_size[r]));
    }
  }
  if (imbalance > 0) c.imbalance = imbalance;
  return c;
}

FrameCosts DefaultFrameCosts(double pixels) {
  FrameCosts c;
  c.tracer_cpu_ms = pixels * 1e-3;  // 1 us a pixel
  c.rays = pixels * 3;
  c.crossings_per_cut = pixels * 0.6;
  c.deposit_bytes = c.rays * kAssumedDepositBytes;
  c.image_bytes = pixels * 4;
  return c;
}

FrameCosts ScaledCosts(FrameCosts c, double from_pixels, double to_pixels) {
  if (from_pixels <= 0) return c;
  const double k = to_pixels / from_pixels;
  c.tracer_cpu_ms *= k;
  c.rays *= k;
  c.crossings_per_cut *= k;
  c.deposit_bytes *= k;
  c.image_bytes *= k;
  return c;
}

absl::StatusOr<int> ParseRings(absl::string_view setting) {
  if (setting == "auto") return kAutoRings;
  int rings = 0;
  if (!absl::SimpleAtoi(setting, &rings) || rings < 1 || rings > kMaxRings) {
    return absl::InvalidArgumentError(absl::StrCat(
        "rings: '", setting, "' is neither auto nor a number of rings in [1, ", kMaxRings, "]"));
  }
  return rings;
}

RingChoice ChooseRings(const FrameCosts& costs, const VolumeSize& volume, ClusterShape shape,
                       int frames, double memory_per_worker, int loaded_rings) {
  RingChoice best;
  double best_ms = 0;
  bool found = false;
  std::string considered;
  for (int r = 1; r <= std::min(shape.workers, kMaxRings); ++r) {
    shape.rings = r;
    const Prediction p = Predict(costs, volume, shape);
    const bool fits = p.memory_per_worker <= memory_per_worker;
    const double load_ms = r == loaded_rings ? 0 : p.load_ms;  // held already
    const double job_ms = load_ms + std::max(1, frames) * p.frame_ms;
    absl::StrAppendFormat(&considered, "%s%d ring(s): %.0f ms (frame %.1f, load %.0f), %.0f MB%s",
                          considered.empty() ? "" : "; ", r, job_ms, p.frame_ms, load_ms,
                          p.memory_per_worker / (1 << 20), fits ? "" : " (does not fit)");
    if (fits && (!found || job_ms < best_ms * 0.98)) {
      found = true;
      best_ms = job_ms;
      best.rings = r;
      best.prediction = p;
    }
  }
  if (!found) {
    shape.rings = 1;
    best.rings = 1;
    best.prediction = Predict(costs, volume, shape);
    best.why = absl::StrFormat(
        "no layout fits %.0f MB per worker (1 ring needs %.0f MB); 1 ring. Considered: %s",
        memory_per_worker / (1 << 20), best.prediction.memory_per_worker / (1 << 20), considered);
    return best;
  }
  best.why = absl::StrFormat(
      "%d ring(s) of %d workers, for %d frame(s) with %.0f MB per worker. "
      "Considered: %s",
      best.rings, shape.workers, std::max(1, frames), memory_per_worker / (1 << 20), considered);
  return best;
}

Sites SitesOf(const std::vector<WorkerSite>& workers) {
  auto host_of = [](const std::string& address) { return address.substr(0, address.rfind(':')); };
  std::map<std::string, int> on_host, on_machine, machine_cpus;
  std::vector<std::string> machine_of;
  for (const WorkerSite& w : workers) {
    ++on_host[host_of(w.address)];
    const std::string& m =
        machine_of.emplace_back(w.machine.empty() ? "host " + host_of(w.address) : w.machine);
    ++on_machine[m];
    machine_cpus[m] = std::max(machine_cpus[m], w.machine_cpus);
  }
  Sites out;
  out.machines = static_cast<int>(on_machine.size());
  out.memory_per_worker = std::numeric_limits<double>::infinity();
  double cores = std::numeric_limits<double>::infinity();
  int threads = 1 << 20;
  for (size_t i = 0; i < workers.size(); ++i) {
    const WorkerSite& w = workers[i];
    const int sharing = on_machine[machine_of[i]];
    double c = std::max(1, w.threads);
    if (w.cpus > 0) c = std::min(c, w.cpus);
    if (const int m = machine_cpus[machine_of[i]]; m > 0) c = std::min(c, double(m) / sharing);
    cores = std::min(cores, c);
    threads = std::min(threads, std::max(1, w.threads));
    if (w.memory_bytes > 0) {
      out.memory_per_worker =
          std::min(out.memory_per_worker, double(w.memory_bytes) / (w.memory_shared ? sharing : 1));
    }
  }
  ClusterShape& shape = out.shape;
  shape.workers = static_cast<int>(workers.size());
  shape.hosts = static_cast<int>(on_host.size());
  shape.threads = threads;
  // PredictFrame gives a worker cores_per_host / (workers a host): so that
  // it gets `cores`.
  const int per_host = (shape.workers + shape.hosts - 1) / shape.hosts;
  shape.cores_per_host = cores * per_host;
  out.why = absl::StrFormat("%d worker(s) on %d host(s) and %d machine(s), %.3g core(s) a worker",
                            shape.workers, shape.hosts, out.machines, cores);
  return out;
}

}  // namespace transtick
