// delay_relay: a TCP relay that holds every byte for a fixed time before it
// passes it on, in both directions. bench/emulated_hosts.sh puts one in
// front of each daemon, in the daemon's network namespace, to give the
// emulated links their latency: the kernel here has no netem, and tc's
// tbf only limits the rate.
//
//   delay_relay --listen HOST:PORT --to HOST:PORT --delay-us N
//               [--stats FILE] [--max-buffer-mb N]
//
// Each accepted connection gets its own connection to --to, and each of
// its two directions a reader thread and a writer thread. The reader stamps
// what it reads with the time it arrived and queues it; the writer sends
// each chunk once its stamp is --delay-us old. So a connection through the
// relay sees one-way latency `delay` each way (a round trip of 2 x delay)
// on top of the links' own, and the relay adds no latency of its own
// beyond a thread wake-up (timer slack is set to 1 ns for that). The queue
// of a direction holds at most --max-buffer-mb (default 64): past it the
// reader stops reading, and TCP's flow control pushes back on the sender.
// At 10 Gbit/s and 5 ms, 6.25 MB are in flight.
//
// What this does not emulate: TCP's own window growth over a long round
// trip (the sender's TCP talks to the relay, near), packet loss and
// jitter. gRPC's HTTP/2 flow control does see the whole round trip, since
// its window updates pass through the relay like any other byte.
//
// --stats FILE: every 100 ms, when something changed, the relay rewrites
// FILE (by a rename, so a reader never sees half of it) with one line per
// peer address that connected:
//   PEER_IP BYTES_IN BYTES_OUT CONNECTIONS
// BYTES_IN are the bytes written towards --to (sent by the peer), BYTES_OUT
// the bytes written back to the peer, both counted when the relay has
// written them, so they include every protocol byte (TLS, HTTP/2, gRPC).
//
// Exit status: 2 for bad flags, 1 when the listening socket cannot be made.
// It runs until killed.

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

// Bytes a reader asks for at once: large enough for 10 Gbit/s at a few
// thousand reads a second.
constexpr size_t kReadBytes = 256 * 1024;
// A read shorter than this is copied into a chunk of its own size, so that
// many small messages in flight do not each hold kReadBytes.
constexpr size_t kCopyBelow = 16 * 1024;

struct Options {
  std::string listen, to;
  std::chrono::microseconds delay{0};
  std::string stats;
  size_t max_buffer = size_t{64} << 20;
};

// HOST:PORT (HOST an IPv4 address or a name) as a socket address.
bool Resolve(const std::string& hostport, sockaddr_storage* out, socklen_t* len) {
  const size_t colon = hostport.rfind(':');
  if (colon == std::string::npos) return false;
  std::string host = hostport.substr(0, colon);
  const std::string port = hostport.substr(colon + 1);
  if (host.size() >= 2 && host.front() == '[') host = host.substr(1, host.size() - 2);
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* res = nullptr;
  if (getaddrinfo(host.c_str(), port.c_str(), &hints, &res) != 0 || res == nullptr) return false;
  std::memcpy(out, res->ai_addr, res->ai_addrlen);
  *len = res->ai_addrlen;
  freeaddrinfo(res);
  return true;
}

std::string PeerIp(const sockaddr_storage& a) {
  char buf[INET6_ADDRSTRLEN] = "?";
  if (a.ss_family == AF_INET) {
    inet_ntop(AF_INET, &reinterpret_cast<const sockaddr_in&>(a).sin_addr, buf, sizeof(buf));
  } else if (a.ss_family == AF_INET6) {
    inet_ntop(AF_INET6, &reinterpret_cast<const sockaddr_in6&>(a).sin6_addr, buf, sizeof(buf));
  }
  return buf;
}

void NoDelay(int fd) {
  int one = 1;
  setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
}

// Byte counts per peer address, for --stats. Thread-safe.
class PeerStats {
 public:
  struct Counts {
    uint64_t in = 0, out = 0, connections = 0;
  };
  void Connected(const std::string& peer) {
    std::lock_guard<std::mutex> lock(mu_);
    ++peers_[peer].connections;
    ++version_;
  }
  void Written(const std::string& peer, bool towards_target, size_t bytes) {
    std::lock_guard<std::mutex> lock(mu_);
    Counts& c = peers_[peer];
    (towards_target ? c.in : c.out) += bytes;
    ++version_;
  }
  // The counts, and a number that changes whenever they do.
  std::map<std::string, Counts> Snapshot(uint64_t* version) {
    std::lock_guard<std::mutex> lock(mu_);
    *version = version_;
    return peers_;
  }

