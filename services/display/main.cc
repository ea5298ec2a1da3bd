// transtick-display: assembles frames from the workers' deposits.
#include <spdlog/spdlog.h>

#include <iostream>

#include "daemon.h"
#include "display_node.h"

int main(int argc, char** argv) {
  using namespace transtick;
  BlockTerminationSignals();
  ReturnLargeBlocksToTheSystem();
  InitLogging("display");
  auto flags = Flags::Parse(argc, argv, 1, {"listen"}, {"help"});
  if (!flags.ok() || flags->Has("help")) {
    if (!flags.ok()) std::cerr << "transtick-display: " << flags.status().message() << "\n";
    std::cerr << "usage: transtick-display [--listen ADDR]  (environment: TRANSTICK_LISTEN)\n";
    return flags.ok() ? 0 : 2;
  }
  const std::string listen = Setting(*flags, "listen", "TRANSTICK_LISTEN", "0.0.0.0:7002");
  auto node = DisplayNode::Start(listen);
  if (!node.ok()) {
    spdlog::error("{}", std::string(node.status().message()));
    return 1;
  }
  spdlog::info("display serving on port {}", (*node)->port());
  int sig = WaitForSignal();
  spdlog::info("signal {}: stopping", sig);
  (*node)->Stop(std::chrono::milliseconds(5000));
  return 0;
}
