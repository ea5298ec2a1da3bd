#include "metrics.h"

#include <httplib.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <spdlog/spdlog.h>

#include <charconv>
#include <chrono>
#include <cmath>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "security.h"
#include "version.h"

namespace transtick {
namespace {

// Values as the exposition format writes them: integers without a
// fraction, others in shortest round-trip form, and +Inf, -Inf, NaN.
std::string Number(double v) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "+Inf" : "-Inf";
  if (v == std::floor(v) && std::fabs(v) < 1e15) return absl::StrCat(static_cast<int64_t>(v));
  char buf[32];
  const auto end = std::to_chars(buf, buf + sizeof(buf), v).ptr;  // shortest that reads back
  return std::string(buf, end);
}

std::string RenderLabels(const Metrics::Labels& labels) {
  std::string out;
  for (const auto& [k, v] : labels) {
    absl::StrAppend(&out, out.empty() ? "" : ",", k, "=\"", EscapeLabelValue(v), "\"");
  }
  return out;
}

const char* TypeName(Metrics::Type type) {
  switch (type) {
    case Metrics::Type::kCounter:
      return "counter";
    case Metrics::Type::kGauge:
      return "gauge";
    case Metrics::Type::kHistogram:
      return "histogram";
  }
  return "untyped";
}

std::string Braced(const std::string& labels) { return labels.empty() ? "" : "{" + labels + "}"; }

}  // namespace

std::string EscapeLabelValue(const std::string& value) {
  std::string out;
  for (char c : value) {
    if (c == '\\') {
      out += "\\\\";
    } else if (c == '"') {
      out += "\\\"";
    } else if (c == '\n') {
      out += "\\n";
    } else {
      out += c;
    }
  }
  return out;
}

Metrics::Metrics() {
  Declare("transtick_build_info", Type::kGauge, "The build: always 1, with its version and commit.");
  Set("transtick_build_info", 1, {{"version", TRANSTICK_VERSION}, {"commit", TRANSTICK_GIT_COMMIT}});
  Declare("transtick_process_start_time_seconds", Type::kGauge,
          "When the daemon started, in seconds since the Unix epoch.");
  Set("transtick_process_start_time_seconds",
      std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count());
}

void Metrics::Declare(const std::string& name, Type type, const std::string& help,
                      std::vector<double> buckets) {
  absl::MutexLock lock(&mu_);
  if (families_.count(name)) return;
  Family& f = families_[name];
  f.type = type;
  f.help = help;
  f.bounds = std::move(buckets);
}

Metrics::Series* Metrics::Find(const std::string& name, Type type, const Labels& labels) {
  auto it = families_.find(name);
  if (it == families_.end() || it->second.type != type) {
    if (!misused_[name]) {
      misused_[name] = true;
      spdlog::error("metric {} is used as a {} but declared {}", name, TypeName(type),
                    it == families_.end() ? "nowhere" : TypeName(it->second.type));
    }
    return nullptr;
  }
  Series& s = it->second.series[RenderLabels(labels)];
  if (type == Type::kHistogram && s.buckets.empty()) s.buckets.assign(it->second.bounds.size(), 0);
  return &s;
}

void Metrics::Add(const std::string& name, double delta, const Labels& labels) {
  if (!(delta >= 0)) return;  // a counter never goes down
  absl::MutexLock lock(&mu_);
  if (Series* s = Find(name, Type::kCounter, labels)) s->value += delta;
}

void Metrics::Set(const std::string& name, double value, const Labels& labels) {
  absl::MutexLock lock(&mu_);
  if (Series* s = Find(name, Type::kGauge, labels)) s->value = value;
}

void Metrics::Observe(const std::string& name, double value, const Labels& labels) {
  absl::MutexLock lock(&mu_);
  Series* s = Find(name, Type::kHistogram, labels);
  if (s == nullptr || std::isnan(value)) return;
  const std::vector<double>& bounds = families_[name].bounds;
  for (size_t i = 0; i < bounds.size(); ++i) {
    if (value <= bounds[i]) {
      ++s->buckets[i];
      break;
    }
  }
  s->sum += value;
  ++s->count;
}

void Metrics::OnScrape(std::function<void(Metrics&)> fn) {
  absl::MutexLock lock(&scrape_mu_);
  scrape_.push_back(std::move(fn));
}

std::string Metrics::Text() {
  {
    absl::MutexLock lock(&scrape_mu_);
    for (const auto& fn : scrape_) fn(*this);
  }
  absl::MutexLock lock(&mu_);
  std::string out;
  for (const auto& [name, f] : families_) {
    if (f.series.empty()) continue;
    absl::StrAppend(&out, "# HELP ", name, " ", f.help, "\n# TYPE ", name, " ", TypeName(f.type),
                    "\n");
    for (const auto& [labels, s] : f.series) {
      if (f.type != Type::kHistogram) {
        absl::StrAppend(&out, name, Braced(labels), " ", Number(s.value), "\n");
        continue;
      }
      const std::string sep = labels.empty() ? "" : ",";
      uint64_t cumulative = 0;
      for (size_t i = 0; i < f.bounds.size(); ++i) {
        cumulative += s.buckets[i];
        absl::StrAppend(&out, name, "_bucket{", labels, sep, "le=\"", Number(f.bounds[i]), "\"} ",
                        cumulative, "\n");
      }
      absl::StrAppend(&out, name, "_bucket{", labels, sep, "le=\"+Inf\"} ", s.count, "\n");
      absl::StrAppend(&out, name, "_sum", Braced(labels), " ", Number(s.sum), "\n");
      absl::StrAppend(&out, name, "_count", Braced(labels), " ", s.count, "\n");
    }
  }
  return out;
}

