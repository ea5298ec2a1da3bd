#include "display_node.h"

namespace transtick {

absl::StatusOr<std::unique_ptr<DisplayNode>> DisplayNode::Start(const std::string& listen,
                                                                const DisplayOptions& options) {
  auto node = std::unique_ptr<DisplayNode>(new DisplayNode());
  node->service_ = std::make_unique<DisplayService>(options);
  auto server = Server::Start(listen, Role::kDisplay, {node->service_.get()});
  if (!server.ok()) return server.status();
  node->server_ = *std::move(server);
  return node;
}

DisplayNode::~DisplayNode() { Stop(std::chrono::milliseconds(0)); }

void DisplayNode::Stop(std::chrono::milliseconds grace) {
  if (server_) server_->Shutdown(grace);  // null when Start failed
}

}  // namespace transtick
