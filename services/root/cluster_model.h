// A model of one frame on the cluster (docs/cluster-model.md): from what a
// frame costs (tracing CPU, rays crossing a slab plane, bytes per ray) and
// what the cluster is (workers, rings, hosts, cores, links), the frame's
// time, the parts it is made of, and the memory each worker needs. The root
// picks the number of rings with it (`--rings auto`); bench/cluster_model
// prints its tables. Pure functions.
#ifndef TRANSTICK_SERVICES_ROOT_CLUSTER_MODEL_H_
#define TRANSTICK_SERVICES_ROOT_CLUSTER_MODEL_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "cluster.pb.h"

namespace transtick {

// A deposit's packed bytes to the display when no frame has shown them
// (docs/formats.md, "Packed deposits"): 7.1-7.9 measured on cthead at
// 400x400 on 1-4 workers, where many pixels are black; a pixel record of a
// lit surface takes about 19 for its 2 deposits.
inline constexpr double kAssumedDepositBytes = 10;

// What one frame of a view costs, whatever the cluster: measured on a
// frame (FrameCostsFrom) or assumed (DefaultFrameCosts). The constants no
// frame shows are as fitted on emulated hosts (docs/cluster-model.md).
struct FrameCosts {
  double tracer_cpu_ms = 0;      // the tracers' CPU for the whole image, summed
  double rays = 0;               // rays traced, all kinds
  double crossings_per_cut = 0;  // rays crossing one slab plane, both ways, whole image
  double bytes_per_ray = 52;     // on the wire: a packed ray and its share of the framing
  double forward_cpu_us = 0.25;  // CPU to send and to receive one ray, both ends summed
  double imbalance = 1.1;        // a ring's slowest worker's tracing over its mean
  double fixed_ms = 28;          // a frame's start, end and image at no latency
  double rounds = 2;             // root-worker and worker-display round trips in series
  double deposit_bytes = 0;      // to the display while the frame runs, packed
  double image_bytes = 0;        // the image on to the root, after the last deposit
  double linger_ms = 1;          // a batch's wait for more rays (FrameOptions::linger)
  // The frame's critical chain: a ray crossing the whole ring and a shadow
  // ray crossing back, each hop a link's latency plus a batch's linger,
  // this many ring lengths of them (fitted on the emulated runs).
  double chain_rings = 0;
};

// The network between hosts: one-way latency and each host's bandwidth
// (full duplex). Workers on one host reach each other without it.
struct Network {
  double latency_ms = 0.05;
  double gbits = 10;
};

struct ClusterShape {
  int workers = 1;
  int rings = 1;
  int hosts = 1;              // workers spread evenly, a ring's neighbours on one host first
  double cores_per_host = 2;  // cores a host gives its workers (fractions: shared)
  int threads = 2;            // tracer threads per worker
  Network network;
};

// The classified volume as the workers hold it.
struct VolumeSize {
  double bytes = 0;  // sticks, scalars and brick map of all planes
  int planes = 1;    // along Y, the axis of the slabs
  // What loading all planes sends, scalars in their coding (docs/formats.md,
  // "Slab scalars"); 0: `bytes`.
  double wire_bytes = 0;
};

struct Prediction {
  double frame_ms = 0;
  double trace_ms = 0;    // the slowest worker's tracing and forwarding, wall
  double link_ms = 0;     // the busiest host link's transfer time (overlaps tracing)
  double deposit_ms = 0;  // the deposits into the display's link (overlaps tracing)
  double chain_ms = 0;    // hops in series at the frame's end
  double fixed_ms = 0;    // start, end and image, with their round trips
  double load_ms = 0;     // sending every worker its slab from the root
  double hops_per_ray = 0;
  double bytes_per_link = 0;     // on one slab plane of a ring, per frame
  double memory_per_worker = 0;  // bytes: the largest slab, twice while it is re-cut
  double efficiency = 0;         // one worker's frame time / (workers x this one)
};

// REQUIRES: shape.workers >= shape.rings >= 1, hosts >= 1.
Prediction Predict(const FrameCosts& costs, const VolumeSize& volume, const ClusterShape& shape);

// The costs of a frame from its workers' statistics, measured on the
// cluster; `fallback` for what they do not show (no plane crossed, no CPU
// measured).
FrameCosts FrameCostsFrom(const std::vector<v1::WorkerFrameStats>& workers,
                          const FrameCosts& fallback);

// The costs assumed for a frame of `pixels` before any was measured on the
// dataset: per pixel, about what a head at 45 degrees with shadows costs.
FrameCosts DefaultFrameCosts(double pixels);
// `costs` measured on a frame of `from_pixels`, for a frame of `to_pixels`:
// what grows with the image scaled (tracing, rays, crossings, deposits).
FrameCosts ScaledCosts(FrameCosts costs, double from_pixels, double to_pixels);

// A ring setting ("auto", or a number 1 .. 64): kAutoRings for "auto".
constexpr int kAutoRings = 0;
absl::StatusOr<int> ParseRings(absl::string_view setting);

struct RingChoice {
  int rings = 1;
  Prediction prediction;
  std::string why;  // every layout considered, for the log
};

// The number of rings for a job of `frames` frames on `shape` (its `rings`
// ignored): the one with the least predicted time for the job, slabs sent
// once and every frame, among those whose largest slab fits in
// `memory_per_worker` bytes; fewer rings on a tie within 2%. The workers
// already hold the slabs of `loaded_rings` rings (0: none), which then cost
// no loading. When none fits, 1 ring (the smallest slabs) and a `why` that
// says so.
RingChoice ChooseRings(const FrameCosts& costs, const VolumeSize& volume, ClusterShape shape,
                       int frames, double memory_per_worker, int loaded_rings = 0);

// Where a registered worker runs, as it told the root (RegisterRequest).
struct WorkerSite {
  std::string address;     // host:port, as the ring dials it
  std::string machine;     // its kernel's boot id; "" unknown
  int threads = 1;         // tracer threads
  double cpus = 0;         // CPUs it may run on; 0 unknown
  int machine_cpus = 0;    // its machine's online CPUs; 0 unknown
  uint64_t memory_bytes = 0;   // 0 unknown
  bool memory_shared = false;  // memory_bytes is its machine's, shared
};

struct Sites {
  ClusterShape shape;  // workers, hosts, cores and threads; rings and network left as made
  double memory_per_worker = 0;  // the least any worker can fill; infinity when unknown
  int machines = 0;
  std::string why;  // the shape in words, for the log
};

// The cluster's shape for the model from its workers. A host is an address's
// host part: a link of its own. A machine is a boot id (the address's host
// when unknown): its CPUs and, when shared, its memory are divided among the
// workers on it, in any container or network namespace. A worker gets the
// least of its threads, its CPUs and its share of its machine's CPUs; the
// model takes the least any worker gets (a ring waits for its slowest).
// REQUIRES: !workers.empty().
Sites SitesOf(const std::vector<WorkerSite>& workers);

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_CLUSTER_MODEL_H_
