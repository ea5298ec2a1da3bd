#include "rpc_channel.h"

#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/support/channel_arguments.h>

#include <cstdint>
#include <map>
#include <mutex>

#include "absl/strings/str_cat.h"

namespace transtick {
namespace {

std::mutex keepalive_mu;
Keepalive keepalive;  // guarded by keepalive_mu

}  // namespace

void SetKeepalive(const Keepalive& k) {
  std::lock_guard<std::mutex> lock(keepalive_mu);
  keepalive = k;
}

Keepalive CurrentKeepalive() {
  std::lock_guard<std::mutex> lock(keepalive_mu);
  return keepalive;
}

std::vector<std::pair<std::string, int>> KeepaliveArguments(bool server) {
  const Keepalive k = CurrentKeepalive();
  std::vector<std::pair<std::string, int>> args = {
      {GRPC_ARG_KEEPALIVE_TIME_MS, static_cast<int>(k.time.count())},
      {GRPC_ARG_KEEPALIVE_TIMEOUT_MS, static_cast<int>(k.timeout.count())},
      // Pings also between frames, when a shared channel carries no call:
      // a peer that vanished then is noticed before the next frame needs it.
      {GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1},
      // Keep pinging a stream that sends nothing for long (a deposit stream
      // while its worker traces, an AwaitFrame): by default a channel stops
      // after two pings without data.
      {GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0},
  };
  if (server) {
    // A ping that comes sooner than this after the last one, while the
    // server sends nothing, is a strike; the third strike is answered with
    // GOAWAY ("too_many_pings"). The clients ping every `time`, so half of
    // it leaves room for timer jitter and keeps the strikes for real floods.
    args.push_back({GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS,
                    static_cast<int>(k.time.count() / 2)});
    args.push_back({GRPC_ARG_HTTP2_MAX_PING_STRIKES, 2});
  }
  return args;
}

std::shared_ptr<grpc::Channel> MakeChannel(const std::string& address, Role role) {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(kMaxMessageBytes);
  args.SetMaxSendMessageSize(kMaxMessageBytes);
  // Each channel gets its own connection: ray streams must not queue behind
  // slab transfers to the same peer.
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  // A peer that went away (a root restarting, a display rescheduled) is
  // tried again at most 1 s apart, not after gRPC's default backoff of up
  // to 120 s: a worker's heartbeat then finds a restarted root within a
  // second or two, and a frame's retry finds a display that is back.
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 250);
  // gRPC takes this as the least time a connection attempt (TCP and the TLS
  // handshake) is given, not as a backoff. 250 ms left a TLS handshake over
  // a slow link or with a loaded peer no margin; a peer that is down still
  // refuses at once, and the attempts stay 250 ms to 1 s apart.
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, 5000);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 1000);
  for (const auto& [name, value] : KeepaliveArguments(/*server=*/false)) args.SetInt(name, value);
  auto creds = ChannelCredentialsFor(role, &args);
  return grpc::CreateCustomChannel(address, creds, args);
}

std::shared_ptr<grpc::Channel> SharedChannel(const std::string& address, Role role,
                                             const std::string& purpose) {
  static std::mutex mu;
  static auto* channels = new std::map<std::string, std::shared_ptr<grpc::Channel>>();
  const std::string key = purpose + "|" + address;
  std::lock_guard<std::mutex> lock(mu);
  // Peers that went away for good (a worker replaced at a new port) would
  // otherwise leave their channels here for the life of the process.
  for (auto it = channels->begin(); it != channels->end();) {
    const auto state = it->second->GetState(false);
    if (it->first != key &&
        (state == GRPC_CHANNEL_TRANSIENT_FAILURE || state == GRPC_CHANNEL_SHUTDOWN)) {
      it = channels->erase(it);
    } else {
      ++it;
    }
  }
  auto& channel = (*channels)[key];
  // A peer that went away (and may be back at the same address) leaves its
  // channel failing; a fresh one connects at once instead of backing off.
  if (!channel || channel->GetState(false) == GRPC_CHANNEL_TRANSIENT_FAILURE ||
      channel->GetState(false) == GRPC_CHANNEL_SHUTDOWN) {
    channel = MakeChannel(address, role);
  }
  return channel;
}

std::chrono::system_clock::time_point Deadline(double seconds) {
  return std::chrono::system_clock::now() +
         std::chrono::microseconds(static_cast<int64_t>(seconds * 1e6));
}

std::string WithPort(const std::string& address, int port) {
  auto colon = address.rfind(':');
  std::string host = colon == std::string::npos ? address : address.substr(0, colon);
  return absl::StrCat(host, ":", port);
}

}  // namespace transtick
