#include "display_node.h"

namespace transtick {

absl::StatusOr<std::unique_ptr<DisplayNode>> DisplayNode::Start(const std::string& listen,
                                                                const DisplayOptions& options) {
  auto node = std::unique_ptr<DisplayNode>(new DisplayNode());
  node->service_ = std::make_unique<DisplayService>(options);
  auto server = Server::Start(listen, {node->service_.get()});
  if (!server.ok()) return server.status();
  node->server_ = *std::move(server);
  return node;
}

DisplayNode::~DisplayNode() { Stop(std::chrono::milliseconds(0)); }

void DisplayNode::Stop(std::chrono::milliseconds grace) { server_->Shutdown(grace); }

}  // namespace transtick
