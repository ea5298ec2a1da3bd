// The cluster's security with real processes and real certificates
// (docs/security.md): a display, a root and a worker serving TLS with
// certificates that deploy/make-certs.sh makes, and callers that hold the
// wrong certificate, none, a certificate of the wrong role, no token or
// another client's token.
#include <fcntl.h>
#include <grpcpp/grpcpp.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "cluster.grpc.pb.h"
#include "gtest/gtest.h"
#include "reflection_client.h"

extern char** environ;

namespace transtick {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;

std::string Slurp(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

int FreePort() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t n = sizeof a;
  getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n);
  close(fd);
  return ntohs(a.sin_port);
}

// A daemon process, its output in `log`; SIGTERM, then SIGKILL, when it goes.
class Process {
 public:
  Process(std::vector<std::string> args, const fs::path& log) : log_(log) {
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    if (posix_spawn(&pid_, argv[0], &fa, nullptr, argv.data(), environ) != 0) pid_ = -1;
    posix_spawn_file_actions_destroy(&fa);
  }
  ~Process() {
    if (pid_ <= 0) return;
    kill(pid_, SIGTERM);
    for (int i = 0; i < 100; ++i) {
      if (waitpid(pid_, nullptr, WNOHANG) == pid_) return;
      std::this_thread::sleep_for(milliseconds(50));
    }
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
  }
  std::string log() const { return Slurp(log_); }
  // The exit status once the process ends within `ms`, else -1.
  int WaitExit(int ms) {
    for (int i = 0; i < ms / 20; ++i) {
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128;
      }
      std::this_thread::sleep_for(milliseconds(20));
    }
    return -1;
  }

 private:
  pid_t pid_ = -1;
  fs::path log_;
};

struct Creds {
  std::string ca, cert, key;  // PEM; no CA: plaintext
};

// A channel to `address` whose server must prove `role` (its certificate's
// name), presenting `creds`' certificate if it has one.
std::shared_ptr<grpc::Channel> Dial(const std::string& address, const std::string& role,
                                    const Creds& creds) {
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  if (creds.ca.empty()) {
    return grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), args);
  }
  args.SetSslTargetNameOverride(role);
  grpc::SslCredentialsOptions o;
  o.pem_root_certs = creds.ca;
  o.pem_cert_chain = creds.cert;
  o.pem_private_key = creds.key;
  return grpc::CreateCustomChannel(address, grpc::SslCredentials(o), args);
}

void Prepare(grpc::ClientContext* ctx, const std::string& token = "") {
  ctx->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  if (!token.empty()) ctx->AddMetadata("authorization", "Bearer " + token);
}

// A 16^3 uint8 volume, values 0..255 along x.
void WriteVolume(const fs::path& path) {
  std::ofstream out(path, std::ios::binary);
  out << "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 16 16 16\nencoding: raw\n\n";
  for (int i = 0; i < 16 * 16 * 16; ++i) out.put(static_cast<char>((i % 16) * 16));
}

v1::Job SmallJob(const std::string& name, const std::vector<std::string>& volumes) {
  v1::Job job;
  job.set_name(name);
  for (const std::string& v : volumes) {
    v1::Dataset* d = job.add_datasets();
    d->set_volume(v);
    v1::Material* m = d->mutable_materials()->add_materials();
    m->set_name("m");
    m->set_min(100);
    m->set_max(255);
    for (float c : {1.0f, 0.5f, 0.2f}) m->add_color(c);
    v1::View* view = d->add_views();
    view->set_azimuth(30);
    view->set_width(32);
    view->set_height(32);
  }
  return job;
}

// Watches a job to its end; returns its last event.
v1::JobEvent WatchToEnd(v1::Root::Stub& root, const std::string& id, const std::string& token) {
  grpc::ClientContext ctx;
  Prepare(&ctx, token);
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  v1::WatchRequest req;
  req.set_job_id(id);
  auto reader = root.Watch(&ctx, req);
  v1::JobEvent e, last;
  while (reader->Read(&e)) last = e;
  reader->Finish();
  return last;
}

class SecurityTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() /
                        absl::StrCat("transtick-security-", getpid()));
    fs::remove_all(*dir_);
    fs::create_directories(*dir_ / "data");
    const std::string make = absl::StrCat(TRANSTICK_SOURCE_DIR, "/deploy/make-certs.sh ");
    ASSERT_EQ(std::system((make + (*dir_ / "certs").string() + " 2>/dev/null").c_str()), 0);
    // Another cluster's: right names, wrong CA.
    ASSERT_EQ(std::system((make + (*dir_ / "rogue").string() + " 2>/dev/null").c_str()), 0);
    WriteVolume(*dir_ / "data" / "a.nrrd");
    WriteVolume(*dir_ / "data" / "b.nrrd");
    WriteVolume(*dir_ / "outside.nrrd");
    // The tokens: two clients and an admin.
    std::ofstream(*dir_ / "tokens") << "alice alice-token-0123456789\n"
                                       "bob bob-token-0123456789abc\n"
                                       "boss boss-token-0123456789ab admin\n";
    root_port_ = FreePort();
    display_port_ = FreePort();
    root_metrics_port_ = FreePort();
    display_ = new Process(Daemon("display", {"--listen", Address(display_port_)}),
                           *dir_ / "display.log");
    root_ = new Process(
        Daemon("root", {"--listen", Address(root_port_), "--display", Address(display_port_),
                        "--data-dir", (*dir_ / "data").string(), "--tokens",
                        (*dir_ / "tokens").string(), "--metrics",
                        Address(root_metrics_port_)}),
        *dir_ / "root.log");
  }
  static void TearDownTestSuite() {
    delete worker_;
    delete root_;
    delete display_;
    fs::remove_all(*dir_);
    delete dir_;
  }

  static std::string Address(int port) { return absl::StrCat("127.0.0.1:", port); }
  static std::vector<std::string> Daemon(const std::string& role, std::vector<std::string> args) {
    std::vector<std::string> a = {
        absl::StrCat(TRANSTICK_BINARY_DIR, "/services/", role, "/transtick-", role)};
    a.insert(a.end(), args.begin(), args.end());
    const fs::path c = *dir_ / "certs";
    for (const std::string& s : {std::string("--tls-ca"), (c / "ca.crt").string(),
                                 std::string("--tls-cert"), (c / (role + ".crt")).string(),
                                 std::string("--tls-key"), (c / (role + ".key")).string()}) {
      a.push_back(s);
    }
    return a;
  }
  // The worker, started when a test first needs it.
  static void StartWorker() {
    if (worker_) return;
    worker_port_ = FreePort();
    worker_ = new Process(Daemon("worker", {"--root", Address(root_port_), "--listen",
                                            Address(worker_port_), "--threads", "1"}),
                          *dir_ / "worker.log");
  }

  static Creds Certs(const std::string& set, const std::string& role) {
    const fs::path c = *dir_ / set;
    return {Slurp(c / "ca.crt"), role.empty() ? "" : Slurp(c / (role + ".crt")),
            role.empty() ? "" : Slurp(c / (role + ".key"))};
  }
  static Creds Cluster(const std::string& role = "") { return Certs("certs", role); }

  std::unique_ptr<v1::Root::Stub> RootAs(const Creds& creds) {
    return v1::Root::NewStub(Dial(Address(root_port_), "transtick-root", creds));
  }
  std::unique_ptr<v1::Worker::Stub> WorkerAs(const Creds& creds) {
    StartWorker();
    return v1::Worker::NewStub(Dial(Address(worker_port_), "transtick-worker", creds));
  }
  std::unique_ptr<v1::Display::Stub> DisplayAs(const Creds& creds) {
    return v1::Display::NewStub(Dial(Address(display_port_), "transtick-display", creds));
  }

  grpc::Status Submit(v1::Root::Stub& root, const v1::Job& job, const std::string& token,
                      std::string* id = nullptr, bool wait_for_ready = true) {
    grpc::ClientContext ctx;
    Prepare(&ctx, token);
    ctx.set_wait_for_ready(wait_for_ready);
    v1::SubmitReply reply;
    grpc::Status s = root.Submit(&ctx, job, &reply);
    if (id) *id = reply.job_id();
    return s;
  }
  static bool Eventually(const std::function<bool()>& done) {
    for (int i = 0; i < 400; ++i) {
      if (done()) return true;
      std::this_thread::sleep_for(milliseconds(25));
    }
    return false;
  }

  static constexpr char kAlice[] = "alice-token-0123456789";
  static constexpr char kBob[] = "bob-token-0123456789abc";
  static constexpr char kBoss[] = "boss-token-0123456789ab";
  static inline fs::path* dir_ = nullptr;
  static inline Process *display_ = nullptr, *root_ = nullptr, *worker_ = nullptr;
  static inline int root_port_ = 0, display_port_ = 0, worker_port_ = 0, root_metrics_port_ = 0;
};

