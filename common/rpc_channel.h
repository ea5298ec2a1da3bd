// Client channels as the cluster uses them: message limits large enough for
// ray and image batches, channels shared per peer and purpose, deadlines for
// unary calls. Used by the transtick command and by the daemons.
#ifndef TRANSTICK_COMMON_RPC_CHANNEL_H_
#define TRANSTICK_COMMON_RPC_CHANNEL_H_

#include <grpcpp/channel.h>

#include <chrono>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "security.h"

namespace transtick {

// The largest message a channel or a server of the cluster sends or
// receives, on both ends.
inline constexpr int kMaxMessageBytes = 64 << 20;

// How the cluster's channels and servers watch a connection that carries
// nothing: each end pings the other after `time` without activity, and
// closes the connection when a ping is not answered within `timeout`. The
// streams on it then fail, as when the peer's process dies, though a host
// that vanishes (powered off, partitioned) sends no reset. The defaults notice
// it within 15-20 s, and cost one small ping frame every 10 s on an idle
// connection (docs/design.md, "Connections").
struct Keepalive {
  std::chrono::milliseconds time = std::chrono::seconds(10);
  std::chrono::milliseconds timeout = std::chrono::seconds(5);
};
// Sets the keepalive of channels and servers made after the call (tests
// shorten it). Thread-safe.
void SetKeepalive(const Keepalive& keepalive);
Keepalive CurrentKeepalive();
// The gRPC channel arguments of the current keepalive, for a client channel
// or, with `server`, for a server, which must also accept the clients' pings
// (else it counts them as abuse and sends GOAWAY).
std::vector<std::pair<std::string, int>> KeepaliveArguments(bool server);

// A channel to a peer of `role` with the cluster's message limits,
// keepalive and security (security.h), and a connection of its own.
std::shared_ptr<grpc::Channel> MakeChannel(const std::string& address, Role role);

// A channel to `address` kept for the life of the process and shared by
// every caller with the same `purpose` ("rays", "deposits", ...), so that
// per-frame streams reuse a warm connection instead of opening one each
// frame. A channel whose peer has failed is replaced by a fresh one.
// Thread-safe.
std::shared_ptr<grpc::Channel> SharedChannel(const std::string& address, Role role,
                                             const std::string& purpose);

// A deadline `seconds` from now, for unary calls.
std::chrono::system_clock::time_point Deadline(double seconds);

// Replaces a trailing ":port" of `address` by the actual port (for ":0").
std::string WithPort(const std::string& address, int port);

}  // namespace transtick

#endif  // TRANSTICK_COMMON_RPC_CHANNEL_H_
