#include "gateway.h"

#include <httplib.h>
#include <openssl/crypto.h>
#include <openssl/rand.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <deque>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/synchronization/mutex.h"
#include "absl/time/clock.h"
#include "assets.h"
#include "client.h"
#include "cluster.grpc.pb.h"
#include "convert.h"
#include "rpc_channel.h"
#include "rpc_status.h"
#include "security.h"
#include "transtick/png.h"
#include "version.h"
#include "web.pb.h"

namespace transtick {
namespace {

constexpr size_t kMaxBody = 1 << 20;
constexpr int kDefaultPreview = 4;
constexpr int kDefaultWaitS = 20;
constexpr int kMaxWaitS = 30;
// Events other than frames a session keeps until they are polled.
constexpr size_t kMaxNotices = 64;

int HttpStatus(absl::StatusCode code) {
  switch (code) {
    case absl::StatusCode::kInvalidArgument:
    case absl::StatusCode::kOutOfRange:
    case absl::StatusCode::kFailedPrecondition:
      return 400;
    case absl::StatusCode::kUnauthenticated:
      return 401;
    case absl::StatusCode::kPermissionDenied:
      return 403;
    case absl::StatusCode::kNotFound:
      return 404;
    case absl::StatusCode::kResourceExhausted:
      return 429;
    case absl::StatusCode::kUnavailable:
    case absl::StatusCode::kDeadlineExceeded:
      return 503;
    default:
      return 500;
  }
}

void SetError(httplib::Response& res, int status, const std::string& message) {
  v1::WebError e;
  e.set_error(message);
  res.status = status;
  res.set_content(ToJson(e, false), "application/json");
  if (status == 401) res.set_header("WWW-Authenticate", "Bearer");
}

void SetStatus(httplib::Response& res, const absl::Status& s) {
  SetError(res, HttpStatus(s.code()), std::string(s.message()));
}

void SetJson(httplib::Response& res, const google::protobuf::Message& m) {
  res.set_content(ToJson(m, false), "application/json");
}

std::string RandomId() {
  unsigned char bytes[16];
  if (RAND_bytes(bytes, sizeof(bytes)) != 1) return "";
  static constexpr char kHex[] = "0123456789abcdef";
  std::string id;
  for (unsigned char b : bytes) {
    id += kHex[b >> 4];
    id += kHex[b & 15];
  }
  return id;
}

// The host of "host:port", "[v6]:port" or a Host header, in lower case.
std::string HostOf(const std::string& address) {
  std::string host = address;
  if (!host.empty() && host.front() == '[') {
    host = host.substr(1, host.find(']') == std::string::npos ? std::string::npos
                                                              : host.find(']') - 1);
  } else if (host.find(':') == host.rfind(':')) {
    host = host.substr(0, host.find(':'));
  }
  return absl::AsciiStrToLower(host);
}

// A session's events, and the reader thread that turns the root's session
// events into them.
class WebSession {
 public:
  struct Stored {
    v1::WebEvent event;
    std::shared_ptr<const std::string> png;  // frames only
  };

  WebSession(std::string id, std::string token, std::unique_ptr<SessionClient> client,
             Metrics* metrics)
      : id_(std::move(id)), token_(std::move(token)), client_(std::move(client)),
        metrics_(metrics), last_used_(absl::Now()) {}
  ~WebSession() { Stop(); }

  const std::string& id() const { return id_; }

  // Whether `token` is the one that opened the session (compared in time
  // independent of where they differ).
  bool Owns(const std::string& token) const {
    return token.size() == token_.size() &&
           CRYPTO_memcmp(token.data(), token_.data(), token.size()) == 0;
  }

  void Start() {
    thread_ = std::thread([this] { Run(); });
  }

  // Ends the session with the root and joins the reader. Idempotent.
  void Stop() {
    client_->Cancel();
    if (thread_.joinable()) thread_.join();
    absl::MutexLock lock(&mu_);
    ended_ = true;
  }

  void Push(v1::WebEvent event, std::shared_ptr<const std::string> png = nullptr) {
    absl::MutexLock lock(&mu_);
    event.set_index(next_index_++);
    const bool frame = event.kind() == "frame";
    if (frame) {
      // A full frame replaces every frame not yet polled; a preview, the
      // previews.
      const bool full = !event.preview();
      std::erase_if(events_, [&](const Stored& s) {
        return s.event.kind() == "frame" && (full || s.event.preview());
      });
    } else {
      size_t notices = 0;
      for (const Stored& s : events_) notices += s.event.kind() != "frame";
      if (notices >= kMaxNotices) {
        auto it = std::find_if(events_.begin(), events_.end(),
                               [](const Stored& s) { return s.event.kind() != "frame"; });
        events_.erase(it);
      }
    }
    if (event.kind() == "end") ended_ = true;
    events_.push_back({std::move(event), std::move(png)});
  }

