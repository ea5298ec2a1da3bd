// The cluster model (services/root/cluster_model.h): known answers on
// simple shapes, the directions every figure must move in, and a ring
// choice that never exceeds the workers' memory.

#include "cluster_model.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>

namespace transtick {
namespace {

FrameCosts Simple() {
  FrameCosts c;
  c.tracer_cpu_ms = 100;
  c.rays = 400000;
  c.crossings_per_cut = 100000;
  c.bytes_per_ray = 100;
  c.forward_cpu_us = 1;
  c.imbalance = 1;
  c.fixed_ms = 10;
  c.rounds = 3;
  c.deposit_bytes = 0;
  c.image_bytes = 0;
  c.linger_ms = 1;
  c.chain_rings = 2;
  return c;
}

TEST(ClusterModel, OneWorkerIsItsTracingAndFixedCost) {
  ClusterShape s;
  s.threads = 2;
  s.cores_per_host = 2;
  const Prediction p = Predict(Simple(), {1 << 20, 100}, s);
  EXPECT_DOUBLE_EQ(p.trace_ms, 50);
  EXPECT_DOUBLE_EQ(p.chain_ms, 0);
  EXPECT_DOUBLE_EQ(p.link_ms, 0);
  EXPECT_DOUBLE_EQ(p.frame_ms, 60);
  EXPECT_DOUBLE_EQ(p.hops_per_ray, 0);
  EXPECT_DOUBLE_EQ(p.efficiency, 1);
}

TEST(ClusterModel, TwoHostsKnownAnswer) {
  // Two workers on two hosts, one ring: each traces half, forwards 1e5
  // crossings at 1 us; 1e7 bytes cross the one plane, half each way, over
  // 1 Gbit/s: 40 ms; the chain is 2 hops of 0.5 ms latency + 1 ms linger.
  ClusterShape s;
  s.workers = 2;
  s.hosts = 2;
  s.threads = 1;
  s.cores_per_host = 1;
  s.network = {0.5, 1};
  const Prediction p = Predict(Simple(), {2 << 20, 100}, s);
  EXPECT_DOUBLE_EQ(p.trace_ms, 50 + 100);
  EXPECT_DOUBLE_EQ(p.bytes_per_link, 1e7);
  EXPECT_NEAR(p.link_ms, 40, 1e-9);
  EXPECT_DOUBLE_EQ(p.chain_ms, 2 * 1.5);
  EXPECT_DOUBLE_EQ(p.fixed_ms, 10 + 3 * 2 * 0.5);
  EXPECT_DOUBLE_EQ(p.frame_ms, 150 + 3 + 13);
  EXPECT_DOUBLE_EQ(p.hops_per_ray, 0.25);
  // Slab of half the volume plus two ghost planes, twice, plus frame buffers.
  EXPECT_DOUBLE_EQ(p.memory_per_worker, 2 * ((1 << 20) + 2 * (2 << 20) / 100.0) + 32 * (1 << 20));
}

TEST(ClusterModel, FiguresMoveTheRightWay) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 3000; ++i) {
    FrameCosts c = Simple();
    c.tracer_cpu_ms = 1 + 1000 * u(rng);
    c.crossings_per_cut = 1e6 * u(rng);
    c.imbalance = 1 + u(rng);
    ClusterShape s;
    s.workers = 1 + rng() % 128;
    s.rings = 1 + rng() % s.workers;
    s.hosts = 1 + rng() % s.workers;
    s.cores_per_host = 1 + rng() % 64;
    s.threads = 1 + rng() % 8;
    s.network = {0.01 + 10 * u(rng), 0.1 + 100 * u(rng)};
    const VolumeSize v{1e6 + 1e10 * u(rng), 1 + int(rng() % 2000)};
    const Prediction p = Predict(c, v, s);
    ASSERT_GT(p.frame_ms, 0);
    ASSERT_GE(p.frame_ms, p.trace_ms);
    ASSERT_GE(p.frame_ms, p.link_ms);
    ASSERT_GT(p.efficiency, 0);
    ASSERT_LE(p.efficiency, 1 + 1e-12) << "superlinear without a reason";
    ClusterShape slower = s;
    slower.network.latency_ms *= 2;
    ASSERT_GE(Predict(c, v, slower).frame_ms, p.frame_ms);
    slower = s;
    slower.network.gbits /= 2;
    ASSERT_GE(Predict(c, v, slower).frame_ms, p.frame_ms);
    // Fewer bytes on the wire (scalars in a narrower coding) load sooner,
    // at the same memory; as many as held load as before.
    VolumeSize coded = v;
    coded.wire_bytes = v.bytes * (0.25 + 0.7 * u(rng));
    const Prediction w = Predict(c, coded, s);
    ASSERT_LT(w.load_ms, p.load_ms);
    ASSERT_EQ(w.memory_per_worker, p.memory_per_worker);
    ASSERT_EQ(w.frame_ms, p.frame_ms);
    coded.wire_bytes = v.bytes;
    ASSERT_EQ(Predict(c, coded, s).load_ms, p.load_ms);
    if (s.rings < s.workers) {
      ClusterShape more = s;
      ++more.rings;
      const Prediction q = Predict(c, v, more);
      ASSERT_GE(q.memory_per_worker, p.memory_per_worker) << "more rings, smaller slabs";
      ASSERT_GE(q.load_ms, p.load_ms);
      ASSERT_LE(q.hops_per_ray, p.hops_per_ray);
    }
  }
}