 private:
  std::mutex mu_;
  std::map<std::string, Counts> peers_;
  uint64_t version_ = 0;
};

// One direction of a relayed connection: bytes read from `from` wait in
// the queue until they are `delay` old, then are written to `to`.
// Thread-safe: one reader thread and one writer thread share it.
class Direction {
 public:
  Direction(int from, int to, bool towards_target, const Options& o, PeerStats& stats,
            std::string peer)
      : from_(from),
        to_(to),
        towards_target_(towards_target),
        delay_(o.delay),
        max_buffer_(o.max_buffer),
        stats_(stats),
        peer_(std::move(peer)) {}

  void ReadLoop() {
    std::vector<char> buf(kReadBytes);
    for (;;) {
      {
        std::unique_lock<std::mutex> lock(mu_);
        room_.wait(lock, [&] { return queued_ < max_buffer_ || failed_; });
        if (failed_) break;
      }
      const ssize_t n = read(from_, buf.data(), buf.size());
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;  // end of stream, or an error: either ends this direction
      Chunk c;
      c.at = Clock::now();
      if (static_cast<size_t>(n) < kCopyBelow) {
        c.bytes.assign(buf.begin(), buf.begin() + n);
      } else {
        c.bytes.swap(buf);
        c.bytes.resize(n);
        buf.assign(kReadBytes, 0);
      }
      std::lock_guard<std::mutex> lock(mu_);
      queued_ += c.bytes.size();
      chunks_.push_back(std::move(c));
      ready_.notify_one();
    }
    std::lock_guard<std::mutex> lock(mu_);
    eof_ = true;
    ready_.notify_one();
  }

  // Returns false when the write side broke (the peer went away).
  bool WriteLoop() {
    for (;;) {
      Chunk c;
      {
        std::unique_lock<std::mutex> lock(mu_);
        ready_.wait(lock, [&] { return !chunks_.empty() || eof_; });
        if (chunks_.empty()) break;  // eof and drained
        c = std::move(chunks_.front());
        chunks_.pop_front();
      }
      std::this_thread::sleep_until(c.at + delay_);
      size_t done = 0;
      while (done < c.bytes.size()) {
        const ssize_t n = send(to_, c.bytes.data() + done, c.bytes.size() - done, MSG_NOSIGNAL);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
          Fail();
          return false;
        }
        done += static_cast<size_t>(n);
      }
      stats_.Written(peer_, towards_target_, c.bytes.size());
      std::lock_guard<std::mutex> lock(mu_);
      queued_ -= c.bytes.size();
      room_.notify_one();
    }
    shutdown(to_, SHUT_WR);  // pass the half-close on, after the last byte
    return true;
  }

  // The other direction broke: this one stops too.
  void Fail() {
    shutdown(from_, SHUT_RDWR);
    std::lock_guard<std::mutex> lock(mu_);
    failed_ = true;
    room_.notify_one();
  }

 private:
  struct Chunk {
    Clock::time_point at;
    std::vector<char> bytes;
  };
  const int from_, to_;
  const bool towards_target_;
  const std::chrono::microseconds delay_;
  const size_t max_buffer_;
  PeerStats& stats_;
  const std::string peer_;

  std::mutex mu_;
  std::condition_variable ready_, room_;
  std::deque<Chunk> chunks_;  // guarded by mu_, as are the three below
  size_t queued_ = 0;
  bool eof_ = false;
  bool failed_ = false;
};

// A relayed connection: the accepted socket, the one to the target, and
// the two directions. Owned by its four threads; the last one out closes
// both sockets.
class Connection {
 public:
  Connection(int client, int target, const Options& o, PeerStats& stats, const std::string& peer)
      : client_(client),
        target_(target),
        up_(client, target, /*towards_target=*/true, o, stats, peer),
        down_(target, client, /*towards_target=*/false, o, stats, peer) {}
  ~Connection() {
    close(client_);
    close(target_);
  }
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  static void Run(std::shared_ptr<Connection> c) {
    std::thread([c] { c->up_.ReadLoop(); }).detach();
    std::thread([c] { c->down_.ReadLoop(); }).detach();
    std::thread([c] {
      if (!c->up_.WriteLoop()) c->down_.Fail();
    }).detach();
    std::thread([c] {
      if (!c->down_.WriteLoop()) c->up_.Fail();
    }).detach();
  }