  SessionClient& client() { return *client_; }

  // The events of index `after` and later, waiting up to `wait` for one;
  // and the index of the next. NOT_FOUND when the session has ended and
  // every event was taken.
  absl::StatusOr<std::pair<uint32_t, std::vector<Stored>>> Poll(uint32_t after,
                                                                absl::Duration wait) {
    absl::MutexLock lock(&mu_);
    ++polling_;
    last_used_ = absl::Now();
    auto have = [&]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
      return ended_ || (!events_.empty() && events_.back().event.index() >= after);
    };
    mu_.AwaitWithTimeout(absl::Condition(&have), wait);
    std::vector<Stored> out;
    for (const Stored& s : events_) {
      if (s.event.index() >= after) out.push_back(s);
    }
    // Polled events go; a frame stays until a newer one replaces it, so a
    // page that reloads shows the image again.
    std::erase_if(events_, [&](const Stored& s) {
      return s.event.index() >= after && s.event.kind() != "frame" && s.event.kind() != "end";
    });
    --polling_;
    last_used_ = absl::Now();
    if (out.empty() && ended_) {
      return absl::NotFoundError("the session has ended (its last event was taken)");
    }
    return std::make_pair(std::max(after, next_index_), std::move(out));
  }

  void Touch() {
    absl::MutexLock lock(&mu_);
    last_used_ = absl::Now();
  }

  // Nobody has polled or sent a request for `idle`.
  bool IdleFor(absl::Duration idle) {
    absl::MutexLock lock(&mu_);
    return polling_ == 0 && absl::Now() - last_used_ > idle;
  }

 private:
  void Run() {
    while (true) {
      auto e = client_->Next();
      v1::WebEvent out;
      if (!e.ok()) {
        out.set_kind("end");
        if (!absl::IsOutOfRange(e.status())) out.set_error(std::string(e.status().message()));
        Push(std::move(out));
        return;
      }
      out.set_seq(static_cast<uint32_t>(e->seq));
      if (e->ready) {
        out.set_kind("ready");
        *out.mutable_ready() = *e->ready;
        Push(std::move(out));
      } else if (!e->error.empty()) {
        out.set_kind("error");
        out.set_error(e->error);
        Push(std::move(out));
      } else if (e->has_frame) {
        const absl::Time start = absl::Now();
        auto png = EncodePng(e->image);
        metrics_->Observe("transtick_web_png_seconds", absl::ToDoubleSeconds(absl::Now() - start));
        if (!png.ok()) {
          out.set_kind("error");
          out.set_error(std::string(png.status().message()));
          Push(std::move(out));
          continue;
        }
        out.set_kind("frame");
        out.set_preview(e->preview);
        out.set_width(e->image.width);
        out.set_height(e->image.height);
        *out.mutable_stats() = std::move(e->stats);
        for (v1::WorkerFrameStats& w : *out.mutable_stats()->mutable_workers()) {
          w.clear_plane_work();
        }
        metrics_->Add("transtick_web_frames_total", 1, {{"kind", e->preview ? "preview" : "full"}});
        metrics_->Add("transtick_web_png_bytes_total", static_cast<double>(png->size()));
        Push(std::move(out), std::make_shared<const std::string>(*std::move(png)));
      }
    }
  }

  const std::string id_;
  const std::string token_;
  const std::unique_ptr<SessionClient> client_;
  Metrics* const metrics_;
  std::thread thread_;
  absl::Mutex mu_;
  std::deque<Stored> events_ ABSL_GUARDED_BY(mu_);
  uint32_t next_index_ ABSL_GUARDED_BY(mu_) = 0;
  bool ended_ ABSL_GUARDED_BY(mu_) = false;
  int polling_ ABSL_GUARDED_BY(mu_) = 0;
  absl::Time last_used_ ABSL_GUARDED_BY(mu_);
};

}  // namespace