TEST(ClusterModel, CostsFromAFrame) {
  std::vector<v1::WorkerFrameStats> f(4);
  for (int i = 0; i < 4; ++i) {
    v1::WorkerFrameStats* w = &f[i];
    w->set_ring(i / 2);
    w->set_cpu_ms(10 + i);
    w->set_active_ms(i == 3 ? 30 : 10);
    w->set_rays_traced(1000);
    w->set_rays_sent(500);
    w->set_bytes_sent(500 * 104);
  }
  const FrameCosts c = FrameCostsFrom(f, FrameCosts{});
  EXPECT_DOUBLE_EQ(c.tracer_cpu_ms, 46);
  EXPECT_DOUBLE_EQ(c.rays, 4000);
  // Two rings of two: one plane each, 1000 crossings each; the whole
  // image's rays through one plane of a single ring would be 2000.
  EXPECT_DOUBLE_EQ(c.crossings_per_cut, 2000);
  EXPECT_DOUBLE_EQ(c.bytes_per_ray, 104);
  // Within ring 1: 30 against a mean of 20.
  EXPECT_DOUBLE_EQ(c.imbalance, 1.5);
  // Workers that did not say what their deposits took: assumed per ray.
  EXPECT_DOUBLE_EQ(c.deposit_bytes, 4000 * kAssumedDepositBytes);
  // Those that did: their packed bytes, summed.
  for (int i = 0; i < 4; ++i) f[i].set_deposit_bytes(700 + i);
  EXPECT_DOUBLE_EQ(FrameCostsFrom(f, FrameCosts{}).deposit_bytes, 2806);
  // A ring of one worker that takes twice as long as a ring of two: the
  // layout's doing, not the slabs'.
  std::vector<v1::WorkerFrameStats> uneven(3);
  for (int i = 0; i < 3; ++i) {
    uneven[i].set_ring(i < 2 ? 0 : 1);
    uneven[i].set_active_ms(i < 2 ? 10 : 20);
  }
  EXPECT_DOUBLE_EQ(FrameCostsFrom(uneven, FrameCosts{}).imbalance, 1);
  // Nothing crossed: the fallback's crossings stay.
  std::vector<v1::WorkerFrameStats> alone(1);
  alone[0].set_cpu_ms(5);
  FrameCosts fallback;
  fallback.crossings_per_cut = 7;
  EXPECT_DOUBLE_EQ(FrameCostsFrom(alone, fallback).crossings_per_cut, 7);
}

