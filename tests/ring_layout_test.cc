// Where rays go on a ring: known answers for SlabOf, Route and the
// footprints, and over random cuts and views, the properties the cluster's
// images rest on. Every pixel's primary ray is made by exactly the slab its
// entry cell lies in, or its miss deposited exactly once; a ray handed on
// hop by hop reaches the slab holding its cell.
#include "transtick/ring_layout.h"

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "gtest/gtest.h"
#include "testing.h"
#include "transtick/partition.h"
#include "transtick/ray_codec.h"
#include "transtick/synthetic.h"
#include "transtick/traversal.h"

namespace transtick {
namespace {

using Hop = RingLayout::Hop;
using PrimaryRole = RingLayout::PrimaryRole;

constexpr std::array<int, 3> kDims = {40, 34, 38};

Camera CameraFor(const std::array<double, 3>& spacing, int width, int height, double azimuth,
                 double elevation, Projection projection = Projection::kPerspective,
                 double zoom = 1) {
  CameraSpec spec;
  spec.width = width;
  spec.height = height;
  spec.azimuth_deg = azimuth;
  spec.elevation_deg = elevation;
  spec.projection = projection;
  spec.zoom = zoom;
  auto camera = Camera::Create(
      spec, Vec3{kDims[0] * spacing[0], kDims[1] * spacing[1], kDims[2] * spacing[2]});
  EXPECT_TRUE(camera.ok()) << camera.status();
  return *camera;
}

Scene SphereScene(const std::array<double, 3>& spacing) {
  Volume v = MakeSphere(kDims, {20, 17, 19}, 14);
  v.spacing = spacing;
  Classification c;
  c.materials = {{.name = "ball", .min = 50, .max = 150}};
  return *Scene::ForSurfaces(v, c);
}

// n random valid cuts of `planes`, one-plane slabs included now and then.
std::vector<int> RandomCuts(std::mt19937& rng, int planes) {
  const int n = 1 + static_cast<int>(rng() % 8);
  std::vector<int> inner;
  for (int y = 1; y < planes; ++y) inner.push_back(y);
  std::shuffle(inner.begin(), inner.end(), rng);
  inner.resize(n - 1);
  std::sort(inner.begin(), inner.end());
  std::vector<int> cuts = {0};
  cuts.insert(cuts.end(), inner.begin(), inner.end());
  cuts.push_back(planes);
  EXPECT_TRUE(ValidCuts(cuts, planes, n));
  return cuts;
}

TEST(RingLayoutTest, SlabOfKnownAnswers) {
  const Camera camera = CameraFor({1, 1, 1}, 16, 16, 0, 0);
  const RingLayout layout({0, 3, 7, 8, 34}, kDims, {1, 1, 1}, camera);
  EXPECT_EQ(layout.slabs(), 4);
  EXPECT_EQ(layout.y_begin(2), 7);
  EXPECT_EQ(layout.y_end(2), 8);
  const int want[] = {0, 0, 0, 1, 1, 1, 1, 2, 3, 3};
  for (int y = 0; y < 10; ++y) EXPECT_EQ(layout.SlabOf(y), want[y]) << "y " << y;
  EXPECT_EQ(layout.SlabOf(33), 3);
  const RingLayout one({0, 34}, kDims, {1, 1, 1}, camera);
  for (int y = 0; y < 34; ++y) EXPECT_EQ(one.SlabOf(y), 0);
}

TEST(RingLayoutTest, RouteKnownAnswers) {
  const Camera camera = CameraFor({1, 1, 1}, 16, 16, 0, 0);
  const RingLayout layout({0, 3, 7, 8, 34}, kDims, {1, 1, 1}, camera);
  EXPECT_EQ(layout.Route(1, {5, 2, 5}), Hop::kLeft);
  EXPECT_EQ(layout.Route(1, {5, 0, 5}), Hop::kLeft);
  EXPECT_EQ(layout.Route(1, {5, 7, 5}), Hop::kRight);
  // Past the next slab (a brick crossed in one step): still the right
  // neighbour, which passes the ray on.
  EXPECT_EQ(layout.Route(1, {5, 20, 5}), Hop::kRight);
  EXPECT_EQ(layout.Route(2, {5, 6, 5}), Hop::kLeft);
  EXPECT_EQ(layout.Route(2, {5, 8, 5}), Hop::kRight);
  // Off the volume on any axis: finished.
  EXPECT_EQ(layout.Route(1, {-1, 2, 5}), Hop::kFinished);
  EXPECT_EQ(layout.Route(1, {5, 2, 38}), Hop::kFinished);
  EXPECT_EQ(layout.Route(0, {5, -1, 5}), Hop::kFinished);
  EXPECT_EQ(layout.Route(3, {5, 34, 5}), Hop::kFinished);
  EXPECT_EQ(RingLayout::Neighbour(1, Hop::kLeft), 0);
  EXPECT_EQ(RingLayout::Neighbour(1, Hop::kRight), 2);
}

// A slab's footprint is where the rays that first enter the volume in its
// planes pass: over random views (orbits, and explicit eyes in, on and
// around the volume's box), spacings, cuts and sample positions, the slab
// holding a ray's entry cell has the ray's pixel in its footprint, and
// each footprint lies within the projection of the slab's box. Seen from
// outside the box, the footprints overlap less than the boxes' did: a ray
// is made on fewer slabs only to be dropped.
TEST(RingLayoutTest, FootprintsHoldTheRaysEnteringTheirSlabs) {
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> unit(0, 1);
  int64_t entries = 0, box_area = 0, footprint_area = 0, inside_views = 0;
  for (const std::array<double, 3>& spacing :
       {std::array<double, 3>{1, 1, 1}, std::array<double, 3>{0.7, 1.3, 2},
        std::array<double, 3>{2, 0.5, 1}}) {
    const Scene scene = SphereScene(spacing);
    const Vec3 half{0.5 * kDims[0] * spacing[0], 0.5 * kDims[1] * spacing[1],
                    0.5 * kDims[2] * spacing[2]};
    for (int v = 0; v < 120; ++v) {
      CameraSpec spec;
      spec.width = 24 + static_cast<int>(rng() % 24);
      spec.height = 24 + static_cast<int>(rng() % 24);
      spec.projection = rng() % 3 == 0 ? Projection::kOrthographic : Projection::kPerspective;
      spec.zoom = 0.5 + 3.5 * unit(rng);
      spec.fov_deg = 10 + 100 * unit(rng);
      const bool orbit = v % 2 == 0;
      if (orbit) {
        spec.azimuth_deg = 360 * unit(rng);
        spec.elevation_deg = v % 8 == 0 ? 90 * ((v / 8) % 3 - 1) : -89 + 178 * unit(rng);
      } else {
        // An eye anywhere from inside the box to twice its size away, now
        // and then on one of its faces' planes.
        Vec3 eye{half.x * (4 * unit(rng) - 2), half.y * (4 * unit(rng) - 2),
                 half.z * (4 * unit(rng) - 2)};
        if (v % 6 == 1) {
          const int a = static_cast<int>(rng() % 3);
          eye[a] = rng() % 2 ? half[a] : -half[a];
        }
        eye.y = v % 10 == 3 ? half.y : eye.y;
        const Vec3 target{half.x * (unit(rng) - 0.5), half.y * (unit(rng) - 0.5),
                          half.z * (unit(rng) - 0.5)};
        if (Length(eye - target) < 1e-3) continue;
        spec.view = ExplicitView{eye, target, Vec3{0, 1, 0}};
        if (std::abs(Dot(Normalize(target - eye), Vec3{0, 1, 0})) > 0.999) {
          spec.view->up = Vec3{1, 0, 0};
        }
        inside_views +=
            std::abs(eye.x) < half.x && std::abs(eye.y) < half.y && std::abs(eye.z) < half.z;
      }
      auto made = Camera::Create(spec, Vec3{2 * half.x, 2 * half.y, 2 * half.z});
      ASSERT_TRUE(made.ok()) << made.status();
      const Camera& camera = *made;
      const Tracer tracer(scene, RenderSettings{}, camera);
      const RingLayout layout(RandomCuts(rng, kDims[1]), kDims, spacing, camera);
      for (int i = 0; i < layout.slabs(); ++i) {
        const Vec3 lo{-half.x, (layout.y_begin(i) - 0.5 * kDims[1]) * spacing[1], -half.z};
        const Vec3 hi{half.x, (layout.y_end(i) - 0.5 * kDims[1]) * spacing[1], half.z};
        const ImageSpans box = camera.Footprint(lo, hi);
        for (int row = 0; row < camera.height(); ++row) {
          const auto [first, last] = layout.Footprint(i).Row(row);
          const auto [box_first, box_last] = box.Row(row);
          if (first < last) {
            EXPECT_GE(first, box_first) << "slab " << i << " row " << row;
            EXPECT_LE(last, box_last) << "slab " << i << " row " << row;
          }
          for (int col = 0; col < camera.width(); ++col) {
            // What a slab holds lies in its footprint's columns.
            const bool held = layout.Holds(i, col, row);
            EXPECT_TRUE(!held || (col >= first && col < last)) << col << "," << row;
            if (orbit) footprint_area += held;
          }
          if (orbit) box_area += std::max(0, box_last - box_first);
        }
      }
      const int samples = 1 + static_cast<int>(rng() % 5);
      for (int row = 0; row < camera.height(); ++row) {
        for (int col = 0; col < camera.width(); ++col) {
          const auto [ox, oy] = SampleOffset(static_cast<int>(rng() % samples), samples);
          RayDescriptor ray;
          if (!tracer.MakePrimary(camera.GenerateAt(col, row, ox, oy), 0, &ray)) continue;
          ++entries;
          ASSERT_TRUE(layout.Holds(layout.SlabOf(ray.cell[1]), col, row))
              << "pixel " << col << "," << row << " enters in slab " << layout.SlabOf(ray.cell[1])
              << " of " << layout.slabs() << ", view " << v;
        }
      }
    }
  }
  EXPECT_GT(entries, 100000);
  EXPECT_GT(inside_views, 5);  // views from inside the box were seen
  // The slabs' footprints overlap far less than their boxes'.
  EXPECT_LT(footprint_area, box_area * 8 / 10) << footprint_area << " of " << box_area;
  EXPECT_GT(footprint_area, 0);
}

// Seen from outside, a pixel's ray enters in one slab, and few pixels are
// held by two: those within the margins of a face's part, and where the
// parts of two faces meet. (The hull of the parts, row by row, spans a
// corner of the box seen at an angle: it held 15-19% of the pixels twice on
// 2 slabs and 46-57% on 4 at the views below that are not frontal, against
// 6-10% and 21-30% now.)
TEST(RingLayoutTest, FewPixelsAreHeldByTwoSlabs) {
  const std::array<double, 3> spacing = {1, 1, 2};
  for (const auto& [azimuth, elevation] : {std::pair{45.0, 15.0}, std::pair{30.0, 40.0},
                                           std::pair{0.0, 15.0}, std::pair{200.0, -35.0}}) {
    const Camera camera = CameraFor(spacing, 200, 200, azimuth, elevation);
    for (int n : {2, 4}) {
      std::vector<int> cuts;
      for (int i = 0; i <= n; ++i) cuts.push_back(kDims[1] * i / n);
      const RingLayout layout(cuts, kDims, spacing, camera);
      int64_t held = 0, extra = 0;
      for (int row = 0; row < camera.height(); ++row) {
        for (int col = 0; col < camera.width(); ++col) {
          int holders = 0;
          for (int i = 0; i < n; ++i) holders += layout.Holds(i, col, row);
          held += holders > 0;
          extra += std::max(0, holders - 1);
        }
      }
      EXPECT_GT(held, 10000);
      // The margins (a plane each side, two pixels) weigh more with more
      // slabs of this small volume (34 planes).
      EXPECT_LT(extra, held * (n == 2 ? 11 : 35) / 100)
          << extra << " of " << held << " at " << azimuth << ", " << elevation << ", " << n
          << " slabs";
    }
  }
}

// Every pixel of every view, over random cuts: exactly one slab makes its
// primary ray, the one holding the ray's entry cell, or, when the ray
// misses, exactly one slab deposits the miss, MissSlab's.
TEST(RingLayoutTest, EveryPixelIsTakenCareOfExactlyOnce) {
  std::mt19937 rng(17);
  struct View {
    double azimuth, elevation;
    Projection projection;
    double zoom;
  };
  const View views[] = {
      {0, 0, Projection::kPerspective, 1},       {45, 20, Projection::kPerspective, 1},
      {0, 90, Projection::kPerspective, 1},      {10, -89, Projection::kOrthographic, 1},
      {200, -30, Projection::kPerspective, 2.5}, {120, 60, Projection::kOrthographic, 0.6},
      {90, 0, Projection::kPerspective, 4}};
  int traced = 0, missed = 0, off_footprint_misses = 0, void_pixels = 0;
  for (const std::array<double, 3>& spacing :
       {std::array<double, 3>{1, 1, 1}, std::array<double, 3>{0.7, 1.3, 2}}) {
    const Scene scene = SphereScene(spacing);
    for (const View& v : views) {
      const Camera camera =
          CameraFor(spacing, 41, 37, v.azimuth, v.elevation, v.projection, v.zoom);
      const Tracer tracer(scene, RenderSettings{}, camera);
      for (int round = 0; round < 4; ++round) {
        const RingLayout layout(RandomCuts(rng, kDims[1]), kDims, spacing, camera);
        for (int row = 0; row < camera.height(); ++row) {
          for (int col = 0; col < camera.width(); ++col) {
            // The pixel's centre, or (on odd pixels) the last of three
            // samples, off the centre: a footprint holds every sample.
            const int samples = (row + col) % 2 ? 3 : 1, sample = samples - 1;
            const auto [ox, oy] = SampleOffset(sample, samples);
            RayDescriptor want;
            const uint32_t pixel = static_cast<uint32_t>(row) * camera.width() + col;
            const bool hits =
                tracer.MakePrimary(camera.GenerateAt(col, row, ox, oy), pixel, &want);
            int tracers = 0, missers = 0, in_footprints = 0;
            for (int i = 0; i < layout.slabs(); ++i) {
              in_footprints += layout.Holds(i, col, row);
              RayDescriptor ray;
              switch (layout.Primary(i, col, row, sample, samples, tracer, &ray)) {
                case PrimaryRole::kTrace:
                  ++tracers;
                  EXPECT_EQ(i, layout.SlabOf(want.cell[1]));
                  EXPECT_EQ(ray.cell, want.cell);
                  EXPECT_EQ(ray.t, want.t);
                  EXPECT_EQ(ray.pixel, pixel);
                  break;
                case PrimaryRole::kMiss:
                  ++missers;
                  EXPECT_EQ(i, layout.MissSlab(col, row));
                  break;
                case PrimaryRole::kNone:
                  break;
              }
            }
            ASSERT_EQ(tracers + missers, 1) << "pixel " << col << "," << row;
            // A ray known to meet nothing is not made: its miss is deposited.
            const bool known_void = tracer.Void(col, row);
            EXPECT_EQ(tracers == 1, hits && !known_void) << "pixel " << col << "," << row;
            void_pixels += hits && known_void;
            // A ray that meets the volume meets the slab it enters, whose
            // footprint therefore holds the pixel.
            if (hits) {
              EXPECT_TRUE(layout.Holds(layout.SlabOf(want.cell[1]), col, row));
            }
            traced += tracers;
            missed += missers;
            off_footprint_misses += missers == 1 && in_footprints == 0;
          }
        }
      }
    }
  }
  // Both kinds of pixel, and misses found both ways, were seen.
  EXPECT_GT(traced, 10000);
  EXPECT_GT(missed, 10000);
  EXPECT_GT(off_footprint_misses, 1000);
  EXPECT_LT(off_footprint_misses, missed);
  EXPECT_GT(void_pixels, 20);
}

// RingLayout::Primaries, which a worker calls for the pixels of a row, is
// Primary for each of their samples: the same rays in the same order, and
// the same miss deposits, those of pixels whose every sample is the slab's
// miss as runs (what a run stands for read back one deposit at a time).
TEST(RingLayoutTest, PrimariesOfARowAreItsPixelsPrimaries) {
  std::mt19937 rng(23);
  const std::array<double, 3> spacing = {1, 1.2, 0.9};
  const Scene scene = SphereScene(spacing);
  uint64_t run_records = 0, run_pixels = 0, single_misses = 0;
  for (int round = 0; round < 40; ++round) {
    const int samples = 1 + static_cast<int>(rng() % 5);
    const int width = 31 + static_cast<int>(rng() % 20), height = 23 + static_cast<int>(rng() % 20);
    const Camera camera =
        CameraFor(spacing, width, height, static_cast<double>(rng() % 360),
                  static_cast<double>(rng() % 170) - 85,
                  rng() % 2 ? Projection::kPerspective : Projection::kOrthographic,
                  0.5 + (rng() % 30) / 10.0);
    RenderSettings settings;
    settings.background = {0.1f * (rng() % 10), 0.5f, 0};
    const Tracer tracer(scene, settings, camera);
    const RingLayout layout(RandomCuts(rng, kDims[1]), kDims, spacing, camera);
    for (int slab = 0; slab < layout.slabs(); ++slab) {
      for (int row = 0; row < camera.height(); ++row) {
        // The whole row, as a unit of a worker's usually is, or a part.
        const bool part = rng() % 3 == 0;
        const int from = part ? static_cast<int>(rng() % camera.width()) : 0;
        const int to =
            part ? from + static_cast<int>(rng() % (camera.width() - from + 1)) : camera.width();
        std::vector<RayDescriptor> want_rays, got_rays;
        std::vector<Deposit> want_misses;
        for (int col = from; col < to; ++col) {
          for (int s = 0; s < samples; ++s) {
            RayDescriptor ray;
            switch (layout.Primary(slab, col, row, s, samples, tracer, &ray)) {
              case PrimaryRole::kTrace:
                want_rays.push_back(ray);
                break;
              case PrimaryRole::kMiss:
                want_misses.push_back(
                    tracer.MissDeposit(static_cast<uint32_t>(row) * camera.width() + col));
                break;
              case PrimaryRole::kNone:
                break;
            }
          }
        }
        std::string records;
        const uint64_t misses =
            layout.Primaries(slab, row, from, to, samples, tracer, &got_rays, &records);
        ASSERT_EQ(misses, want_misses.size());
        ASSERT_EQ(got_rays.size(), want_rays.size());
        for (size_t i = 0; i < want_rays.size(); ++i) {
          ASSERT_EQ(got_rays[i].pixel, want_rays[i].pixel);
          ASSERT_EQ(got_rays[i].cell, want_rays[i].cell);
          ASSERT_EQ(got_rays[i].t, want_rays[i].t);
          ASSERT_EQ(got_rays[i].direction.x, want_rays[i].direction.x);
        }
        // The records read back (docs/formats.md, "Deposit"): misses of
        // no spawned ray, and runs of the view's samples a pixel.
        ASSERT_EQ(records.size() % kDepositRecordBytes, 0u);
        for (size_t at = 0; at < records.size(); at += kDepositRecordBytes) {
          const uint8_t kind = static_cast<uint8_t>(records[at + 4]);
          uint16_t field;
          std::memcpy(&field, records.data() + at + 6, 2);
          ASSERT_TRUE(kind == 0 || kind == 2);
          if (kind == 0) {
            ASSERT_EQ(field, 0);
            ++single_misses;
            continue;
          }
          ASSERT_EQ(static_cast<uint8_t>(records[at + 5]), samples);
          ASSERT_GE(field, 1);
          ++run_records;
          run_pixels += field;
        }
        std::vector<Deposit> got_misses = UnpackDepositRecords(records);
        auto key = [](const Deposit& d) {
          return std::make_tuple(d.pixel, d.color[0], d.color[1], d.color[2]);
        };
        auto order = [&](const Deposit& a, const Deposit& b) { return key(a) < key(b); };
        std::sort(want_misses.begin(), want_misses.end(), order);
        std::sort(got_misses.begin(), got_misses.end(), order);
        ASSERT_EQ(got_misses.size(), want_misses.size());
        for (size_t i = 0; i < want_misses.size(); ++i) {
          ASSERT_EQ(key(got_misses[i]), key(want_misses[i]));
          ASSERT_EQ(got_misses[i].kind, RayKind::kPrimary);
        }
      }
    }
  }
  // Runs covered many pixels in few records.
  EXPECT_GT(run_records, 500u);
  EXPECT_GT(run_pixels, 4 * run_records);
  EXPECT_GT(single_misses, 0u);
}

// Camera::Bounds holds every pixel of Camera::Footprint, for random boxes
// seen from random views, boxes behind the eye and around it included.
TEST(RingLayoutTest, BoundsHoldTheFootprint) {
  std::mt19937 rng(29);
  std::uniform_real_distribution<double> unit(0, 1);
  int pixels = 0, outside = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const std::array<double, 3> spacing = {0.5 + unit(rng), 0.5 + unit(rng), 0.5 + 2 * unit(rng)};
    const Camera camera = CameraFor(
        spacing, 20 + static_cast<int>(rng() % 60), 20 + static_cast<int>(rng() % 60),
        360 * unit(rng), 178 * unit(rng) - 89,
        trial % 3 ? Projection::kPerspective : Projection::kOrthographic, 0.3 + 4 * unit(rng));
    Vec3 lo, hi;
    for (int a = 0; a < 3; ++a) {
      const double extent = kDims[a] * spacing[a];
      const double p = (unit(rng) - 0.5) * 1.5 * extent, size = unit(rng) * extent / 3;
      lo[a] = p;
      hi[a] = p + size;
    }
    const ImageSpans spans = camera.Footprint(lo, hi);
    const Camera::PixelRect r = camera.Bounds(lo, hi);
    for (int row = 0; row < camera.height(); ++row) {
      for (int col = 0; col < camera.width(); ++col) {
        if (!spans.Contains(col, row)) {
          ++outside;
          continue;
        }
        ++pixels;
        ASSERT_TRUE(col >= r.x0 && col < r.x1 && row >= r.y0 && row < r.y1)
            << "trial " << trial << ": pixel " << col << "," << row << " of the footprint outside ["
            << r.x0 << ", " << r.x1 << ") x [" << r.y0 << ", " << r.y1 << ")";
      }
    }
  }
  EXPECT_GT(pixels, 10000);
  EXPECT_GT(outside, 10000);
}

// A ray handed on by Route one hop at a time reaches the slab that holds
// its cell, in as many hops as slabs lie between, and never leaves the
// ring; a cell off the volume finishes wherever it is.
TEST(RingLayoutTest, HopsReachTheSlabHoldingTheCell) {
  std::mt19937 rng(5);
  const Camera camera = CameraFor({1, 1, 1}, 8, 8, 0, 0);
  for (int round = 0; round < 500; ++round) {
    const RingLayout layout(RandomCuts(rng, kDims[1]), kDims, {1, 1, 1}, camera);
    for (int from = 0; from < layout.slabs(); ++from) {
      for (int y = 0; y < kDims[1]; ++y) {
        const std::array<int32_t, 3> cell = {static_cast<int32_t>(rng() % kDims[0]), y,
                                             static_cast<int32_t>(rng() % kDims[2])};
        const int owner = layout.SlabOf(y);
        EXPECT_GE(y, layout.y_begin(owner));
        EXPECT_LT(y, layout.y_end(owner));
        if (owner == from) continue;
        int at = from, hops = 0;
        while (at != owner) {
          const Hop hop = layout.Route(at, cell);
          ASSERT_NE(hop, Hop::kFinished);
          ASSERT_EQ(hop, owner < at ? Hop::kLeft : Hop::kRight);
          at = RingLayout::Neighbour(at, hop);
          ASSERT_GE(at, 0);
          ASSERT_LT(at, layout.slabs());
          ++hops;
        }
        EXPECT_EQ(hops, std::abs(owner - from));
      }
      std::array<int32_t, 3> off = {3, 3, 3};
      const int axis = static_cast<int>(rng() % 3);
      off[axis] = (rng() & 1) ? -1 : kDims[axis];
      ASSERT_FALSE(Traversal::Inside(off, kDims));
      EXPECT_EQ(layout.Route(from, off), Hop::kFinished);
    }
  }
}

TEST(RingLayoutDeathTest, InvalidCutsAreAProgrammerError) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const Camera camera = CameraFor({1, 1, 1}, 8, 8, 0, 0);
  EXPECT_DEATH((void)RingLayout({0, 5, 5, 34}, kDims, {1, 1, 1}, camera), "ValidCuts");
  EXPECT_DEATH((void)RingLayout({0, 20}, kDims, {1, 1, 1}, camera), "ValidCuts");
  EXPECT_DEATH((void)RingLayout({0}, kDims, {1, 1, 1}, camera), "cuts_.size\\(\\) >= 2u");
}

}  // namespace
}  // namespace transtick
