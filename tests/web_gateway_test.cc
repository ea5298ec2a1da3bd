// The web gateway over a real embedded cluster (docs/formats.md, "Web
// gateway"): its frames are the in-process render's pixels; a burst of
// cameras ends on the newest; hostile requests get a clear 4xx and leave the
// gateway serving; sessions are bounded, expire when idle, and are answered
// only on a loopback Host; the volume listing finds what ReadVolume reads
// and nothing outside the data directory.
#include <arpa/inet.h>
#include <fcntl.h>
#include <httplib.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <random>
#include <thread>

#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/synchronization/mutex.h"
#include "convert.h"
#include "dicom_writer.h"
#include "gateway.h"
#include "gtest/gtest.h"
#include "local_cluster.h"
#include "session_fixture.h"
#include "testing.h"
#include "transtick/camera.h"
#include "transtick/image_io.h"
#include "transtick/png.h"
#include "transtick/scene.h"
#include "transtick/synthetic.h"
#include "transtick/volume_io.h"
#include "volumes.h"
#include "web.pb.h"

namespace transtick {
namespace {

using testing::Camera;
using testing::Materials;

// One answer of /events, decoded.
struct Events {
  v1::WebEvents header;
  std::vector<std::string> pngs;  // per event: its PNG, or ""
};

absl::StatusOr<Events> DecodeEvents(const std::string& body) {
  if (body.size() < 4) return absl::InvalidArgumentError("shorter than its length");
  uint32_t n = 0;
  for (int i = 0; i < 4; ++i) n |= static_cast<uint32_t>(static_cast<unsigned char>(body[i])) << (8 * i);
  if (n > body.size() - 4) return absl::InvalidArgumentError("the JSON length runs past the end");
  Events out;
  if (absl::Status s = ParseJson(body.substr(4, n), "events", &out.header); !s.ok()) return s;
  const std::string images = body.substr(4 + n);
  for (const v1::WebEvent& e : out.header.events()) {
    if (e.png_size() == 0) {
      out.pngs.emplace_back();
      continue;
    }
    if (e.png_size() != 2 || uint64_t{e.png(0)} + e.png(1) > images.size()) {
      return absl::InvalidArgumentError("a png range outside the images");
    }
    out.pngs.push_back(images.substr(e.png(0), e.png(1)));
  }
  return out;
}

// A PNG decoded to the bytes of its pixels (through OpenImageIO, from a file).
std::vector<uint8_t> PngPixels(const std::string& png, const std::string& dir) {
  static int n = 0;
  const std::string path = absl::StrCat(dir, "/frame", n++, ".png");
  std::ofstream(path, std::ios::binary) << png;
  auto image = ReadImage(path);
  EXPECT_TRUE(image.ok()) << image.status();
  std::vector<uint8_t> out;
  if (image.ok()) {
    for (float v : image->rgb) out.push_back(ToByte(v));
  }
  return out;
}

std::vector<uint8_t> Bytes(const Image& image) {
  std::vector<uint8_t> out;
  for (float v : image.rgb) out.push_back(ToByte(v));
  return out;
}

class WebGatewayTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing::TempDir();
    cluster_ = testing::PhantomCluster(dir_);
    ASSERT_TRUE(cluster_);
    StartGateway({});
  }
  void StartGateway(WebOptions o) {
    gateway_.reset();
    o.listen = "127.0.0.1:0";
    o.root = cluster_->root_address();
    auto g = WebGateway::Start(o);
    ASSERT_TRUE(g.ok()) << g.status();
    gateway_ = *std::move(g);
    http_ = std::make_unique<httplib::Client>("127.0.0.1", gateway_->port());
    http_->set_read_timeout(std::chrono::seconds(60));
  }
  Image Reference(const v1::View& view, float lo = 45) {
    return testing::PhantomReference(dir_, view, lo);
  }
  std::string OpenBody(const v1::View& view, int preview = 4) {
    v1::WebOpenRequest r;
    r.mutable_dataset()->set_volume("p.nrrd");
    *r.mutable_dataset()->mutable_materials() = Materials(45);
    *r.mutable_dataset()->add_views() = view;
    r.set_preview(preview);
    return ToJson(r, false);
  }
  // Opens a session; its id.
  std::string Open(const v1::View& view, int preview = 4) {
    auto res = http_->Post("/api/sessions", OpenBody(view, preview), "application/json");
    EXPECT_TRUE(res) << "no answer";
    if (!res) return "";
    EXPECT_EQ(res->status, 200) << res->body;
    v1::WebOpenReply reply;
    EXPECT_TRUE(ParseJson(res->body, "open", &reply).ok()) << res->body;
    EXPECT_EQ(reply.session().size(), 32u);
    EXPECT_EQ(reply.ready().dims_size(), 3);
    return reply.session();
  }
  // Polls until a full frame of request `seq` comes (or 60 s pass): its PNG.
  std::string NextFull(const std::string& id, uint32_t* after, uint32_t seq,
                       int* frames = nullptr) {
    for (int i = 0; i < 120; ++i) {
      auto res = http_->Get(absl::StrCat("/api/sessions/", id, "/events?after=", *after, "&wait=5"));
      EXPECT_TRUE(res);
      if (!res) return "";
      EXPECT_EQ(res->status, 200) << res->body;
      EXPECT_EQ(res->get_header_value("Content-Type"), "application/x-transtick-events");
      auto events = DecodeEvents(res->body);
      EXPECT_TRUE(events.ok()) << events.status();
      if (!events.ok()) return "";
      EXPECT_GE(events->header.next(), *after);
      *after = events->header.next();
      std::string found;
      for (int k = 0; k < events->header.events_size(); ++k) {
        const v1::WebEvent& e = events->header.events(k);
        EXPECT_NE(e.kind(), "error") << e.error();
        EXPECT_NE(e.kind(), "end") << e.error();
        if (e.kind() != "frame") continue;
        EXPECT_FALSE(events->pngs[k].empty());
        EXPECT_EQ(e.stats().workers_size(), 2);
        for (const auto& w : e.stats().workers()) EXPECT_EQ(w.plane_work_size(), 0);
        if (!e.preview() && frames) ++*frames;
        if (!e.preview() && e.seq() == seq) found = events->pngs[k];
      }
      if (!found.empty()) return found;
    }
    ADD_FAILURE() << "no full frame of seq " << seq;
    return "";
  }
  uint32_t Update(const std::string& id, const std::string& body) {
    auto res = http_->Post(absl::StrCat("/api/sessions/", id), body, "application/json");
    EXPECT_TRUE(res);
    if (!res) return 0;
    EXPECT_EQ(res->status, 200) << res->body;
    v1::WebSeqReply reply;
    EXPECT_TRUE(ParseJson(res->body, "seq", &reply).ok()) << res->body;
    return reply.seq();
  }
  // An error answer: its status is `status` and its JSON names `needle`.
  void ExpectError(const httplib::Result& res, int status, const std::string& needle) {
    ASSERT_TRUE(res) << "no answer";
    EXPECT_EQ(res->status, status) << res->body;
    v1::WebError e;
    EXPECT_TRUE(ParseJson(res->body, "error", &e).ok()) << res->body;
    EXPECT_TRUE(absl::StrContains(e.error(), needle)) << e.error() << " lacks " << needle;
  }
  double Gauge(const std::string& name) {
    auto res = http_->Get("/metrics");
    if (!res) return -1;
    for (absl::string_view line : absl::StrSplit(res->body, '\n')) {
      if (absl::StartsWith(line, name + " ")) {
        double v = 0;
        if (absl::SimpleAtod(line.substr(name.size() + 1), &v)) return v;
      }
    }
    return -1;
  }

