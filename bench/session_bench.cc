// Interactive sessions through an embedded cluster: how long a camera
// change takes to come back as a full frame, against the frame's own time
// at the root (the goal: within 1.5x), with and without a preview,
// and what a drag (a camera every few ms) does; then the same steps through
// the web gateway (HTTP, PNG) paired with direct gRPC ones, interleaved.
//
//   session_bench [--volume cthead.nrrd] [--materials FILE] [--workers 2]
//                 [--size 400x400] [--steps 20] [--drag-ms 3000] [--every-ms 15]
//                 [--image float32|rgb8]
//
// --image is the encoding the direct (gRPC) sessions ask for (docs/formats.md,
// "Image chunks"); the gateway always asks for rgb8.
//
// Needs TRANSTICK_DATA_DIR (the volume's directory; default ../shared/data).
#include <httplib.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "bench_util.h"
#include "client.h"
#include "convert.h"
#include "daemon.h"
#include "gateway.h"
#include "local_cluster.h"
#include "web.pb.h"

namespace transtick {
namespace {

int Main(int argc, char** argv) {
  std::string volume = "cthead.nrrd";
  std::string materials = std::string(TRANSTICK_SOURCE_DIR) + "/examples/cthead_materials.json";
  int workers = 2, width = 400, height = 400, steps = 20, drag_ms = 3000, every_ms = 15;
  v1::ImageEncoding encoding = v1::FLOAT32;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i], value = argv[i + 1];
    bool ok = true;
    if (flag == "--volume") {
      volume = value;
    } else if (flag == "--materials") {
      materials = value;
    } else if (flag == "--workers") {
      ok = bench::ParseInt(value, 1, 16, &workers);
    } else if (flag == "--size") {
      ok = bench::ParseSize(value, 8192, &width, &height);
    } else if (flag == "--steps") {
      ok = bench::ParseInt(value, 2, 10000, &steps);
    } else if (flag == "--drag-ms") {
      ok = bench::ParseInt(value, 0, 600000, &drag_ms);
    } else if (flag == "--every-ms") {
      ok = bench::ParseInt(value, 1, 10000, &every_ms);
    } else if (flag == "--image") {
      auto e = ParseEnum<v1::ImageEncoding>(value, "--image");
      ok = e.ok();
      if (ok) encoding = *e;
    } else {
      ok = false;
    }
    if (!ok) {
      std::fprintf(stderr, "session_bench: bad flag %s %s\n", flag.c_str(), value.c_str());
      return 2;
    }
  }
  const char* data = std::getenv("TRANSTICK_DATA_DIR");
  LocalCluster::Options o;
  o.workers = workers;
  o.threads_per_worker = 1;
  o.data_dir = data ? data : "../shared/data";
  auto cluster = LocalCluster::Start(o);
  if (!cluster.ok()) {
    std::fprintf(stderr, "session_bench: %s\n", std::string(cluster.status().message()).c_str());
    return 1;
  }
  v1::Dataset dataset;
  dataset.set_volume(volume);
  {
    std::ifstream f(materials);
    std::stringstream text;
    text << f.rdbuf();
    if (absl::Status s = ParseJson(text.str(), materials, dataset.mutable_materials()); !s.ok()) {
      std::fprintf(stderr, "session_bench: %s\n", std::string(s.message()).c_str());
      return 1;
    }
  }
  auto view = [&](double azimuth) {
    v1::View v;
    v.set_azimuth(azimuth);
    v.set_width(width);
    v.set_height(height);
    v.set_shadows(true);
    return v;
  };
  *dataset.add_views() = view(45);
  std::printf("session_bench: %s %dx%d, %d workers x 1 thread, shadows on, images %s\n",
              volume.c_str(), width, height, workers, EnumName(encoding).c_str());

  for (int preview : {0, 4}) {
    auto session = SessionClient::Open((*cluster)->root_address(), dataset, preview, "", encoding);
    if (!session.ok()) return 1;
    auto next_full = [&](uint64_t seq, double* preview_ms,
                         std::chrono::steady_clock::time_point t0) -> absl::StatusOr<SessionClient::Event> {
      while (true) {
        auto e = (*session)->Next();
        if (!e.ok()) return e.status();
        if (!e->error.empty()) return absl::InternalError(e->error);
        if (e->has_frame && e->preview && e->seq == seq && preview_ms) *preview_ms = bench::MsSince(t0);
        if (e->has_frame && !e->preview && e->seq == seq) return e;
      }
    };
    auto first = next_full(1, nullptr, std::chrono::steady_clock::now());  // ready, and camera 1
    if (!first.ok()) {
      std::fprintf(stderr, "session_bench: %s\n", std::string(first.status().message()).c_str());
      return 1;
    }
    std::vector<double> latency, frame, ratio, previews;
    for (int i = 0; i < steps; ++i) {
      const auto t0 = std::chrono::steady_clock::now();
      auto seq = (*session)->SetView(view(45 + 7 * (i + 1)));
      double preview_ms = 0;
      auto e = next_full(*seq, &preview_ms, t0);
      if (!e.ok()) return 1;
      latency.push_back(bench::MsSince(t0));
      frame.push_back(e->stats.frame_ms());
      ratio.push_back(latency.back() / e->stats.frame_ms());
      if (preview) previews.push_back(preview_ms);
    }
    std::printf("  steps, preview %s: camera -> full frame median %.1f ms (min %.1f), frame at the "
                "root %.1f ms; latency/frame median %.2f%s\n",
                preview ? "1/4" : "off", bench::Median(latency),
                *std::min_element(latency.begin(), latency.end()), bench::Median(frame),
                bench::Median(ratio),
                preview ? absl::StrCat("; camera -> preview median ",
                                       absl::StrFormat("%.1f", bench::Median(previews)), " ms")
                              .c_str()
                        : "");
    if (drag_ms > 0) {
      // A drag: cameras every `every_ms` while frames come back.
      std::atomic<bool> dragging{true};
      std::atomic<uint64_t> last_sent{0};
      int sent = 0;
      std::thread sender([&] {
        const auto start = std::chrono::steady_clock::now();
        for (int i = 0; bench::MsSince(start) < drag_ms; ++i) {
          last_sent = *(*session)->SetView(view(100 + 0.5 * i));
          ++sent;
          std::this_thread::sleep_for(std::chrono::milliseconds(every_ms));
        }
        dragging = false;
      });
      int full = 0, previewed = 0;
      uint64_t newest = 0;
      std::chrono::steady_clock::time_point stop_at;
      while (true) {
        auto e = (*session)->Next();
        if (!e.ok()) return 1;
        if (!e->has_frame) continue;
        (e->preview ? previewed : full) += 1;
        newest = e->seq;
        if (!dragging && stop_at == std::chrono::steady_clock::time_point()) {
          stop_at = std::chrono::steady_clock::now();
        }
        if (!dragging && !e->preview && newest == last_sent) break;
      }
      const double settle = bench::MsSince(stop_at);
      sender.join();
      std::printf("  drag %d ms, a camera every %d ms: %d cameras sent, %d full frames and %d "
                  "previews back (%.1f full frames/s); the last camera's frame %.0f ms after the "
                  "drag ended\n",
                  drag_ms, every_ms, sent, full, previewed, full * 1000.0 / drag_ms, settle);
    }
    if (!(*session)->Close().ok()) return 1;
  }