absl::StatusOr<std::unique_ptr<MetricsServer>> MetricsServer::Start(
    const std::string& address, std::shared_ptr<Metrics> metrics) {
  const size_t colon = address.rfind(':');
  int port = -1;
  if (colon == std::string::npos || !absl::SimpleAtoi(address.substr(colon + 1), &port) ||
      port < 0 || port > 65535) {
    return absl::InvalidArgumentError(
        absl::StrCat("metrics address '", address, "' is not HOST:PORT"));
  }
  std::string host = address.substr(0, colon);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') {
    host = host.substr(1, host.size() - 2);
  }
  const Security& security = CurrentSecurity();
  auto server = std::unique_ptr<MetricsServer>(new MetricsServer());
  server->metrics_ = std::move(metrics);
  if (security.tls()) {
    // The daemon's own certificate and key, from their PEM text.
    BIO* cert_bio = BIO_new_mem_buf(security.cert.data(), static_cast<int>(security.cert.size()));
    BIO* key_bio = BIO_new_mem_buf(security.key.data(), static_cast<int>(security.key.size()));
    X509* cert = cert_bio ? PEM_read_bio_X509(cert_bio, nullptr, nullptr, nullptr) : nullptr;
    EVP_PKEY* key = key_bio ? PEM_read_bio_PrivateKey(key_bio, nullptr, nullptr, nullptr) : nullptr;
    BIO_free(cert_bio);
    BIO_free(key_bio);
    if (cert == nullptr || key == nullptr) {
      X509_free(cert);
      EVP_PKEY_free(key);
      return absl::InvalidArgumentError(
          "metrics: the daemon's certificate or key cannot be read for HTTPS");
    }
    // The context takes its own references.
    auto ssl = std::make_unique<httplib::SSLServer>(cert, key);
    X509_free(cert);
    EVP_PKEY_free(key);
    if (!ssl->is_valid()) {
      return absl::InvalidArgumentError("metrics: the certificate and key do not make a TLS server");
    }
    server->server_ = std::move(ssl);
  } else {
    if (!security.insecure && !IsLoopback(address)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "metrics on ", address, " would be plaintext HTTP on a non-loopback address: give the "
          "daemon TLS (it then serves HTTPS), listen on a loopback address, or pass --insecure"));
    }
    server->server_ = std::make_unique<httplib::Server>();
  }
  httplib::Server& http = *server->server_;
  // A few threads and short timeouts: a scraper that stalls holds a thread
  // for 5 s at most, and scrapes are small.
  http.new_task_queue = [] { return new httplib::ThreadPool(2); };
  http.set_read_timeout(std::chrono::seconds(5));
  http.set_write_timeout(std::chrono::seconds(5));
  http.set_keep_alive_timeout(5);
  http.set_payload_max_length(1 << 16);
  Metrics* m = server->metrics_.get();
  auto serve = [m](const httplib::Request&, httplib::Response& res) {
    res.set_content(m->Text(), "text/plain; version=0.0.4; charset=utf-8");
  };
  http.Get("/metrics", serve);
  auto refuse = [](const httplib::Request&, httplib::Response& res) {
    res.status = 405;
    res.set_header("Allow", "GET, HEAD");
    res.set_content("only GET /metrics\n", "text/plain");
  };
  for (const char* path : {"/metrics", R"(/.*)"}) {
    http.Post(path, refuse);
    http.Put(path, refuse);
    http.Delete(path, refuse);
    http.Patch(path, refuse);
  }
  http.set_error_handler([](const httplib::Request&, httplib::Response& res) {
    if (res.status == 404) res.set_content("not found: the metrics are at /metrics\n", "text/plain");
  });
  if (port == 0) {
    port = http.bind_to_any_port(host);
    if (port <= 0) return absl::UnavailableError(absl::StrCat("metrics: cannot bind ", address));
  } else if (!http.bind_to_port(host, port)) {
    return absl::UnavailableError(absl::StrCat("metrics: cannot bind ", address));
  }
  server->port_ = port;
  server->thread_ = std::thread([&http] { http.listen_after_bind(); });
  return server;
}

absl::StatusOr<std::unique_ptr<MetricsServer>> StartMetrics(const MetricsEndpoint& endpoint,
                                                            std::shared_ptr<Metrics> metrics) {
  if (endpoint.address.empty()) return std::unique_ptr<MetricsServer>();
  auto server = MetricsServer::Start(endpoint.address, std::move(metrics));
  if (!server.ok() && !endpoint.required && absl::IsUnavailable(server.status())) {
    spdlog::warn("{}; serving no /metrics (give --metrics ADDR to choose a port)",
                 std::string(server.status().message()));
    return std::unique_ptr<MetricsServer>();
  }
  return server;
}

MetricsServer::~MetricsServer() {
  if (server_) server_->stop();
  if (thread_.joinable()) thread_.join();
}

}  // namespace transtick
