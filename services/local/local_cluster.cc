#include "local_cluster.h"

#include <chrono>
#include <thread>

#include "absl/strings/str_cat.h"
#include "display_node.h"
#include "root_node.h"
#include "worker_node.h"

namespace transtick {

absl::StatusOr<std::unique_ptr<LocalCluster>> LocalCluster::Start(const Options& options) {
  auto c = std::unique_ptr<LocalCluster>(new LocalCluster());
  const MetricsEndpoint metrics{options.metrics ? "127.0.0.1:0" : "", true};
  auto display = DisplayNode::Start("127.0.0.1:0", {}, metrics);
  if (!display.ok()) return display.status();
  c->display_ = *std::move(display);
  RootOptions ro;
  ro.data_dir = options.data_dir;
  ro.display = absl::StrCat("127.0.0.1:", c->display_->port());
  ro.rings = options.rings;
  ro.frames_tracing = options.frames_tracing;
  ro.worker_wait_s = 30;
  auto root = RootNode::Start("127.0.0.1:0", ro, metrics);
  if (!root.ok()) return root.status();
  c->root_ = *std::move(root);
  for (int i = 0; i < options.workers; ++i) {
    WorkerNodeOptions wo;
    wo.listen = "127.0.0.1:0";
    wo.root = c->root_address();
    wo.threads = options.threads_per_worker;
    wo.metrics = metrics;
    // The advertised address is fixed once the port is known.
    auto w = WorkerNode::Start(wo);
    if (!w.ok()) return w.status();
    c->workers_.push_back(*std::move(w));
  }
  // Ready once every worker has registered.
  for (int tries = 0; c->root_->service().WorkerCount() < options.workers; ++tries) {
    if (tries > 1000) return absl::DeadlineExceededError("workers did not register");
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return c;
}

LocalCluster::~LocalCluster() {
  for (auto& w : workers_) w->Stop(std::chrono::milliseconds(1000));
  if (root_) root_->Stop(std::chrono::milliseconds(1000));
  if (display_) display_->Stop(std::chrono::milliseconds(1000));
}

std::string LocalCluster::root_address() const { return absl::StrCat("127.0.0.1:", root_->port()); }

int LocalCluster::root_metrics_port() const { return root_->metrics_port(); }

int LocalCluster::display_metrics_port() const { return display_->metrics_port(); }

std::vector<int> LocalCluster::worker_metrics_ports() const {
  std::vector<int> ports;
  for (const auto& w : workers_) ports.push_back(w->metrics_port());
  return ports;
}

std::vector<std::string> LocalCluster::worker_addresses() const {
  std::vector<std::string> addresses;
  for (const auto& w : workers_) addresses.push_back(w->address());
  return addresses;
}

}  // namespace transtick