  // The web gateway against gRPC, step for step: a camera to its full frame
  // through HTTP (a POST, then the long poll's answer with the PNG), and the
  // same through a SessionClient, alternately.
  WebOptions wo;
  wo.listen = "127.0.0.1:0";
  wo.root = (*cluster)->root_address();
  auto gateway = WebGateway::Start(wo);
  if (!gateway.ok()) {
    std::fprintf(stderr, "session_bench: %s\n", std::string(gateway.status().message()).c_str());
    return 1;
  }
  httplib::Client http("127.0.0.1", (*gateway)->port());
  http.set_read_timeout(std::chrono::seconds(60));
  v1::WebOpenRequest open;
  *open.mutable_dataset() = dataset;
  open.set_preview(0);
  auto opened = http.Post("/api/sessions", ToJson(open, false), "application/json");
  v1::WebOpenReply reply;
  if (!opened || opened->status != 200 || !ParseJson(opened->body, "open", &reply).ok()) {
    std::fprintf(stderr, "session_bench: the gateway did not open a session\n");
    return 1;
  }
  const std::string path = "/api/sessions/" + reply.session();
  uint32_t after = 0;
  size_t png_bytes = 0;
  // Polls until the full frame of `seq`.
  auto web_full = [&](uint32_t seq) -> bool {
    while (true) {
      auto res = http.Get(absl::StrCat(path, "/events?after=", after, "&wait=10"));
      if (!res || res->status != 200 || res->body.size() < 4) return false;
      uint32_t n = 0;
      for (int i = 0; i < 4; ++i) n |= static_cast<uint32_t>(static_cast<unsigned char>(res->body[i])) << (8 * i);
      v1::WebEvents events;
      if (!ParseJson(res->body.substr(4, n), "events", &events).ok()) return false;
      after = events.next();
      for (const v1::WebEvent& e : events.events()) {
        if (e.kind() == "frame" && !e.preview() && e.seq() == seq) {
          png_bytes = e.png_size() == 2 ? e.png(1) : 0;
          return true;
        }
      }
    }
  };
  if (!web_full(1)) return 1;
  auto direct = SessionClient::Open((*cluster)->root_address(), dataset, 0, "", encoding);
  if (!direct.ok()) return 1;
  for (uint64_t seq = 1;;) {  // its first frame
    auto e = (*direct)->Next();
    if (!e.ok()) return 1;
    if (e->has_frame && !e->preview && e->seq == seq) break;
  }
  std::vector<double> web_ms, grpc_ms;
  for (int i = 0; i < 2 * steps; ++i) {
    const v1::View v = view(45 + 7 * (i / 2 + 1));
    const auto t0 = std::chrono::steady_clock::now();
    if (i % 2 == 0) {
      v1::WebSessionUpdate u;
      *u.mutable_view() = v;
      auto res = http.Post(path, ToJson(u, false), "application/json");
      v1::WebSeqReply seq;
      if (!res || res->status != 200 || !ParseJson(res->body, "seq", &seq).ok()) return 1;
      if (!web_full(seq.seq())) return 1;
      web_ms.push_back(bench::MsSince(t0));
    } else {
      auto seq = (*direct)->SetView(v);
      if (!seq.ok()) return 1;
      while (true) {
        auto e = (*direct)->Next();
        if (!e.ok()) return 1;
        if (e->has_frame && !e->preview && e->seq == *seq) break;
      }
      grpc_ms.push_back(bench::MsSince(t0));
    }
  }
  std::printf("  web gateway, preview off, %d steps each, interleaved: camera -> full frame median "
              "%.1f ms through HTTP (PNG %zu bytes), %.1f ms through gRPC; web/gRPC %.2f\n",
              steps, bench::Median(web_ms), png_bytes, bench::Median(grpc_ms),
              bench::Median(web_ms) / bench::Median(grpc_ms));
  (void)http.Delete(path);
  return 0;
}

}  // namespace
}  // namespace transtick

int main(int argc, char** argv) {
  transtick::UseReleaseLocking();          // as the daemons it stands for
  spdlog::set_level(spdlog::level::warn);  // the embedded root logs every frame at info
  return transtick::Main(argc, argv);
}
