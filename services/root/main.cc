// transtick-root: the client-facing API and the coordinator of the cluster.
#include <spdlog/spdlog.h>

#include <iostream>

#include "cluster_model.h"
#include "daemon.h"
#include "heap.h"
#include "root_node.h"

int main(int argc, char** argv) {
  using namespace transtick;
  BlockTerminationSignals();
  TuneHeap();
  UseReleaseLocking();
  InitLogging("root");
  auto flags =
      Flags::Parse(argc, argv, 1,
                   WithSecurityFlags({"listen", "data-dir", "state-dir", "display", "rings",
                                      "frames-tracing", "link-latency-ms", "link-gbits",
                                      "max-volume-mb", "frame-timeout", "max-queued-jobs",
                                      "max-jobs-per-client", "max-job-megapixels", "metrics"}),
                   WithSecuritySwitches({"help"}));
  if (!flags.ok() || flags->Has("help")) {
    if (!flags.ok()) std::cerr << "transtick-root: " << flags.status().message() << "\n";
    std::cerr
        << "usage: transtick-root [--listen ADDR] [--data-dir DIR] [--state-dir DIR] "
           "[--display ADDR] [--rings R|auto] [--frames-tracing auto|1|2] [--link-latency-ms MS] "
           "[--link-gbits G] "
           "[--max-volume-mb N] [--frame-timeout S] "
           "[--max-queued-jobs N] [--max-jobs-per-client N] [--max-job-megapixels N]\n"
           "(environment: TRANSTICK_LISTEN, TRANSTICK_DATA_DIR, TRANSTICK_STATE_DIR, "
           "TRANSTICK_DISPLAY, TRANSTICK_RINGS, TRANSTICK_FRAMES_TRACING, "
           "TRANSTICK_LINK_LATENCY_MS, TRANSTICK_LINK_GBITS, "
           "TRANSTICK_MAX_VOLUME_MB, "
           "TRANSTICK_FRAME_TIMEOUT, TRANSTICK_MAX_QUEUED_JOBS, "
           "TRANSTICK_MAX_JOBS_PER_CLIENT, TRANSTICK_MAX_JOB_MEGAPIXELS)\n"
           "TLS: "
        << kSecurityUsage
        << " [--tokens FILE] (or TRANSTICK_TLS_CA, TRANSTICK_TLS_CERT, "
           "TRANSTICK_TLS_KEY, TRANSTICK_TOKENS); without them it serves plaintext on loopback "
           "only "
           "(docs/security.md)\n"
           "Without a state directory the jobs live in memory and a restart loses them.\n"
           "/metrics (Prometheus): --metrics ADDR|off (TRANSTICK_METRICS), default the --listen "
           "address with port + 100; HTTPS with TLS\n";
    return flags.ok() ? 0 : 2;
  }
  if (absl::Status s = UseDaemonSecurity(*flags); !s.ok()) {
    std::cerr << "transtick-root: " << s.message() << "\n";
    return 2;
  }
  RootOptions o;
  const std::string listen = Setting(*flags, "listen", "TRANSTICK_LISTEN", "0.0.0.0:7000");
  o.data_dir = Setting(*flags, "data-dir", "TRANSTICK_DATA_DIR", "/data");
  o.state_dir = Setting(*flags, "state-dir", "TRANSTICK_STATE_DIR", "");
  o.display = Setting(*flags, "display", "TRANSTICK_DISPLAY", "127.0.0.1:7002");
  try {
    o.network.latency_ms =
        std::stod(Setting(*flags, "link-latency-ms", "TRANSTICK_LINK_LATENCY_MS", "0.05"));
    o.network.gbits = std::stod(Setting(*flags, "link-gbits", "TRANSTICK_LINK_GBITS", "10"));
    o.max_volume_bytes =
        std::stoull(Setting(*flags, "max-volume-mb", "TRANSTICK_MAX_VOLUME_MB", "8192")) << 20;
    o.frame_timeout_s =
        std::stod(Setting(*flags, "frame-timeout", "TRANSTICK_FRAME_TIMEOUT", "600"));
    const std::string frames_tracing =
        Setting(*flags, "frames-tracing", "TRANSTICK_FRAMES_TRACING", "auto");
    o.frames_tracing = frames_tracing == "auto" ? kAutoFramesTracing : std::stoi(frames_tracing);
    o.max_queued = std::stoi(Setting(*flags, "max-queued-jobs", "TRANSTICK_MAX_QUEUED_JOBS", "1000"));
    o.max_jobs_per_client =
        std::stoi(Setting(*flags, "max-jobs-per-client", "TRANSTICK_MAX_JOBS_PER_CLIENT", "100"));
    o.max_job_pixels = static_cast<uint64_t>(std::stoull(Setting(
                           *flags, "max-job-megapixels", "TRANSTICK_MAX_JOB_MEGAPIXELS", "2048")))
                       << 20;
  } catch (...) {
    std::cerr << "transtick-root: --max-volume-mb, --frame-timeout, --frames-tracing, --link-* "
                 "and the --max-* limits take numbers\n";
    return 2;
  }
  if (o.frames_tracing < 0 || o.frames_tracing > 2) {
    std::cerr << "transtick-root: --frames-tracing is auto, 1 or 2\n";
    return 2;
  }
  if (o.max_queued < 1 || o.max_jobs_per_client < 1 || o.max_job_pixels == 0) {
    std::cerr << "transtick-root: the --max-* limits must be positive\n";
    return 2;
  }
  if (auto rings = ParseRings(Setting(*flags, "rings", "TRANSTICK_RINGS", "1")); !rings.ok()) {
    std::cerr << "transtick-root: --" << rings.status().message() << "\n";
    return 2;
  } else {
    o.rings = *rings;
  }
  if (!(o.network.latency_ms >= 0 && o.network.latency_ms < 1e4 && o.network.gbits > 0 &&
        o.network.gbits < 1e5)) {
    std::cerr << "transtick-root: --link-latency-ms must be in [0, 10000) and --link-gbits in "
                 "(0, 100000)\n";
    return 2;
  }
  auto metrics = MetricsAddress(*flags, listen);
  if (!metrics.ok()) {
    std::cerr << "transtick-root: " << metrics.status().message() << "\n";
    return 2;
  }
  auto node = RootNode::Start(listen, o, *metrics);
  if (!node.ok()) {
    spdlog::error("{}", std::string(node.status().message()));
    return 1;
  }
  spdlog::info(
      "root serving on port {} (metrics on {}); data {}, state {}, display {}, {} ring(s), "
      "frames tracing {}",
      (*node)->port(),
      (*node)->metrics_port() == 0 ? "no port" : std::to_string((*node)->metrics_port()),
      o.data_dir, o.state_dir.empty() ? "(memory)" : o.state_dir, o.display, o.rings,
      o.frames_tracing == kAutoFramesTracing
          ? std::string("auto (2 when a worker runs on another machine)")
          : std::to_string(o.frames_tracing));
  int sig = WaitForSignal();
  spdlog::info("signal {}: stopping", sig);
  (*node)->Stop(std::chrono::milliseconds(5000));
  return 0;
}
