// Known answers of the renderer: a sphere's silhouette and shading, the
// transmittance of semi-transparent slabs, the shadow a sphere casts.
#include "transtick/render.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include "gtest/gtest.h"
#include "testing.h"
#include "transtick/synthetic.h"
#include "transtick/tracer.h"

namespace transtick {
namespace {

using testing::MakeCamera;
using testing::RenderWhole;

float Pixel(const Image& img, int x, int y, int c = 0) {
  return img.rgb[(static_cast<size_t>(y) * img.width + x) * 3 + c];
}

Material Opaque(const std::string& name, float lo, float hi, float grey = 0.5f) {
  return Material{.name = name, .min = lo, .max = hi, .color = {grey, grey, grey}, .opacity = 1};
}

TEST(RenderTest, OpaqueSphereSilhouette) {
  std::array<int, 3> dims = {64, 64, 64};
  const double r = 20;
  Volume v = MakeSphere(dims, {32, 32, 32}, r);
  Classification c;
  c.materials = {Opaque("ball", 50, 150)};
  Scene scene = *Scene::ForSurfaces(v, c);
  for (double az : {0.0, 30.0, 90.0}) {
    Camera cam = MakeCamera(dims, 200, az, 10, Projection::kOrthographic);
    Image img = RenderWhole(scene, cam, RenderSettings{});
    // Pixel size: the orthographic view spans the bounding sphere + 5%.
    const double half = 0.5 * std::sqrt(3.0) * 64 * 1.05;
    const double pixel = 2 * half / 200;
    int covered = 0;
    for (int y = 0; y < 200; ++y)
      for (int x = 0; x < 200; ++x) covered += Pixel(img, x, y) > 0;
    const double expected = std::numbers::pi * r * r / (pixel * pixel);
    // Surfaces are voxel-exact: seen obliquely, voxel corners stand out of
    // the sphere by up to half a voxel, about 5% of the area at r = 20.
    EXPECT_NEAR(covered / expected, 1.0, az == 0 ? 0.03 : 0.06) << "azimuth " << az;
    // The silhouette is centred.
    EXPECT_GT(Pixel(img, 100, 100), 0);
    EXPECT_EQ(Pixel(img, 100, 100 - static_cast<int>(r / pixel) - 3), 0);
  }
}

TEST(RenderTest, SphereShadingFollowsLambert) {
  std::array<int, 3> dims = {64, 64, 64};
  Volume v = MakeSphere(dims, {32, 32, 32}, 24);
  Classification c;
  c.materials = {Opaque("ball", 50, 150)};
  Scene scene = *Scene::ForSurfaces(v, c);
  Camera cam = MakeCamera(dims, 201, 0, 0, Projection::kOrthographic);
  RenderSettings settings;
  settings.light = {0, 0, 1};  // from the viewer
  Image img = RenderWhole(scene, cam, settings);
  const Material& m = c.materials[0];
  // Facing the viewer: ambient + diffuse + full specular highlight.
  const float centre = m.ambient * 0.5f + m.diffuse * 0.5f + m.specular;
  EXPECT_NEAR(Pixel(img, 100, 100), centre, 0.03);
  // Along a radius the brightness follows cos(theta) (within voxel noise).
  const double half = 0.5 * std::sqrt(3.0) * 64 * 1.05, pixel = 2 * half / 201;
  for (double s : {0.5, 0.7, 0.85}) {
    int x = 100 + static_cast<int>(std::lround(s * 24 / pixel));
    const double cos_theta = std::sqrt(1 - s * s);
    const double expected = m.ambient * 0.5 + m.diffuse * 0.5 * cos_theta;  // specular ~0 here
    EXPECT_NEAR(Pixel(img, x, 100), expected, 0.06) << "at " << s << " of the radius";
  }
  // Shadow rays from a convex body lit from the viewer find nothing.
  settings.shadows = false;
  Image no_shadows = RenderWhole(scene, cam, settings);
  for (size_t i = 0; i < img.rgb.size(); ++i) ASSERT_NEAR(img.rgb[i], no_shadows.rgb[i], 1e-6);
}

// Black, unlit material: a surface only takes away light from behind.
Material Filter(const std::string& name, float lo, float hi, float opacity) {
  return Material{.name = name,
                  .min = lo,
                  .max = hi,
                  .color = {0, 0, 0},
                  .opacity = opacity,
                  .ambient = 0,
                  .diffuse = 0,
                  .specular = 0};
}

TEST(RenderTest, SemiTransparentSlabsTransmit) {
  std::array<int, 3> dims = {32, 32, 40};
  Volume one = MakeSlab(dims, 2, 10, 20);
  Volume two = MakeSlab(dims, 2, 5, 10);
  Volume second = MakeSlab(dims, 2, 25, 30);
  for (size_t i = 0; i < two.values.size(); ++i) two.values[i] += second.values[i];
  Classification c;
  c.materials = {Filter("glass", 50, 150, 0.4f)};
  RenderSettings settings;
  settings.background = {1, 1, 1};
  Camera cam = MakeCamera(dims, 64, 0, 0, Projection::kOrthographic);
  Image a = RenderWhole(*Scene::ForSurfaces(one, c), cam, settings);
  Image b = RenderWhole(*Scene::ForSurfaces(two, c), cam, settings);
  EXPECT_NEAR(Pixel(a, 32, 32), 0.6f, 1e-6);
  EXPECT_NEAR(Pixel(b, 32, 32), 0.36f, 1e-6);
  // Rays that miss the volume see the background.
  EXPECT_EQ(Pixel(a, 0, 0), 1.0f);
  // Seen at 60 degrees the slab is still crossed once: one surface, one
  // attenuation (the paper's threshold surfaces, not a path length).
  Image tilted = RenderWhole(*Scene::ForSurfaces(one, c), MakeCamera(dims, 64, 60, 0), settings);
  EXPECT_NEAR(Pixel(tilted, 32, 32), 0.6f, 1e-6);
}

TEST(RenderTest, DvrSlabTransmittanceFollowsDepth) {
  std::array<int, 3> dims = {32, 32, 48};
  Volume v = MakeSlab(dims, 2, 14, 34);  // 20 voxels deep
  TransferFunction tf;
  tf.points = {
      {0, {0, 0, 0, 0}}, {60, {0, 0, 0, 0}}, {90, {0, 0, 0, 0.1f}}, {100, {0, 0, 0, 0.1f}}};
  tf.shading = false;
  RenderSettings settings;
  settings.background = {1, 1, 1};
  Scene scene = *Scene::ForDvr(v, tf);
  Image img = RenderWhole(scene, MakeCamera(dims, 64, 0, 0, Projection::kOrthographic), settings);
  const float t = Pixel(img, 32, 32);
  // 20 voxels of alpha 0.1 per voxel, give or take the soft faces.
  EXPECT_GT(t, std::pow(0.9f, 21.0f));
  EXPECT_LT(t, std::pow(0.9f, 19.0f));
  // Halving the step changes little: opacity is corrected for it.
  settings.step = 0.25;
  Image fine = RenderWhole(scene, MakeCamera(dims, 64, 0, 0, Projection::kOrthographic), settings);
  EXPECT_NEAR(Pixel(fine, 32, 32), t, 0.01);
}

TEST(RenderTest, SphereCastsShadowOnFloor) {
  std::array<int, 3> dims = {96, 64, 96};
  // A floor plate y in [0, 6) and a ball above it.
  Volume v = MakeSlab(dims, 1, 0, 6, 100);
  const Vec3 centre{48, 30, 48};
  const double r = 12;
  Volume ball = MakeSphere(dims, {centre.x, centre.y, centre.z}, r, 200);
  for (size_t i = 0; i < v.values.size(); ++i) v.values[i] += ball.values[i];
  Classification c;
  c.materials = {Opaque("floor", 50, 150, 0.8f), Opaque("ball", 150, 350, 0.8f)};
  Scene scene = *Scene::ForSurfaces(v, c);
  Camera cam = MakeCamera(dims, 160, 0, 90, Projection::kOrthographic);  // from above
  RenderSettings settings;
  settings.light = {1, 0, 1};  // 45 degrees from straight up, toward the camera's right
  Image img = RenderWhole(scene, cam, settings);
  const Vec3 light = Normalize(cam.right() * 1.0 - cam.forward() * 1.0);
  const Vec3 half{dims[0] / 2.0, dims[1] / 2.0, dims[2] / 2.0};
  int agree = 0, judged = 0, shadowed = 0;
  for (int y = 0; y < 160; ++y) {
    for (int x = 0; x < 160; ++x) {
      WorldRay w = cam.Generate(x, y);
      Vec3 o = w.origin + half;
      // Where the pixel's ray meets the floor's top (y = 6), if it misses the ball.
      double t = (6 - o.y) / w.direction.y;
      Vec3 p = o + w.direction * t;
      if (p.x < 2 || p.z < 2 || p.x > dims[0] - 2 || p.z > dims[2] - 2) continue;
      Vec3 oc = o - centre;
      double bq = Dot(oc, w.direction), cq = Dot(oc, oc) - (r + 2) * (r + 2);
      if (bq * bq - cq > 0) continue;  // the ball (or its rim) is in front
      // Distance from the ball's centre to the shadow ray from p.
      Vec3 pc = centre - p;
      double along = Dot(pc, light);
      double miss = Length(pc - light * along);
      if (std::fabs(miss - r) < 2.0) continue;  // the penumbra of voxels
      bool in_shadow = along > 0 && miss < r;
      bool dark = Pixel(img, x, y) < 0.8f * (0.25f + 0.35f);  // ambient + half of lit diffuse
      ++judged;
      agree += in_shadow == dark;
      shadowed += in_shadow;
    }
  }
  EXPECT_GT(shadowed, 200);
  EXPECT_GT(judged, 5000);
  EXPECT_GE(agree, judged * 0.99);
  // Without shadow rays no floor pixel is dark.
  settings.shadows = false;
  Image lit = RenderWhole(scene, cam, settings);
  // (The floor spans image columns 32..128; the shadow falls left of the ball.)
  float darkest = 1;
  for (int y = 40; y < 120; ++y) darkest = std::min(darkest, Pixel(lit, 120, y));
  EXPECT_GT(darkest, 0.3f);
}

// A volume of an analytic field f (float samples at voxel centres) with
// one opaque material where f >= 0.
Scene FieldScene(std::array<int, 3> dims, double (*f)(const Vec3&), SurfaceModel model) {
  Volume v;
  v.dims = dims;
  v.values.resize(v.VoxelCount());
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x)
        v.values[v.Index(x, y, z)] = static_cast<float>(f(Vec3{x + 0.5, y + 0.5, z + 0.5}));
  Classification c;
  c.materials = {Opaque("m", 0, 1e6f, 0.8f)};
  c.surface = model;
  return *Scene::ForSurfaces(v, c);
}

// How two images of one view differ: the largest difference of a channel,
// and the fraction of pixels lit in `b` that differ by more than 0.01.
struct Difference {
  double worst = 0, fraction = 0;
};
Difference Compare(const Image& a, const Image& b) {
  Difference d;
  size_t lit = 0, differ = 0;
  for (size_t p = 0; p * 3 < a.rgb.size(); ++p) {
    double most = 0;
    for (int c = 0; c < 3; ++c) {
      most = std::max(most, double{std::fabs(a.rgb[p * 3 + c] - b.rgb[p * 3 + c])});
    }
    d.worst = std::max(d.worst, most);
    if (b.rgb[p * 3] > 0) {
      ++lit;
      differ += most > 0.01;
    }
  }
  d.fraction = lit ? static_cast<double>(differ) / lit : 0;
  return d;
}

// A convex body cannot shadow itself where it is lit, so with smooth
// surfaces shadow rays change almost no pixel of a sphere: no acne, no
// stripes, from any view. The paper's voxel faces do shadow themselves (their
// shadow rays start 1.5 voxels out, past a staircase), which shows the test
// can fail.
TEST(RenderTest, SmoothSurfacesDoNotShadowThemselves) {
  auto sphere = [](const Vec3& p) { return 13 - Length(p - Vec3{20, 20, 20}); };
  const Scene smooth = FieldScene({40, 40, 40}, sphere, SurfaceModel::kSmooth);
  const Scene voxel = FieldScene({40, 40, 40}, sphere, SurfaceModel::kVoxel);
  double voxel_fraction = 0;
  for (auto [azimuth, elevation] : {std::pair{0.0, 0.0}, {37.0, 21.0}, {130.0, -50.0}}) {
    Camera cam = MakeCamera({40, 40, 40}, 96, azimuth, elevation);
    RenderSettings on, off;
    off.shadows = false;
    // At the terminator a shadow ray grazes the surface, and the trilinear
    // sphere is convex only to within its cells: a pixel or two there
    // differ by about 1% of full scale (measured 0.0127 at most, 0.11% of
    // the lit pixels). The voxel model: 0.14-0.24, 0.9-2.3%.
    const Difference d = Compare(RenderWhole(smooth, cam, on), RenderWhole(smooth, cam, off));
    EXPECT_LT(d.worst, 0.03) << "azimuth " << azimuth;
    EXPECT_LT(d.fraction, 0.003) << "azimuth " << azimuth;
    const Difference v = Compare(RenderWhole(voxel, cam, on), RenderWhole(voxel, cam, off));
    voxel_fraction = std::max(voxel_fraction, v.fraction);
    EXPECT_GT(v.worst, 0.1) << "azimuth " << azimuth;
  }
  EXPECT_GT(voxel_fraction, 0.005);
}

// A hostile record can start a smooth ray a cell past its slab's plane
// (Validate allows a cell of rounding between a ray's cell and its point).
// The point it is shaded at, where its shadow ray starts and its gradient
// is read, stays within a quarter voxel of the slab, so only stored planes
// are read. It was clamped into the field's cell past the slab, and its
// gradient read a plane past the slab's ghosts (found by batch_fuzzer).
TEST(RenderTest, ASmoothHitPastTheSlabsPlaneIsShadedInTheSlab) {
  // A ramp along y inside the material from y = 4 on: every point the rays
  // start at is in it, with a gradient to light.
  const Scene whole = FieldScene(
      {32, 32, 32}, [](const Vec3& p) { return p.y - 4; }, SurfaceModel::kSmooth);
  constexpr int kBegin = 8, kEnd = 16;
  const Scene slab = whole.Slab(kBegin, kEnd);
  const Camera cam = MakeCamera({32, 32, 32}, 24, 30, 20);
  const Tracer tracer(slab, RenderSettings{}, cam);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(-1, 1), past(0.0, 0.999);
  int shaded = 0;
  for (int i = 0; i < 2000; ++i) {
    // The record's cell is the slab's last plane (or its first), and its
    // point up to a cell past the plane.
    const bool above = i % 2 == 0;
    const Vec3 point{16 + 8 * unit(rng), above ? kEnd + past(rng) : kBegin - past(rng),
                     16 + 8 * unit(rng)};
    const Vec3 d = Normalize(Vec3{unit(rng), unit(rng), unit(rng)});
    RayDescriptor ray;
    ray.direction = d;
    ray.t = 50;
    ray.t_start = 40;
    ray.origin = point - d * ray.t;
    ray.cell = {static_cast<int32_t>(point.x), above ? kEnd - 1 : kBegin,
                static_cast<int32_t>(point.z)};
    ray.kind = RayKind::kPrimary;
    if (!tracer.Validate(ray).ok()) continue;
    std::vector<RayDescriptor> spawned;
    Deposit deposit;
    TraceCounters counters;
    tracer.Trace(ray, spawned, deposit, counters);
    for (const RayDescriptor& s : spawned) {
      ++shaded;
      ASSERT_GE(s.origin.y, kBegin - 0.25) << "point " << point.y;
      ASSERT_LE(s.origin.y, kEnd + 0.25) << "point " << point.y;
    }
  }
  EXPECT_GT(shaded, 200);  // the records were taken and shaded
}

// A wall 0.7 voxel thick (thinner than a voxel, so its field crosses the
// threshold twice within one or two cells) between the light and a back
// wall: the shadow ray meets both roots and the light does not leak.
TEST(RenderTest, AThinWallBlocksTheLight) {
  auto field = [](const Vec3& p) {
    const double back = 8 - p.z;                     // the back wall, z < 8
    const double plate = 0.35 - std::fabs(p.x - 20.5);  // x in [20.15, 20.85]
    return std::max(back, p.z < 24 ? plate : -1.0);
  };
  const std::array<int, 3> dims = {40, 40, 40};
  const Scene scene = FieldScene(dims, field, SurfaceModel::kSmooth);
  Camera cam = MakeCamera(dims, 80, 0, 0, Projection::kOrthographic);  // along -z
  RenderSettings on, off;
  on.light = off.light = {1, 0, 1};  // from the right, toward the viewer
  off.shadows = false;
  const Image lit = RenderWhole(scene, cam, off), shaded = RenderWhole(scene, cam, on);
  const Vec3 half{dims[0] / 2.0, dims[1] / 2.0, dims[2] / 2.0};
  int dark = 0, bright = 0;
  for (int y = 20; y < 60; ++y) {
    for (int x = 0; x < 80; ++x) {
      // Where the pixel's ray meets the back wall, and whether the way to
      // the light from there passes the plate (which reaches z = 24).
      const double wx = (cam.Generate(x, y).origin + half).x;
      if (wx > 10 && wx < 18) {  // behind the plate from the light
        EXPECT_LT(Pixel(shaded, x, y), 0.5f * Pixel(lit, x, y)) << x << "," << y;
        ++dark;
      } else if (wx > 22 && wx < 38) {  // in the light
        EXPECT_NEAR(Pixel(shaded, x, y), Pixel(lit, x, y), 1e-5) << x << "," << y;
        ++bright;
      }
    }
  }
  EXPECT_GT(dark, 300);
  EXPECT_GT(bright, 300);
}

TEST(RenderTest, ThreadCountDoesNotChangeTheImage) {
  std::array<int, 3> dims = {48, 40, 36};
  Volume v = MakeNoisyPhantom(dims, 9);
  auto range = v.Range();
  Classification c;
  c.materials = {Material{.name = "soft",
                          .min = range[1] * 0.3f,
                          .max = range[1] * 0.6f,
                          .color = {0.9f, 0.6f, 0.5f},
                          .opacity = 0.3f},
                 Opaque("hard", range[1] * 0.6f, range[1] + 1)};
  Scene scene = *Scene::ForSurfaces(v, c);
  Camera cam = MakeCamera(dims, 96, 37, 20);
  Image one = RenderWhole(scene, cam, RenderSettings{}, 1);
  Image three = RenderWhole(scene, cam, RenderSettings{}, 3);
  EXPECT_EQ(one.rgb, three.rgb);
}

// A float volume may hold values near +-FLT_MAX, infinities and NaN (found
// by volume_fuzzer): the dvr table spanned hi - lo, which overflowed to
// infinity and made the table NaN, so every deposit was NaN and the display
// refused them; NaN samples reached an undefined float-to-int conversion.
TEST(RenderTest, DvrOfExtremeValuesGivesAFiniteImage) {
  std::array<int, 3> dims = {12, 10, 8};
  Volume v = MakeNoisyPhantom(dims, 3);
  for (size_t i = 0; i < v.values.size(); i += 7) v.values[i] = 3e38f;
  for (size_t i = 3; i < v.values.size(); i += 11) v.values[i] = -3e38f;
  v.values[5] = INFINITY;
  v.values[6] = -INFINITY;
  v.values[9] = NAN;
  EXPECT_EQ(v.Range(), (std::array<float, 2>{-3e38f, 3e38f}));
  TransferFunction tf;
  tf.points = {{-3e38f, {0, 0, 0, 0}}, {0, {0.2f, 0.4f, 0.6f, 0.3f}}, {3e38f, {1, 1, 1, 0.9f}}};
  auto scene = Scene::ForDvr(v, tf);
  ASSERT_TRUE(scene.ok()) << scene.status();
  const Camera cam = MakeCamera(dims, 24, 30, 20);
  const Tracer tracer(*scene, RenderSettings{}, cam);
  int traced = 0;
  for (int py = 0; py < 24; ++py) {
    for (int px = 0; px < 24; ++px) {
      RayDescriptor ray;
      if (!tracer.MakePrimary(cam.Generate(px, py), 0, &ray)) continue;
      std::vector<RayDescriptor> spawned;
      Deposit deposit;
      TraceCounters counters;
      ASSERT_EQ(tracer.Trace(ray, spawned, deposit, counters), Tracer::Outcome::kFinished);
      // What the display's decoder accepts.
      for (float c : deposit.color) ASSERT_TRUE(std::isfinite(c)) << px << "," << py;
      ++traced;
    }
  }
  EXPECT_GT(traced, 100);
}

// Gradient reads most points' 4^3 voxels with vector instructions, four
// corners at a time; PortableGradient one voxel at a time. They must give the
// same bits, or nodes built for different processors would shade apart: at
// random points of whole volumes and of slabs (whose last planes take the
// clamped path), on random spacings, over values from noise to extremes.
TEST(RenderTest, VectorGradientEqualsPortableBitForBit) {
  std::mt19937 rng(20261205);
  std::uniform_real_distribution<double> unit(0, 1);
  const std::array<int, 3> dims = {23, 19, 17};
  int compared = 0;
  for (int volume = 0; volume < 8; ++volume) {
    Volume v;
    v.dims = dims;
    for (double& s : v.spacing) s = 0.2 + 3 * unit(rng);
    v.values.resize(v.VoxelCount());
    for (float& x : v.values) {
      switch (volume % 4) {
        case 0:
          x = static_cast<float>(1000 * unit(rng));
          break;  // noise
        case 1:
          x = static_cast<float>(
              std::ldexp(unit(rng) - 0.5, static_cast<int>(unit(rng) * 200) - 100));
          break;
        case 2:
          x = unit(rng) < 0.5 ? 0.0f : -0.0f;
          break;  // signed zeros
        default:
          x = static_cast<float>((unit(rng) - 0.5) * 6e38);
          break;  // near FLT_MAX: differences overflow
      }
    }
    Classification c;
    c.materials = {Opaque("any", -1e30f, 1e30f)};
    const Scene whole = *Scene::ForSurfaces(v, c);
    const int cut = 1 + static_cast<int>(unit(rng) * (dims[1] - 2));
    const Scene slabs[] = {whole.Slab(0, cut), whole.Slab(cut, dims[1])};
    const Camera cam = MakeCamera(dims, 8, 30, 10);
    for (const Scene* scene : {&whole, &slabs[0], &slabs[1]}) {
      const Tracer tracer(*scene, RenderSettings{}, cam);
      for (int i = 0; i < 3000; ++i) {
        // A shading point lies in the scene's planes, as HitPoint keeps it.
        const Vec3 p{unit(rng) * dims[0],
                     scene->y_begin() + unit(rng) * (scene->y_end() - scene->y_begin()),
                     unit(rng) * dims[2]};
        const Vec3f a = tracer.Gradient(p), b = tracer.PortableGradient(p);
        for (int k = 0; k < 3; ++k) {
          if (std::isnan(a[k]) || std::isnan(b[k])) {
            EXPECT_TRUE(std::isnan(a[k]) && std::isnan(b[k]))
                << "volume " << volume << " point " << i;
          } else {
            EXPECT_EQ(std::bit_cast<uint32_t>(a[k]), std::bit_cast<uint32_t>(b[k]))
                << "volume " << volume << " point " << i << " axis " << k << ": " << a[k]
                << " against " << b[k];
          }
        }
        ++compared;
      }
    }
  }
  EXPECT_EQ(compared, 8 * 3 * 3000);
}

// Transfer function points more than FLT_MAX apart: the interpolation
// weight was (value - a) / (b - a) in float, inf / inf near the top, so
// the dvr table and every deposit were NaN (found by volume_fuzzer).
TEST(RenderTest, TransferFunctionPointsFarApartInterpolate) {
  TransferFunction tf;
  tf.points = {{-3e38f, {0, 0, 0, 0}}, {3.1e38f, {1, 1, 1, 1}}};
  ASSERT_TRUE(tf.Validate().ok());
  for (float v : {-3e38f, -1e38f, 0.0f, 2e38f, 3.09e38f, 3.1e38f}) {
    for (float c : tf.Evaluate(v)) {
      EXPECT_TRUE(c >= 0 && c <= 1) << v;
    }
  }
  EXPECT_NEAR(tf.Evaluate(0)[3], 3e38 / 6.1e38, 1e-6);
}

TEST(CameraTest, FrontalViewLooksAlongMinusZ) {
  auto cam = Camera::Create(CameraSpec{}, Vec3{100, 100, 100});
  ASSERT_TRUE(cam.ok());
  EXPECT_NEAR(cam->forward().z, -1, 1e-12);
  WorldRay centre = cam->Generate(200, 200);
  EXPECT_GT(centre.origin.z, 50);
  // 45 degrees of azimuth turns the view direction about +Y.
  CameraSpec spec;
  spec.azimuth_deg = 45;
  auto side = Camera::Create(spec, Vec3{100, 100, 100});
  EXPECT_NEAR(side->forward().x, -std::sqrt(0.5), 1e-12);
  EXPECT_NEAR(side->forward().z, -std::sqrt(0.5), 1e-12);
}

TEST(CameraTest, RejectsAbsurdSizesAndViews) {
  CameraSpec spec;
  spec.width = 8193;
  EXPECT_NE(Camera::Create(spec, Vec3{1, 1, 1}).status().message().find("8193x400"),
            std::string::npos);
  spec.width = 0;
  EXPECT_FALSE(Camera::Create(spec, Vec3{1, 1, 1}).ok());
  spec.width = 8192;
  spec.height = 8192;
  EXPECT_TRUE(Camera::Create(spec, Vec3{1, 1, 1}).ok());
  spec.zoom = 0;
  EXPECT_FALSE(Camera::Create(spec, Vec3{1, 1, 1}).ok());
  spec.zoom = 1;
  spec.view = ExplicitView{{0, 0, 5}, {0, 0, 5}, {0, 1, 0}};
  EXPECT_FALSE(Camera::Create(spec, Vec3{1, 1, 1}).ok());
  spec.view = ExplicitView{{0, 0, 5}, {0, 0, 0}, {0, 0, 1}};
  EXPECT_FALSE(Camera::Create(spec, Vec3{1, 1, 1}).ok());
}

// An explicit view is refused for what is wrong with it, by name: an eye or
// a target so far that rounding is all a ray would have (once, an eye at
// 1e300 was refused as "up is parallel to the view direction": its distance
// overflowed), or an up of zero length. An up of any other length is as
// good as the unit one, however short or long, and a far eye within the
// bound is taken.
TEST(CameraTest, ExplicitViewsAreRefusedForWhatIsWrong) {
  const Vec3 extent{30, 40, 10};
  CameraSpec spec;
  spec.width = spec.height = 8;
  auto message = [&](const ExplicitView& v) {
    spec.view = v;
    return std::string(Camera::Create(spec, extent).status().message());
  };
  for (double far : {1.01e15, 1e300, -1e200}) {
    const std::string eye = message({{far, 0, 0}, {0, 0, 0}, {0, 1, 0}});
    EXPECT_NE(eye.find("the eye"), std::string::npos) << eye;
    EXPECT_NE(eye.find("1e+15 world units"), std::string::npos) << eye;
    const std::string target = message({{0, 0, 50}, {0, far, far}, {0, 1, 0}});
    EXPECT_NE(target.find("the target"), std::string::npos) << target;
  }
  EXPECT_NE(message({{0, 0, 50}, {0, 0, 0}, {0, 0, 0}}).find("up is zero"), std::string::npos);
  EXPECT_NE(message({{0, 0, 50}, {0, 0, 0}, {0, 0, 1e-300}}).find("parallel"), std::string::npos);

  spec.view = ExplicitView{{10, 20, 50}, {1, -2, 3}, {0, 1, 0}};
  auto unit = Camera::Create(spec, extent);
  ASSERT_TRUE(unit.ok()) << unit.status();
  // Powers of two, so that the unit up's rounding is every scale's: down to
  // a subnormal, and up to where the squares overflow.
  for (double s : {0x1p-1060, 0x1p-700, 0x1p-100, 0x1p100, 0x1p700, 0x1p1000}) {
    spec.view->up = {0, s, 0};
    auto scaled = Camera::Create(spec, extent);
    ASSERT_TRUE(scaled.ok()) << s << ": " << scaled.status();
    for (int p = 0; p < 64; p += 7) {
      const WorldRay a = unit->Generate(p % 8, p / 8), b = scaled->Generate(p % 8, p / 8);
      for (int k = 0; k < 3; ++k) {
        EXPECT_EQ(a.origin[k], b.origin[k]) << s;
        EXPECT_EQ(a.direction[k], b.direction[k]) << s;
      }
    }
  }
  // Within the bound, however far: taken.
  spec.view = ExplicitView{{9e14, 1, -3}, {0, 0, 0}, {0, 1, 0}};
  EXPECT_TRUE(Camera::Create(spec, extent).ok());
}

// Whether the ray meets the box [lo, hi] (slab method; touching counts).
bool HitsBox(const WorldRay& r, const Vec3& lo, const Vec3& hi) {
  double t0 = 0, t1 = HUGE_VAL;
  for (int a = 0; a < 3; ++a) {
    if (r.direction[a] == 0) {
      if (r.origin[a] < lo[a] || r.origin[a] > hi[a]) return false;
      continue;
    }
    double ta = (lo[a] - r.origin[a]) / r.direction[a], tb = (hi[a] - r.origin[a]) / r.direction[a];
    t0 = std::max(t0, std::min(ta, tb));
    t1 = std::min(t1, std::max(ta, tb));
  }
  return t0 <= t1;
}

TEST(CameraTest, FootprintHoldsEveryPixelWhoseRayMeetsTheBox) {
  // Slabs of a 80x60x40 volume, from many views: no pixel outside a slab's
  // footprint sees the slab at its centre or at any of 9 samples across
  // it, thin slabs seen from the side leave most rows out, and a footprint
  // follows the slab's outline rather than its bounding rectangle.
  const Vec3 extent{80, 60, 40};
  int rows_left_out = 0;
  int64_t in_footprints = 0, in_rectangles = 0, seen = 0;
  for (Projection projection : {Projection::kPerspective, Projection::kOrthographic}) {
    for (auto [az, el, zoom] : {std::tuple{0.0, 0.0, 1.0}, std::tuple{45.0, 0.0, 1.0},
                                std::tuple{120.0, 35.0, 1.0}, std::tuple{10.0, 89.0, 1.0},
                                std::tuple{200.0, -50.0, 2.5}, std::tuple{300.0, 10.0, 0.5}}) {
      CameraSpec spec;
      spec.projection = projection;
      spec.azimuth_deg = az;
      spec.elevation_deg = el;
      spec.zoom = zoom;
      spec.width = 90;
      spec.height = 70;
      auto cam = Camera::Create(spec, extent);
      ASSERT_TRUE(cam.ok());
      for (auto [y0, y1] : {std::pair{0, 60}, std::pair{0, 7}, std::pair{29, 31}, std::pair{50, 60}}) {
        const Vec3 lo{-40, y0 - 30.0, -20}, hi{40, y1 - 30.0, 20};
        const ImageSpans r = cam->Footprint(lo, hi);
        ASSERT_EQ(r.rows.size(), 70u);
        int x_lo = 90, x_hi = 0, y_lo = 70, y_hi = 0;
        for (int py = 0; py < 70; ++py) {
          const auto [first, last] = r.Row(py);
          if (first >= last) {
            ++rows_left_out;
            continue;
          }
          in_footprints += last - first;
          x_lo = std::min(x_lo, first), x_hi = std::max(x_hi, last);
          y_lo = std::min(y_lo, py), y_hi = std::max(y_hi, py + 1);
        }
        if (x_lo < x_hi) in_rectangles += int64_t{x_hi - x_lo} * (y_hi - y_lo);
        for (int py = 0; py < 70; ++py) {
          for (int px = 0; px < 90; ++px) {
            for (int s = 0; s < 9; ++s) {
              const auto [ox, oy] = SampleOffset(s, 9);
              if (!HitsBox(cam->GenerateAt(px, py, ox, oy), lo, hi)) continue;
              ++seen;
              ASSERT_TRUE(r.Contains(px, py)) << az << " " << el << " slab " << y0 << "-" << y1
                                               << " pixel " << px << "," << py;
            }
          }
        }
      }
    }
  }
  EXPECT_GT(rows_left_out, 1000);
  EXPECT_GT(seen, 0);
  EXPECT_LT(in_footprints, 0.9 * in_rectangles) << in_footprints << " " << in_rectangles;
  // A box behind a perspective eye: the whole image, not a guess.
  auto cam = Camera::Create(CameraSpec{}, extent);
  const ImageSpans all = cam->Footprint({-1, -1, 1000}, {1, 1, 1001});
  ASSERT_EQ(all.rows.size(), 400u);
  for (const auto& row : all.rows) EXPECT_EQ(row, (std::pair{0, 400}));
}

TEST(FramebufferTest, CompletesPixelsInAnyOrder) {
  Framebuffer fb(2, 1);
  // Pixel 0: a primary that spawned two shadow rays; they arrive first.
  EXPECT_FALSE(fb.Add(Deposit{0, RayKind::kShadow, 0, {0.25f, 0, 0}}));
  EXPECT_FALSE(fb.Add(Deposit{0, RayKind::kShadow, 0, {0.25f, 0, 0}}));
  EXPECT_FALSE(fb.Complete());
  EXPECT_TRUE(fb.Add(Deposit{0, RayKind::kPrimary, 2, {0.5f, 0, 0}}));
  EXPECT_EQ(fb.complete_pixels(), 1u);
  // Pixel 1: primary first, then its one shadow ray.
  EXPECT_FALSE(fb.Add(Deposit{1, RayKind::kPrimary, 1, {0, 0.5f, 0}}));
  EXPECT_TRUE(fb.Add(Deposit{1, RayKind::kShadow, 0, {0, 0.125f, 0}}));
  EXPECT_TRUE(fb.Complete());
  Image img = fb.Resolve();
  EXPECT_EQ(img.rgb[0], 1.0f);
  EXPECT_EQ(img.rgb[4], 0.625f);
}

// AddUncounted leaves the count of complete pixels to its caller: what it
// returns, summed and handed to CountCompleted, gives the state Add gives.
TEST(FramebufferTest, UncountedDepositsCountedOnceGiveTheSameState) {
  std::mt19937 rng(6);
  for (int round = 0; round < 100; ++round) {
    const int width = 1 + static_cast<int>(rng() % 9), height = 1 + static_cast<int>(rng() % 9);
    Framebuffer counted(width, height, 2), uncounted(width, height, 2);
    uint64_t completed = 0, returned = 0;
    for (int k = 0; k < 6 * width * height; ++k) {
      const uint32_t pixel = static_cast<uint32_t>(rng() % (width * height));
      const bool primary = rng() % 3 != 0;
      const Deposit d{pixel,
                      primary ? RayKind::kPrimary : RayKind::kShadow,
                      static_cast<uint16_t>(primary ? rng() % 2 : 0),
                      {0.25f, 0.5f, 0.125f}};
      const bool a = counted.Add(d);
      const bool b = uncounted.AddUncounted(d);
      ASSERT_EQ(a, b);
      returned += a;
      completed += b;
    }
    uncounted.CountCompleted(completed);
    EXPECT_EQ(counted.complete_pixels(), returned);
    EXPECT_EQ(uncounted.complete_pixels(), counted.complete_pixels());
    EXPECT_EQ(uncounted.Resolve().rgb, counted.Resolve().rgb);
  }
}

// CompleteRows counts the rows from the top whose every pixel is complete,
// whatever order pixels complete in, and the count only grows; Clear
// starts it again.
TEST(FramebufferTest, CompleteRowsAreTheLeadingRowsAllComplete) {
  std::mt19937 rng(5);
  for (int round = 0; round < 300; ++round) {
    const int width = 1 + static_cast<int>(rng() % 17), height = 1 + static_cast<int>(rng() % 13);
    Framebuffer fb(width, height);
    for (int pass = 0; pass < 2; ++pass) {
      std::vector<uint32_t> order(static_cast<size_t>(width) * height);
      for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
      // Mostly top to bottom, as rows are traced, with pixels out of place.
      for (size_t k = 0; k < order.size() / 3; ++k) {
        std::swap(order[rng() % order.size()], order[rng() % order.size()]);
      }
      std::vector<bool> done(order.size(), false);
      int last = 0;
      for (uint32_t p : order) {
        fb.Add(Deposit{p, RayKind::kPrimary, 0, {0.5f, 0, 0}});
        done[p] = true;
        if (rng() % 3 != 0) continue;
        int want = 0;
        while (want < height && std::all_of(done.begin() + static_cast<ptrdiff_t>(want) * width,
                                            done.begin() + static_cast<ptrdiff_t>(want + 1) * width,
                                            [](bool b) { return b; })) {
          ++want;
        }
        const int got = fb.CompleteRows();
        ASSERT_EQ(got, want) << width << "x" << height;
        ASSERT_GE(got, last);
        last = got;
      }
      ASSERT_EQ(fb.CompleteRows(), height);
      fb.Clear();
      ASSERT_EQ(fb.CompleteRows(), 0);
    }
  }
}

// With N samples a pixel completes after N primaries and every shadow ray
// they announce, in any order, and resolves to their mean.
TEST(FramebufferTest, APixelOfSamplesCompletesAfterAllOfThem) {
  Framebuffer fb(1, 1, 3);
  EXPECT_FALSE(fb.Add(Deposit{0, RayKind::kPrimary, 1, {0.3f, 0, 0}}));
  EXPECT_FALSE(fb.Add(Deposit{0, RayKind::kPrimary, 0, {0.3f, 0, 0}}));
  EXPECT_FALSE(fb.Add(Deposit{0, RayKind::kShadow, 0, {0.3f, 0, 0}}));
  EXPECT_FALSE(fb.Complete());
  EXPECT_TRUE(fb.Add(Deposit{0, RayKind::kPrimary, 0, {0.3f, 0.6f, 0}}));
  EXPECT_NEAR(fb.Resolve().rgb[0], 0.4f, 1e-6);
  EXPECT_NEAR(fb.Resolve().rgb[1], 0.2f, 1e-6);
  // Cleared for one sample, the same memory completes on one primary.
  fb.Clear(1);
  EXPECT_TRUE(fb.Add(Deposit{0, RayKind::kPrimary, 0, {0.5f, 0, 0}}));
  EXPECT_EQ(fb.Resolve().rgb[0], 0.5f);
}

// The stratified pattern: every offset inside the pixel, distinct, and
// evenly spread (each of N columns holds one sample, or a grid for squares).
TEST(CameraTest, SampleOffsetsAreStratified) {
  EXPECT_EQ(SampleOffset(0, 1), (std::array<double, 2>{0.5, 0.5}));
  for (int n = 1; n <= kMaxSamplesPerPixel; ++n) {
    std::vector<int> columns(n, 0);
    for (int s = 0; s < n; ++s) {
      const auto [x, y] = SampleOffset(s, n);
      ASSERT_TRUE(x > 0 && x < 1 && y > 0 && y < 1) << s << " of " << n;
      ++columns[static_cast<int>(x * n)];
      for (int t = 0; t < s; ++t) ASSERT_NE(SampleOffset(t, n), SampleOffset(s, n)) << n;
    }
    const int side = static_cast<int>(std::lround(std::sqrt(n)));
    if (side * side != n) {
      for (int c : columns) ASSERT_EQ(c, 1) << n;
    }
  }
}

// Deposits no renderer sends, as a hostile peer may (found by batch_fuzzer):
// a pixel completed twice made complete_pixels() reach the image's size with
// pixel 1 never deposited, and colours beyond 2^31 overflowed the int64 sums
// (undefined behaviour). Sums now wrap, and still do not depend on order.
TEST(FramebufferTest, HostileDepositsNeitherCountTwiceNorOverflow) {
  Framebuffer fb(2, 1);
  EXPECT_TRUE(fb.Add(Deposit{0, RayKind::kPrimary, 0, {0.5f, 0, 0}}));
  EXPECT_FALSE(fb.Add(Deposit{0, RayKind::kShadow, 0, {0, 0, 0}}));
  EXPECT_FALSE(fb.Add(Deposit{0, RayKind::kPrimary, 1, {0, 0, 0}}));
  EXPECT_EQ(fb.complete_pixels(), 1u);
  EXPECT_FALSE(fb.Complete());

  const std::vector<Deposit> huge = {{1, RayKind::kPrimary, 0, {3e38f, -3e38f, 4e9f}},
                                     {1, RayKind::kShadow, 0, {3e38f, -3e38f, 4e9f}},
                                     {1, RayKind::kShadow, 0, {1, 1, 4e9f}}};
  Framebuffer forward(2, 1), backward(2, 1);
  for (size_t i = 0; i < huge.size(); ++i) {
    forward.Add(huge[i]);
    backward.Add(huge[huge.size() - 1 - i]);
  }
  EXPECT_EQ(forward.Resolve().rgb, backward.Resolve().rgb);
}

// Resolving is the fixed-point sum over kScale * samples, divided, for any
// sample count (powers of two take a multiplication by the exact
// reciprocal): bit for bit, for sums anywhere in an int64, rows resolved
// whole or in pieces; and a cleared framebuffer is as good as a new one,
// for the next frame's sample count too.
TEST(FramebufferTest, ResolveIsTheSumOverTheSamplesAndClearForgetsAll) {
  std::mt19937_64 rng(17);
  const int width = 7, height = 5;
  Framebuffer reused(width, height, 1);
  for (int samples = 1; samples <= 64; ++samples) {
    reused.Clear(samples);
    Framebuffer fresh(width, height, samples);
    std::vector<std::array<int64_t, 3>> sums(width * height, {0, 0, 0});
    for (uint32_t p = 0; p < sums.size(); ++p) {
      for (int s = 0; s < samples; ++s) {
        Deposit d{p, RayKind::kPrimary, 0, {}};
        for (int c = 0; c < 3; ++c) {
          // Colours from tiny to the largest ToFixed keeps, either sign.
          const int shift = static_cast<int>(rng() % 60);
          const int64_t v = static_cast<int64_t>(rng() >> 4) >> shift;
          d.color[c] = static_cast<float>(static_cast<double>(rng() % 2 ? v : -v) / 0x1p32);
          sums[p][c] =
              static_cast<int64_t>(static_cast<uint64_t>(sums[p][c]) +
                                   static_cast<uint64_t>(Framebuffer::ToFixed(d.color[c])));
        }
        reused.Add(d);
        fresh.Add(d);
      }
    }
    ASSERT_TRUE(reused.Complete());
    const Image a = reused.Resolve(), b = fresh.Resolve();
    ASSERT_EQ(a.rgb, b.rgb) << samples << " samples";
    for (size_t p = 0; p < sums.size(); ++p) {
      for (int c = 0; c < 3; ++c) {
        const float want =
            static_cast<float>(static_cast<double>(sums[p][c]) / (Framebuffer::kScale * samples));
        ASSERT_EQ(std::bit_cast<uint32_t>(a.rgb[p * 3 + c]), std::bit_cast<uint32_t>(want))
            << samples << " samples, pixel " << p << " channel " << c;
      }
    }
    std::vector<float> rows(static_cast<size_t>(2) * width * 3);
    reused.ResolveRows(2, 4, rows.data());
    ASSERT_TRUE(std::equal(rows.begin(), rows.end(), a.rgb.begin() + 2 * width * 3));
  }
}

}  // namespace
}  // namespace transtick