// Every RPC a client can make, with no token, a wrong one, or over
// plaintext to a TLS port: none gets in.
TEST_F(SecurityTest, AClientWithoutATokenCannotSubmitWatchCancelOrList) {
  for (const std::string token : {"", "not-a-token-of-this-root"}) {
    auto root = RootAs(Cluster());
    EXPECT_EQ(Submit(*root, SmallJob("x", {"a.nrrd"}), token).error_code(),
              grpc::StatusCode::UNAUTHENTICATED);
    {
      grpc::ClientContext ctx;
      Prepare(&ctx, token);
      v1::StatusReply reply;
      EXPECT_EQ(root->Status(&ctx, {}, &reply).error_code(), grpc::StatusCode::UNAUTHENTICATED);
    }
    {
      grpc::ClientContext ctx;
      Prepare(&ctx, token);
      v1::VolumesReply reply;
      EXPECT_EQ(root->Volumes(&ctx, {}, &reply).error_code(), grpc::StatusCode::UNAUTHENTICATED);
    }
    {
      grpc::ClientContext ctx;
      Prepare(&ctx, token);
      v1::JobRef ref;
      ref.set_job_id("job-1");
      v1::CancelReply reply;
      EXPECT_EQ(root->Cancel(&ctx, ref, &reply).error_code(), grpc::StatusCode::UNAUTHENTICATED);
    }
    {
      grpc::ClientContext ctx;
      Prepare(&ctx, token);
      v1::WatchRequest req;
      req.set_job_id("job-1");
      auto reader = root->Watch(&ctx, req);
      v1::JobEvent e;
      EXPECT_FALSE(reader->Read(&e));
      EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::UNAUTHENTICATED);
    }
  }
  // Plaintext to the TLS port, even with a valid token.
  auto plain = RootAs(Creds{});
  EXPECT_EQ(Submit(*plain, SmallJob("x", {"a.nrrd"}), kAlice, nullptr, false).error_code(),
            grpc::StatusCode::UNAVAILABLE);
}

