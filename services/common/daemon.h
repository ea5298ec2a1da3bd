// Shared plumbing of the three daemons: mapping statuses across the gRPC
// boundary, serving with the standard health service, stopping on SIGTERM,
// and reading settings from flags or environment variables.
#ifndef TRANSTICK_SERVICES_COMMON_DAEMON_H_
#define TRANSTICK_SERVICES_COMMON_DAEMON_H_

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "flags.h"

namespace transtick {

// The one mapping between absl and gRPC statuses, at every service boundary.
grpc::Status ToGrpc(const absl::Status& status);
absl::Status FromGrpc(const grpc::Status& status);

// A gRPC server on one address, with the health service reporting SERVING.
// Owns the server; Shutdown is idempotent. Thread-safe.
class Server {
 public:
  // Binds `address` ("host:port"; port 0 picks one) and starts serving.
  static absl::StatusOr<std::unique_ptr<Server>> Start(const std::string& address,
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

// A channel with the cluster's message limits (large ray and image batches).
std::shared_ptr<grpc::Channel> MakeChannel(const std::string& address);

// A channel to `address` kept for the life of the process and shared by
// every caller with the same `purpose` ("rays", "deposits", ...), so that
// per-frame streams reuse a warm connection instead of opening one each
// frame. A channel whose peer has failed is replaced by a fresh one.
// Thread-safe.
std::shared_ptr<grpc::Channel> SharedChannel(const std::string& address,
                                             const std::string& purpose);

// A deadline `seconds` from now, for unary calls.
std::chrono::system_clock::time_point Deadline(double seconds);

// Replaces a trailing ":port" of `address` by the actual port (for ":0").
std::string WithPort(const std::string& address, int port);

// Sets up spdlog's default logger: "[time] [level] [name] message".
void InitLogging(const std::string& name);

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_COMMON_DAEMON_H_