class WebGateway::Impl {
 public:
  Impl(WebOptions options, std::shared_ptr<Metrics> metrics)
      : options_(std::move(options)), metrics_(std::move(metrics)),
        auth_(CurrentSecurity().tls()),
        stub_(v1::Root::NewStub(MakeChannel(options_.root, Role::kRoot))) {
    metrics_->Declare("transtick_web_sessions", Metrics::Type::kGauge,
                      "Interactive sessions the gateway holds.");
    metrics_->Declare("transtick_web_sessions_opened_total", Metrics::Type::kCounter,
                      "Sessions opened through the gateway.");
    metrics_->Declare("transtick_web_requests_total", Metrics::Type::kCounter,
                      "HTTP requests by route and status code.");
    metrics_->Declare("transtick_web_frames_total", Metrics::Type::kCounter,
                      "Frames received for the browsers, previews and full.");
    metrics_->Declare("transtick_web_png_bytes_total", Metrics::Type::kCounter,
                      "Bytes of the PNG images made for the browsers.");
    metrics_->Declare("transtick_web_png_seconds", Metrics::Type::kHistogram,
                      "Time to encode a frame as PNG.",
                      {0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5});
    metrics_->OnScrape([this](Metrics& m) {
      absl::MutexLock lock(&mu_);
      m.Set("transtick_web_sessions", static_cast<double>(sessions_.size()));
    });
  }

  // Ends the sessions first, which wakes the polls waiting on them, so the
  // server's threads are free to stop.
  ~Impl() {
    std::map<std::string, std::shared_ptr<WebSession>> sessions;
    {
      absl::MutexLock lock(&mu_);
      stopping_ = true;
      sessions.swap(sessions_);
    }
    for (auto& [id, s] : sessions) s->Stop();
    if (reaper_.joinable()) reaper_.join();
    if (server_) server_->stop();
    if (thread_.joinable()) thread_.join();
  }

  absl::Status Start();
  int port() const { return port_; }
  std::string url() const {
    std::string host = HostOf(options_.listen);
    if (host.empty() || host == "0.0.0.0" || host == "::") host = "127.0.0.1";
    if (host.find(':') != std::string::npos) host = "[" + host + "]";
    return absl::StrCat(https_ ? "https" : "http", "://", host, ":", port_, "/");
  }
  const std::shared_ptr<Metrics>& metrics() const { return metrics_; }

 private:
  using Handler = std::function<void(const httplib::Request&, httplib::Response&)>;
  // `handler` behind the checks every /api/ request passes: the Host (DNS
  // rebinding of a loopback gateway), the token when the root authenticates
  // clients, a JSON body for POST; and counted by `route`.
  Handler Api(const std::string& route, bool post,
              std::function<void(const httplib::Request&, httplib::Response&,
                                 const std::string& token)> handler,
              bool needs_token = true);
  absl::StatusOr<std::string> Token(const httplib::Request& req) const;
  bool HostAllowed(const httplib::Request& req) const;
  void Call(grpc::ClientContext* ctx, const std::string& token, double timeout_s) const {
    if (!token.empty()) ctx->AddMetadata("authorization", "Bearer " + token);
    ctx->set_deadline(Deadline(timeout_s));
  }
  // The session `id` when `token` opened it.
  std::shared_ptr<WebSession> Find(const std::string& id, const std::string& token) {
    absl::MutexLock lock(&mu_);
    auto it = sessions_.find(id);
    if (it == sessions_.end() || !it->second->Owns(token)) return nullptr;
    return it->second;
  }
  void Serve(const std::string& path, httplib::Response& res) const;

  void OpenSession(const httplib::Request& req, httplib::Response& res, const std::string& token);
  void UpdateSession(const httplib::Request& req, httplib::Response& res,
                     const std::string& token);
  void PollSession(const httplib::Request& req, httplib::Response& res, const std::string& token);
  void CloseSession(const httplib::Request& req, httplib::Response& res,
                    const std::string& token);
  void Reap();

  const WebOptions options_;
  const std::shared_ptr<Metrics> metrics_;
  const bool auth_;
  const std::unique_ptr<v1::Root::Stub> stub_;
  std::unique_ptr<httplib::Server> server_;
  bool https_ = false;
  std::thread thread_;
  std::thread reaper_;
  int port_ = 0;
  absl::Mutex mu_;
  std::map<std::string, std::shared_ptr<WebSession>> sessions_ ABSL_GUARDED_BY(mu_);
  int opening_ ABSL_GUARDED_BY(mu_) = 0;  // sessions being opened: they count against the limit
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;
};