TEST(ChooseRings, NeverExceedsTheMemoryAndTakesTheFastestThatFits) {
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 2000; ++i) {
    FrameCosts c = Simple();
    c.crossings_per_cut = 1e6 * u(rng);
    ClusterShape s;
    s.workers = 1 + rng() % 32;
    s.hosts = 1 + rng() % s.workers;
    s.network = {0.01 + 5 * u(rng), 1 + 10 * u(rng)};
    const VolumeSize v{1e8 + 1e10 * u(rng), 100 + int(rng() % 1000)};
    const double memory = 1e8 + 2e10 * u(rng);
    const int frames = 1 + rng() % 100;
    const int loaded = static_cast<int>(rng() % (s.workers + 1));  // 0: nothing held
    const RingChoice choice = ChooseRings(c, v, s, frames, memory, loaded);
    ASSERT_GE(choice.rings, 1);
    ASSERT_LE(choice.rings, s.workers);
    ASSERT_FALSE(choice.why.empty());
    s.rings = 1;
    const bool any_fits = Predict(c, v, s).memory_per_worker <= memory;
    if (!any_fits) {
      ASSERT_EQ(choice.rings, 1);
      ASSERT_NE(choice.why.find("no layout fits"), std::string::npos);
      continue;
    }
    ASSERT_LE(choice.prediction.memory_per_worker, memory);
    auto job_ms = [&](int r, const Prediction& p) {
      return (r == loaded ? 0 : p.load_ms) + frames * p.frame_ms;
    };
    const double chosen = job_ms(choice.rings, choice.prediction);
    for (int r = 1; r <= s.workers; ++r) {
      s.rings = r;
      const Prediction p = Predict(c, v, s);
      if (p.memory_per_worker > memory) continue;
      ASSERT_LE(chosen, job_ms(r, p) / 0.98 + 1e-9) << r;
    }
  }
}

TEST(ChooseRings, LongJobsTakeMoreRingsOneFrameOnASlowLinkFewer) {
  // 8 workers on 8 hosts, a 2 GB volume, room for it whole on each.
  FrameCosts c = Simple();
  c.crossings_per_cut = 3e5;
  ClusterShape s;
  s.workers = 8;
  s.hosts = 8;
  s.network = {0.5, 1};
  const VolumeSize v{2e9, 500};
  const double memory = 8e9;
  EXPECT_EQ(ChooseRings(c, v, s, 1, memory).rings, 1) << "a copy per ring costs 16 s a ring";
  EXPECT_GT(ChooseRings(c, v, s, 100000, memory).rings, 1);
  // The slabs of 4 rings already held: a short job keeps them.
  EXPECT_EQ(ChooseRings(c, v, s, 1, memory, /*loaded_rings=*/4).rings, 4);
  // Memory for a quarter of the volume: at most 2 rings.
  const RingChoice tight = ChooseRings(c, v, s, 100000, 2 * (2e9 / 4 + 2 * 2e9 / 500) + 64e6);
  EXPECT_LE(tight.rings, 2);
}

// The cores the model gives each worker of `sites`.
double ModelCores(const Sites& sites) {
  const ClusterShape& s = sites.shape;
  const int per_host = (s.workers + s.hosts - 1) / s.hosts;
  return std::min<double>(s.threads, s.cores_per_host / per_host);
}

