// The daemons' metrics (docs/formats.md, "Metrics"): the exposition text
// against its definition, the HTTP endpoint for real on loopback, and an
// embedded cluster whose counters must agree with the frames' own
// statistics and with each other. Also gRPC server reflection on the
// daemons, called as grpcurl calls it.
#include <grpcpp/grpcpp.h>
#include <httplib.h>

#include <fstream>
#include <map>
#include <regex>
#include <string>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "client.h"
#include "gtest/gtest.h"
#include "local_cluster.h"
#include "metrics.h"
#include "reflection_client.h"
#include "rpc_channel.h"
#include "testing.h"
#include "transtick/synthetic.h"

namespace transtick {
namespace {

using T = Metrics::Type;

// Each sample line "name{labels} value" as name{labels} -> value; checks
// the text's grammar on the way: HELP and TYPE before a family's samples,
// one family's samples together, histogram buckets cumulative up to +Inf
// equal to _count.
std::map<std::string, double> Parse(const std::string& text) {
  static const std::regex kSample(R"(^([a-zA-Z_:][a-zA-Z0-9_:]*)(\{[^}]*\})? (\S+)$)");
  std::map<std::string, double> out;
  std::map<std::string, std::string> types;
  std::string family;
  double last_bucket = -1;
  const std::vector<std::string> lines = absl::StrSplit(text, '\n', absl::SkipEmpty());
  for (const std::string& line : lines) {
    if (line.rfind("# HELP ", 0) == 0) {
      const std::string rest = line.substr(7);
      family = rest.substr(0, rest.find(' '));
      EXPECT_FALSE(types.count(family)) << family << " described twice";
      last_bucket = -1;
      continue;
    }
    if (line.rfind("# TYPE ", 0) == 0) {
      std::vector<std::string> parts = absl::StrSplit(line.substr(7), ' ');
      EXPECT_EQ(parts.size(), 2u) << line;
      EXPECT_EQ(parts[0], family) << "TYPE without its HELP: " << line;
      types[parts[0]] = parts[1];
      continue;
    }
    std::smatch m;
    EXPECT_TRUE(std::regex_match(line, m, kSample)) << "not a sample line: " << line;
    if (m.empty()) continue;
    const std::string name = m[1];
    EXPECT_EQ(name.rfind(family, 0), 0u) << name << " outside its family " << family;
    double value = 0;
    if (m[3] == "+Inf") {
      value = INFINITY;
    } else {
      EXPECT_TRUE(absl::SimpleAtod(std::string(m[3]), &value)) << line;
    }
    const std::string key = name + std::string(m[2]);
    EXPECT_FALSE(out.count(key)) << key << " twice";
    out[key] = value;
    if (types[family] == "histogram" && name == family + "_bucket") {
      EXPECT_GE(value, last_bucket) << "buckets not cumulative: " << line;
      last_bucket = value;
    }
    if (types[family] == "histogram" && name == family + "_count") {
      EXPECT_EQ(value, last_bucket) << "+Inf bucket != _count in " << family;
      last_bucket = -1;
    }
  }
  return out;
}

TEST(MetricsTest, TextFollowsTheExpositionFormat) {
  Metrics m;
  m.Declare("t_jobs_total", T::kCounter, "Jobs.");
  m.Declare("t_depth", T::kGauge, "Depth.");
  m.Declare("t_seconds", T::kHistogram, "Time.", {0.1, 1});
  m.Add("t_jobs_total", 2, {{"state", "done"}});
  m.Add("t_jobs_total", 3, {{"state", "done"}});
  m.Add("t_jobs_total", -7, {{"state", "done"}});  // a counter never goes down
  m.Add("t_jobs_total", 1, {{"state", "a\"b\\c\nd"}});
  m.Set("t_depth", 4.5);
  m.Set("t_depth", 2);
  for (double v : {0.05, 0.1, 0.5, 7.0}) m.Observe("t_seconds", v);
  m.Add("t_undeclared_total", 1);  // dropped, logged
  m.Set("t_jobs_total", 9);        // the wrong type: dropped
  const std::string text = m.Text();
  EXPECT_NE(text.find("# HELP t_jobs_total Jobs.\n# TYPE t_jobs_total counter\n"),
            std::string::npos);
  EXPECT_NE(text.find("t_jobs_total{state=\"done\"} 5\n"), std::string::npos) << text;
  EXPECT_NE(text.find("t_jobs_total{state=\"a\\\"b\\\\c\\nd\"} 1\n"), std::string::npos) << text;
  EXPECT_NE(text.find("t_depth 2\n"), std::string::npos);
  EXPECT_NE(text.find("t_seconds_bucket{le=\"0.1\"} 2\nt_seconds_bucket{le=\"1\"} 3\n"
                      "t_seconds_bucket{le=\"+Inf\"} 4\nt_seconds_sum 7.65\nt_seconds_count 4\n"),
            std::string::npos)
      << text;
  EXPECT_EQ(text.find("t_undeclared"), std::string::npos);
  EXPECT_NE(text.find("transtick_build_info{version=\""), std::string::npos);
  auto parsed = Parse(text);
  EXPECT_EQ(parsed["t_jobs_total{state=\"done\"}"], 5);
}

TEST(MetricsTest, ScrapeFunctionsSetGaugesAtEachScrape) {
  Metrics m;
  m.Declare("t_now", T::kGauge, "Now.");
  int calls = 0;
  m.OnScrape([&calls](Metrics& g) { g.Set("t_now", ++calls); });
  EXPECT_NE(m.Text().find("t_now 1\n"), std::string::npos);
  EXPECT_NE(m.Text().find("t_now 2\n"), std::string::npos);
}

TEST(MetricsTest, ServedOverHttpOnLoopbackOnly) {
  auto metrics = std::make_shared<Metrics>();
  metrics->Declare("t_up", T::kGauge, "Up.");
  metrics->Set("t_up", 1);
  auto server = MetricsServer::Start("127.0.0.1:0", metrics);
  ASSERT_TRUE(server.ok()) << server.status();
  httplib::Client client("127.0.0.1", (*server)->port());
  auto res = client.Get("/metrics");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200);
  EXPECT_EQ(res->get_header_value("Content-Type"), "text/plain; version=0.0.4; charset=utf-8");
  EXPECT_NE(res->body.find("t_up 1\n"), std::string::npos);
  auto missing = client.Get("/");
  ASSERT_TRUE(missing);
  EXPECT_EQ(missing->status, 404);
  auto post = client.Post("/metrics", "x", "text/plain");
  ASSERT_TRUE(post);
  EXPECT_EQ(post->status, 405);
  // Plaintext beyond loopback needs TLS or --insecure, as the gRPC ports do.
  auto open = MetricsServer::Start("0.0.0.0:0", metrics);
  EXPECT_TRUE(absl::IsInvalidArgument(open.status())) << open.status();
  EXPECT_TRUE(absl::IsInvalidArgument(MetricsServer::Start("nonsense", metrics).status()));
  EXPECT_TRUE(absl::IsInvalidArgument(MetricsServer::Start("127.0.0.1:99999", metrics).status()));
}

std::map<std::string, double> Scrape(int port) {
  httplib::Client client("127.0.0.1", port);
  auto res = client.Get("/metrics");
  EXPECT_TRUE(res && res->status == 200);
  return res ? Parse(res->body) : std::map<std::string, double>{};
}

std::string ReflectedServices(const std::string& address) {
  grpc::Status status;
  std::string listed = testing::ReflectedServices(
      grpc::CreateChannel(address, grpc::InsecureChannelCredentials()), "", &status);
  EXPECT_TRUE(status.ok()) << status.error_message();
  return listed;
}

TEST(ClusterMetricsTest, CountersAgreeWithTheFramesAndWithEachOther) {
  const std::string dir = testing::TempDir();
  const std::array<int, 3> dims = {40, 36, 44};
  Volume v = MakeNoisyPhantom(dims, 33);
  {
    std::ofstream f(dir + "/phantom.nrrd", std::ios::binary);
    f << "NRRD0004\ntype: float\ndimension: 3\nsizes: 40 36 44\nendian: little\n"
         "encoding: raw\n\n";
    f.write(reinterpret_cast<const char*>(v.values.data()), v.values.size() * 4);
  }
  LocalCluster::Options o;
  o.workers = 2;
  o.data_dir = dir;
  o.metrics = true;
  auto cluster = LocalCluster::Start(o);
  ASSERT_TRUE(cluster.ok()) << cluster.status();
  v1::Job job;
  v1::Dataset* d = job.add_datasets();
  d->set_volume("phantom.nrrd");
  v1::Material* m = d->mutable_materials()->add_materials();
  m->set_name("hard");
  m->set_min(45);
  m->set_max(1000);
  for (float c : {0.9f, 0.7f, 0.6f}) m->add_color(c);
  for (double az : {30.0, 120.0}) {
    v1::View* view = d->add_views();
    view->set_azimuth(az);
    view->set_elevation(20);
    view->set_width(48);
    view->set_height(40);
    view->set_shadows(true);
    view->set_output(absl::StrCat(dir, "/f", az, ".png"));
  }
  auto stats = SubmitAndWatch((*cluster)->root_address(), job, WatchOptions{});
  ASSERT_TRUE(stats.ok()) << stats.status();
  ASSERT_EQ(stats->size(), 2u);
  uint64_t primary = 0, shadow = 0, forwarded = 0;
  for (const auto& fs : *stats) {
    for (const auto& w : fs.workers()) {
      primary += w.primary_traced();
      shadow += w.shadow_traced();
      forwarded += w.rays_sent();
    }
  }
  ASSERT_GT(forwarded, 0u) << "two slabs and a 30-degree view forward rays";

  auto root = Scrape((*cluster)->root_metrics_port());
  EXPECT_EQ(root["transtick_root_frames_total"], 2);
  EXPECT_EQ(root["transtick_root_frame_seconds_count"], 2);
  EXPECT_EQ(root["transtick_root_job_start_seconds_count"], 1);
  EXPECT_EQ(root["transtick_root_jobs_submitted_total"], 1);
  EXPECT_EQ(root["transtick_root_jobs{state=\"DONE\"}"], 1);
  EXPECT_EQ(root["transtick_root_jobs{state=\"RUNNING\"}"], 0);
  EXPECT_EQ(root["transtick_root_workers"], 2);
  EXPECT_EQ(root["transtick_root_rings"], 1);
  EXPECT_EQ(root["transtick_root_rays_traced_total{kind=\"primary\"}"], primary);
  EXPECT_EQ(root["transtick_root_rays_traced_total{kind=\"shadow\"}"], shadow);
  EXPECT_EQ(root["transtick_root_rays_forwarded_total"], forwarded);

  double w_primary = 0, w_sent = 0, w_received = 0, w_bytes_sent = 0, w_bytes_received = 0;
  for (int port : (*cluster)->worker_metrics_ports()) {
    auto w = Scrape(port);
    EXPECT_EQ(w["transtick_worker_frames_total{result=\"done\"}"], 2);
    EXPECT_EQ(w["transtick_worker_frame_seconds_count"], 2);
    EXPECT_EQ(w["transtick_worker_datasets_held"], 1);
    EXPECT_EQ(w["transtick_worker_rays_rejected_total"], 0);
    EXPECT_GT(w["transtick_worker_busy_seconds_total"], 0);
    w_primary += w["transtick_worker_rays_traced_total{kind=\"primary\"}"];
    w_sent += w["transtick_worker_rays_forwarded_total{direction=\"left\"}"] +
              w["transtick_worker_rays_forwarded_total{direction=\"right\"}"];
    w_received += w["transtick_worker_rays_received_total{direction=\"left\"}"] +
                  w["transtick_worker_rays_received_total{direction=\"right\"}"];
    w_bytes_sent += w["transtick_worker_stream_bytes_total{direction=\"sent\"}"];
    w_bytes_received += w["transtick_worker_stream_bytes_total{direction=\"received\"}"];
  }
  EXPECT_EQ(w_primary, primary);
  EXPECT_EQ(w_sent, forwarded);
  EXPECT_EQ(w_received, w_sent) << "every ray forwarded in a ring is received";
  // The receiver also counts each stream's first batch, which names the
  // frame and holds no rays: a few bytes per stream and frame.
  EXPECT_NEAR(w_bytes_received, w_bytes_sent, 2 * 2 * 16);
  EXPECT_GT(w_bytes_sent, 0);

  auto display = Scrape((*cluster)->display_metrics_port());
  EXPECT_EQ(display["transtick_display_frames_total{result=\"complete\"}"], 2);
  EXPECT_EQ(display["transtick_display_frames_open"], 0);
  EXPECT_GE(display["transtick_display_deposits_total"], 2.0 * 48 * 40);
  // One assembly time per complete frame, each within the root's frame time.
  EXPECT_EQ(display["transtick_display_frame_assembly_seconds_count"], 2);
  EXPECT_GT(display["transtick_display_frame_assembly_seconds_sum"], 0);
  EXPECT_LE(display["transtick_display_frame_assembly_seconds_sum"],
            root["transtick_root_frame_seconds_sum"]);

  // Reflection lists each daemon's own API and the health service.
  const std::string listed = ReflectedServices((*cluster)->root_address());
  EXPECT_NE(listed.find("transtick.v1.Root"), std::string::npos) << listed;
  EXPECT_NE(listed.find("grpc.health.v1.Health"), std::string::npos);
  const std::string worker = ReflectedServices((*cluster)->worker_addresses()[0]);
  EXPECT_NE(worker.find("transtick.v1.Worker"), std::string::npos) << worker;
}

}  // namespace
}  // namespace transtick