absl::StatusOr<std::string> WebGateway::Impl::Token(const httplib::Request& req) const {
  if (!auth_) return std::string();
  const std::string header = req.get_header_value("Authorization");
  std::string_view value = header;
  if (header.empty()) {
    return absl::UnauthenticatedError(
        "the root authenticates clients: send 'Authorization: Bearer TOKEN' with a token of "
        "the root's table (docs/security.md)");
  }
  constexpr std::string_view kBearer = "Bearer ";
  if (!value.starts_with(kBearer)) {
    return absl::UnauthenticatedError("the Authorization header is not 'Bearer TOKEN'");
  }
  value.remove_prefix(kBearer.size());
  if (value.empty() || value.size() > 4096) {
    return absl::UnauthenticatedError("the Authorization header is not 'Bearer TOKEN'");
  }
  for (char c : value) {
    if (c < 0x21 || c > 0x7e) {
      return absl::UnauthenticatedError("the bearer token holds a character tokens never have");
    }
  }
  return std::string(value);
}

bool WebGateway::Impl::HostAllowed(const httplib::Request& req) const {
  // With tokens, the Host does not matter; without, a page of another site
  // whose name was re-bound to this address must not reach the API.
  if (auth_ || CurrentSecurity().insecure) return true;
  const std::string host = absl::AsciiStrToLower(req.get_header_value("Host"));
  return IsLoopback(host) || HostOf(host) == HostOf(options_.listen);
}

WebGateway::Impl::Handler WebGateway::Impl::Api(
    const std::string& route, bool post,
    std::function<void(const httplib::Request&, httplib::Response&, const std::string&)> handler,
    bool needs_token) {
  return [this, route, post, handler, needs_token](const httplib::Request& req,
                                                   httplib::Response& res) {
    res.set_header("Cache-Control", "no-store");
    if (!HostAllowed(req)) {
      SetError(res, 403, "this gateway answers only requests to a loopback host name");
    } else if (post && !absl::StartsWith(absl::AsciiStrToLower(req.get_header_value("Content-Type")),
                                         "application/json")) {
      SetError(res, 415, "a POST to the API must be Content-Type: application/json");
    } else if (!needs_token) {
      handler(req, res, "");
    } else if (auto token = Token(req); !token.ok()) {
      SetStatus(res, token.status());
    } else {
      handler(req, res, *token);
    }
    const int code = res.status < 0 ? 200 : res.status;  // httplib's 200 is set after
    metrics_->Add("transtick_web_requests_total", 1,
                  {{"code", std::to_string(code)}, {"route", route}});
  };
}

void WebGateway::Impl::Serve(const std::string& path, httplib::Response& res) const {
  const std::string name = path == "/" ? "/index.html" : path;
  std::string bytes;
  bool found = false;
  if (!options_.static_dir.empty()) {
    // Only a plain file name beneath the directory.
    const std::string file = name.substr(1);
    if (!file.empty() && file.find('/') == std::string::npos && file[0] != '.') {
      std::ifstream in(options_.static_dir + "/" + file, std::ios::binary);
      std::stringstream text;
      text << in.rdbuf();
      found = static_cast<bool>(in);
      bytes = text.str();
    }
  } else {
    for (const WebAsset& a : WebAssets()) {
      if (a.path == name) {
        bytes = std::string(a.bytes);
        found = true;
      }
    }
  }
  if (!found) {
    res.status = 404;
    res.set_content("not found\n", "text/plain");
    return;
  }
  // The media type by the extension.
  std::string type = "application/octet-stream";
  for (const auto& [ext, t] : {std::pair<const char*, const char*>{".html", "text/html; charset=utf-8"},
                               {".js", "text/javascript; charset=utf-8"},
                               {".mjs", "text/javascript; charset=utf-8"},
                               {".css", "text/css; charset=utf-8"},
                               {".png", "image/png"},
                               {".svg", "image/svg+xml"}}) {
    if (absl::EndsWith(name, ext)) type = t;
  }
  res.set_content(std::move(bytes), type);
}

