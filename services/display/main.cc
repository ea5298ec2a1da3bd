// transtick-display: assembles frames from the workers' deposits.
#include <spdlog/spdlog.h>

#include <iostream>

#include "daemon.h"
#include "display_service.h"

int main(int argc, char** argv) {
  using namespace transtick;
  BlockTerminationSignals();
  InitLogging("display");
  auto flags = Flags::Parse(argc, argv, 1, {"listen"}, {"help"});
  if (!flags.ok() || flags->Has("help")) {
    if (!flags.ok()) std::cerr << "transtick-display: " << flags.status().message() << "\n";
    std::cerr << "usage: transtick-display [--listen ADDR]  (environment: TRANSTICK_LISTEN)\n";
    return flags.ok() ? 0 : 2;
  }
  const std::string listen = Setting(*flags, "listen", "TRANSTICK_LISTEN", "0.0.0.0:7002");
  DisplayService service;
  auto server = Server::Start(listen, {&service});
  if (!server.ok()) {
    spdlog::error("{}", std::string(server.status().message()));
    return 1;
  }
  spdlog::info("display serving on port {}", (*server)->port());
  int sig = WaitForSignal();
  spdlog::info("signal {}: stopping", sig);
  (*server)->Shutdown(std::chrono::milliseconds(5000));
  return 0;
}