  std::string dir_;
  std::unique_ptr<LocalCluster> cluster_;
  std::unique_ptr<WebGateway> gateway_;
  std::unique_ptr<httplib::Client> http_;
};

// A TCP port that answers only after `delay`, then relays every connection
// to `target_port`: a root that is still coming up.
class LateRelay {
 public:
  LateRelay(int target_port, std::chrono::milliseconds delay) : target_port_(target_port) {
    // A free port, closed again until the delay has passed.
    const int probe = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a = Loopback(0);
    EXPECT_EQ(bind(probe, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    socklen_t len = sizeof a;
    getsockname(probe, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
    close(probe);
    thread_ = std::thread([this, delay] {
      std::this_thread::sleep_for(delay);
      listen_fd_ = socket(AF_INET, SOCK_STREAM, 0);
      const int one = 1;
      setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
      sockaddr_in l = Loopback(port_);
      if (bind(listen_fd_, reinterpret_cast<sockaddr*>(&l), sizeof l) != 0 ||
          listen(listen_fd_, 16) != 0) {
        return;
      }
      while (!stop_) {
        pollfd p{listen_fd_, POLLIN, 0};
        if (poll(&p, 1, 50) <= 0) continue;
        const int in = accept(listen_fd_, nullptr, nullptr);
        if (in < 0) continue;
        const int out = socket(AF_INET, SOCK_STREAM, 0);
        sockaddr_in t = Loopback(target_port_);
        if (connect(out, reinterpret_cast<sockaddr*>(&t), sizeof t) != 0) {
          close(in);
          close(out);
          continue;
        }
        absl::MutexLock lock(&mu_);
        fds_.push_back(in);
        fds_.push_back(out);
        pumps_.emplace_back([in, out] { Pump(in, out); });
        pumps_.emplace_back([in, out] { Pump(out, in); });
      }
    });
  }
  ~LateRelay() {
    stop_ = true;
    thread_.join();
    {
      absl::MutexLock lock(&mu_);
      for (int fd : fds_) shutdown(fd, SHUT_RDWR);
    }
    for (std::thread& t : pumps_) t.join();
    for (int fd : fds_) close(fd);
    close(listen_fd_);
  }
  std::string address() const { return absl::StrCat("127.0.0.1:", port_); }

 private:
  static sockaddr_in Loopback(int port) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(static_cast<uint16_t>(port));
    return a;
  }
  static void Pump(int from, int to) {
    char buf[16384];
    ssize_t n;
    while ((n = read(from, buf, sizeof buf)) > 0) {
      if (write(to, buf, static_cast<size_t>(n)) != n) break;
    }
    shutdown(to, SHUT_WR);
  }

  const int target_port_;
  int port_ = 0;
  int listen_fd_ = -1;
  std::atomic<bool> stop_{false};
  absl::Mutex mu_;
  std::vector<int> fds_;
  std::vector<std::thread> pumps_;
  std::thread thread_;
};

// A gateway destroyed at once after it started used to leave httplib's
// listening thread in accept() for ever (its stop() does nothing before the
// loop runs), and the destructor waiting on it: the test hung now and then.
// A watchdog fails it instead of letting it hang.
TEST_F(WebGatewayTest, StopsRightAfterItStarts) {
  std::atomic<bool> done{false};
  std::thread watchdog([&] {
    for (int i = 0; i < 600 && !done; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    if (!done) {
      std::fprintf(stderr, "a gateway did not stop within 60 s of starting\n");
      std::abort();
    }
  });
  for (int i = 0; i < 200; ++i) StartGateway({});
  gateway_.reset();
  done = true;
  watchdog.join();
}

// A session opened while the root cannot be reached yet (restarting, a
// stalled machine) opens once it can, within the gateway's 10 s of trying.
TEST_F(WebGatewayTest, AnOpenWaitsForARootThatComesUp) {
  const std::string root = cluster_->root_address();
  LateRelay late(std::stoi(root.substr(root.rfind(':') + 1)), std::chrono::milliseconds(1500));
  WebOptions o;
  o.listen = "127.0.0.1:0";
  o.root = late.address();
  auto g = WebGateway::Start(o);
  ASSERT_TRUE(g.ok()) << g.status();
  gateway_ = *std::move(g);
  http_ = std::make_unique<httplib::Client>("127.0.0.1", gateway_->port());
  http_->set_read_timeout(std::chrono::seconds(60));
  const auto t0 = std::chrono::steady_clock::now();
  const std::string id = Open(Camera(30));
  ASSERT_FALSE(id.empty());
  EXPECT_GE(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(1400));
  uint32_t after = 0;
  EXPECT_FALSE(NextFull(id, &after, 1).empty());
  gateway_.reset();  // its sessions end before the relay goes
}

TEST_F(WebGatewayTest, FramesAreTheInProcessRenderAndTheNewestCameraWins) {
  const std::string id = Open(Camera(30));
  ASSERT_FALSE(id.empty());
  uint32_t after = 0;
  std::string png = NextFull(id, &after, 1);
  EXPECT_EQ(PngPixels(png, dir_), Bytes(Reference(Camera(30))));
  for (double az : {80.0, 200.0}) {
    v1::WebSessionUpdate u;
    *u.mutable_view() = Camera(az, 48, 40);
    const uint32_t seq = Update(id, ToJson(u, false));
    png = NextFull(id, &after, seq);
    EXPECT_EQ(PngPixels(png, dir_), Bytes(Reference(Camera(az, 48, 40)))) << "azimuth " << az;
  }
  // A drag: 30 cameras at once. Frames of stale cameras are dropped, and
  // the last frame is the newest camera's.
  uint32_t last = 0;
  for (int i = 0; i < 30; ++i) {
    v1::WebSessionUpdate u;
    *u.mutable_view() = Camera(200 + 3 * i, 48, 40);
    last = Update(id, ToJson(u, false));
  }
  int frames = 0;
  png = NextFull(id, &after, last, &frames);
  EXPECT_EQ(PngPixels(png, dir_), Bytes(Reference(Camera(200 + 3 * 29, 48, 40))));
  EXPECT_LT(frames, 30) << "every stale camera was rendered";
  // A classification and a camera in one request.
  v1::WebSessionUpdate u;
  *u.mutable_view() = Camera(10);
  *u.mutable_materials() = Materials(30);
  const uint32_t seq = Update(id, ToJson(u, false));
  png = NextFull(id, &after, seq);
  EXPECT_EQ(PngPixels(png, dir_), Bytes(Reference(Camera(10), 30)));
  auto res = http_->Delete(absl::StrCat("/api/sessions/", id));
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200);
  ExpectError(http_->Get(absl::StrCat("/api/sessions/", id, "/events?wait=0")), 404, "no such session");
}

TEST_F(WebGatewayTest, PngIsTheBytesOfThePngFile) {
  // EncodePng against OpenImageIO's reading of it, on random images with
  // values outside [0, 1] as well; the last few are large, so that the
  // deflated data outgrow the encoder's 64 KB steps many times (the very
  // last stored, at level 0, larger than the image).
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> value(-0.2f, 1.2f);
  for (int t = 0; t < 44; ++t) {
    const bool large = t >= 40;
    Image image;
    image.width = large ? 300 + static_cast<int>(rng() % 500) : 1 + static_cast<int>(rng() % 70);
    image.height = large ? 200 + static_cast<int>(rng() % 300) : 1 + static_cast<int>(rng() % 50);
    image.rgb.resize(static_cast<size_t>(image.width) * image.height * 3);
    for (float& v : image.rgb) v = (rng() % 4 == 0) ? 0.0f : value(rng);
    auto png = EncodePng(image, t == 43 ? 0 : 1 + t % 9);
    ASSERT_TRUE(png.ok()) << png.status();
    EXPECT_EQ(PngPixels(*png, dir_), Bytes(image)) << image.width << "x" << image.height;
  }
  Image bad;
  bad.width = 3;
  bad.height = 2;
  bad.rgb.resize(5);
  EXPECT_FALSE(EncodePng(bad).ok());
}

TEST_F(WebGatewayTest, HostileRequestsGetClearErrorsAndTheGatewayServesOn) {
  const std::string json = "application/json";
  ExpectError(http_->Post("/api/sessions", "{", json), 400, "not a valid WebOpenRequest");
  ExpectError(http_->Post("/api/sessions", R"({"dataset": {}, "bogus": 1})", json), 400, "bogus");
  ExpectError(http_->Post("/api/sessions", OpenBody(Camera(0)), "text/plain"), 415,
              "application/json");
  ExpectError(http_->Post("/api/sessions", std::string(2 << 20, ' '), json), 413, "1 MiB");
  v1::WebOpenRequest r;
  r.mutable_dataset()->set_volume("../etc/passwd");
  *r.mutable_dataset()->mutable_materials() = Materials(45);
  *r.mutable_dataset()->add_views() = Camera(0);
  ExpectError(http_->Post("/api/sessions", ToJson(r, false), json), 403, "outside the data directory");
  r.mutable_dataset()->set_volume("absent.nrrd");
  ExpectError(http_->Post("/api/sessions", ToJson(r, false), json), 404, "absent.nrrd");
  r.mutable_dataset()->set_volume("p.nrrd");
  r.mutable_dataset()->mutable_views(0)->set_width(0);
  ExpectError(http_->Post("/api/sessions", ToJson(r, false), json), 400, "image size 0x32");
  r.mutable_dataset()->clear_views();
  ExpectError(http_->Post("/api/sessions", ToJson(r, false), json), 400, "one view");

  const std::string id = Open(Camera(30));
  const std::string path = absl::StrCat("/api/sessions/", id);
  ExpectError(http_->Post(path, "{}", json), 400, "no view, materials or transfer");
  ExpectError(http_->Post(path, R"({"materials": {}, "transfer": {}})", json), 400, "not both");
  ExpectError(http_->Get(path + "/events?after=x"), 400, "after=");
  ExpectError(http_->Get(path + "/events?wait=99"), 400, "wait=");
  ExpectError(http_->Get(absl::StrCat("/api/sessions/", std::string(32, 'a'), "/events")), 404,
              "no such session");
  ExpectError(http_->Get("/api/nothing"), 404, "no such API path");
  ExpectError(http_->Put("/api/sessions", "{}", json), 405, "not one of this path's methods (POST)");
  ExpectError(http_->Get("/api/sessions"), 405, "(POST)");
  ExpectError(http_->Delete("/api/status"), 405, "(GET)");
  ExpectError(http_->Get(path), 405, "(POST, DELETE)");
  // A camera the root refuses is an error event; the session goes on.
  uint32_t bad = Update(id, R"({"view": {"width": 40, "height": 32, "zoom": -1}})");
  uint32_t after = 0;
  bool error_seen = false;
  for (int i = 0; i < 40 && !error_seen; ++i) {
    auto res = http_->Get(absl::StrCat(path, "/events?after=", after, "&wait=5"));
    ASSERT_TRUE(res);
    auto events = DecodeEvents(res->body);
    ASSERT_TRUE(events.ok());
    after = events->header.next();
    for (const auto& e : events->header.events()) {
      if (e.kind() == "error" && e.seq() == bad) error_seen = true;
    }
  }
  EXPECT_TRUE(error_seen);
  // Random bodies and paths: always a 4xx with a JSON error, never a crash.
  std::mt19937 rng(11);
  const std::vector<std::string> pieces = {"{", "}", "[", "]", "\"view\"", ":", ",", "1e999",
                                           "\"materials\"", "null", "-", "\"\\u0000\"", "true",
                                           "{\"width\":", "\"azimuth\"", "99999999999999999999"};
  for (int t = 0; t < 600; ++t) {
    std::string body;
    const int n = static_cast<int>(rng() % 12);
    for (int k = 0; k < n; ++k) body += pieces[rng() % pieces.size()];
    auto res = t % 2 ? http_->Post(path, body, json) : http_->Post("/api/sessions", body, json);
    ASSERT_TRUE(res) << "no answer to " << body;
    if (res->status == 200) continue;  // a body that happens to be a valid request
    EXPECT_GE(res->status, 400) << body;
    EXPECT_LT(res->status, 500) << body << " -> " << res->body;
    v1::WebError e;
    EXPECT_TRUE(ParseJson(res->body, "error", &e).ok()) << res->body;
  }
  // Still serving: a frame of a good camera.
  v1::WebSessionUpdate u;
  *u.mutable_view() = Camera(60);
  const uint32_t seq = Update(id, ToJson(u, false));
  EXPECT_EQ(PngPixels(NextFull(id, &after, seq), dir_), Bytes(Reference(Camera(60))));
}

TEST_F(WebGatewayTest, OnlyLoopbackHostNamesAreAnswered) {
  httplib::Headers evil = {{"Host", "rebound.example:8080"}};
  auto res = http_->Get("/api/status", evil);
  ExpectError(res, 403, "loopback");
  res = http_->Get("/", evil);
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 403);
  res = http_->Get("/api/status", {{"Host", "localhost:8080"}});
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200) << res->body;
  v1::StatusReply status;
  ASSERT_TRUE(ParseJson(res->body, "status", &status).ok());
  EXPECT_EQ(status.workers_size(), 2);
  // Headers every answer carries.
  EXPECT_EQ(res->get_header_value("X-Content-Type-Options"), "nosniff");
  EXPECT_TRUE(absl::StrContains(res->get_header_value("Content-Security-Policy"), "default-src 'self'"));
  EXPECT_EQ(res->get_header_value("Cache-Control"), "no-store");
  // No page is served from outside the compiled-in files.
  res = http_->Get("/..%2f..%2fetc%2fpasswd");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 404);
}