 private:
  const int client_, target_;
  Direction up_, down_;
};

void WriteStats(const std::string& path, PeerStats& stats) {
  uint64_t written = ~uint64_t{0};
  for (;;) {
    uint64_t version;
    auto peers = stats.Snapshot(&version);
    if (version != written) {
      const std::string tmp = path + ".tmp";
      {
        std::ofstream f(tmp, std::ios::trunc);
        for (const auto& [peer, c] : peers) {
          f << peer << " " << c.in << " " << c.out << " " << c.connections << "\n";
        }
      }
      if (std::rename(tmp.c_str(), path.c_str()) == 0) written = version;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
}

int Usage(const char* why) {
  std::fprintf(stderr,
               "delay_relay: %s\nusage: delay_relay --listen HOST:PORT --to HOST:PORT "
               "--delay-us N [--stats FILE] [--max-buffer-mb N]\n",
               why);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (i + 1 >= argc) return Usage(("no value for " + flag).c_str());
    const std::string value = argv[++i];
    char* end = nullptr;
    if (flag == "--listen") {
      o.listen = value;
    } else if (flag == "--to") {
      o.to = value;
    } else if (flag == "--delay-us") {
      const long long us = std::strtoll(value.c_str(), &end, 10);
      if (*end != '\0' || us < 0 || us > 10'000'000) return Usage("--delay-us is 0 .. 10000000");
      o.delay = std::chrono::microseconds(us);
    } else if (flag == "--stats") {
      o.stats = value;
    } else if (flag == "--max-buffer-mb") {
      const long long mb = std::strtoll(value.c_str(), &end, 10);
      if (*end != '\0' || mb < 1 || mb > 4096) return Usage("--max-buffer-mb is 1 .. 4096");
      o.max_buffer = static_cast<size_t>(mb) << 20;
    } else {
      return Usage(("unknown flag " + flag).c_str());
    }
  }
  if (o.listen.empty() || o.to.empty()) return Usage("--listen and --to are required");
  sockaddr_storage listen_addr{}, to_addr{};
  socklen_t listen_len = 0, to_len = 0;
  if (!Resolve(o.listen, &listen_addr, &listen_len)) return Usage("--listen is not HOST:PORT");
  if (!Resolve(o.to, &to_addr, &to_len)) return Usage("--to is not HOST:PORT");

  // Threads made from here on inherit it: sleeps end within microseconds of
  // their time instead of the default 50 us slack, which is the whole
  // delay of the shortest emulated link.
  prctl(PR_SET_TIMERSLACK, 1UL, 0, 0, 0);
  signal(SIGPIPE, SIG_IGN);

  const int lfd = socket(listen_addr.ss_family, SOCK_STREAM | SOCK_CLOEXEC, 0);
  int one = 1;
  setsockopt(lfd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
  if (lfd < 0 || bind(lfd, reinterpret_cast<sockaddr*>(&listen_addr), listen_len) != 0 ||
      listen(lfd, 128) != 0) {
    std::fprintf(stderr, "delay_relay: cannot listen on %s: %s\n", o.listen.c_str(),
                 std::strerror(errno));
    return 1;
  }
  PeerStats stats;
  if (!o.stats.empty()) std::thread(WriteStats, o.stats, std::ref(stats)).detach();
  for (;;) {
    sockaddr_storage peer{};
    socklen_t peer_len = sizeof(peer);
    const int client = accept4(lfd, reinterpret_cast<sockaddr*>(&peer), &peer_len, SOCK_CLOEXEC);
    if (client < 0) {
      if (errno == EINTR || errno == ECONNABORTED) continue;
      // Out of descriptors or memory: wait rather than spin.
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      continue;
    }
    const int target = socket(to_addr.ss_family, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (target < 0 || connect(target, reinterpret_cast<sockaddr*>(&to_addr), to_len) != 0) {
      // The daemon behind is not up (yet): the peer sees the connection
      // close, as it would see a refused one, and retries.
      if (target >= 0) close(target);
      close(client);
      continue;
    }
    NoDelay(client);
    NoDelay(target);
    const std::string ip = PeerIp(peer);
    stats.Connected(ip);
    Connection::Run(std::make_shared<Connection>(client, target, o, stats, ip));
  }
}
