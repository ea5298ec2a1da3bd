#include "daemon.h"

#include <grpcpp/ext/channelz_service_plugin.h>
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <signal.h>
#include <spdlog/pattern_formatter.h>
#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdlib>
#include <fstream>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/synchronization/mutex.h"

namespace transtick {

absl::StatusOr<std::unique_ptr<Server>> Server::Start(const std::string& address, Role self,
                                                      std::vector<grpc::Service*> services) {
  auto creds = ServerCredentialsFor(self, address);
  if (!creds.ok()) return creds.status();
  grpc::EnableDefaultHealthCheckService(true);
  // Server reflection (grpcurl can list and call the services) and channelz
  // (the channels' and sockets' counters) on every daemon. Both pass the same
  // credentials and, at the root, the same token check as the API.
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::channelz::experimental::InitChannelzService();
  grpc::ServerBuilder builder;
  auto server = std::unique_ptr<Server>(new Server());
  builder.AddListeningPort(address, *creds, &server->port_);
  // No SO_REUSEPORT: with it a second daemon on a taken port shares it
  // silently (its connections split between the two), and a port-0 listener
  // may be given a port another daemon holds (a worker was seen taking the
  // root's).
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
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

absl::StatusOr<MetricsEndpoint> MetricsAddress(const Flags& flags, const std::string& listen) {
  const std::string set = Setting(flags, "metrics", "TRANSTICK_METRICS", "");
  if (set == "off") return MetricsEndpoint{"", false};
  const std::string address = set.empty() ? listen : set;
  const size_t colon = address.rfind(':');
  int port = -1;
  if (colon == std::string::npos || !absl::SimpleAtoi(address.substr(colon + 1), &port) ||
      port < 0 || port > 65535) {
    return absl::InvalidArgumentError(absl::StrCat(
        set.empty() ? "--listen '" : "--metrics '", address, "' is not HOST:PORT"));
  }
  if (!set.empty()) return MetricsEndpoint{set, true};
  if (port == 0) return MetricsEndpoint{address, false};
  if (port + 100 > 65535) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--listen port ", port, " leaves no port + 100 for metrics: give --metrics ADDR or off"));
  }
  return MetricsEndpoint{absl::StrCat(address.substr(0, colon), ":", port + 100), false};
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

namespace {

// %j in a pattern: the message as the inside of a JSON string (quotes,
// backslashes and control characters escaped), for JSON lines.
class JsonMessage : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&,
              spdlog::memory_buf_t& dest) override {
    static constexpr char kHex[] = "0123456789abcdef";
    for (char c : std::string_view(msg.payload.data(), msg.payload.size())) {
      const auto u = static_cast<unsigned char>(c);
      if (c == '"' || c == '\\') {
        dest.push_back('\\');
        dest.push_back(c);
      } else if (u < 0x20) {
        for (char e : {'\\', 'u', '0', '0', kHex[u >> 4], kHex[u & 15]}) dest.push_back(e);
      } else {
        dest.push_back(c);
      }
    }
  }
  std::unique_ptr<custom_flag_formatter> clone() const override {
    return std::make_unique<JsonMessage>();
  }
};

}  // namespace

void UseReleaseLocking() {
#ifdef NDEBUG
  absl::SetMutexDeadlockDetectionMode(absl::OnDeadlockCycle::kIgnore);
#endif
}

void InitLogging(const std::string& name) {
  const char* format = std::getenv("TRANSTICK_LOG_FORMAT");
  if (format != nullptr && std::string_view(format) == "json") {
    // One JSON object per line: time (UTC), level, daemon, message.
    auto formatter = std::make_unique<spdlog::pattern_formatter>(spdlog::pattern_time_type::utc);
    formatter->add_flag<JsonMessage>('j').set_pattern(absl::StrCat(
        R"({"time":"%Y-%m-%dT%H:%M:%S.%eZ","level":"%l","daemon":")", name, R"(","msg":"%j"})"));
    spdlog::set_formatter(std::move(formatter));
  } else {
    spdlog::set_pattern(absl::StrCat("[%Y-%m-%d %H:%M:%S.%e] [%l] [", name, "] %v"));
  }
  if (const char* level = std::getenv("TRANSTICK_LOG_LEVEL")) {
    spdlog::set_level(spdlog::level::from_str(level));
  }
}

std::string MachineId() {
  std::ifstream in("/proc/sys/kernel/random/boot_id");
  std::string id;
  if (!std::getline(in, id) || id.size() > 64) return "";
  return id;
}

}  // namespace transtick