// The web gateway holds no token: each browser's goes to the root with its
// requests, so a page without one gets nothing, and a client's session
// answers nobody else. Off loopback it serves only HTTPS.
TEST_F(SecurityTest, TheWebGatewayPassesEachBrowsersTokenOn) {
  StartWorker();
  const fs::path body = *dir_ / "web-body.txt";
  // curl's HTTP status for `args` (0 when nothing answered); the body in `body`.
  auto curl = [&](const std::string& args) {
    fs::remove(body);
    const fs::path code = *dir_ / "web-code.txt";
    std::system(absl::StrCat("curl -s -m 20 -o ", body.string(), " -w '%{http_code}' ", args,
                             " > ", code.string(), " 2>/dev/null").c_str());
    return std::atoi(Slurp(code).c_str());
  };
  auto bearer = [](const std::string& token) {
    return absl::StrCat("-H 'Authorization: Bearer ", token, "' ");
  };
  const std::vector<std::string> web = {
      absl::StrCat(TRANSTICK_BINARY_DIR, "/services/web/transtick-web"), "--root",
      Address(root_port_), "--tls-ca", (*dir_ / "certs" / "ca.crt").string()};
  auto with = [&](std::vector<std::string> more) {
    std::vector<std::string> a = web;
    a.insert(a.end(), more.begin(), more.end());
    return a;
  };
  // Each gateway picks its port (a free port chosen here could be the one
  // the root has not bound yet) and logs where it serves.
  auto served_at = [](const Process& p) {
    std::string url;
    Eventually([&] {
      const std::string log = p.log();
      const size_t at = log.find("serving the viewer at ");
      if (at == std::string::npos) return false;
      url = log.substr(at + 22, log.find('/', log.find("//", at) + 2) - at - 22);
      return true;
    });
    return url;
  };
  Process gateway(with({"--listen", "127.0.0.1:0"}), *dir_ / "web.log");
  const std::string url = served_at(gateway);
  ASSERT_TRUE(Eventually([&] { return curl(url + "/healthz") == 200; })) << gateway.log();

  // The root may still be starting when this test runs first.
  ASSERT_TRUE(Eventually([&] { return curl(bearer(kAlice) + url + "/api/status") == 200; }))
      << Slurp(body);
  EXPECT_EQ(curl(url + "/api/config"), 200);
  EXPECT_NE(Slurp(body).find("\"auth\":true"), std::string::npos) << Slurp(body);
  EXPECT_EQ(curl(url + "/api/status"), 401);
  EXPECT_NE(Slurp(body).find("Bearer"), std::string::npos) << Slurp(body);
  EXPECT_EQ(curl(bearer("not-a-token-of-this-root") + url + "/api/status"), 401);
  EXPECT_EQ(curl(bearer("bad\x01") + url + "/api/volumes"), 401);
  EXPECT_EQ(curl("-X POST -H 'Content-Type: application/json' -d '{}' " + url +
                 "/api/jobs/job-1/cancel"), 401);
  EXPECT_EQ(curl(bearer(kAlice) + url + "/api/status"), 200) << Slurp(body);
  EXPECT_NE(Slurp(body).find("\"workers\""), std::string::npos);
  EXPECT_EQ(curl(bearer(kAlice) + url + "/api/volumes"), 200) << Slurp(body);
  EXPECT_NE(Slurp(body).find("a.nrrd"), std::string::npos);
  EXPECT_EQ(Slurp(body).find("outside"), std::string::npos);

  const std::string open =
      R"({"dataset": {"volume": "a.nrrd", "preset": {"name": "grey"}, )"
      R"("views": [{"width": 32, "height": 32}]}})";
  const std::string post = "-X POST -H 'Content-Type: application/json' -d '" + open + "' ";
  EXPECT_EQ(curl(post + url + "/api/sessions"), 401);
  ASSERT_EQ(curl(bearer(kAlice) + post + url + "/api/sessions"), 200) << Slurp(body);
  const std::string reply = Slurp(body);
  const size_t at = reply.find("\"session\":\"");
  ASSERT_NE(at, std::string::npos) << reply;
  const std::string id = reply.substr(at + 11, 32);
  const std::string events = url + "/api/sessions/" + id + "/events?wait=0";
  EXPECT_EQ(curl(bearer(kBob) + events), 404) << "Bob reads Alice's session";
  EXPECT_EQ(curl(bearer(kBoss) + events), 404) << "an admin reads Alice's session";
  EXPECT_EQ(curl(events), 401);
  EXPECT_EQ(curl(bearer(kAlice) + events), 200) << Slurp(body);
  EXPECT_EQ(curl(bearer(kBob) + "-X DELETE " + url + "/api/sessions/" + id), 404);

  // Off loopback: tokens would cross in the clear, so plaintext is refused...
  Process plain(with({"--listen", "0.0.0.0:0"}), *dir_ / "web-plain.log");
  EXPECT_EQ(plain.WaitExit(10000), 1);
  EXPECT_NE(plain.log().find("--https-cert"), std::string::npos) << plain.log();
  // ...and HTTPS with a certificate of the gateway's own serves.
  const fs::path cert = *dir_ / "web.crt", key = *dir_ / "web.key";
  ASSERT_EQ(std::system(absl::StrCat("openssl req -x509 -newkey rsa:2048 -nodes -days 2 -subj "
                                     "/CN=localhost -addext subjectAltName=IP:127.0.0.1 -keyout ",
                                     key.string(), " -out ", cert.string(), " 2>/dev/null")
                            .c_str()),
            0);
  Process secure(with({"--listen", "0.0.0.0:0", "--https-cert", cert.string(), "--https-key",
                       key.string()}),
                 *dir_ / "web-https.log");
  const std::string https = served_at(secure);
  ASSERT_EQ(https.substr(0, 8), "https://") << secure.log();
  ASSERT_TRUE(Eventually([&] {
    return curl("--cacert " + cert.string() + " " + https + "/healthz") == 200;
  })) << secure.log();
  EXPECT_EQ(curl("--cacert " + cert.string() + " " + bearer(kAlice) + https + "/api/status"), 200);
  EXPECT_EQ(curl("http://" + https.substr(8) + "/healthz"), 0)
      << "plaintext answered on the HTTPS port";
}

