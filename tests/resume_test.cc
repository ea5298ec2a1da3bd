// A ray stopped at a slab plane and resumed on the next slab gives the same
// pixel bit for bit: images rendered by passing rays between slabs equal the
// single-scene render exactly, for any cut, view, mode and shadow setting.
#include "gtest/gtest.h"
#include "testing.h"
#include "transtick/synthetic.h"
#include "transtick/volume_io.h"

namespace transtick {
namespace {

using testing::MakeCamera;
using testing::RenderSlabs;
using testing::RenderWhole;

Scene PhantomSurfaces(std::array<int, 3> dims, SurfaceModel model = SurfaceModel::kSmooth) {
  Volume v = MakeNoisyPhantom(dims, 21);
  auto range = v.Range();
  Classification c;
  c.surface = model;
  c.materials = {Material{.name = "skin",
                          .min = range[1] * 0.2f,
                          .max = range[1] * 0.45f,
                          .color = {0.9f, 0.7f, 0.6f},
                          .opacity = 0.35f},
                 Material{.name = "brain",
                          .min = range[1] * 0.45f,
                          .max = range[1] * 0.7f,
                          .color = {0.8f, 0.5f, 0.5f},
                          .opacity = 0.6f},
                 Material{.name = "bone",
                          .min = range[1] * 0.7f,
                          .max = range[1] + 1,
                          .color = {1, 1, 0.9f},
                          .opacity = 1}};
  return *Scene::ForSurfaces(v, c);
}

Scene PhantomDvr(std::array<int, 3> dims) {
  Volume v = MakeNoisyPhantom(dims, 22);
  auto range = v.Range();
  TransferFunction tf;
  tf.points = {{range[1] * 0.2f, {0, 0, 0, 0}},
               {range[1] * 0.4f, {0.9f, 0.6f, 0.4f, 0.05f}},
               {range[1] * 0.8f, {1, 1, 1, 0.4f}}};
  return *Scene::ForDvr(v, tf);
}

struct View {
  double azimuth, elevation;
};

void ExpectSlabsMatch(const Scene& scene, const std::vector<View>& views, int size) {
  const int ny = scene.dims()[1];
  // 2, 3, 5 and 8 slabs, cut off the brick grid, plus one-plane slabs.
  std::vector<std::vector<int>> cuts = {
      {ny / 2}, {ny / 3, 2 * ny / 3 + 1}, {5, 11, 19, 30}, {3, 7, 9, 13, 21, 22, 29}, {1, ny - 1}};
  for (bool shadows : {true, false}) {
    RenderSettings settings;
    settings.shadows = shadows;
    settings.background = {0.1f, 0.2f, 0.3f};
    for (const View& v : views) {
      Camera cam = MakeCamera(scene.dims(), size, v.azimuth, v.elevation);
      Image whole = RenderWhole(scene, cam, settings);
      uint64_t total_handoffs = 0;
      for (const auto& c : cuts) {
        uint64_t handoffs = 0;
        Image slabs = RenderSlabs(scene, c, cam, settings, &handoffs);
        total_handoffs += handoffs;
        ASSERT_EQ(whole.rgb, slabs.rgb)
            << "azimuth " << v.azimuth << " elevation " << v.elevation << " shadows " << shadows
            << " with " << c.size() + 1 << " slabs";
      }
      // Rays did cross slab planes (a frontal view crosses few).
      EXPECT_GT(total_handoffs, 0u);
    }
  }
}

TEST(ResumeTest, SurfacesAcrossSlabsAreBitIdentical) {
  // Views across the slabs, oblique, and along the slab axis (Y), where
  // every ray crosses every slab.
  ExpectSlabsMatch(PhantomSurfaces({40, 34, 38}),
                   {{0, 0}, {45, 0}, {30, 40}, {0, 90}, {10, -89}, {200, -30}}, 64);
}

// Content in a band of planes with wide empty space beside it, as
// balancing cuts it: the walk crosses the empty space by cubes of void
// bricks that reach over several slabs.
TEST(ResumeTest, EmptySpaceAcrossSlabsIsBitIdentical) {
  const std::array<int, 3> dims = {64, 96, 128};
  Volume v = MakeRandom(dims, 3, 2);
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x) {
        float& value = v.values[v.Index(x, y, z)];
        value = y < 24 && value > 0.5f ? 30.0f : 0.0f;
      }
  for (SurfaceModel model : {SurfaceModel::kSmooth, SurfaceModel::kVoxel}) {
    Classification c;
    c.surface = model;
    c.materials = {Material{.name = "faint", .min = 20, .max = 45, .opacity = 0.04f}};
    const Scene scene = *Scene::ForSurfaces(v, c);
    for (bool shadows : {true, false}) {
      RenderSettings settings;
      settings.shadows = shadows;
      for (const View& view : std::vector<View>{{0, 0}, {30, 20}, {0, 80}, {120, -40}}) {
        const Camera cam = MakeCamera(dims, 80, view.azimuth, view.elevation);
        const Image whole = RenderWhole(scene, cam, settings);
        for (const std::vector<int>& cuts :
             {std::vector<int>{6, 13, 19}, {24}, {3, 30, 50, 70}, {40, 41, 90}}) {
          uint64_t handoffs = 0, ended = 0;
          ASSERT_EQ(whole.rgb, RenderSlabs(scene, cuts, cam, settings, &handoffs, &ended).rgb)
              << (model == SurfaceModel::kSmooth ? "smooth" : "voxel") << " azimuth "
              << view.azimuth << " elevation " << view.elevation << " shadows " << shadows
              << ", cuts at " << cuts[0] << "...";
          // Smooth rays that reach a plane past the content's bricks (the
          // content ends at plane 24; the bricks of cells 24-31 read it)
          // end there (the field summary); voxel rays have none. Frontal
          // rays keep their plane: those past the content cross only void,
          // and are not made (Tracer::Void).
          const bool frontal = view.azimuth == 0 && view.elevation == 0;
          if (model == SurfaceModel::kSmooth && cuts.back() >= 32 && !frontal) {
            EXPECT_GT(ended, 0u) << "azimuth " << view.azimuth << ", cuts at " << cuts[0];
          } else if (model == SurfaceModel::kVoxel) {
            EXPECT_EQ(ended, 0u);
          }
        }
      }
    }
  }
}

// Spacings far from 1: a ray's t is in world units, so with voxels 7e12
// wide it passes 1e9 within a voxel of its entry, and every neighbour
// refused the rays handed on (found by volume_fuzzer).
TEST(ResumeTest, ExtremeSpacingsAcrossSlabsAreBitIdentical) {
  for (double s : {7.3e12, 1e-9}) {
    Volume v = MakeNoisyPhantom({12, 10, 9}, 23);
    v.spacing = {s, s, s};
    const auto range = v.Range();
    Classification c;
    c.materials = {Material{.name = "low", .min = range[1] * 0.3f, .max = range[1] * 0.6f,
                            .opacity = 0.4f},
                   Material{.name = "high", .min = range[1] * 0.6f, .max = range[1] + 1,
                            .opacity = 1}};
    for (SurfaceModel model : {SurfaceModel::kSmooth, SurfaceModel::kVoxel}) {
      c.surface = model;
      const Scene scene = *Scene::ForSurfaces(v, c);
      RenderSettings settings;
      for (const View& view : std::vector<View>{{0, 0}, {35, 25}, {0, 89}}) {
        CameraSpec spec;
        spec.width = spec.height = 24;
        spec.azimuth_deg = view.azimuth;
        spec.elevation_deg = view.elevation;
        const auto& d = scene.dims();
        const Camera cam = *Camera::Create(spec, Vec3{d[0] * s, d[1] * s, d[2] * s});
        const Image whole = RenderWhole(scene, cam, settings);
        uint64_t handoffs = 0;
        ASSERT_EQ(whole.rgb, RenderSlabs(scene, {3, 6}, cam, settings, &handoffs).rgb)
            << "spacing " << s << " azimuth " << view.azimuth;
        if (view.elevation > 80) {
          EXPECT_GT(handoffs, 0u) << "spacing " << s;
        }
      }
    }
  }
}

// Voxel sizes that differ a lot, within the bound a scene accepts, still
// give the same image across slabs; beyond it (a ray could not be placed
// within a voxel of the thin axis: the fuzzer's NIfTI with spacing
// 128 x 1.4e-14 x 2.5, 10^16 of its smallest voxels across), the scene is
// refused, naming the spacing.
TEST(ResumeTest, AnisotropicSpacingsAcrossSlabsAreBitIdenticalUpToTheBound) {
  for (const std::array<double, 3>& spacing :
       {std::array<double, 3>{100, 2e-4, 2.5}, {3e-3, 700, 1}, {1, 1, 9.9e5}, {1e-7, 1, 900}}) {
    Volume v = MakeNoisyPhantom({12, 10, 9}, 29);
    v.spacing = spacing;
    const auto range = v.Range();
    Classification c;
    c.materials = {Material{.name = "high", .min = range[1] * 0.5f, .max = range[1] + 1}};
    for (SurfaceModel model : {SurfaceModel::kSmooth, SurfaceModel::kVoxel}) {
      c.surface = model;
      auto scene = Scene::ForSurfaces(v, c);
      ASSERT_TRUE(scene.ok()) << scene.status();
      for (const View& view : std::vector<View>{{0, 0}, {35, 25}, {0, 89}, {120, -40}}) {
        CameraSpec spec;
        spec.width = spec.height = 24;
        spec.azimuth_deg = view.azimuth;
        spec.elevation_deg = view.elevation;
        const auto& d = scene->dims();
        const Camera cam = *Camera::Create(
            spec, Vec3{d[0] * spacing[0], d[1] * spacing[1], d[2] * spacing[2]});
        ASSERT_EQ(RenderWhole(*scene, cam, RenderSettings{}).rgb,
                  RenderSlabs(*scene, {3, 6}, cam, RenderSettings{}).rgb)
            << "spacing " << spacing[0] << " " << spacing[1] << " " << spacing[2];
      }
    }
  }
  Volume v = MakeNoisyPhantom({12, 10, 9}, 29);
  v.spacing = {128, 1.4e-14, 2.5};
  Classification c;
  c.materials = {Material{.name = "all", .min = -1e9f, .max = 1e9f}};
  auto refused = Scene::ForSurfaces(v, c);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("128 x 1.4e-14 x 2.5"), std::string::npos)
      << refused.status();
}

