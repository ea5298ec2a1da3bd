// transtick-web: the viewer page and its JSON API, in front of a root
// (docs/formats.md, "Web gateway").
#include <spdlog/spdlog.h>

#include <iostream>

#include "daemon.h"
#include "heap.h"
#include "gateway.h"
#include "security.h"

int main(int argc, char** argv) {
  using namespace transtick;
  BlockTerminationSignals();
  TuneHeap();
  UseReleaseLocking();
  InitLogging("web");
  auto flags = Flags::Parse(argc, argv, 1,
                            {"listen", "root", "https-cert", "https-key", "max-sessions", "idle-s",
                             "static-dir", "tls-ca", "tls-cert", "tls-key"},
                            {"help", "insecure"});
  if (!flags.ok() || flags->Has("help")) {
    if (!flags.ok()) std::cerr << "transtick-web: " << flags.status().message() << "\n";
    std::cerr
        << "usage: transtick-web --root ADDR [--listen ADDR] [--https-cert FILE --https-key FILE]\n"
           "         [--max-sessions N] [--idle-s S] [--static-dir DIR]\n"
           "         [--tls-ca FILE [--tls-cert FILE --tls-key FILE]] [--insecure]\n"
           "(environment: TRANSTICK_ROOT, TRANSTICK_LISTEN (default 127.0.0.1:8080),\n"
           "TRANSTICK_HTTPS_CERT, TRANSTICK_HTTPS_KEY, TRANSTICK_MAX_SESSIONS (16),\n"
           "TRANSTICK_IDLE_S (60), TRANSTICK_TLS_CA, ...)\n"
           "With --tls-ca the root authenticates clients: each browser sends its own token,\n"
           "which the gateway passes on, and the gateway serves HTTPS unless on loopback.\n"
           "Without TLS it serves plaintext on loopback only, unless --insecure.\n"
           "The page and API: docs/formats.md, \"Web gateway\"; /metrics on the same port.\n";
    return flags.ok() ? 0 : 2;
  }
  auto security = SecurityFromFlags(*flags, /*daemon=*/false);
  if (!security.ok()) {
    std::cerr << "transtick-web: " << security.status().message() << "\n";
    return 2;
  }
  if (!security->token.empty()) {
    spdlog::warn("TRANSTICK_TOKEN_FILE is ignored: the gateway sends each browser's own token");
    security->token.clear();
  }
  SetSecurity(*std::move(security));
  WebOptions o;
  o.listen = Setting(*flags, "listen", "TRANSTICK_LISTEN", o.listen);
  o.root = Setting(*flags, "root", "TRANSTICK_ROOT", "");
  o.https_cert = Setting(*flags, "https-cert", "TRANSTICK_HTTPS_CERT", "");
  o.https_key = Setting(*flags, "https-key", "TRANSTICK_HTTPS_KEY", "");
  o.static_dir = Setting(*flags, "static-dir", "TRANSTICK_STATIC_DIR", "");
  auto max_sessions = IntSetting(*flags, "max-sessions", "TRANSTICK_MAX_SESSIONS", o.max_sessions, 1);
  auto idle = SecondsSetting(*flags, "idle-s", "TRANSTICK_IDLE_S", o.idle);
  for (const absl::Status& s : {max_sessions.status(), idle.status()}) {
    if (!s.ok()) {
      std::cerr << "transtick-web: " << s.message() << "\n";
      return 2;
    }
  }
  o.max_sessions = static_cast<int>(*max_sessions);
  o.idle = *idle;
  auto gateway = WebGateway::Start(o);
  if (!gateway.ok()) {
    spdlog::error("{}", std::string(gateway.status().message()));
    return 1;
  }
  spdlog::info("serving the viewer at {} for the root at {}", (*gateway)->url(), o.root);
  int sig = WaitForSignal();
  spdlog::info("signal {}: stopping", sig);
  gateway->reset();
  return 0;
}
