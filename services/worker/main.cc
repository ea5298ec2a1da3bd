// transtick-worker: holds slabs and traces rays in a ring of workers.
#include <spdlog/spdlog.h>

#include <iostream>

#include "daemon.h"
#include "worker_node.h"

int main(int argc, char** argv) {
  using namespace transtick;
  BlockTerminationSignals();
  ReturnLargeBlocksToTheSystem();
  InitLogging("worker");
  auto flags = Flags::Parse(argc, argv, 1, {"listen", "root", "advertise", "threads"}, {"help"});
  if (!flags.ok() || flags->Has("help")) {
    if (!flags.ok()) std::cerr << "transtick-worker: " << flags.status().message() << "\n";
    std::cerr << "usage: transtick-worker --root HOST:PORT [--listen ADDR] [--advertise ADDR] "
                 "[--threads N]\n(environment: TRANSTICK_ROOT, TRANSTICK_LISTEN, "
                 "TRANSTICK_ADVERTISE, TRANSTICK_THREADS)\n";
    return flags.ok() ? 0 : 2;
  }
  WorkerNodeOptions o;
  o.listen = Setting(*flags, "listen", "TRANSTICK_LISTEN", "0.0.0.0:7001");
  o.root = Setting(*flags, "root", "TRANSTICK_ROOT", "");
  o.advertise = Setting(*flags, "advertise", "TRANSTICK_ADVERTISE", "");
  try {
    o.threads = std::stoi(Setting(*flags, "threads", "TRANSTICK_THREADS", "0"));
  } catch (...) {
    std::cerr << "transtick-worker: --threads must be an integer\n";
    return 2;
  }
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
