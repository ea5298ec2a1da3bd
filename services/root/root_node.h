// A running root: its server and service. Used by the transtick-root daemon
// and by embedded clusters. Thread-safe.
#ifndef TRANSTICK_SERVICES_ROOT_ROOT_NODE_H_
#define TRANSTICK_SERVICES_ROOT_ROOT_NODE_H_

#include <memory>

#include "absl/status/statusor.h"
#include "daemon.h"
#include "root_service.h"

namespace transtick {

class RootNode {
 public:
  static absl::StatusOr<std::unique_ptr<RootNode>> Start(const std::string& listen,
                                                         const RootOptions& options);
  ~RootNode() { Stop(std::chrono::milliseconds(0)); }

  int port() const { return server_->port(); }
  RootService& service() { return *service_; }
  void Stop(std::chrono::milliseconds grace) {
    if (service_) service_->Stop();
    if (server_) server_->Shutdown(grace);  // null when Start failed
  }

 private:
  std::unique_ptr<RootService> service_;
  std::unique_ptr<Server> server_;
};

inline absl::StatusOr<std::unique_ptr<RootNode>> RootNode::Start(const std::string& listen,
                                                                 const RootOptions& options) {
  auto node = std::unique_ptr<RootNode>(new RootNode());
  auto service = RootService::Create(options);
  if (!service.ok()) return service.status();
  node->service_ = *std::move(service);
  auto server = Server::Start(listen, Role::kRoot, {node->service_.get()});
  if (!server.ok()) return server.status();
  node->server_ = *std::move(server);
  return node;
}

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_ROOT_ROOT_NODE_H_