TEST_F(WebGatewayTest, SessionsAreBoundedAndExpireWhenIdle) {
  WebOptions o;
  o.max_sessions = 2;
  o.idle = std::chrono::milliseconds(600);
  StartGateway(o);
  const std::string a = Open(Camera(0), 0);
  const std::string b = Open(Camera(0), 0);
  ExpectError(http_->Post("/api/sessions", OpenBody(Camera(0)), "application/json"), 429,
              "--max-sessions");
  EXPECT_EQ(Gauge("transtick_web_sessions"), 2);
  // A poll in progress keeps its session; the other expires.
  auto res = http_->Get(absl::StrCat("/api/sessions/", a, "/events?after=1000&wait=2"));
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200);
  ExpectError(http_->Get(absl::StrCat("/api/sessions/", b, "/events?wait=0")), 404, "no such session");
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  ExpectError(http_->Get(absl::StrCat("/api/sessions/", a, "/events?wait=0")), 404, "no such session");
  EXPECT_EQ(Gauge("transtick_web_sessions"), 0);
  EXPECT_FALSE(Open(Camera(0), 0).empty());  // room again
}

TEST_F(WebGatewayTest, VolumesListsWhatCanBeOpenedAndNothingOutside) {
  namespace fs = std::filesystem;
  fs::create_directories(dir_ + "/ct/series1");
  fs::create_directories(dir_ + "/a/b/c/d/e");
  std::ofstream(dir_ + "/ct/head.nii.gz") << "x";
  std::ofstream(dir_ + "/ct/notes.txt") << "x";
  std::ofstream(dir_ + "/raw.raw") << "x";
  std::ofstream(dir_ + "/.hidden.nrrd") << "x";
  std::ofstream(dir_ + "/a/b/c/d/e/deep.nrrd") << "x";
  {
    std::string dicom(200, '\0');
    dicom.replace(128, 4, "DICM");
    std::ofstream(dir_ + "/ct/series1/IM0001", std::ios::binary) << dicom;
    std::ofstream(dir_ + "/ct/series1/IM0002", std::ios::binary) << dicom;
  }
  fs::create_symlink("/etc", dir_ + "/outside");
  fs::create_symlink("p.nrrd", dir_ + "/link.nrrd");
  mkfifo((dir_ + "/fifo.nrrd").c_str(), 0600);
  // Names a protobuf string cannot hold, or a terminal should not print.
  std::ofstream(dir_ + "/bad\xff.nrrd") << "x";
  std::ofstream(dir_ + "/over\xc0\xaflong.nrrd") << "x";
  std::ofstream(dir_ + "/line\nbreak.nrrd") << "x";
  std::ofstream(dir_ + "/caf\xc3\xa9.nrrd") << "x";  // café: listed
  auto res = http_->Get("/api/volumes");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 200) << res->body;
  v1::VolumesReply reply;
  ASSERT_TRUE(ParseJson(res->body, "volumes", &reply).ok()) << res->body;
  std::vector<std::string> paths;
  for (const auto& v : reply.volumes()) {
    paths.push_back(v.path() + (v.series() ? "/" : ""));
    if (v.path() == "p.nrrd") {
      EXPECT_EQ(v.bytes(), fs::file_size(dir_ + "/p.nrrd"));
    }
    if (v.series()) {
      EXPECT_EQ(v.bytes(), 400u);
      // Its files start as DICOM does and do not read: listed, saying so.
      EXPECT_TRUE(absl::StrContains(v.error(), "ct/series1/IM0001")) << v.error();
      EXPECT_EQ(v.description(), "");
    }
  }
  EXPECT_EQ(paths, (std::vector<std::string>{"caf\xc3\xa9.nrrd", "ct/head.nii.gz", "ct/series1/",
                                             "link.nrrd", "p.nrrd"}));
  EXPECT_TRUE(reply.truncated());  // a/b/c/d/e is deeper than the walk goes
  EXPECT_GE(reply.presets_size(), 4);
  bool bone = false;
  for (const auto& p : reply.presets()) bone |= p.name() == "ct-bone" && p.surfaces();
  EXPECT_TRUE(bone);
}