// Server reflection passes the root's token check like the API; /metrics
// is HTTPS with the root's certificate, which a scraper checks against the
// cluster's CA (and then under the name transtick-root).
TEST_F(SecurityTest, ReflectionNeedsATokenAndMetricsAreHttpsOnly) {
  grpc::Status status;
  const auto channel = Dial(Address(root_port_), "transtick-root", Cluster());
  testing::ReflectedServices(channel, "", &status);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAUTHENTICATED) << status.error_message();
  const std::string listed = testing::ReflectedServices(channel, kAlice, &status);
  EXPECT_TRUE(status.ok()) << status.error_message();
  EXPECT_NE(listed.find("transtick.v1.Root"), std::string::npos);

  const std::string url = absl::StrCat("transtick-root:", root_metrics_port_, "/metrics");
  const std::string resolve =
      absl::StrCat("--resolve transtick-root:", root_metrics_port_, ":127.0.0.1 ");
  const fs::path out = *dir_ / "metrics.txt";
  auto curl = [&](const std::string& args) {
    fs::remove(out);
    return std::system(absl::StrCat("curl -s -f -m 10 -o ", out.string(), " ", resolve, args,
                                    " 2>/dev/null")
                           .c_str());
  };
  EXPECT_EQ(curl(absl::StrCat("--cacert ", (*dir_ / "certs" / "ca.crt").string(), " https://", url)),
            0);
  EXPECT_NE(Slurp(out).find("transtick_root_workers"), std::string::npos);
  EXPECT_NE(curl(absl::StrCat("--cacert ", (*dir_ / "rogue" / "ca.crt").string(), " https://", url)),
            0) << "another CA's scraper trusts the root";
  EXPECT_NE(curl(absl::StrCat("http://", url)), 0) << "plaintext HTTP answered on a TLS port";
}

// Alice's job is hers: Bob can neither watch nor cancel it, nor see it in
// Status; the admin sees it. And it renders, through TLS on every hop.
TEST_F(SecurityTest, AClientCannotWatchOrCancelAnothersJob) {
  StartWorker();
  auto root = RootAs(Cluster());
  std::string id;
  ASSERT_TRUE(Submit(*root, SmallJob("alice's", {"a.nrrd"}), kAlice, &id).ok());
  {
    grpc::ClientContext ctx;
    Prepare(&ctx, kBob);
    v1::JobRef ref;
    ref.set_job_id(id);
    v1::CancelReply reply;
    grpc::Status s = root->Cancel(&ctx, ref, &reply);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND) << s.error_message();
  }
  {
    grpc::ClientContext ctx;
    Prepare(&ctx, kBob);
    v1::WatchRequest req;
    req.set_job_id(id);
    auto reader = root->Watch(&ctx, req);
    v1::JobEvent e;
    EXPECT_FALSE(reader->Read(&e));
    EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::NOT_FOUND);
  }
  auto listed = [&](const char* token) {
    grpc::ClientContext ctx;
    Prepare(&ctx, token);
    v1::StatusReply reply;
    EXPECT_TRUE(root->Status(&ctx, {}, &reply).ok());
    for (const auto& j : reply.jobs()) {
      if (j.job_id() == id) return j.owner();
    }
    return std::string("(not listed)");
  };
  EXPECT_EQ(listed(kBob), "(not listed)");
  EXPECT_EQ(listed(kAlice), "alice");
  EXPECT_EQ(listed(kBoss), "alice");
  const v1::JobEvent last = WatchToEnd(*root, id, kAlice);
  EXPECT_EQ(last.state(), v1::DONE) << last.error();
  EXPECT_EQ(last.frames_done(), 1);
}

