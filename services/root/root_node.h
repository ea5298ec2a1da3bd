// A running root: its server and service. Used by the transtick-root daemon
// and by embedded clusters. Thread-safe.
#ifndef TRANSTICK_SERVICES_ROOT_ROOT_NODE_H_
#define TRANSTICK_SERVICES_ROOT_ROOT_NODE_H_

#include <memory>

#include "absl/status/statusor.h"
#include "daemon.h"
#include "metrics.h"
#include "root_service.h"

namespace transtick {

class RootNode {
 public:
  // Serves the API on `listen`, and /metrics at `metrics` (StartMetrics).
  static absl::StatusOr<std::unique_ptr<RootNode>> Start(const std::string& listen,
                                                         const RootOptions& options,
                                                         const MetricsEndpoint& metrics = {});
  ~RootNode() { Stop(std::chrono::milliseconds(0)); }

  int port() const { return server_->port(); }
  int metrics_port() const { return metrics_ ? metrics_->port() : 0; }
  RootService& service() { return *service_; }
  void Stop(std::chrono::milliseconds grace) {
    metrics_.reset();
    if (service_) service_->Stop();
    if (server_) server_->Shutdown(grace);  // null when Start failed
  }

 private:
  std::unique_ptr<RootService> service_;
  std::unique_ptr<Server> server_;
  std::unique_ptr<MetricsServer> metrics_;
};

inline absl::StatusOr<std::unique_ptr<RootNode>> RootNode::Start(
    const std::string& listen, const RootOptions& options, const MetricsEndpoint& metrics) {
  auto node = std::unique_ptr<RootNode>(new RootNode());
  auto service = RootService::Create(options);
  if (!service.ok()) return service.status();
  node->service_ = *std::move(service);
  auto server = Server::Start(listen, Role::kRoot, {node->service_.get()});
  if (!server.ok()) return server.status();
  node->server_ = *std::move(server);
  auto served = StartMetrics(metrics, node->service_->metrics());
  if (!served.ok()) return served.status();
  node->metrics_ = *std::move(served);
  return node;
}

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_ROOT_NODE_H_