void WebGateway::Impl::OpenSession(const httplib::Request& req, httplib::Response& res,
                                   const std::string& token) {
  v1::WebOpenRequest open;
  if (absl::Status s = ParseJson(req.body, "the request", &open); !s.ok()) {
    return SetStatus(res, s);
  }
  const int preview = open.has_preview() ? open.preview() : kDefaultPreview;
  {
    absl::MutexLock lock(&mu_);
    if (stopping_) return SetError(res, 503, "the gateway is stopping");
    if (static_cast<int>(sessions_.size()) + opening_ >= options_.max_sessions) {
      return SetError(res, 429,
                      absl::StrCat("the gateway holds ", options_.max_sessions,
                                   " sessions, its most (--max-sessions): close one"));
    }
    ++opening_;
  }
  auto release = [this] {
    absl::MutexLock lock(&mu_);
    --opening_;
  };
  // The session and its first event: the dataset is ready, or the open
  // failed. A root that could not be reached (a connection that failed, a
  // root restarting, a stalled machine) is tried again for up to 10 s
  // before the browser hears of it; the root holds no session for an open
  // that never reached it, or whose stream broke.
  absl::StatusOr<std::unique_ptr<SessionClient>> client;
  absl::StatusOr<SessionClient::Event> first;
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  for (auto backoff = std::chrono::milliseconds(100);;
       backoff = std::min(backoff * 2, std::chrono::milliseconds(1000))) {
    // The browser gets PNGs: the frames' 8-bit values are all it needs, in a
    // quarter of the float image's bytes.
    client = SessionClient::Open(options_.root, open.dataset(), preview, token, v1::RGB8);
    first = client.ok() ? (*client)->Next() : client.status();
    if (first.ok() || !absl::IsUnavailable(first.status()) ||
        std::chrono::steady_clock::now() + backoff > give_up) {
      break;
    }
    spdlog::warn("web: opening a session on the root failed ({}); trying again",
                 Printable(first.status().message()));
    std::this_thread::sleep_for(backoff);
  }
  if (!first.ok() || !first->ready) {
    release();
    return SetStatus(res, first.ok() ? absl::InternalError("the root's first event was not ready")
                                     : first.status());
  }
  const std::string id = RandomId();
  if (id.empty()) {
    release();
    return SetError(res, 500, "no random bytes for a session id");
  }
  auto session = std::make_shared<WebSession>(id, token, *std::move(client), metrics_.get());
  v1::WebEvent ready;
  ready.set_kind("ready");
  ready.set_seq(static_cast<uint32_t>(first->seq));
  *ready.mutable_ready() = *first->ready;
  session->Push(ready);
  session->Start();
  {
    absl::MutexLock lock(&mu_);
    --opening_;
    if (stopping_) {
      session->Stop();
      return SetError(res, 503, "the gateway is stopping");
    }
    sessions_[id] = session;
  }
  metrics_->Add("transtick_web_sessions_opened_total", 1);
  spdlog::info("web session {} opened on {} (root session {})", id,
               Printable(open.dataset().volume()), first->ready->session_id());
  v1::WebOpenReply reply;
  reply.set_session(id);
  *reply.mutable_ready() = *first->ready;
  SetJson(res, reply);
}

void WebGateway::Impl::UpdateSession(const httplib::Request& req, httplib::Response& res,
                                     const std::string& token) {
  auto session = Find(req.matches[1], token);
  if (!session) return SetError(res, 404, "no such session (it may have expired)");
  session->Touch();
  v1::WebSessionUpdate update;
  if (absl::Status s = ParseJson(req.body, "the request", &update); !s.ok()) {
    return SetStatus(res, s);
  }
  const bool materials = update.has_materials(), transfer = update.has_transfer();
  if (!update.has_view() && !materials && !transfer) {
    return SetError(res, 400, "the request has no view, materials or transfer");
  }
  if (materials && transfer) {
    return SetError(res, 400, "a request has materials or a transfer function, not both");
  }
  // One request to the root: the camera and the classification together.
  v1::SessionRequest r;
  if (update.has_view()) *r.mutable_view() = update.view();
  if (materials) *r.mutable_materials() = update.materials();
  if (transfer) *r.mutable_transfer() = update.transfer();
  absl::StatusOr<uint64_t> seq = session->client().Send(std::move(r));
  if (!seq.ok()) return SetStatus(res, seq.status());
  v1::WebSeqReply reply;
  reply.set_seq(static_cast<uint32_t>(*seq));
  SetJson(res, reply);
}

