#include "worker_node.h"

#include <sched.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <fstream>
#include <random>
#include <string>
#include <thread>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/time/time.h"

namespace transtick {
namespace {

std::string RandomId() {
  std::random_device rd;
  return absl::StrFormat("w-%08x%08x", rd(), rd());
}

// The cgroup's memory limit (cgroup v2, a container's), 0 when it has none.
uint64_t CgroupLimit() {
  std::ifstream in("/sys/fs/cgroup/memory.max");
  std::string value;
  if (!(in >> value) || value == "max") return 0;
  try {
    return std::stoull(value);
  } catch (const std::exception&) {
    return 0;
  }
}

// The host's memory (MemTotal), 0 when unknown.
uint64_t HostMemory() {
  std::ifstream in("/proc/meminfo");
  for (std::string key; in >> key;) {
    uint64_t kb = 0;
    if (key == "MemTotal:" && in >> kb) return kb * 1024;
    in.ignore(1 << 10, '\n');
  }
  return 0;
}

// The CPUs this process may run on: its affinity mask, capped by its
// cgroup's CPU quota (cgroup v2 cpu.max "QUOTA PERIOD", a container's
// --cpus). 0 when unknown.
double ProcessCpus() {
  double cpus = 0;
  cpu_set_t set;
  if (sched_getaffinity(0, sizeof(set), &set) == 0) cpus = CPU_COUNT(&set);
  std::ifstream in("/sys/fs/cgroup/cpu.max");
  std::string quota;
  double period = 0;
  if (in >> quota >> period && quota != "max" && period > 0) {
    try {
      const double q = std::stod(quota) / period;
      if (q > 0 && (cpus == 0 || q < cpus)) cpus = q;
    } catch (const std::exception&) {
    }
  }
  return cpus;
}

}  // namespace

absl::StatusOr<std::unique_ptr<WorkerNode>> WorkerNode::Start(const WorkerNodeOptions& options) {
  if (options.root.empty()) {
    return absl::InvalidArgumentError(
        "worker: the root's address is required (--root or TRANSTICK_ROOT)");
  }
  auto node = std::unique_ptr<WorkerNode>(new WorkerNode());
  node->options_ = options;
  node->id_ = RandomId();
  node->threads_ = options.threads > 0
                       ? options.threads
                       : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  if (options.memory_bytes > 0) {
    node->memory_ = {options.memory_bytes, false};
  } else if (const uint64_t limit = CgroupLimit(); limit > 0) {
    node->memory_ = {limit, false};
  } else {
    node->memory_ = {HostMemory(), true};
  }
  node->machine_ = MachineId();
  node->cpus_ = ProcessCpus();
  node->machine_cpus_ = static_cast<int>(std::max(0L, sysconf(_SC_NPROCESSORS_ONLN)));
  WorkerOptions wo;
  wo.id = node->id_;
  wo.threads = node->threads_;
  wo.batch_rays = options.batch_rays;
  wo.linger = options.linger;
  wo.frames = options.frames;
  node->service_ = std::make_unique<WorkerService>(std::move(wo));
  auto server = Server::Start(options.listen, Role::kWorker, {node->service_.get()});
  if (!server.ok()) return server.status();
  node->server_ = *std::move(server);
  auto served = StartMetrics(options.metrics, node->service_->metrics());
  if (!served.ok()) return served.status();
  node->metrics_ = *std::move(served);
  const std::string listen_host = options.listen.substr(0, options.listen.rfind(':'));
  if (!options.advertise.empty()) {
    node->address_ = options.advertise;
  } else if (!listen_host.empty() && listen_host != "0.0.0.0" && listen_host != "[::]") {
    node->address_ = absl::StrCat(listen_host, ":", node->server_->port());
  } else {
    char host[256] = {0};
    gethostname(host, sizeof host - 1);
    node->address_ = absl::StrCat(host, ":", node->server_->port());
  }
  node->service_->set_address(node->address_);
  node->registrar_ = std::thread([n = node.get()] { n->RegisterLoop(); });
  spdlog::info(
      "worker {} serving on {} ({} tracer threads on {:.4g} of the machine's {} CPUs, {:.0f} MB{}, "
      "metrics on {}), registering with {}",
      node->id_, node->address_, node->threads_, node->cpus_, node->machine_cpus_,
      node->memory_.bytes / 1048576.0, node->memory_.shared ? " of the host's" : "",
      node->metrics_ ? std::to_string(node->metrics_->port()) : "no port", options.root);
  return node;
}

void WorkerNode::RegisterLoop() {
  auto stub = v1::Root::NewStub(MakeChannel(options_.root, Role::kRoot));
  const std::chrono::milliseconds first_backoff(100), max_backoff(3000);
  std::chrono::milliseconds backoff = first_backoff;
  bool warned = false;
  std::string last_error;  // said once until it changes
  while (true) {
    {
      absl::MutexLock lock(&mu_);
      if (stopping_) return;
    }
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(5));
    v1::RegisterRequest req;
    req.set_id(id_);
    req.set_address(address_);
    req.set_threads(threads_);
    req.set_memory_bytes(memory_.bytes);
    req.set_memory_shared(memory_.shared);
    req.set_machine(machine_);
    req.set_cpus(cpus_);
    req.set_machine_cpus(machine_cpus_);
    v1::RegisterReply reply;
    grpc::Status s = stub->Register(&ctx, req, &reply);
    // ALREADY_EXISTS: the root knows this worker; the call renewed it.
    const bool known = s.ok() || s.error_code() == grpc::StatusCode::ALREADY_EXISTS;
    std::chrono::milliseconds wait = options_.heartbeat;
    if (known) {
      if (!registered_.exchange(true) || warned) {
        spdlog::info("registered with the root at {}", options_.root);
      }
      warned = false;
      last_error.clear();
      backoff = first_backoff;
    } else {
      registered_ = false;
      // A root not up yet, then one that refuses this worker's certificate:
      // each reason is logged when it first appears.
      if (!warned || s.error_message() != last_error) {
        spdlog::warn("registration with {} failed ({}); retrying", options_.root,
                     s.error_message());
        warned = true;
        last_error = s.error_message();
      }
      wait = backoff;
      backoff = std::min(backoff * 2, max_backoff);
      // A fresh channel for the next try, as the client does when it lost
      // the root (cli/client.cc): a TLS channel whose peer died mid-call may
      // not connect again.
      stub = v1::Root::NewStub(MakeChannel(options_.root, Role::kRoot));
    }
    absl::MutexLock lock(&mu_);  // until the next heartbeat, or Stop
    mu_.AwaitWithTimeout(absl::Condition(&stopping_), absl::FromChrono(wait));
  }
}

void WorkerNode::Stop(std::chrono::milliseconds grace) {
  {
    absl::MutexLock lock(&mu_);
    if (stopping_) return;
    stopping_ = true;
  }
  if (registrar_.joinable()) registrar_.join();
  metrics_.reset();
  if (registered_) {
    auto stub = v1::Root::NewStub(MakeChannel(options_.root, Role::kRoot));
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(2));
    v1::RegisterRequest req;
    req.set_id(id_);
    req.set_address(address_);
    v1::RegisterReply reply;
    grpc::Status s = stub->Unregister(&ctx, req, &reply);
    if (!s.ok()) spdlog::warn("unregistering from the root failed: {}", s.error_message());
  }
  service_->CancelAll();
  if (server_) server_->Shutdown(grace);  // null when Start failed
}

WorkerNode::~WorkerNode() { Stop(std::chrono::milliseconds(0)); }

}  // namespace transtick
