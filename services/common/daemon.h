// Shared plumbing of the three daemons: serving with the standard health
// service, stopping on SIGTERM, logging, and reading settings from flags or
// environment variables.
//
// The daemons also speak to each other, and this header brings the common
// layer's RPC helpers with it: ToGrpc/FromGrpc (rpc_status.h), MakeChannel,
// SharedChannel and Deadline (rpc_channel.h), and Flags (flags.h).
#ifndef TRANSTICK_SERVICES_COMMON_DAEMON_H_
#define TRANSTICK_SERVICES_COMMON_DAEMON_H_

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "flags.h"
#include "metrics.h"
#include "rpc_channel.h"
#include "rpc_status.h"

namespace transtick {

// A gRPC server on one address, with the health service reporting SERVING.
// Owns the server; Shutdown is idempotent. Thread-safe.
class Server {
 public:
  // Binds `address` ("host:port"; port 0 picks one) and starts serving as
  // `self`, with the process's security (security.h).
  static absl::StatusOr<std::unique_ptr<Server>> Start(const std::string& address, Role self,
                                                       std::vector<grpc::Service*> services);
  ~Server();

  int port() const { return port_; }
  // Stops accepting calls and waits up to `grace` for calls in flight, then
  // cancels what remains.
  void Shutdown(std::chrono::milliseconds grace);
  void Wait();

 private:
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  bool shut_down_ = false;
};

// Blocks SIGTERM and SIGINT in the calling thread (call before starting any
// thread, so every thread inherits the mask) and returns; WaitForSignal then
// waits for one and returns its number.
void BlockTerminationSignals();
int WaitForSignal();

// The value of --flag, else $ENV, else `fallback`.
std::string Setting(const Flags& flags, const std::string& flag, const char* env,
                    const std::string& fallback);
// Setting, as a whole number no smaller than `min`; fails INVALID_ARGUMENT
// naming the flag and the environment variable.
absl::StatusOr<int64_t> IntSetting(const Flags& flags, const std::string& flag, const char* env,
                                   int64_t fallback, int64_t min);
// Setting, in seconds (fractions allowed), as a duration of at least 10 ms.
absl::StatusOr<std::chrono::milliseconds> SecondsSetting(const Flags& flags,
                                                         const std::string& flag, const char* env,
                                                         std::chrono::milliseconds fallback);

// Where the daemon serves /metrics (metrics.h): --metrics or
// $TRANSTICK_METRICS, "off" for nowhere (""), by default the gRPC address
// `listen` with its port + 100 (7000 -> 7100; port 0 stays 0). An error
// names a malformed address.
absl::StatusOr<MetricsEndpoint> MetricsAddress(const Flags& flags, const std::string& listen);

// Reads the daemon's TLS flags (security.h) and makes them the process's.
absl::Status UseDaemonSecurity(const Flags& flags);

// Sets up spdlog's default logger: "[time] [level] [name] message".
void InitLogging(const std::string& name);

// In a release build (NDEBUG), turns off absl::Mutex's deadlock detection
// for the process; a debug build keeps it. Debian's Abseil is built without
// NDEBUG, so by default every Lock, ours and gRPC's, also records the lock
// order in a process-wide graph under one global lock: a lock and unlock
// took 47 ns against 20 without, and the graph's lock is one more that
// every thread of the process shares. Every daemon and the CLI call this
// first; the tests, which build their clusters in their own process, keep
// the detection.
void UseReleaseLocking();

// The kernel's boot id: the same for every process of one machine, in any
// container or network namespace; empty when unreadable.
std::string MachineId();

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_COMMON_DAEMON_H_