void WebGateway::Impl::PollSession(const httplib::Request& req, httplib::Response& res,
                                   const std::string& token) {
  auto session = Find(req.matches[1], token);
  if (!session) return SetError(res, 404, "no such session (it may have expired)");
  uint32_t after = 0;
  int wait = kDefaultWaitS;
  if (req.has_param("after") && !absl::SimpleAtoi(req.get_param_value("after"), &after)) {
    return SetError(res, 400, "after= is not a whole number");
  }
  if (req.has_param("wait") &&
      (!absl::SimpleAtoi(req.get_param_value("wait"), &wait) || wait < 0 || wait > kMaxWaitS)) {
    return SetError(res, 400, absl::StrCat("wait= is not a whole number of seconds in [0, ",
                                           kMaxWaitS, "]"));
  }
  auto polled = session->Poll(after, absl::Seconds(wait));
  if (!polled.ok()) return SetStatus(res, polled.status());
  auto& [next, events] = *polled;
  v1::WebEvents out;
  out.set_next(next);
  std::string images;
  for (WebSession::Stored& s : events) {
    v1::WebEvent* e = out.add_events();
    *e = std::move(s.event);
    if (s.png) {
      e->add_png(static_cast<uint32_t>(images.size()));
      e->add_png(static_cast<uint32_t>(s.png->size()));
      images += *s.png;
    }
  }
  const std::string json = ToJson(out, false);
  std::string body;
  body.reserve(4 + json.size() + images.size());
  const uint32_t n = static_cast<uint32_t>(json.size());
  for (int i = 0; i < 4; ++i) body += static_cast<char>((n >> (8 * i)) & 0xff);
  body += json;
  body += images;
  res.set_content(std::move(body), "application/x-transtick-events");
}

void WebGateway::Impl::CloseSession(const httplib::Request& req, httplib::Response& res,
                                    const std::string& token) {
  std::shared_ptr<WebSession> session;
  {
    absl::MutexLock lock(&mu_);
    auto it = sessions_.find(req.matches[1]);
    if (it != sessions_.end() && it->second->Owns(token)) {
      session = it->second;
      sessions_.erase(it);
    }
  }
  if (!session) return SetError(res, 404, "no such session (it may have expired)");
  session->Stop();
  spdlog::info("web session {} closed by its page", session->id());
  res.set_content("{}", "application/json");
}

void WebGateway::Impl::Reap() {
  const absl::Duration idle = absl::FromChrono(options_.idle);
  while (true) {
    std::vector<std::shared_ptr<WebSession>> idle_sessions;
    {
      absl::MutexLock lock(&mu_);
      auto stop = [this]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) { return stopping_; };
      mu_.AwaitWithTimeout(absl::Condition(&stop),
                           std::min(absl::Seconds(1), idle / 4 + absl::Milliseconds(1)));
      if (stopping_) return;
      for (auto it = sessions_.begin(); it != sessions_.end();) {
        if (it->second->IdleFor(idle)) {
          idle_sessions.push_back(it->second);
          it = sessions_.erase(it);
        } else {
          ++it;
        }
      }
    }
    for (auto& s : idle_sessions) {
      s->Stop();
      spdlog::info("web session {} closed: idle for {} s", s->id(), absl::ToDoubleSeconds(idle));
    }
  }
}