TEST(ResumeTest, VoxelSurfacesAcrossSlabsAreBitIdentical) {
  ExpectSlabsMatch(PhantomSurfaces({40, 34, 38}, SurfaceModel::kVoxel),
                   {{0, 0}, {45, 0}, {30, 40}, {0, 90}, {200, -30}}, 64);
}

// The two surface models are different images of one classification (so
// that the tests above exercise both): smooth hits lie inside voxels.
TEST(ResumeTest, SmoothAndVoxelSurfacesDiffer) {
  const Scene smooth = PhantomSurfaces({40, 34, 38});
  const Scene voxel = PhantomSurfaces({40, 34, 38}, SurfaceModel::kVoxel);
  const Camera cam = MakeCamera(smooth.dims(), 64, 30, 20);
  RenderSettings settings;
  const Image a = RenderWhole(smooth, cam, settings), b = RenderWhole(voxel, cam, settings);
  size_t differ = 0;
  for (size_t i = 0; i < a.rgb.size(); ++i) differ += a.rgb[i] != b.rgb[i];
  EXPECT_GT(differ, a.rgb.size() / 20);
}

// Several primary rays per pixel, each its own descriptor, across every
// cut: the same bits as the single scene, with and without shadows.
TEST(ResumeTest, SamplesPerPixelAcrossSlabsAreBitIdentical) {
  const Scene scene = PhantomSurfaces({40, 34, 38});
  const int ny = scene.dims()[1];
  for (int samples : {2, 4, 5}) {
    for (bool shadows : {true, false}) {
      RenderSettings settings;
      settings.samples = samples;
      settings.shadows = shadows;
      const Camera cam = MakeCamera(scene.dims(), 40, 35, 25);
      const Image whole = RenderWhole(scene, cam, settings);
      for (const std::vector<int>& cuts : {std::vector<int>{ny / 2}, {5, 11, 19, 30}}) {
        ASSERT_EQ(whole.rgb, RenderSlabs(scene, cuts, cam, settings).rgb)
            << samples << " samples, shadows " << shadows << ", " << cuts.size() + 1 << " slabs";
      }
    }
  }
}

