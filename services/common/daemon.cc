#include "daemon.h"

#include <grpcpp/health_check_service_interface.h>
#include <malloc.h>
#include <signal.h>
#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdlib>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"

namespace transtick {

absl::StatusOr<std::unique_ptr<Server>> Server::Start(const std::string& address, Role self,
                                                      std::vector<grpc::Service*> services) {
  auto creds = ServerCredentialsFor(self, address);
  if (!creds.ok()) return creds.status();
  grpc::EnableDefaultHealthCheckService(true);
  grpc::ServerBuilder builder;
  auto server = std::unique_ptr<Server>(new Server());
  builder.AddListeningPort(address, *creds, &server->port_);
  builder.SetMaxReceiveMessageSize(kMaxMessageBytes);
  builder.SetMaxSendMessageSize(kMaxMessageBytes);
  // A client whose host vanished is noticed (its streams fail), and the
  // clients' own pings are accepted.
  for (const auto& [name, value] : KeepaliveArguments(/*server=*/true)) {
    builder.AddChannelArgument(name, value);
  }
  // Long-lived ray streams each hold a thread of the synchronous server.
  builder.SetSyncServerOption(grpc::ServerBuilder::SyncServerOption::MAX_POLLERS, 4);
  for (grpc::Service* s : services) builder.RegisterService(s);
  server->server_ = builder.BuildAndStart();
  if (!server->server_ || server->port_ == 0) {
    return absl::UnavailableError(absl::StrCat("cannot listen on ", address));
  }
  server->server_->GetHealthCheckService()->SetServingStatus(true);
  return server;
}

Server::~Server() { Shutdown(std::chrono::milliseconds(0)); }

void Server::Shutdown(std::chrono::milliseconds grace) {
  if (shut_down_ || !server_) return;
  shut_down_ = true;
  server_->GetHealthCheckService()->SetServingStatus(false);
  server_->Shutdown(std::chrono::system_clock::now() + grace);
  server_->Wait();
}

void Server::Wait() {
  if (server_) server_->Wait();
}

void BlockTerminationSignals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGINT);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
}

int WaitForSignal() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGINT);
  int sig = 0;
  sigwait(&set, &sig);
  return sig;
}

absl::Status UseDaemonSecurity(const Flags& flags) {
  auto security = SecurityFromFlags(flags, /*daemon=*/true);
  if (!security.ok()) return security.status();
  SetSecurity(*std::move(security));
  return absl::OkStatus();
}

std::string Setting(const Flags& flags, const std::string& flag, const char* env,
                    const std::string& fallback) {
  if (flags.Has(flag)) return flags.Get(flag);
  if (const char* v = std::getenv(env); v != nullptr && *v != '\0') return v;
  return fallback;
}

namespace {

// The setting as a number no smaller than `min` (`fallback` when unset);
// `whole` asks for an integer.
absl::StatusOr<double> Number(const Flags& flags, const std::string& flag, const char* env,
                              double fallback, double min, bool whole) {
  const std::string text = Setting(flags, flag, env, "");
  const std::string name = absl::StrCat("--", flag, " (or ", env, ")");
  double v = fallback;
  if (!text.empty() &&
      (!absl::SimpleAtod(text, &v) || !std::isfinite(v) || (whole && v != std::floor(v)))) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": '", text, "' is not ", whole ? "a whole number" : "a number"));
  }
  if (v < min) return absl::InvalidArgumentError(absl::StrCat(name, ": ", v, " is below ", min));
  return v;
}

}  // namespace

absl::StatusOr<int64_t> IntSetting(const Flags& flags, const std::string& flag, const char* env,
                                   int64_t fallback, int64_t min) {
  auto v = Number(flags, flag, env, static_cast<double>(fallback), static_cast<double>(min),
                  /*whole=*/true);
  if (!v.ok()) return v.status();
  return static_cast<int64_t>(*v);
}

absl::StatusOr<std::chrono::milliseconds> SecondsSetting(const Flags& flags,
                                                         const std::string& flag, const char* env,
                                                         std::chrono::milliseconds fallback) {
  auto v = Number(flags, flag, env, fallback.count() / 1e3, 0.01, /*whole=*/false);
  if (!v.ok()) return v.status();
  return std::chrono::milliseconds(static_cast<int64_t>(*v * 1e3));
}

void ReturnLargeBlocksToTheSystem() { mallopt(M_MMAP_THRESHOLD, 1 << 20); }

void InitLogging(const std::string& name) {
  spdlog::set_pattern(absl::StrCat("[%Y-%m-%d %H:%M:%S.%e] [%l] [", name, "] %v"));
  if (const char* level = std::getenv("TRANSTICK_LOG_LEVEL")) {
    spdlog::set_level(spdlog::level::from_str(level));
  }
}

}  // namespace transtick
