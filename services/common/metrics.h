// A daemon's metrics, and the HTTP endpoint that serves them in
// Prometheus' text exposition format (version 0.0.4) at /metrics. The names,
// types and labels every daemon exports are in docs/formats.md, "Metrics".
//
// Counters are added to where the work is done (per frame, per ray batch:
// never per ray), gauges are set by functions run at each scrape, so a
// scrape reads the state as it is then. Thread-safe.
#ifndef TRANSTICK_SERVICES_COMMON_METRICS_H_
#define TRANSTICK_SERVICES_COMMON_METRICS_H_

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"

namespace httplib {
class Server;
}

namespace transtick {

class Metrics {
 public:
  using Labels = std::vector<std::pair<std::string, std::string>>;
  enum class Type { kCounter, kGauge, kHistogram };

  // Every daemon's families: transtick_build_info and
  // transtick_process_start_time_seconds.
  Metrics();

  // Declares a family before it is used; `buckets` are a histogram's upper
  // bounds, increasing (+Inf is implied). Declaring a name twice keeps the
  // first.
  void Declare(const std::string& name, Type type, const std::string& help,
               std::vector<double> buckets = {});
  // A counter grows by `delta` (>= 0); a gauge is set; a histogram observes
  // a value. A name not declared, or of another type, is a defect: it is
  // logged once and dropped.
  void Add(const std::string& name, double delta, const Labels& labels = {});
  void Set(const std::string& name, double value, const Labels& labels = {});
  void Observe(const std::string& name, double value, const Labels& labels = {});
  // Gauges set to the state of the moment: `fn` runs at every scrape, before
  // the text is made. A gauge series `fn` no longer sets keeps its last value;
  // `fn` may Set 0 instead.
  void OnScrape(std::function<void(Metrics&)> fn);

  // The exposition text: for each family in name order, # HELP, # TYPE and
  // its series in label order.
  std::string Text();

 private:
  struct Series {
    double value = 0;
    std::vector<uint64_t> buckets;  // histogram: counts per bound, not cumulative
    double sum = 0;
    uint64_t count = 0;
  };
  struct Family {
    Type type = Type::kCounter;
    std::string help;
    std::vector<double> bounds;
    std::map<std::string, Series> series;  // by rendered label set
  };
  Series* Find(const std::string& name, Type type, const Labels& labels)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  absl::Mutex scrape_mu_;  // held while the OnScrape functions run, before mu_
  std::vector<std::function<void(Metrics&)>> scrape_ ABSL_GUARDED_BY(scrape_mu_);
  absl::Mutex mu_;
  std::map<std::string, Family> families_ ABSL_GUARDED_BY(mu_);
  std::map<std::string, bool> misused_ ABSL_GUARDED_BY(mu_);
};

// Label values in the exposition format: backslash, double quote and newline
// escaped.
std::string EscapeLabelValue(const std::string& value);

// Serves GET /metrics (and HEAD) on `address`, with the process's security
// (security.h): with TLS, HTTPS with the daemon's own certificate, so a
// scraper checks it against the cluster's CA; without, plaintext, and then
// only on a loopback address unless --insecure. Any other path is 404, any
// other method 405. Stops (and joins its thread) when destroyed.
class MetricsServer {
 public:
  static absl::StatusOr<std::unique_ptr<MetricsServer>> Start(const std::string& address,
                                                              std::shared_ptr<Metrics> metrics);
  ~MetricsServer();
  MetricsServer(const MetricsServer&) = delete;
  MetricsServer& operator=(const MetricsServer&) = delete;

  int port() const { return port_; }

 private:
  MetricsServer() = default;
  std::shared_ptr<Metrics> metrics_;
  std::unique_ptr<httplib::Server> server_;
  std::thread thread_;
  int port_ = 0;
};

// Where a daemon serves /metrics. An address the operator chose must be
// served; the default one (the gRPC port + 100) is served if it can be, and
// a daemon whose default metrics port is taken still starts, with a warning.
struct MetricsEndpoint {
  std::string address;  // empty: no /metrics
  bool required = true;
};

// MetricsServer::Start on `endpoint`: null when it has no address, or when
// an optional one cannot be bound (logged).
absl::StatusOr<std::unique_ptr<MetricsServer>> StartMetrics(const MetricsEndpoint& endpoint,
                                                            std::shared_ptr<Metrics> metrics);

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_COMMON_METRICS_H_