// Without the cluster's certificate (none, or another CA's with the right
// names) nothing reaches a worker, the display or the root's Register.
TEST_F(SecurityTest, AWorkerWithoutTheClustersCertificateGetsNothing) {
  for (const Creds& creds : {Creds{Cluster().ca, "", ""}, Certs("rogue", "worker")}) {
    // Register with the root (the rogue CA's certificate fails the handshake;
    // no certificate is refused by the root's token check).
    {
      auto root = RootAs(Creds{Cluster().ca, creds.cert, creds.key});
      grpc::ClientContext ctx;
      Prepare(&ctx);
      v1::RegisterRequest req;
      req.set_id("rogue");
      req.set_address("127.0.0.1:1");
      v1::RegisterReply reply;
      grpc::Status s = root->Register(&ctx, req, &reply);
      EXPECT_FALSE(s.ok());
      EXPECT_NE(s.error_code(), grpc::StatusCode::UNIMPLEMENTED) << s.error_message();
    }
    auto worker = WorkerAs(Creds{Cluster().ca, creds.cert, creds.key});
    // Stream rays.
    {
      grpc::ClientContext ctx;
      Prepare(&ctx);
      auto stream = worker->Rays(&ctx);
      v1::RayBatch hello;
      hello.set_frame_id(1);
      stream->Write(hello);
      stream->WritesDone();
      EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::UNAVAILABLE);
    }
    // Fetch planes.
    {
      grpc::ClientContext ctx;
      Prepare(&ctx);
      v1::PlanesRequest req;
      auto reader = worker->FetchPlanes(&ctx, req);
      v1::SlabChunk chunk;
      EXPECT_FALSE(reader->Read(&chunk));
      EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::UNAVAILABLE);
    }
    // Receive (or be sent) a slab.
    {
      grpc::ClientContext ctx;
      Prepare(&ctx);
      v1::LoadReply reply;
      auto writer = worker->LoadSlab(&ctx, &reply);
      writer->WritesDone();
      EXPECT_EQ(writer->Finish().error_code(), grpc::StatusCode::UNAVAILABLE);
    }
    // Deposit pixels at the display.
    {
      auto display = DisplayAs(Creds{Cluster().ca, creds.cert, creds.key});
      grpc::ClientContext ctx;
      Prepare(&ctx);
      v1::FrameAck ack;
      auto writer = display->Deposits(&ctx, &ack);
      writer->WritesDone();
      EXPECT_EQ(writer->Finish().error_code(), grpc::StatusCode::UNAVAILABLE);
    }
  }
  // The rogue never registered.
  auto root = RootAs(Cluster());
  grpc::ClientContext ctx;
  Prepare(&ctx, kBoss);
  v1::StatusReply reply;
  ASSERT_TRUE(root->Status(&ctx, {}, &reply).ok());
  for (const auto& w : reply.workers()) EXPECT_NE(w.id(), "rogue");
}

// A certificate of the cluster does not make its holder the root: a worker
// (or the display, or a client with a token) cannot command a worker, make
// it dial an address (Reslab), or register at the root as a worker.
TEST_F(SecurityTest, ACertificateOfAnotherRoleIsRefused) {
  for (const char* role : {"worker", "display"}) {
    auto worker = WorkerAs(Cluster(role));
    {
      grpc::ClientContext ctx;
      Prepare(&ctx);
      v1::ReslabRequest req;
      req.set_old_key("k");
      v1::LoadReply reply;
      grpc::Status s = worker->Reslab(&ctx, req, &reply);
      EXPECT_EQ(s.error_code(), grpc::StatusCode::PERMISSION_DENIED) << role;
      EXPECT_NE(s.error_message().find("Reslab is for transtick-root"), std::string::npos)
          << s.error_message();
    }
    {
      grpc::ClientContext ctx;
      Prepare(&ctx);
      v1::FrameSpec spec;
      v1::FrameAck ack;
      EXPECT_EQ(worker->PrepareFrame(&ctx, spec, &ack).error_code(),
                grpc::StatusCode::PERMISSION_DENIED);
    }
    {
      grpc::ClientContext ctx;
      Prepare(&ctx);
      v1::DatasetRef ref;
      ref.set_dataset_key("k");
      v1::FrameAck ack;
      EXPECT_EQ(worker->Evict(&ctx, ref, &ack).error_code(),
                grpc::StatusCode::PERMISSION_DENIED);
    }
    auto display = DisplayAs(Cluster(role));
    grpc::ClientContext ctx;
    Prepare(&ctx);
    v1::DisplayFrame frame;
    frame.set_frame_id(77);
    frame.set_width(8);
    frame.set_height(8);
    v1::FrameAck ack;
    EXPECT_EQ(display->BeginFrame(&ctx, frame, &ack).error_code(),
              grpc::StatusCode::PERMISSION_DENIED);
  }
  // The display's certificate cannot stream rays; a client's token cannot
  // register a worker.
  {
    auto worker = WorkerAs(Cluster("display"));
    grpc::ClientContext ctx;
    Prepare(&ctx);
    auto stream = worker->Rays(&ctx);
    stream->WritesDone();
    EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::PERMISSION_DENIED);
  }
  auto root = RootAs(Cluster());
  grpc::ClientContext ctx;
  Prepare(&ctx, kBoss);
  v1::RegisterRequest req;
  req.set_id("client-as-worker");
  req.set_address("127.0.0.1:1");
  v1::RegisterReply reply;
  EXPECT_EQ(root->Register(&ctx, req, &reply).error_code(), grpc::StatusCode::PERMISSION_DENIED);
  // A channel that dials a worker refuses a peer whose certificate is the
  // display's: the worker dialled is not who answers.
  auto wrong = v1::Worker::NewStub(
      Dial(Address(display_port_), "transtick-worker", Cluster("root")));
  grpc::ClientContext ctx2;
  Prepare(&ctx2);
  v1::FrameAck ack;
  EXPECT_EQ(wrong->Evict(&ctx2, v1::DatasetRef(), &ack).error_code(),
            grpc::StatusCode::UNAVAILABLE);
}