TEST(ResumeTest, DvrAcrossSlabsIsBitIdentical) {
  ExpectSlabsMatch(PhantomDvr({40, 34, 38}), {{0, 0}, {45, 20}, {0, 90}, {120, -60}}, 48);
}

TEST(ResumeTest, RealHeadAcrossSlabsIsBitIdentical) {
  std::string path = testing::DataFile("headsq.nrrd");
  if (path.empty()) GTEST_SKIP() << "headsq.nrrd not found";
  auto v = ReadNrrd(path);
  ASSERT_TRUE(v.ok()) << v.status();
  Classification c;
  c.materials = {
      Material{
          .name = "skin", .min = 500, .max = 1200, .color = {0.9f, 0.7f, 0.6f}, .opacity = 0.3f},
      Material{.name = "bone", .min = 1200, .max = 5000, .color = {1, 1, 0.9f}}};
  Scene scene = *Scene::ForSurfaces(*v, c);
  RenderSettings settings;
  for (View view : {View{45, 0}, View{0, 90}}) {
    Camera cam = MakeCamera(scene.dims(), 96, view.azimuth, view.elevation);
    Image whole = RenderWhole(scene, cam, settings);
    EXPECT_EQ(whole.rgb, RenderSlabs(scene, {16, 32, 48}, cam, settings).rgb);
  }
}

}  // namespace
}  // namespace transtick
