// A running display: its service and the server it is served on. Used by
// the transtick-display daemon and by embedded clusters. Thread-safe.
#ifndef TRANSTICK_SERVICES_DISPLAY_DISPLAY_NODE_H_
#define TRANSTICK_SERVICES_DISPLAY_DISPLAY_NODE_H_

#include <chrono>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "daemon.h"
#include "display_service.h"
#include "metrics.h"

namespace transtick {

class DisplayNode {
 public:
  // Serves a DisplayService on `listen` ("host:port"; port 0 picks one).
  // And /metrics at `metrics` (StartMetrics).
  static absl::StatusOr<std::unique_ptr<DisplayNode>> Start(const std::string& listen,
                                                            const DisplayOptions& options = {},
                                                            const MetricsEndpoint& metrics = {});
  // Stops serving at once if Stop was not called.
  ~DisplayNode();

  DisplayNode(const DisplayNode&) = delete;
  DisplayNode& operator=(const DisplayNode&) = delete;

  int port() const { return server_->port(); }
  int metrics_port() const { return metrics_ ? metrics_->port() : 0; }
  DisplayService& service() { return *service_; }
  // Stops accepting calls and waits up to `grace` for calls in flight (a
  // root waiting for its frame), then cancels what remains. Idempotent.
  void Stop(std::chrono::milliseconds grace);

 private:
  DisplayNode() = default;

  // In this order so that the server is destroyed before the service it
  // serves.
  std::unique_ptr<DisplayService> service_;
  std::unique_ptr<Server> server_;
  std::unique_ptr<MetricsServer> metrics_;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_DISPLAY_DISPLAY_NODE_H_