// Paths: absolute, "..", and links out of the data directory are refused
// at Submit; a file swapped for such a link after Submit is not read when
// the job runs.
TEST_F(SecurityTest, APathSwappedForASymlinkAfterSubmitIsNotRead) {
  const fs::path data = *dir_ / "data";
  fs::create_symlink(*dir_ / "outside.nrrd", data / "link.nrrd");
  auto root = RootAs(Cluster());
  for (const std::string& path :
       {std::string("link.nrrd"), std::string("../outside.nrrd"), (*dir_ / "outside.nrrd").string()}) {
    grpc::Status s = Submit(*root, SmallJob("p", {path}), kAlice);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::PERMISSION_DENIED) << path << ": " << s.error_message();
    EXPECT_EQ(s.error_message().find((*dir_ / "data").string()), std::string::npos)
        << "the server's own paths stay private: " << s.error_message();
  }
  // Dataset 1 passes the check at Submit, then becomes a link out while
  // the job waits for a worker (dataset 0 is loaded before the wait).
  delete worker_;
  worker_ = nullptr;
  ASSERT_TRUE(Eventually([&] {
    grpc::ClientContext ctx;
    Prepare(&ctx, kBoss);
    v1::StatusReply reply;
    return root->Status(&ctx, {}, &reply).ok() && reply.workers_size() == 0;
  }));
  fs::copy_file(data / "b.nrrd", data / "swap.nrrd");
  std::string id;
  ASSERT_TRUE(Submit(*root, SmallJob("swap", {"a.nrrd", "swap.nrrd"}), kAlice, &id).ok());
  fs::remove(data / "swap.nrrd");
  fs::create_symlink(*dir_ / "outside.nrrd", data / "swap.nrrd");
  StartWorker();
  const v1::JobEvent last = WatchToEnd(*root, id, kAlice);
  EXPECT_EQ(last.state(), v1::FAILED);
  EXPECT_NE(last.error().find("'swap.nrrd' leads outside the data directory"), std::string::npos)
      << last.error();
  EXPECT_EQ(last.frames_done(), 1);
}

// A job name with a newline and a fake log prefix stays on its own line.
TEST_F(SecurityTest, AJobNameCannotForgeALogLine) {
  auto root = RootAs(Cluster());
  const std::string forged = "[2026-01-01 00:00:00.000] [info] [root] forged";
  ASSERT_TRUE(Submit(*root, SmallJob("x\n" + forged + "\r\x1b[2K", {"a.nrrd"}), kAlice).ok());
  ASSERT_TRUE(Eventually([] { return root_->log().find("forged") != std::string::npos; }));
  const std::string log = root_->log();
  EXPECT_EQ(log.find("\n" + forged), std::string::npos);
  EXPECT_EQ(log.find('\x1b'), std::string::npos);
  EXPECT_NE(log.find("x\\n[2026-01-01"), std::string::npos);
}

}  // namespace
}  // namespace transtick
