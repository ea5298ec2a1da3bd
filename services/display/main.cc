// transtick-display: assembles frames from the workers' deposits.
#include <spdlog/spdlog.h>

#include <iostream>

#include "daemon.h"
#include "heap.h"
#include "display_node.h"

int main(int argc, char** argv) {
  using namespace transtick;
  BlockTerminationSignals();
  TuneHeap();
  UseReleaseLocking();
  InitLogging("display");
  auto flags = Flags::Parse(
      argc, argv, 1,
      WithSecurityFlags({"listen", "max-frames", "max-framebuffer-mb", "frame-idle-s", "metrics"}),
      WithSecuritySwitches({"help"}));
  if (!flags.ok() || flags->Has("help")) {
    if (!flags.ok()) std::cerr << "transtick-display: " << flags.status().message() << "\n";
    std::cerr << "usage: transtick-display [--listen ADDR] [--max-frames N] "
                 "[--max-framebuffer-mb N] [--frame-idle-s S]\n(environment: TRANSTICK_LISTEN, "
                 "TRANSTICK_MAX_FRAMES, TRANSTICK_MAX_FRAMEBUFFER_MB, TRANSTICK_FRAME_IDLE_S)\n"
                 "TLS: " << kSecurityUsage << " (or TRANSTICK_TLS_CA, TRANSTICK_TLS_CERT, "
                 "TRANSTICK_TLS_KEY); without them it serves plaintext on loopback only "
                 "(docs/security.md)\n"
                 "/metrics (Prometheus): --metrics ADDR|off (TRANSTICK_METRICS), default the --listen "
                 "address with port + 100; HTTPS with TLS\n";
    return flags.ok() ? 0 : 2;
  }
  if (absl::Status s = UseDaemonSecurity(*flags); !s.ok()) {
    std::cerr << "transtick-display: " << s.message() << "\n";
    return 2;
  }
  const std::string listen = Setting(*flags, "listen", "TRANSTICK_LISTEN", "0.0.0.0:7002");
  DisplayOptions o;
  auto max_frames = IntSetting(*flags, "max-frames", "TRANSTICK_MAX_FRAMES",
                               static_cast<int64_t>(o.max_frames), 1);
  auto max_mb = IntSetting(*flags, "max-framebuffer-mb", "TRANSTICK_MAX_FRAMEBUFFER_MB",
                           static_cast<int64_t>(o.max_bytes >> 20), 1);
  auto idle = SecondsSetting(*flags, "frame-idle-s", "TRANSTICK_FRAME_IDLE_S", o.idle);
  for (const absl::Status& s : {max_frames.status(), max_mb.status(), idle.status()}) {
    if (!s.ok()) {
      std::cerr << "transtick-display: " << s.message() << "\n";
      return 2;
    }
  }
  o.max_frames = static_cast<size_t>(*max_frames);
  o.max_bytes = static_cast<uint64_t>(*max_mb) << 20;
  o.idle = *idle;
  auto metrics = MetricsAddress(*flags, listen);
  if (!metrics.ok()) {
    std::cerr << "transtick-display: " << metrics.status().message() << "\n";
    return 2;
  }
  auto node = DisplayNode::Start(listen, o, *metrics);
  if (!node.ok()) {
    spdlog::error("{}", std::string(node.status().message()));
    return 1;
  }
  spdlog::info("display serving on port {}, metrics on {}", (*node)->port(),
               (*node)->metrics_port() == 0 ? "no port" : std::to_string((*node)->metrics_port()));
  int sig = WaitForSignal();
  spdlog::info("signal {}: stopping", sig);
  (*node)->Stop(std::chrono::milliseconds(5000));
  return 0;
}