namespace transtick {
namespace {

// NaN and infinite samples are mapped, not refused (docs/security.md): in
// any mix with finite ones, at random places, every pixel of every view in
// both modes is finite, NaN voxels are empty in surfaces mode, and a volume
// of nothing else renders as background.
TEST(RenderTest, NonFiniteSamplesGiveFiniteImages) {
  const std::array<int, 3> dims = {20, 18, 22};
  const float kInf = std::numeric_limits<float>::infinity();
  const float kNaN = std::numeric_limits<float>::quiet_NaN();
  const std::vector<float> odd = {kNaN, kInf, -kInf, std::numeric_limits<float>::max(),
                                  -std::numeric_limits<float>::max()};
  uint64_t state = 12345;
  auto next = [&] {
    state = state * 6364136223846793005ULL + 1442695040888963407ULL;
    return static_cast<uint32_t>(state >> 33);
  };
  Classification c;
  c.materials = {Opaque("a", 50, 150), Filter("b", 150, 250, 0.5f)};
  TransferFunction tf;
  tf.points = {{0, {0, 0, 0, 0}}, {100, {1, 0.5f, 0.2f, 0.3f}}, {250, {1, 1, 1, 0.8f}}};
  RenderSettings settings;
  settings.background = {0.25f, 0.5f, 0.75f};
  for (int trial = 0; trial < 24; ++trial) {
    Volume v;
    v.dims = dims;
    v.values.resize(v.VoxelCount());
    const int odd_percent = trial % 4 == 3 ? 100 : 5 + 30 * (trial % 3);
    for (float& x : v.values) {
      x = static_cast<int>(next() % 100) < odd_percent ? odd[next() % odd.size()]
                                                       : static_cast<float>(next() % 300);
    }
    const bool only_nan = trial % 8 == 7;
    if (only_nan) std::fill(v.values.begin(), v.values.end(), kNaN);
    const Camera cam = MakeCamera(dims, 24, 15.0 * trial, 10.0 * (trial % 5) - 20);
    for (bool dvr : {false, true}) {
      auto scene = dvr ? Scene::ForDvr(v, tf) : Scene::ForSurfaces(v, c);
      ASSERT_TRUE(scene.ok()) << scene.status();
      const Image img = RenderWhole(*scene, cam, settings);
      for (size_t i = 0; i < img.rgb.size(); ++i) {
        ASSERT_TRUE(std::isfinite(img.rgb[i])) << "trial " << trial << (dvr ? " dvr" : " surfaces")
                                               << " value " << i;
      }
      if (only_nan) {
        for (size_t i = 0; i < img.rgb.size(); ++i) {
          ASSERT_EQ(img.rgb[i], settings.background[i % 3]) << "trial " << trial << " value " << i;
        }
      }
      // Mostly finite: the finite voxels still show.
      if (odd_percent == 5) {
        size_t shown = 0;
        for (size_t i = 0; i < img.rgb.size(); ++i) shown += img.rgb[i] != settings.background[i % 3];
        EXPECT_GT(shown, img.rgb.size() / 10) << "trial " << trial << (dvr ? " dvr" : " surfaces");
      }
    }
  }
}

}  // namespace
}  // namespace transtick