absl::Status WebGateway::Impl::Start() {
  const Security& security = CurrentSecurity();
  const bool loopback = IsLoopback(options_.listen);
  if (options_.https_cert.empty() != options_.https_key.empty()) {
    return absl::InvalidArgumentError("--https-cert and --https-key go together");
  }
  if (!options_.https_cert.empty()) {
    auto ssl = std::make_unique<httplib::SSLServer>(options_.https_cert.c_str(),
                                                    options_.https_key.c_str());
    if (!ssl->is_valid()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "the certificate ", options_.https_cert, " and key ", options_.https_key,
          " do not make an HTTPS server (PEM files, the key the certificate's)"));
    }
    server_ = std::move(ssl);
    https_ = true;
  } else {
    if (auth_ && !loopback) {
      return absl::FailedPreconditionError(absl::StrCat(
          "the gateway on ", options_.listen, " would take the root's bearer tokens over "
          "plaintext HTTP: give --https-cert and --https-key, or listen on a loopback address"));
    }
    if (!auth_ && !loopback && !security.insecure) {
      return absl::FailedPreconditionError(absl::StrCat(
          "the gateway on ", options_.listen, " would serve plaintext HTTP with no "
          "authentication on a non-loopback address: give the root TLS (--tls-ca) and the "
          "gateway --https-cert/--https-key, listen on a loopback address, or pass --insecure"));
    }
    server_ = std::make_unique<httplib::Server>();
  }
  httplib::Server& http = *server_;
  // A long poll holds its connection's thread while it waits, and a page
  // keeps a few connections: four threads per session, and some for the
  // rest.
  const int threads = 4 * options_.max_sessions + 8;
  http.new_task_queue = [threads] { return new httplib::ThreadPool(threads); };
  http.set_read_timeout(std::chrono::seconds(10));
  http.set_write_timeout(std::chrono::seconds(10));
  http.set_keep_alive_timeout(5);
  http.set_payload_max_length(kMaxBody);
  // Headers and body go out in separate writes: without this, Nagle's
  // algorithm and the browser's delayed ACK held small answers ~40 ms.
  http.set_tcp_nodelay(true);

  http.set_post_routing_handler([](const httplib::Request&, httplib::Response& res) {
    res.set_header("X-Content-Type-Options", "nosniff");
    res.set_header("Referrer-Policy", "no-referrer");
    res.set_header("X-Frame-Options", "DENY");
    res.set_header("Content-Security-Policy",
                   "default-src 'self'; img-src 'self' blob: data:; style-src 'self'; "
                   "script-src 'self'; connect-src 'self'; frame-ancestors 'none'");
  });

  http.Get("/healthz", [](const httplib::Request&, httplib::Response& res) {
    res.set_content("ok\n", "text/plain");
  });
  http.Get("/metrics", [this](const httplib::Request&, httplib::Response& res) {
    res.set_content(metrics_->Text(), "text/plain; version=0.0.4; charset=utf-8");
  });
  http.Get("/api/config", Api("config", false, [this](const httplib::Request&,
                                                      httplib::Response& res, const std::string&) {
    v1::WebConfig c;
    c.set_auth(auth_);
    c.set_version(absl::StrCat(TRANSTICK_VERSION, " (", TRANSTICK_GIT_COMMIT, ")"));
    c.set_max_sessions(options_.max_sessions);
    c.set_idle_s(static_cast<int>(options_.idle.count() / 1000));
    SetJson(res, c);
  }, /*needs_token=*/false));  // the page learns from it that it must ask for one
  http.Get("/api/volumes", Api("volumes", false, [this](const httplib::Request&,
                                                        httplib::Response& res,
                                                        const std::string& token) {
    grpc::ClientContext ctx;
    Call(&ctx, token, 10);
    v1::VolumesReply reply;
    if (absl::Status s = FromGrpc(stub_->Volumes(&ctx, v1::VolumesRequest(), &reply)); !s.ok()) {
      return SetStatus(res, s);
    }
    SetJson(res, reply);
  }));
  http.Get("/api/status", Api("status", false, [this](const httplib::Request&,
                                                      httplib::Response& res,
                                                      const std::string& token) {
    grpc::ClientContext ctx;
    Call(&ctx, token, 5);
    v1::StatusReply reply;
    if (absl::Status s = FromGrpc(stub_->Status(&ctx, v1::StatusRequest(), &reply)); !s.ok()) {
      return SetStatus(res, s);
    }
    SetJson(res, reply);
  }));
  http.Post(R"(/api/jobs/([A-Za-z0-9._-]{1,128})/cancel)",
            Api("cancel", true, [this](const httplib::Request& req, httplib::Response& res,
                                       const std::string& token) {
              grpc::ClientContext ctx;
              Call(&ctx, token, 5);
              v1::JobRef ref;
              ref.set_job_id(req.matches[1]);
              v1::CancelReply reply;
              if (absl::Status s = FromGrpc(stub_->Cancel(&ctx, ref, &reply)); !s.ok()) {
                return SetStatus(res, s);
              }
              SetJson(res, reply);
            }));
  http.Post("/api/sessions", Api("open", true, [this](const httplib::Request& req,
                                                      httplib::Response& res,
                                                      const std::string& token) {
    OpenSession(req, res, token);
  }));
  const std::string session_path = R"(/api/sessions/([0-9a-f]{32}))";
  http.Post(session_path, Api("update", true, [this](const httplib::Request& req,
                                                     httplib::Response& res,
                                                     const std::string& token) {
    UpdateSession(req, res, token);
  }));
  http.Delete(session_path, Api("close", false, [this](const httplib::Request& req,
                                                       httplib::Response& res,
                                                       const std::string& token) {
    CloseSession(req, res, token);
  }));
  http.Get(session_path + "/events", Api("events", false, [this](const httplib::Request& req,
                                                                 httplib::Response& res,
                                                                 const std::string& token) {
    PollSession(req, res, token);
  }));
  // A known API path asked with another method: 405 with the methods it has.
  const std::vector<std::pair<std::string, std::string>> allowed = {
      {"/api/config", "GET"},           {"/api/volumes", "GET"},
      {"/api/status", "GET"},           {R"(/api/jobs/[^/]+/cancel)", "POST"},
      {"/api/sessions", "POST"},        {session_path, "POST, DELETE"},
      {session_path + "/events", "GET"}};
  for (const auto& [pattern, methods] : allowed) {
    auto refuse = [this, methods = methods](const httplib::Request& req, httplib::Response& res) {
      res.set_header("Allow", methods);
      SetError(res, 405, absl::StrCat(req.method, " is not one of this path's methods (", methods,
                                      ")"));
      metrics_->Add("transtick_web_requests_total", 1, {{"code", "405"}, {"route", "method"}});
    };
    for (const char* m : {"GET", "POST", "PUT", "DELETE", "PATCH"}) {
      if (methods.find(m) != std::string::npos) continue;
      if (std::string(m) == "GET") http.Get(pattern, refuse);
      if (std::string(m) == "POST") http.Post(pattern, refuse);
      if (std::string(m) == "PUT") http.Put(pattern, refuse);
      if (std::string(m) == "DELETE") http.Delete(pattern, refuse);
      if (std::string(m) == "PATCH") http.Patch(pattern, refuse);
    }
  }
  http.Get(R"(/|/[A-Za-z0-9._-]+)", [this](const httplib::Request& req, httplib::Response& res) {
    if (!HostAllowed(req)) return SetError(res, 403, "this gateway answers only loopback host names");
    Serve(req.path, res);
  });
  http.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
    if (!res.body.empty()) return;
    if (absl::StartsWith(req.path, "/api/")) {
      SetError(res, res.status, res.status == 404   ? "no such API path (docs/formats.md, \"Web gateway\")"
                                : res.status == 413 ? "the request body is over 1 MiB"
                                                    : "the request was refused");
    } else {
      res.set_content(absl::StrCat(res.status, "\n"), "text/plain");
    }
  });

  const std::string host = HostOf(options_.listen);
  const size_t colon = options_.listen.rfind(':');
  int port = 0;
  if (colon == std::string::npos || !absl::SimpleAtoi(options_.listen.substr(colon + 1), &port) ||
      port < 0 || port > 65535) {
    return absl::InvalidArgumentError(
        absl::StrCat("--listen ", options_.listen, " is not HOST:PORT"));
  }
  const std::string bind_host = host.empty() ? "0.0.0.0" : host;
  if (port == 0) {
    port = http.bind_to_any_port(bind_host);
    if (port <= 0) return absl::UnavailableError(absl::StrCat("cannot bind ", options_.listen));
  } else if (!http.bind_to_port(bind_host, port)) {
    return absl::UnavailableError(absl::StrCat("cannot bind ", options_.listen));
  }
  port_ = port;
  // httplib's stop() does nothing until the listening thread has begun its
  // loop: a gateway destroyed right after it started left that thread in
  // accept() for ever, and its destructor waiting on it (seen in
  // web_gateway_test). So the gateway is up only once the loop runs.
  auto listened = std::make_shared<std::atomic<bool>>(false);
  thread_ = std::thread([&http, listened] {
    http.listen_after_bind();
    *listened = true;
  });
  while (!http.is_running() && !*listened) {
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  if (!http.is_running()) {
    thread_.join();
    return absl::UnavailableError(absl::StrCat("the gateway on ", options_.listen,
                                               " stopped listening as it started"));
  }
  reaper_ = std::thread([this] { Reap(); });
  return absl::OkStatus();
}

WebGateway::WebGateway(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
WebGateway::~WebGateway() = default;

absl::StatusOr<std::unique_ptr<WebGateway>> WebGateway::Start(const WebOptions& options) {
  if (options.root.empty()) return absl::InvalidArgumentError("the gateway needs --root ADDR");
  if (options.max_sessions < 1) return absl::InvalidArgumentError("--max-sessions must be >= 1");
  auto impl = std::make_unique<Impl>(options, std::make_shared<Metrics>());
  if (absl::Status s = impl->Start(); !s.ok()) return s;
  return std::unique_ptr<WebGateway>(new WebGateway(std::move(impl)));
}

int WebGateway::port() const { return impl_->port(); }
std::string WebGateway::url() const { return impl_->url(); }
const std::shared_ptr<Metrics>& WebGateway::metrics() const { return impl_->metrics(); }

}  // namespace transtick
