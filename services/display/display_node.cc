#include "display_node.h"

namespace transtick {

absl::StatusOr<std::unique_ptr<DisplayNode>> DisplayNode::Start(const std::string& listen,
                                                                const DisplayOptions& options,
                                                                const MetricsEndpoint& metrics) {
  auto node = std::unique_ptr<DisplayNode>(new DisplayNode());
  node->service_ = std::make_unique<DisplayService>(options);
  auto server = Server::Start(listen, Role::kDisplay, {node->service_.get()});
  if (!server.ok()) return server.status();
  node->server_ = *std::move(server);
  auto served = StartMetrics(metrics, node->service_->metrics());
  if (!served.ok()) return served.status();
  node->metrics_ = *std::move(served);
  return node;
}

DisplayNode::~DisplayNode() { Stop(std::chrono::milliseconds(0)); }

void DisplayNode::Stop(std::chrono::milliseconds grace) {
  metrics_.reset();
  if (server_) server_->Shutdown(grace);  // null when Start failed
}

}  // namespace transtick
