// transtick-worker: holds slabs and traces rays in a ring of workers.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <iostream>

#include "daemon.h"
#include "heap.h"
#include "transtick/parallel.h"
#include "worker_node.h"

int main(int argc, char** argv) {
  using namespace transtick;
  BlockTerminationSignals();
  TuneHeap();
  UseReleaseLocking();
  InitLogging("worker");
  auto flags = Flags::Parse(argc, argv, 1,
                            WithSecurityFlags({"listen", "root", "advertise", "threads",
                                               "memory-mb", "batch-rays", "linger-us",
                                               "max-frames", "frame-idle-s",
                                               "running-frame-idle-s", "metrics"}),
                            WithSecuritySwitches({"help"}));
  if (!flags.ok() || flags->Has("help")) {
    if (!flags.ok()) std::cerr << "transtick-worker: " << flags.status().message() << "\n";
    std::cerr << "usage: transtick-worker --root HOST:PORT [--listen ADDR] [--advertise ADDR] "
                 "[--threads N] [--memory-mb N] [--batch-rays N] [--linger-us US] "
                 "[--max-frames N] [--frame-idle-s S] [--running-frame-idle-s S]\n"
                 "(environment: TRANSTICK_ROOT, TRANSTICK_LISTEN, TRANSTICK_ADVERTISE, "
                 "TRANSTICK_THREADS, TRANSTICK_MEMORY_MB, TRANSTICK_BATCH_RAYS, "
                 "TRANSTICK_LINGER_US, TRANSTICK_MAX_FRAMES, TRANSTICK_FRAME_IDLE_S, "
                 "TRANSTICK_RUNNING_FRAME_IDLE_S)\n"
                 "TLS: " << kSecurityUsage << " (or TRANSTICK_TLS_CA, TRANSTICK_TLS_CERT, "
                 "TRANSTICK_TLS_KEY); without them it serves plaintext on loopback only "
                 "(docs/security.md)\n"
                 "/metrics (Prometheus): --metrics ADDR|off (TRANSTICK_METRICS), default the --listen "
                 "address with port + 100; HTTPS with TLS\n";
    return flags.ok() ? 0 : 2;
  }
  if (absl::Status s = UseDaemonSecurity(*flags); !s.ok()) {
    std::cerr << "transtick-worker: " << s.message() << "\n";
    return 2;
  }
  WorkerNodeOptions o;
  o.listen = Setting(*flags, "listen", "TRANSTICK_LISTEN", "0.0.0.0:7001");
  o.root = Setting(*flags, "root", "TRANSTICK_ROOT", "");
  o.advertise = Setting(*flags, "advertise", "TRANSTICK_ADVERTISE", "");
  const FrameLimits defaults;
  auto threads = IntSetting(*flags, "threads", "TRANSTICK_THREADS", 0, 0);
  // Ray batches to the neighbours (frame.h): at most 65536 rays (6.9 MB) a
  // message, well under the 64 MB message limit, and a linger of at most 1 s.
  const FrameOptions frame_defaults;
  auto batch_rays = IntSetting(*flags, "batch-rays", "TRANSTICK_BATCH_RAYS",
                               static_cast<int64_t>(frame_defaults.batch_rays), 1);
  auto linger_us = IntSetting(*flags, "linger-us", "TRANSTICK_LINGER_US",
                              frame_defaults.linger.count(), 0);
  auto memory_mb = IntSetting(*flags, "memory-mb", "TRANSTICK_MEMORY_MB", 0, 0);
  auto max_frames = IntSetting(*flags, "max-frames", "TRANSTICK_MAX_FRAMES",
                               static_cast<int64_t>(defaults.max_frames), 1);
  auto prepared_idle =
      SecondsSetting(*flags, "frame-idle-s", "TRANSTICK_FRAME_IDLE_S", defaults.prepared_idle);
  auto running_idle = SecondsSetting(*flags, "running-frame-idle-s",
                                     "TRANSTICK_RUNNING_FRAME_IDLE_S", defaults.running_idle);
  for (const absl::Status& s :
       {threads.status(), memory_mb.status(), batch_rays.status(), linger_us.status(),
        max_frames.status(), prepared_idle.status(), running_idle.status()}) {
    if (!s.ok()) {
      std::cerr << "transtick-worker: " << s.message() << "\n";
      return 2;
    }
  }
  o.threads = static_cast<int>(std::min<int64_t>(*threads, 4096));
  // A worker told to trace on N threads builds its slabs on N too.
  SetBuildThreads(o.threads);
  if (*batch_rays > 65536 || *linger_us > 1'000'000) {
    std::cerr << "transtick-worker: --batch-rays is at most 65536 and --linger-us at most "
                 "1000000\n";
    return 2;
  }
  o.batch_rays = static_cast<size_t>(*batch_rays);
  o.linger = std::chrono::microseconds(*linger_us);
  o.memory_bytes = static_cast<uint64_t>(std::min<int64_t>(*memory_mb, int64_t{1} << 30)) << 20;
  o.frames.max_frames = static_cast<size_t>(*max_frames);
  o.frames.prepared_idle = *prepared_idle;
  o.frames.running_idle = *running_idle;
  auto metrics = MetricsAddress(*flags, o.listen);
  if (!metrics.ok()) {
    std::cerr << "transtick-worker: " << metrics.status().message() << "\n";
    return 2;
  }
  o.metrics = *metrics;
  auto node = WorkerNode::Start(o);
  if (!node.ok()) {
    spdlog::error("{}", std::string(node.status().message()));
    return 1;
  }
  int sig = WaitForSignal();
  spdlog::info("signal {}: unregistering and stopping", sig);
  (*node)->Stop(std::chrono::milliseconds(5000));
  spdlog::info("stopped");
  return 0;
}
