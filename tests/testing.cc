#include "testing.h"

#include <unistd.h>

#include <cstdlib>
#include <deque>
#include <filesystem>

#include "absl/strings/str_cat.h"
#include "gtest/gtest.h"
#include "transtick/ray_codec.h"
#include "transtick/render.h"
#include "transtick/ring_layout.h"

namespace transtick::testing {

std::string DataDir() {
  if (const char* d = std::getenv("TRANSTICK_DATA_DIR")) return d;
  // Through StrCat: operator+ on a literal draws a false
  // -Wstringop-overflow from GCC 12 when linked with -flto.
  return absl::StrCat(TRANSTICK_SOURCE_DIR, "/../shared/data");
}

std::string DataFile(const std::string& name) {
  std::string path = DataDir() + "/" + name;
  return std::filesystem::exists(path) ? path : "";
}

std::string TempDir() {
  std::string base = ::testing::TempDir() + "transtick-XXXXXX";
  std::vector<char> buf(base.begin(), base.end());
  buf.push_back('\0');
  const char* dir = mkdtemp(buf.data());
  EXPECT_NE(dir, nullptr);
  return dir ? dir : "/tmp";
}

Image RenderSlabs(const Scene& whole, const std::vector<int>& cuts, const Camera& camera,
                  const RenderSettings& settings, uint64_t* handoffs, uint64_t* ended_early) {
  std::vector<int> bounds = {0};
  bounds.insert(bounds.end(), cuts.begin(), cuts.end());
  bounds.push_back(whole.dims()[1]);
  const RingLayout layout(bounds, whole.dims(), whole.spacing(), camera);
  std::vector<Scene> slabs;
  std::vector<Tracer> tracers;
  slabs.reserve(bounds.size() - 1);
  for (size_t i = 0; i + 1 < bounds.size(); ++i)
    slabs.push_back(whole.Slab(bounds[i], bounds[i + 1]));
  for (const Scene& s : slabs) tracers.emplace_back(s, settings, camera);
  Framebuffer fb(camera.width(), camera.height(), settings.samples);
  std::vector<std::deque<RayDescriptor>> queues(slabs.size());
  TraceCounters counters;
  // Each slab makes its own primary rays by the rule the workers use
  // (RingLayout::Primary): only for the pixels of its footprint, keeping
  // the rays that enter the volume in its slab; each miss is deposited by
  // one slab. Every sample of every pixel must be taken care of exactly
  // once.
  const int samples = settings.samples;
  std::vector<int> taken(static_cast<size_t>(camera.width()) * camera.height(), 0);
  for (int i = 0; i < layout.slabs(); ++i) {
    for (int py = 0; py < camera.height(); ++py) {
      for (int px = 0; px < camera.width(); ++px) {
       for (int s = 0; s < samples; ++s) {
        const uint32_t pixel = static_cast<uint32_t>(py) * camera.width() + px;
        RayDescriptor ray;
        switch (layout.Primary(i, px, py, s, samples, tracers[i], &ray)) {
          case RingLayout::PrimaryRole::kTrace:
            EXPECT_EQ(layout.SlabOf(ray.cell[1]), i);
            EXPECT_EQ(ray.pixel, pixel);
            queues[i].push_back(ray);
            ++taken[pixel];
            break;
          case RingLayout::PrimaryRole::kMiss:
            fb.Add(tracers[i].MissDeposit(pixel));
            ++taken[pixel];
            break;
          case RingLayout::PrimaryRole::kNone:
            break;
        }
       }
      }
    }
  }
  for (size_t p = 0; p < taken.size(); ++p) {
    EXPECT_EQ(taken[p], samples) << "pixel " << p % camera.width() << "," << p / camera.width();
  }
  uint64_t moved = 0;
  std::vector<RayDescriptor> spawned;
  Deposit deposit;
  bool busy = true;
  while (busy) {
    busy = false;
    // Round-robin over slabs, a few rays each, so rays interleave as they
    // would on a ring.
    for (size_t i = 0; i < slabs.size(); ++i) {
      // The rays slab i hands on in this turn, per neighbour, as queued records.
      std::vector<std::string> outgoing(slabs.size());
      for (int n = 0; n < 7 && !queues[i].empty(); ++n) {
        busy = true;
        RayDescriptor ray = queues[i].front();
        queues[i].pop_front();
        spawned.clear();
        auto outcome = tracers[i].Trace(ray, spawned, deposit, counters);
        for (const auto& s : spawned) queues[i].push_back(s);
        if (outcome == Tracer::Outcome::kFinished) {
          fb.Add(deposit);
        } else {
          // To the neighbour, as a worker sends it; a neighbour that does
          // not hold the cell either passes it on in turn.
          const RingLayout::Hop hop = layout.Route(static_cast<int>(i), ray.cell);
          EXPECT_NE(hop, RingLayout::Hop::kFinished);
          if (hop == RingLayout::Hop::kFinished) continue;
          const int o = RingLayout::Neighbour(static_cast<int>(i), hop);
          EXPECT_GE(o, 0);
          EXPECT_LT(o, layout.slabs());
          EXPECT_NE(o, static_cast<int>(i));
          ++moved;
          AppendRay(ray, &outgoing[o]);
        }
      }
      // Through the wire form, packed in a batch as between workers.
      for (size_t o = 0; o < slabs.size(); ++o) {
        if (outgoing[o].empty()) continue;
        std::string wire;
        const size_t count = PackRays(outgoing[o], &wire);
        EXPECT_EQ(count, outgoing[o].size() / kRayRecordBytes);
        const DecodedRays decoded = DecodePackedRays(wire, camera.width() * camera.height());
        EXPECT_TRUE(!decoded.broken && decoded.invalid == 0 && decoded.rays.size() == count)
            << decoded.error;
        for (const RayDescriptor& r : decoded.rays) {
          // Every ray a tracer hands on is one its neighbour accepts.
          EXPECT_TRUE(tracers[o].Validate(r).ok()) << tracers[o].Validate(r);
          queues[o].push_back(r);
        }
      }
    }
  }
  EXPECT_TRUE(fb.Complete());
  if (handoffs) *handoffs = moved;
  if (ended_early) *ended_early = counters.ended_early;
  return fb.Resolve();
}

Image RenderWhole(const Scene& scene, const Camera& camera, const RenderSettings& settings,
                  int threads) {
  RenderStats stats;
  auto image = RenderLocal(scene, camera, settings, threads, &stats);
  EXPECT_TRUE(image.ok()) << image.status();
  return image.ok() ? *image : Image{};
}

Camera MakeCamera(std::array<int, 3> dims, int size, double azimuth, double elevation,
                  Projection projection, double zoom) {
  CameraSpec spec;
  spec.width = spec.height = size;
  spec.azimuth_deg = azimuth;
  spec.elevation_deg = elevation;
  spec.projection = projection;
  spec.zoom = zoom;
  auto camera = Camera::Create(spec, Vec3{double(dims[0]), double(dims[1]), double(dims[2])});
  EXPECT_TRUE(camera.ok());
  return *camera;
}

}  // namespace transtick::testing
