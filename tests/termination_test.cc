// Every ray ends: the termination argument of docs/design.md ("Why every ray
// ends") checked over sweeps of hostile geometry. Each walk runs under a cap
// of its own, so a regression fails here instead of hanging the suite.
#include <cmath>
#include <limits>
#include <random>

#include "gtest/gtest.h"
#include "testing.h"
#include "transtick/render.h"
#include "transtick/synthetic.h"
#include "transtick/tracer.h"
#include "transtick/traversal.h"
#include "transtick/volume_io.h"

namespace transtick {
namespace {

constexpr double kDenormal = 4.9406564584124654e-324;

// Blobs of two materials in noise: many material changes, edges and
// corners for rays to run along, and empty bricks between them.
Volume BlobVolume(std::array<int, 3> dims, uint32_t seed) {
  Volume v = MakeRandom(dims, seed, 3);
  Volume ball = MakeSphere(dims, {dims[0] * 0.45, dims[1] * 0.5, dims[2] * 0.55}, dims[0] * 0.35);
  for (size_t i = 0; i < v.values.size(); ++i) {
    if (ball.values[i] == 0) v.values[i] = 0;
  }
  return v;
}

Classification TwoMaterials(SurfaceModel surface = SurfaceModel::kSmooth) {
  Classification c;
  c.surface = surface;
  c.materials = {{.name = "a", .min = 0.5f, .max = 1.5f, .opacity = 0.4f},
                 {.name = "b", .min = 1.5f, .max = 2.5f, .opacity = 0.7f}};
  return c;
}

TransferFunction Ramp() {
  TransferFunction tf;
  tf.points = {{0, {0, 0, 0, 0}}, {1, {0.5f, 0.5f, 1, 0.05f}}, {2, {1, 0.8f, 0.5f, 0.2f}}};
  return tf;
}

// Walks a ray through `scene` with the bare traversal, capped well past
// the bound. Returns the number of segments, or -1 when the cap was hit.
int64_t Walk(const Scene& scene, const Vec3& origin, const Vec3& direction) {
  auto box = IntersectBox(origin, direction, scene.dims());
  if (!box) return 0;
  Traversal trav(scene, origin, direction, CellAt(origin, direction, (*box)[0], scene.dims()),
                 (*box)[0]);
  const int64_t cap = 4 * Traversal::MaxSegments(scene.dims()) + 16;
  int64_t n = 0;
  double last_t = trav.t();
  while (auto seg = trav.Next()) {
    EXPECT_GE(seg->t0, last_t);
    EXPECT_GE(seg->t1, seg->t0);
    last_t = seg->t1;
    if (++n > cap) return -1;
  }
  return n;
}

std::vector<Segment> Segments(const Scene& scene, const Vec3& origin, const Vec3& direction) {
  std::vector<Segment> out;
  auto box = IntersectBox(origin, direction, scene.dims());
  if (!box) return out;
  Traversal trav(scene, origin, direction, CellAt(origin, direction, (*box)[0], scene.dims()),
                 (*box)[0]);
  while (auto seg = trav.Next()) out.push_back(*seg);
  return out;
}

// A component too small to invert moves the ray by nothing measurable: the
// walk is the walk of the ray parallel to that axis, to the end of the box.
TEST(TerminationTest, DenormalComponentsWalkAsParallel) {
  const std::array<int, 3> dims = {40, 37, 45};
  // Voxel surfaces, whose tracer takes this walk (with the brick map's reach).
  auto scene = Scene::ForSurfaces(BlobVolume(dims, 11), TwoMaterials(SurfaceModel::kVoxel));
  ASSERT_TRUE(scene.ok());
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0, 1);
  for (int r = 0; r < 2000; ++r) {
    const int axis = static_cast<int>(rng() % 3);
    Vec3 origin{u(rng) * dims[0], u(rng) * dims[1], u(rng) * dims[2]};
    // On a cell face half the time, where a plane time would be 0 x inf.
    for (int a = 0; a < 3; ++a) {
      if (rng() & 1) origin[a] = std::floor(origin[a]);
    }
    origin[axis] = (rng() & 1) ? -5.0 : dims[axis] + 5.0;
    Vec3 parallel{0, 0, 0};
    parallel[axis] = origin[axis] < 0 ? 1.0 : -1.0;
    Vec3 hostile = parallel;
    hostile[(axis + 1) % 3] = (rng() & 1) ? kDenormal : -kDenormal;
    if (rng() & 1) hostile[(axis + 2) % 3] = kDenormal;
    auto want = Segments(*scene, origin, parallel);
    auto got = Segments(*scene, origin, hostile);
    ASSERT_FALSE(want.empty());
    ASSERT_EQ(got.size(), want.size()) << "ray " << r;
    for (size_t i = 0; i < want.size(); ++i) {
      ASSERT_EQ(got[i].t0, want[i].t0);
      ASSERT_EQ(got[i].t1, want[i].t1);
      ASSERT_EQ(got[i].material, want[i].material);
    }
  }
}

// One component of a hostile direction.
double Component(std::mt19937_64& rng) {
  std::uniform_int_distribution<int> pick(0, 9);
  std::uniform_real_distribution<double> u(-1, 1);
  std::uniform_int_distribution<int> exp10(17, 300);
  const double sign = (rng() & 1) ? 1.0 : -1.0;
  switch (pick(rng)) {
    case 0:
      return 0.0;
    case 1:
      return -0.0;
    case 2:
      return sign;
    case 3:
      return sign * kDenormal;
    case 4:
      return sign * std::pow(10.0, -exp10(rng));
    case 5:
      return sign * 1e-17;
    default:
      return u(rng);
  }
}

// Points on cell corners, edges and faces as often as not: where rounding
// bites.
double Coordinate(std::mt19937_64& rng, int extent) {
  std::uniform_real_distribution<double> u(-0.25 * extent, 1.25 * extent);
  std::uniform_int_distribution<int> cell(0, extent);
  switch (rng() % 3) {
    case 0:
      return cell(rng);
    case 1:
      return cell(rng) + 0.5;
    default:
      return u(rng);
  }
}

TEST(TerminationTest, EveryTraversalEndsWithinTheBound) {
  const std::array<int, 3> dims = {40, 37, 45};
  for (bool dvr : {false, true}) {
    Volume v = BlobVolume(dims, 11);
    // The scenes whose tracer takes this walk, with the brick map's reach.
    auto scene =
        dvr ? Scene::ForDvr(v, Ramp()) : Scene::ForSurfaces(v, TwoMaterials(SurfaceModel::kVoxel));
    ASSERT_TRUE(scene.ok()) << scene.status();
    std::mt19937_64 rng(dvr ? 7 : 5);
    const int64_t bound = Traversal::MaxSegments(dims);
    int64_t walked = 0, max_seen = 0;
    for (int r = 0; r < 200000; ++r) {
      Vec3 origin{Coordinate(rng, dims[0]), Coordinate(rng, dims[1]), Coordinate(rng, dims[2])};
      Vec3 dir{Component(rng), Component(rng), Component(rng)};
      if (dir.x == 0 && dir.y == 0 && dir.z == 0) dir.x = 1;
      const int64_t n = Walk(*scene, origin, dir);
      ASSERT_GE(n, 0) << "ray " << r << " loops: origin (" << origin.x << ", " << origin.y << ", "
                      << origin.z << ") direction (" << dir.x << ", " << dir.y << ", " << dir.z
                      << ")";
      ASSERT_LE(n, bound) << "ray " << r;
      walked += n > 0;
      max_seen = std::max(max_seen, n);
    }
    EXPECT_GT(walked, 50000);
    EXPECT_GT(max_seen, 10);
  }
}

// The views a user can ask for, at their most awkward: exactly along an
// axis (both signs, with -0 components), a hair off it (down to 1e-300),
// the eye inside the volume, orthographic, image sizes up to 2048. Each
// view traces a sample of its pixels with the real tracer; every ray must
// finish below the tracer's bound (counters.truncated stays 0) and every
// walk below the traversal's.
TEST(TerminationTest, TenThousandHostileViewsFinish) {
  const std::array<int, 3> dims = {40, 37, 45};
  Volume v = BlobVolume(dims, 3);
  auto surfaces = Scene::ForSurfaces(v, TwoMaterials());
  auto dvr = Scene::ForDvr(v, Ramp());
  // The bare walk's scene for surfaces: voxel surfaces, whose tracer takes
  // it (smooth surfaces walk the field's cells, CrossingWalk).
  auto voxel = Scene::ForSurfaces(v, TwoMaterials(SurfaceModel::kVoxel));
  ASSERT_TRUE(surfaces.ok() && dvr.ok() && voxel.ok());
  const Vec3 extent{double(dims[0]), double(dims[1]), double(dims[2])};
  std::mt19937_64 rng(2024);
  std::uniform_real_distribution<double> u(-1, 1);
  const int sizes[] = {1, 2, 3, 7, 64, 255, 400, 701, 1024, 2048};
  const double tiny[] = {0, -0.0, 1e-300, -1e-300, 1e-200, 1e-100, 1e-30, 1e-17, 1e-9, 1e-4};
  int views = 0;
  uint64_t rays = 0;
  TraceCounters total;
  for (int i = 0; i < 10000; ++i) {
    CameraSpec spec;
    spec.width = sizes[rng() % 10];
    spec.height = (rng() & 1) ? spec.width : sizes[rng() % 10];
    spec.projection = (rng() & 1) ? Projection::kOrthographic : Projection::kPerspective;
    // A direction along an axis (either sign), then tilted by tiny amounts.
    const int axis = static_cast<int>(rng() % 3);
    Vec3 dir{tiny[rng() % 10], tiny[rng() % 10], tiny[rng() % 10]};
    if (rng() & 1) dir = -dir;
    dir[axis] = (rng() & 1) ? 1.0 : -1.0;
    if (i % 5 == 4) dir = Normalize(Vec3{u(rng), u(rng), u(rng)});
    // The eye outside, or inside the volume (every third view).
    const double back = i % 3 == 0 ? u(rng) * 10 : 80 + 40 * (u(rng) + 1);
    Vec3 target{0, 0, 0};
    if (rng() & 1) {
      // Aim at a voxel corner or face rather than the centre.
      target = Vec3{std::round(u(rng) * 15), std::round(u(rng) * 15), std::round(u(rng) * 15)};
    }
    ExplicitView ev;
    ev.eye = target - dir * back;
    ev.target = target;
    ev.up = axis == 1 ? Vec3{0, 0, 1} : Vec3{0, 1, 0};
    spec.view = ev;
    auto camera = Camera::Create(spec, extent);
    ASSERT_TRUE(camera.ok()) << camera.status() << " view " << i;
    const Scene& scene = i % 4 == 3 ? *dvr : *surfaces;
    RenderSettings settings;
    settings.shadows = rng() & 1;
    const Tracer tracer(scene, settings, *camera);
    // The centre pixel(s), the corners and a few at random.
    std::vector<std::array<int, 2>> pixels = {
        {camera->width() / 2, camera->height() / 2},
        {(camera->width() - 1) / 2, (camera->height() - 1) / 2},
        {0, 0},
        {camera->width() - 1, camera->height() - 1}};
    for (int k = 0; k < 12; ++k) {
      pixels.push_back(
          {static_cast<int>(rng() % camera->width()), static_cast<int>(rng() % camera->height())});
    }
    for (auto [px, py] : pixels) {
      const WorldRay world = camera->Generate(px, py);
      RayDescriptor ray;
      if (!tracer.MakePrimary(world, 0, &ray)) continue;
      ASSERT_TRUE(tracer.Validate(ray).ok()) << tracer.Validate(ray) << " view " << i;
      // The bare walk first: a loop fails here rather than hanging below.
      ASSERT_GE(Walk(i % 4 == 3 ? *dvr : *voxel, ray.origin, ray.direction), 0)
          << "view " << i << " pixel " << px << "," << py;
      std::vector<RayDescriptor> pending = {ray};
      Deposit deposit;
      while (!pending.empty()) {
        RayDescriptor r = pending.back();
        pending.pop_back();
        if (r.kind == RayKind::kShadow) {
          ASSERT_TRUE(tracer.Validate(r).ok() || !Traversal::Inside(r.cell, dims))
              << tracer.Validate(r);
        }
        ASSERT_EQ(tracer.Trace(r, pending, deposit, total), Tracer::Outcome::kFinished);
        ++rays;
      }
    }
    ++views;
  }
  EXPECT_EQ(views, 10000);
  EXPECT_GT(rays, 50000u);
  EXPECT_EQ(total.truncated, 0u);
}

// The case that looped for ever: cthead at azimuth 90, 700x700 (and its
// neighbours, and the other axis-aligned orbits).
TEST(TerminationTest, CtheadAlongTheAxes) {
  const std::string path = testing::DataFile("cthead.nrrd");
  if (path.empty()) GTEST_SKIP() << "cthead.nrrd not present";
  auto volume = ReadVolume(path);
  ASSERT_TRUE(volume.ok()) << volume.status();
  Classification c;
  c.materials = {{.name = "skin", .min = 600, .max = 1350, .opacity = 0.3f},
                 {.name = "bone", .min = 1350, .max = 4000, .opacity = 1.0f}};
  auto scene = Scene::ForSurfaces(*volume, c);
  ASSERT_TRUE(scene.ok()) << scene.status();
  // The bare walk's scene: voxel surfaces, whose tracer takes it.
  c.surface = SurfaceModel::kVoxel;
  auto voxel = Scene::ForSurfaces(*volume, c);
  ASSERT_TRUE(voxel.ok()) << voxel.status();
  const Vec3 extent{volume->dims[0] * volume->spacing[0], volume->dims[1] * volume->spacing[1],
                    volume->dims[2] * volume->spacing[2]};
  for (double az : {90.0, 0.0, 180.0, 270.0}) {
    for (double el : {0.0, 90.0}) {
      CameraSpec spec;
      spec.width = spec.height = 700;
      spec.azimuth_deg = az;
      spec.elevation_deg = el;
      auto camera = Camera::Create(spec, extent);
      ASSERT_TRUE(camera.ok());
      const Tracer tracer(*scene, RenderSettings{}, *camera);
      // Every pixel's primary walk, capped; then the whole frame.
      for (int py = 0; py < 700; ++py) {
        for (int px = 0; px < 700; ++px) {
          RayDescriptor ray;
          if (!tracer.MakePrimary(camera->Generate(px, py), 0, &ray)) continue;
          ASSERT_GE(Walk(*voxel, ray.origin, ray.direction), 0)
              << "azimuth " << az << " elevation " << el << " pixel " << px << "," << py;
        }
      }
      RenderStats stats;
      auto image = RenderLocal(*scene, *camera, RenderSettings{}, 2, &stats);
      ASSERT_TRUE(image.ok());
      EXPECT_EQ(stats.counters.truncated, 0u);
    }
  }
}

TEST(TerminationTest, DvrStepAndFrameBudgetAreBounded) {
  const std::array<int, 3> dims = {40, 37, 45};
  const std::array<double, 3> spacing = {1, 1, 2};
  RenderSettings s;
  s.step = 1e-9;
  absl::Status st = CheckRenderSettings(s, RenderMode::kDvr, dims, spacing, 400 * 400);
  EXPECT_FALSE(st.ok());
  EXPECT_NE(st.message().find("finer than the finest allowed"), std::string::npos) << st;
  s.step = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(CheckRenderSettings(s, RenderMode::kDvr, dims, spacing, 100).ok());
  s.step = 1.0 / kMaxSamplesPerVoxel;
  EXPECT_TRUE(CheckRenderSettings(s, RenderMode::kDvr, dims, spacing, 400 * 400).ok());
  // Surfaces take no samples: the step does not matter there.
  s.step = 1e-9;
  EXPECT_TRUE(CheckRenderSettings(s, RenderMode::kSurfaces, dims, spacing, 100).ok());
  // The frame's budget: the finest step on a large image of a large volume.
  s.step = 1.0 / kMaxSamplesPerVoxel;
  st = CheckRenderSettings(s, RenderMode::kDvr, {1024, 1024, 1024}, {1, 1, 1}, 8192LL * 8192);
  EXPECT_FALSE(st.ok());
  EXPECT_NE(st.message().find("samples"), std::string::npos) << st;

  // A tracer given a step below the bound anyway (no check) raises it, so
  // each ray's samples stay bounded; RenderLocal refuses it outright.
  Volume v = BlobVolume(dims, 1);
  auto scene = Scene::ForDvr(v, Ramp());
  ASSERT_TRUE(scene.ok());
  Camera camera = testing::MakeCamera(dims, 16, 30, 20);
  s.step = 1e-9;
  const Tracer tracer(*scene, s, camera);
  EXPECT_GE(tracer.step(), 1.0 / kMaxSamplesPerVoxel);
  RenderStats stats;
  auto image = RenderLocal(*scene, camera, s, 1, &stats);
  ASSERT_FALSE(image.ok());
  EXPECT_NE(image.status().message().find("step"), std::string::npos);
}

// Descriptors from elsewhere are checked before any tracer sees them: the
// ones a tracer makes pass (also checked for every hand-over in
// testing::RenderSlabs), and each kind of damage is refused by name.
TEST(TerminationTest, ValidateRefusesHostileDescriptors) {
  const std::array<int, 3> dims = {40, 37, 45};
  Volume v = BlobVolume(dims, 4);
  v.spacing = {1, 1, 2};
  for (bool dvr : {false, true}) {
    auto scene = dvr ? Scene::ForDvr(v, Ramp()) : Scene::ForSurfaces(v, TwoMaterials());
    ASSERT_TRUE(scene.ok());
    CameraSpec spec;
    spec.width = spec.height = 32;
    spec.azimuth_deg = 30;
    spec.elevation_deg = 20;
    auto camera = Camera::Create(spec, Vec3{40, 37, 90});
    ASSERT_TRUE(camera.ok());
    const Tracer tracer(*scene, RenderSettings{}, *camera);
    RayDescriptor good;
    int made = 0;
    for (int p = 0; p < 32 * 32; ++p) {
      RayDescriptor r;
      if (!tracer.MakePrimary(camera->Generate(p % 32, p / 32), p, &r)) continue;
      ASSERT_TRUE(tracer.Validate(r).ok()) << tracer.Validate(r);
      good = r;
      ++made;
    }
    ASSERT_GT(made, 100);
    auto refused = [&](auto damage, const char* words) {
      RayDescriptor r = good;
      damage(r);
      absl::Status s = tracer.Validate(r);
      EXPECT_FALSE(s.ok()) << words;
      EXPECT_NE(s.message().find(words), std::string::npos) << s;
    };
    refused([](RayDescriptor& r) { r.direction = {kDenormal, kDenormal, kDenormal}; }, "length");
    refused([](RayDescriptor& r) { r.direction = r.direction * 2.0; }, "length");
    refused([](RayDescriptor& r) { r.direction = {0, 0, 0}; }, "length");
    refused([](RayDescriptor& r) { r.t = std::nan(""); }, "non-finite");
    refused([](RayDescriptor& r) { r.origin.x = INFINITY; }, "non-finite");
    refused([](RayDescriptor& r) { r.color[1] = std::nan(""); }, "non-finite");
    refused([](RayDescriptor& r) { r.cell = {-1, 3, 3}; }, "outside");
    refused([](RayDescriptor& r) { r.cell = {3, 3, 45}; }, "outside");
    refused([](RayDescriptor& r) { r.cell[0] = r.cell[0] > 10 ? 0 : 39; }, "not where the ray is");
    refused([](RayDescriptor& r) { r.t_start = r.t + 1; }, "one pass");
    refused([](RayDescriptor& r) { r.t_start = -1e300; }, "further than");
    refused([](RayDescriptor& r) { r.t_start = r.t - 1e6; }, "one pass");
    refused(
        [](RayDescriptor& r) {
          r.origin = r.origin + r.direction * -1e12;
          r.t += 1e12;
          r.t_start += 1e12;
        },
        "further than");
    refused([](RayDescriptor& r) { r.transmittance = 2; }, "transmittance");
    refused([](RayDescriptor& r) { r.kind = static_cast<RayKind>(9); }, "kind");
    if (dvr) {
      refused([](RayDescriptor& r) { r.sample = 4000000000u; }, "sample index");
      refused([](RayDescriptor& r) { r.band = 0; }, "without smooth surfaces");
      // A dvr scene has no materials: tracing a shadow ray there read
      // materials[m - 1] of an empty list (found by batch_fuzzer).
      refused([](RayDescriptor& r) { r.kind = RayKind::kShadow; }, "shadow ray");
    } else {
      refused([](RayDescriptor& r) { r.material = 3; }, "material");
      // Edges 0.5, 1.5 and 2.5: four bands, 0-3.
      refused([](RayDescriptor& r) { r.band = 4; }, "band 4 of 4");
      RayDescriptor banded = good;
      banded.band = 3;
      EXPECT_TRUE(tracer.Validate(banded).ok()) << tracer.Validate(banded);
      RayDescriptor shadow = good;
      shadow.kind = RayKind::kShadow;
      EXPECT_TRUE(tracer.Validate(shadow).ok()) << tracer.Validate(shadow);
      RenderSettings no_shadows;
      no_shadows.shadows = false;
      absl::Status s = Tracer(*scene, no_shadows, *camera).Validate(shadow);
      EXPECT_NE(s.message().find("shadows off"), std::string::npos) << s;
    }
  }
}

// An eye far from the volume in index space, from an explicit view or from a
// tiny spacing, gave primary rays whose origin and t Validate refuses as too
// far: on a ring every ray handed on was dropped and the frame aborted
// (found by job_fuzzer and volume_fuzzer). Such rays start at their entry
// now; every hand-off is accepted (RenderSlabs checks) and the ring's image
// is the single scene's.
TEST(TerminationTest, FarEyesMakeRaysANeighbourAccepts) {
  const std::array<int, 3> dims = {24, 20, 16};
  for (int c = 0; c < 2; ++c) {
    Volume v = BlobVolume(dims, 5);
    CameraSpec spec;
    spec.width = spec.height = 16;
    if (c == 0) {
      spec.projection = Projection::kOrthographic;
      spec.view = ExplicitView{.eye = {4e10, 10, -60}, .target = {0, 0, 0}};
    } else {
      v.spacing = {1e-9, 1, 1};
      spec.azimuth_deg = 30;
      spec.elevation_deg = 10;
    }
    auto scene = Scene::ForSurfaces(v, TwoMaterials());
    ASSERT_TRUE(scene.ok());
    const Vec3 extent{dims[0] * v.spacing[0], dims[1] * v.spacing[1], dims[2] * v.spacing[2]};
    auto camera = Camera::Create(spec, extent);
    ASSERT_TRUE(camera.ok()) << camera.status();
    const Tracer tracer(*scene, RenderSettings{}, *camera);
    int made = 0;
    for (int p = 0; p < 16 * 16; ++p) {
      RayDescriptor ray;
      if (!tracer.MakePrimary(camera->Generate(p % 16, p / 16), p, &ray)) continue;
      ASSERT_TRUE(tracer.Validate(ray).ok()) << tracer.Validate(ray) << " case " << c;
      ++made;
    }
    EXPECT_GT(made, 20) << "case " << c;
    const Image ring = testing::RenderSlabs(*scene, {7, 13}, *camera, RenderSettings{});
    EXPECT_EQ(ring.rgb, testing::RenderWhole(*scene, *camera, RenderSettings{}).rgb)
        << "case " << c;
  }
}

// A file may give spacings many orders of magnitude apart; the tracer's
// per-ray bound on dvr samples then overflowed int64 (undefined, and
// negative on x86, so every dvr ray was truncated at once; found by
// volume_fuzzer). It is capped at the frame's budget instead. Spacings so
// far apart that a ray cannot be placed within a voxel (1e-20 x 1 x 1e6)
// are refused by the scene since; these are as far apart as it accepts.
TEST(TerminationTest, BoundsStayPositiveForSpacingsFarApart) {
  const std::array<int, 3> dims = {12, 10, 8};
  Volume v = BlobVolume(dims, 2);
  v.spacing = {1e-20, 1, 1e6};
  EXPECT_FALSE(Scene::ForSurfaces(v, TwoMaterials()).ok());
  v.spacing = {1e-6, 1, 1e4};
  for (bool dvr : {false, true}) {
    auto scene = dvr ? Scene::ForDvr(v, Ramp()) : Scene::ForSurfaces(v, TwoMaterials());
    ASSERT_TRUE(scene.ok()) << scene.status();
    CameraSpec spec;
    spec.width = spec.height = 8;
    auto camera = Camera::Create(spec, Vec3{12e-6, 10, 8e4});
    ASSERT_TRUE(camera.ok()) << camera.status();
    const Tracer tracer(*scene, RenderSettings{}, *camera);
    EXPECT_GT(tracer.max_samples(), 0);
    EXPECT_LE(tracer.max_samples(), kMaxFrameSamples + 2 + tracer.max_segments());
    EXPECT_EQ(tracer.max_segments(), Traversal::MaxSegments(dims) + 1);
  }
}

}  // namespace
}  // namespace transtick