TEST(SitesOf, KnownAnswers) {
  // Four workers of one thread, each in a network namespace of its own on
  // one machine of 2 CPUs (bench/emulated_hosts.sh): 4 hosts, half a core
  // each.
  std::vector<WorkerSite> ns;
  for (int i = 0; i < 4; ++i) {
    ns.push_back({"10.9.0." + std::to_string(i + 2) + ":7001", "boot-a", 1, 2, 2, 0, false});
  }
  Sites a = SitesOf(ns);
  EXPECT_EQ(a.shape.workers, 4);
  EXPECT_EQ(a.shape.hosts, 4);
  EXPECT_EQ(a.machines, 1);
  EXPECT_DOUBLE_EQ(ModelCores(a), 0.5);
  EXPECT_EQ(a.memory_per_worker, std::numeric_limits<double>::infinity());
  EXPECT_NE(a.why.find("4 worker(s) on 4 host(s) and 1 machine(s), 0.5 core(s)"), std::string::npos)
      << a.why;
  // Without boot ids, each address is its own machine: a core each.
  for (auto& w : ns) w.machine.clear();
  EXPECT_DOUBLE_EQ(ModelCores(SitesOf(ns)), 1);
  // Two workers of 8 threads at one address on an 8-CPU machine: 4 each;
  // one limited to 1.5 CPUs by its cgroup sets the ring's pace.
  std::vector<WorkerSite> pair = {{"h:7001", "", 8, 8, 8, uint64_t{16} << 30, true},
                                  {"h:7002", "", 8, 8, 8, uint64_t{16} << 30, true}};
  Sites b = SitesOf(pair);
  EXPECT_EQ(b.shape.hosts, 1);
  EXPECT_DOUBLE_EQ(ModelCores(b), 4);
  EXPECT_DOUBLE_EQ(b.memory_per_worker, double(uint64_t{8} << 30))
      << "the machine's memory, halved";
  pair[1].cpus = 1.5;
  pair[1].memory_shared = false;
  pair[1].memory_bytes = uint64_t{3} << 30;
  b = SitesOf(pair);
  EXPECT_DOUBLE_EQ(ModelCores(b), 1.5);
  EXPECT_DOUBLE_EQ(b.memory_per_worker, double(uint64_t{3} << 30));
  // Unknown CPUs: the threads.
  EXPECT_DOUBLE_EQ(ModelCores(SitesOf({{"x:1", "", 3, 0, 0, 0, false}})), 3);
}

TEST(SitesOf, NoMachineIsOverbooked) {
  // Random clusters: the model never gives the workers of a machine more
  // cores together than it has, nor a worker more than its threads or CPUs,
  // and some worker gets exactly what the model assumes.
  std::mt19937 rng(5);
  for (int i = 0; i < 2000; ++i) {
    const int machines = 1 + rng() % 4, workers = 1 + rng() % 12;
    std::vector<int> machine_cpus(machines);
    for (int& c : machine_cpus) c = 1 + rng() % 16;
    std::vector<WorkerSite> sites;
    for (int w = 0; w < workers; ++w) {
      const int m = rng() % machines;
      WorkerSite s;
      s.address = "m" + std::to_string(m) + "-" + std::to_string(rng() % 3) + ":" +
                  std::to_string(7000 + w);
      s.machine = "boot-" + std::to_string(m);
      s.threads = 1 + rng() % 8;
      s.cpus = rng() % 3 == 0 ? 0 : 0.25 * (1 + rng() % 64);
      s.machine_cpus = machine_cpus[m];
      sites.push_back(s);
    }
    const Sites got = SitesOf(sites);
    const double cores = ModelCores(got);
    ASSERT_GT(cores, 0);
    std::vector<int> on(machines);
    for (const auto& s : sites) ++on[s.machine[5] - '0'];
    bool someone_exact = false;
    for (const auto& s : sites) {
      const int m = s.machine[5] - '0';
      ASSERT_LE(cores * on[m], machine_cpus[m] + 1e-9);
      ASSERT_LE(cores, s.threads);
      if (s.cpus > 0) {
        ASSERT_LE(cores, s.cpus);
      }
      const double own =
          std::min({double(s.threads), s.cpus > 0 ? s.cpus : 1e9, double(machine_cpus[m]) / on[m]});
      someone_exact = someone_exact || std::abs(own - cores) < 1e-12;
    }
    ASSERT_TRUE(someone_exact);
  }
}

}  // namespace
}  // namespace transtick
