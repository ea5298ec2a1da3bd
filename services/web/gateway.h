// The web gateway: the viewer page and its JSON API over HTTP(S), as a
// client of the root (docs/formats.md, "Web gateway"). Each browser request
// becomes a call to the root carrying the browser's bearer token; an
// interactive session is a SessionClient whose events wait here until the
// page polls for them. Thread-safe.
#ifndef TRANSTICK_SERVICES_WEB_GATEWAY_H_
#define TRANSTICK_SERVICES_WEB_GATEWAY_H_

#include <chrono>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "metrics.h"

namespace transtick {

struct WebOptions {
  std::string listen = "127.0.0.1:8080";  // port 0 picks one
  std::string root;                       // the root's gRPC address
  // PEM files of the certificate browsers see; with them the gateway
  // serves HTTPS.
  std::string https_cert, https_key;
  int max_sessions = 16;
  std::chrono::milliseconds idle{60000};  // a session nobody polls is closed after this
  // Serve the page from this directory instead of the copy compiled in
  // (for working on the page).
  std::string static_dir;
};

class WebGateway {
 public:
  // Binds options.listen and serves. Refused (FAILED_PRECONDITION, naming
  // what to do): plaintext HTTP on an address that is not loopback unless
  // the process's security is --insecure, or when the root authenticates
  // clients (TLS), since tokens would then cross in the clear.
  static absl::StatusOr<std::unique_ptr<WebGateway>> Start(const WebOptions& options);
  ~WebGateway();
  WebGateway(const WebGateway&) = delete;
  WebGateway& operator=(const WebGateway&) = delete;

  int port() const;
  // "http://HOST:PORT/" or "https://...".
  std::string url() const;
  const std::shared_ptr<Metrics>& metrics() const;

 private:
  class Impl;
  explicit WebGateway(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_WEB_GATEWAY_H_
