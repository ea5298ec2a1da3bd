// Keepalive on the cluster's connections, with its times shortened: a peer
// whose host vanishes (here a TCP forwarder that stops forwarding, and keeps
// its connections open: no FIN, no reset, as a powered-off host) is noticed
// by the streams that wait on it, and an idle stream whose client pings is
// not cut off by the server's ping policy.
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "cluster.grpc.pb.h"
#include "gtest/gtest.h"
#include "nodes_fixture.h"
#include "transtick/ray_codec.h"

namespace transtick {
namespace {

using std::chrono::milliseconds;
using Clock = std::chrono::steady_clock;
using testing::Eventually;

// A ping every 100 ms; an unanswered one closes the connection after a
// second (generous, for a loaded machine).
constexpr Keepalive kShort = {milliseconds(100), milliseconds(1000)};

// Forwards connections on 127.0.0.1 to `target_port`, until Freeze: from
// then on it reads and writes nothing and answers nothing, and keeps every
// connection open. Its own thread does the work.
class Forwarder {
 public:
  explicit Forwarder(int target_port) : target_port_(target_port) {
    listen_fd_ = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    EXPECT_EQ(bind(listen_fd_, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    EXPECT_EQ(listen(listen_fd_, 16), 0);
    socklen_t len = sizeof a;
    getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
    thread_ = std::thread([this] { Loop(); });
  }
  ~Forwarder() {
    stop_ = true;
    thread_.join();
    for (int fd : fds_) close(fd);
    close(listen_fd_);
  }

  std::string address() const { return absl::StrCat("127.0.0.1:", port_); }
  void Freeze() { frozen_ = true; }

 private:
  void Loop() {
    while (!stop_) {
      if (frozen_) {
        std::this_thread::sleep_for(milliseconds(10));
        continue;
      }
      std::vector<pollfd> polls = {{listen_fd_, POLLIN, 0}};
      for (int fd : fds_) polls.push_back({fd, POLLIN, 0});
      if (poll(polls.data(), polls.size(), 10) <= 0) continue;
      if (polls[0].revents & POLLIN) Accept();
      for (size_t i = 1; i < polls.size(); ++i) {
        if (!(polls[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
        // fds_ holds pairs: 2k is a client, 2k + 1 its connection upstream.
        const size_t k = i - 1;
        char buf[65536];
        const ssize_t n = read(fds_[k], buf, sizeof buf);
        if (n <= 0) return;  // a peer closed: the tests never get here
        for (ssize_t off = 0; off < n;) {
          const ssize_t w = write(fds_[k ^ 1], buf + off, n - off);
          if (w <= 0) return;
          off += w;
        }
      }
    }
  }
  void Accept() {
    const int client = accept(listen_fd_, nullptr, nullptr);
    const int upstream = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(target_port_);
    ASSERT_EQ(connect(upstream, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    fds_.push_back(client);
    fds_.push_back(upstream);
  }

  const int target_port_;
  int listen_fd_ = -1;
  int port_ = 0;
  std::vector<int> fds_;  // the loop's only, until it stops
  std::atomic<bool> frozen_{false}, stop_{false};
  std::thread thread_;
};

class KeepaliveTest : public testing::NodesTest {
 protected:
  // Before SetUp makes the servers and channels.
  KeepaliveTest() { SetKeepalive(kShort); }
  ~KeepaliveTest() override { SetKeepalive(Keepalive{}); }
};

// A worker's deposit stream reaches the display through a host that then
// vanishes, in the middle of a frame: the display notices by itself, and
// aborts the frame at once, as when a worker process dies.
TEST_F(KeepaliveTest, TheDisplayNoticesAWorkerWhoseHostVanished) {
  Forwarder to_display(display_->port());
  v1::FrameSpec spec = Spec(1);
  spec.set_display(to_display.address());
  spec.set_row_end(kSize / 2);  // half the image: the frame never completes
  ASSERT_TRUE(Begin(1).ok());
  ASSERT_TRUE(PrepareOnly(spec).ok());
  ASSERT_TRUE(Run(1).ok());
  std::this_thread::sleep_for(milliseconds(300));  // its deposits are in
  to_display.Freeze();
  const auto t0 = Clock::now();
  grpc::Status s = Await(1);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::ABORTED) << s.error_message();
  EXPECT_NE(s.error_message().find("a worker's deposit stream broke"), std::string::npos)
      << s.error_message();
  // Without keepalive the stream would wait for the frame's expiry (60 s).
  EXPECT_LT(Clock::now() - t0, milliseconds(5000));
}

// The left neighbour's host vanishes after the frame: the worker notices
// and lets go of the frame. Without keepalive the stream would hold the
// frame for ever, since a vanished host never closes its side.
TEST_F(KeepaliveTest, AWorkerNoticesALeftNeighbourWhoseHostVanished) {
  Forwarder to_worker(worker_->port());
  ASSERT_TRUE(Prepare(2).ok());
  auto stub = v1::Worker::NewStub(MakeChannel(to_worker.address(), Role::kWorker));
  grpc::ClientContext ctx;
  auto stream = stub->Rays(&ctx);
  v1::RayBatch hello;
  hello.set_frame_id(2);
  ASSERT_TRUE(stream->Write(hello));
  // The stream must hold the frame before it ends, or the hello finds no
  // frame and the stream closes at once.
  ASSERT_TRUE(Eventually([&] { return worker_service_->LeftAttached(2); }));
  ASSERT_TRUE(Run(2).ok());
  EXPECT_TRUE(Await(2).ok());
  ASSERT_TRUE(End(2).ok());
  ASSERT_TRUE(Eventually([] { return Frame::alive() == 1; }, milliseconds(5000))) << Frame::alive();
  to_worker.Freeze();
  EXPECT_TRUE(Eventually([] { return Frame::alive() == 0; }, milliseconds(5000))) << Frame::alive();
  EXPECT_FALSE(stream->Finish().ok());
}

// A stream that carries nothing for many keepalive periods, on a channel
// that pings, survives, and so does the connection: the server accepts the
// pings rather than answering GOAWAY ("too_many_pings"), which would make
// the channel reconnect for its next call.
TEST_F(KeepaliveTest, AnIdleStreamIsNotCutOff) {
  ASSERT_TRUE(Prepare(3).ok());
  auto channel = MakeChannel(worker_address_, Role::kWorker);
  auto stub = v1::Worker::NewStub(channel);
  grpc::ClientContext ctx;
  auto stream = stub->Rays(&ctx);
  v1::RayBatch batch;
  batch.set_frame_id(3);
  ASSERT_TRUE(stream->Write(batch));
  std::this_thread::sleep_for(50 * kShort.time);
  EXPECT_EQ(channel->GetState(false), GRPC_CHANNEL_READY);
  std::string records;
  AppendRay(CentreRay(), &records);
  PackRays(records, batch.mutable_packed());
  EXPECT_TRUE(stream->Write(batch));
  // Write returns once the batch is buffered: the worker must have read it
  // before the frame ends, or it is not counted.
  EXPECT_TRUE(Eventually([&] { return worker_service_->RaysReceivedLeft(3) == 1; }));
  auto stats = End(3, /*cancel=*/true);
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_EQ(stats->received_left(), 1u);
  stream->Finish();
}

}  // namespace
}  // namespace transtick