TEST_F(WebGatewayTest, VolumesListsEachSeriesOfAStudyAsThePathThatOpensIt) {
  namespace fs = std::filesystem;
  // A study of two series whose files interleave, a report beside them; a
  // directory of one series; one whose series misses a slice.
  auto write = [&](const std::string& dir, const std::string& name, testing::DicomSlice s) {
    fs::create_directories(dir_ + "/" + dir);
    s.pixels.assign(static_cast<size_t>(s.columns) * s.rows, 0);
    for (size_t k = 0; k < s.pixels.size(); ++k) s.pixels[k] = static_cast<int16_t>(1024 + 40 * k);
    const std::string bytes = testing::DicomSliceFile(s);
    ASSERT_FALSE(bytes.empty());
    std::ofstream(dir_ + "/" + dir + "/" + name, std::ios::binary) << bytes;
  };
  for (int i = 0; i < 3; ++i) {
    testing::DicomSlice a;
    a.series = "1.2.840.99.1";
    a.number = 3;
    a.description = "AX BONE";
    a.position = {0, 0, 2.0 * i};
    write("study", absl::StrCat("A", i), a);
    testing::DicomSlice b;
    b.series = "1.2.840.99.12";
    b.number = 4;
    b.columns = 6;
    b.rows = 5;
    b.position = {0, 0, 1.5 * i};
    write("study", absl::StrCat("B", i), b);
  }
  std::ofstream(dir_ + "/study/README.txt") << "scanned on a Tuesday";
  for (int i = 0; i < 2; ++i) {
    testing::DicomSlice c;
    c.series = "1.2.840.99.7";
    c.position = {0, 0, 1.0 * i};
    write("one", absl::StrCat("IM", i, ".dcm"), c);
  }
  for (double z : {0.0, 1.0, 3.0}) {
    testing::DicomSlice d;
    d.series = "1.2.840.99.8";
    d.position = {0, 0, z};
    write("gap", absl::StrCat("IM", z, ".dcm"), d);
  }
  auto list = [&] {
    auto res = http_->Get("/api/volumes");
    EXPECT_TRUE(res);
    v1::VolumesReply reply;
    if (!res) return reply;
    EXPECT_EQ(res->status, 200) << res->body;
    EXPECT_TRUE(ParseJson(res->body, "volumes", &reply).ok()) << res->body;
    return reply;
  };
  v1::VolumesReply reply = list();
  EXPECT_FALSE(reply.truncated());
  std::map<std::string, v1::VolumeEntry> by_path;
  for (const auto& v : reply.volumes()) by_path[v.path()] = v;
  ASSERT_TRUE(by_path.count("study#1.2.840.99.1")) << reply.DebugString();
  ASSERT_TRUE(by_path.count("study#1.2.840.99.12")) << reply.DebugString();
  EXPECT_FALSE(by_path.count("study"));
  const v1::VolumeEntry& bone = by_path["study#1.2.840.99.1"];
  EXPECT_TRUE(bone.series());
  EXPECT_EQ(bone.description(), "CT, series 3 'AX BONE', 3 files, 4x3x3");
  EXPECT_EQ(bone.error(), "");
  uint64_t bone_bytes = 0;
  for (int i = 0; i < 3; ++i) bone_bytes += fs::file_size(dir_ + "/study/A" + std::to_string(i));
  EXPECT_EQ(bone.bytes(), bone_bytes);
  EXPECT_EQ(by_path["study#1.2.840.99.12"].description(), "CT, series 4, 3 files, 6x5x3");
  ASSERT_TRUE(by_path.count("one"));
  EXPECT_EQ(by_path["one"].description(), "CT, 2 files, 4x3x2");
  EXPECT_EQ(by_path["one"].error(), "");
  ASSERT_TRUE(by_path.count("gap"));
  EXPECT_TRUE(absl::StrContains(by_path["gap"].error(), "a missing slice"))
      << by_path["gap"].error();
  // Each listed path opens: a session on the study's second series.
  {
    v1::WebOpenRequest r;
    r.mutable_dataset()->set_volume("study#1.2.840.99.12");
    r.mutable_dataset()->mutable_preset()->set_name("grey");
    *r.mutable_dataset()->add_views() = Camera(0);
    auto res = http_->Post("/api/sessions", ToJson(r, false), "application/json");
    ASSERT_TRUE(res);
    ASSERT_EQ(res->status, 200) << res->body;
    v1::WebOpenReply open;
    ASSERT_TRUE(ParseJson(res->body, "open", &open).ok()) << res->body;
    ASSERT_EQ(open.ready().dims_size(), 3);
    EXPECT_EQ(open.ready().dims(0), 6);
    EXPECT_EQ(open.ready().dims(1), 5);
    EXPECT_EQ(open.ready().dims(2), 3);
  }
  // The headers are read again when a directory changes, and only then: a
  // third series appears in "one", and the missing slice in "gap".
  testing::DicomSlice extra;
  extra.series = "1.2.840.99.20";
  write("one", "X0.dcm", extra);
  testing::DicomSlice fill;
  fill.series = "1.2.840.99.8";
  fill.position = {0, 0, 2.0};
  write("gap", "IM2.dcm", fill);
  reply = list();
  by_path.clear();
  for (const auto& v : reply.volumes()) by_path[v.path()] = v;
  EXPECT_FALSE(by_path.count("one"));
  EXPECT_TRUE(by_path.count("one#1.2.840.99.7"));
  EXPECT_EQ(by_path["one#1.2.840.99.20"].description(), "CT, 1 file, 4x3x1");
  ASSERT_TRUE(by_path.count("gap"));
  EXPECT_EQ(by_path["gap"].error(), "");
  EXPECT_EQ(by_path["gap"].description(), "CT, 4 files, 4x3x4");
  // What a directory's headers said is kept while its files keep their
  // names, sizes and times: a file rewritten to the same size with its
  // time put back is not read again; touched, it is.
  {
    const std::string a0 = dir_ + "/study/A0";
    struct stat before {};
    ASSERT_EQ(stat(a0.c_str(), &before), 0);
    // The file rewritten with another description of the same length, in
    // place (GDCM, writing it anew, makes UIDs of varying length).
    std::string bytes;
    {
      std::ifstream in(a0, std::ios::binary);
      bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
    const size_t at = bytes.find("AX BONE");
    ASSERT_NE(at, std::string::npos);
    bytes.replace(at, 7, "AX SOFT");
    std::ofstream(a0, std::ios::binary | std::ios::trunc) << bytes;
    ASSERT_EQ(fs::file_size(a0), static_cast<uintmax_t>(before.st_size));
    const timespec times[2] = {before.st_atim, before.st_mtim};
    ASSERT_EQ(utimensat(AT_FDCWD, a0.c_str(), times, 0), 0);
    reply = list();
    for (const auto& v : reply.volumes()) by_path[v.path()] = v;
    EXPECT_EQ(by_path["study#1.2.840.99.1"].description(),
              "CT, series 3 'AX BONE', 3 files, 4x3x3");
    const timespec later[2] = {{before.st_mtim.tv_sec + 5, 0}, {before.st_mtim.tv_sec + 5, 0}};
    ASSERT_EQ(utimensat(AT_FDCWD, a0.c_str(), later, 0), 0);
    reply = list();
    for (const auto& v : reply.volumes()) by_path[v.path()] = v;
    EXPECT_EQ(by_path["study#1.2.840.99.1"].description(),
              "CT, series 3 'AX SOFT', 3 files, 4x3x3");
  }
  // Past the bounds on headers read, a directory is listed once, unread.
  auto data = ConfinedDir::Open(dir_);
  ASSERT_TRUE(data.ok());
  for (int bound = 0; bound < 2; ++bound) {
    VolumeListingBounds bounds;
    if (bound == 0) {
      bounds.dicom_headers = 0;
    } else {
      bounds.dicom_bytes = 0;
    }
    auto bounded = ListVolumes(**data, bounds);
    ASSERT_TRUE(bounded.ok()) << bounded.status();
    EXPECT_TRUE(bounded->truncated());
    std::vector<std::string> series;
    for (const auto& v : bounded->volumes()) {
      if (!v.series()) continue;
      series.push_back(v.path());
      EXPECT_EQ(v.description(), "");
      EXPECT_EQ(v.error(), "");
    }
    EXPECT_EQ(series, (std::vector<std::string>{"gap", "one", "study"}));
  }
}

}  // namespace
}  // namespace transtick
