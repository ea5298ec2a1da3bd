// surface_bench: how exact, how clean and how fast the surfaces are, in
// numbers, for the smooth surfaces beside the paper's voxel faces.
//
//   surface_bench [--size N] [--radius R] [--threads N] [--rays N]
//                 [--volume FILE] [--materials FILE] [--repeat N]
//
// 1. Accuracy. Analytic fields sampled at voxel centres in 48^3 float
//    volumes (a sphere, a torus, a tilted plane), `rays` random rays
//    each: the hits CrossingWalk reports against the first crossing
//    of the trilinear field found by brute force (4096 samples along the
//    ray, then bisection in double). Prints the largest distance between
//    the two along the ray, in voxels, and the rays that should hit and
//    missed (and the reverse).
// 2. Looks. An analytic sphere f = R - |x - c| in a 48^3 int16 volume (100
//    units per voxel), one opaque material at f >= 0, orthographic from
//    the front (about 5.1 pixels per voxel at the default 448x448), shadows
//    on and off, both surface models:
//    silhouette: the RMS distance of the silhouette's boundary pixels (hit
//      pixels with a 4-neighbour that missed) from their least-squares
//      circle, in voxels, beside the same figure for a perfect disk of that
//      circle rasterised at pixel centres (the best a 1-sample image can do);
//    speckle: the fraction of interior pixels (more than 3 pixels inside the
//      circle) whose luminance differs from the median of their 5x5
//      neighbourhood by more than 8% of full scale: striping, acne and
//      speckles, which a smooth sphere has none of.
// 3. Speed. A real volume (default cthead.nrrd beside the repository and
//    examples/cthead_materials.json), 400x400, azimuth 45, shadows on:
//    voxel and smooth frames interleaved, `repeat` of each after a warm-up;
//    medians and their ratio.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <random>

#include "bench_util.h"
#include "convert.h"
#include "transtick/camera.h"
#include "transtick/isosurface.h"
#include "transtick/render.h"
#include "transtick/scene.h"
#include "transtick/volume_io.h"

namespace transtick {
namespace {

using bench::Median;
using bench::MsSince;
using bench::ParseInt;

struct Circle {
  double cx = 0, cy = 0, r = 0;
};

// The algebraic (Kasa) least-squares circle through `points`.
Circle FitCircle(const std::vector<std::array<double, 2>>& points) {
  // Solve for x^2 + y^2 + D x + E y + F = 0 in the least-squares sense.
  double sxx = 0, sxy = 0, syy = 0, sx = 0, sy = 0, n = 0, sxz = 0, syz = 0, sz = 0;
  for (const auto& p : points) {
    const double x = p[0], y = p[1], z = x * x + y * y;
    sxx += x * x, sxy += x * y, syy += y * y, sx += x, sy += y, n += 1;
    sxz += x * z, syz += y * z, sz += z;
  }
  // Normal equations [sxx sxy sx; sxy syy sy; sx sy n] [D E F] = -[sxz syz sz].
  double m[3][4] = {{sxx, sxy, sx, -sxz}, {sxy, syy, sy, -syz}, {sx, sy, n, -sz}};
  for (int c = 0; c < 3; ++c) {
    int pivot = c;
    for (int r = c + 1; r < 3; ++r)
      if (std::abs(m[r][c]) > std::abs(m[pivot][c])) pivot = r;
    for (int k = 0; k < 4; ++k) std::swap(m[c][k], m[pivot][k]);
    for (int r = 0; r < 3; ++r) {
      if (r == c) continue;
      const double f = m[r][c] / m[c][c];
      for (int k = c; k < 4; ++k) m[r][k] -= f * m[c][k];
    }
  }
  const double d = m[0][3] / m[0][0], e = m[1][3] / m[1][1], f = m[2][3] / m[2][2];
  Circle circle;
  circle.cx = -d / 2;
  circle.cy = -e / 2;
  circle.r = std::sqrt(circle.cx * circle.cx + circle.cy * circle.cy - f);
  return circle;
}

// Boundary pixels of a hit mask, as pixel centres.
std::vector<std::array<double, 2>> Boundary(const std::vector<uint8_t>& hit, int w, int h) {
  std::vector<std::array<double, 2>> out;
  for (int y = 1; y + 1 < h; ++y) {
    for (int x = 1; x + 1 < w; ++x) {
      const size_t i = static_cast<size_t>(y) * w + x;
      if (hit[i] && (!hit[i - 1] || !hit[i + 1] || !hit[i - w] || !hit[i + w])) {
        out.push_back({x + 0.5, y + 0.5});
      }
    }
  }
  return out;
}

double RmsFrom(const std::vector<std::array<double, 2>>& points, const Circle& c) {
  double sum = 0;
  for (const auto& p : points) {
    const double d = std::hypot(p[0] - c.cx, p[1] - c.cy) - c.r;
    sum += d * d;
  }
  return points.empty() ? 0 : std::sqrt(sum / points.size());
}

struct Figures {
  double silhouette_voxels = 0, disk_voxels = 0, speckle = 0, frame_ms = 0, px_per_voxel = 0;
  size_t interior = 0;
};

Figures Measure(const Image& img, double radius_voxels, double frame_ms) {
  const int w = img.width, h = img.height;
  std::vector<uint8_t> hit(static_cast<size_t>(w) * h);
  std::vector<double> lum(hit.size());
  for (size_t i = 0; i < hit.size(); ++i) {
    const float* p = &img.rgb[i * 3];
    hit[i] = p[0] > 0 || p[1] > 0 || p[2] > 0;
    lum[i] = std::clamp(0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2], 0.0, 1.0);
  }
  Figures f;
  f.frame_ms = frame_ms;
  const auto boundary = Boundary(hit, w, h);
  const Circle c = FitCircle(boundary);
  f.px_per_voxel = c.r / radius_voxels;
  f.silhouette_voxels = RmsFrom(boundary, c) / f.px_per_voxel;
  // The same circle, rasterised perfectly at pixel centres.
  std::vector<uint8_t> disk(hit.size());
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      disk[static_cast<size_t>(y) * w + x] = std::hypot(x + 0.5 - c.cx, y + 0.5 - c.cy) < c.r;
  const auto disk_boundary = Boundary(disk, w, h);
  f.disk_voxels = RmsFrom(disk_boundary, FitCircle(disk_boundary)) / f.px_per_voxel;
  size_t speckled = 0;
  for (int y = 2; y + 2 < h; ++y) {
    for (int x = 2; x + 2 < w; ++x) {
      if (std::hypot(x + 0.5 - c.cx, y + 0.5 - c.cy) > c.r - 3) continue;
      std::array<double, 25> around;
      int k = 0;
      for (int dy = -2; dy <= 2; ++dy)
        for (int dx = -2; dx <= 2; ++dx) around[k++] = lum[static_cast<size_t>(y + dy) * w + x + dx];
      std::nth_element(around.begin(), around.begin() + 12, around.end());
      ++f.interior;
      if (std::abs(lum[static_cast<size_t>(y) * w + x] - around[12]) > 0.08) ++speckled;
    }
  }
  f.speckle = f.interior ? static_cast<double>(speckled) / f.interior : 0;
  return f;
}


struct Accuracy {
  int rays = 0, hits = 0, missed = 0, spurious = 0;
  double worst = 0;  // voxels along the ray
};

// Random rays through a field's volume: CrossingWalk's first crossing
// against brute force.
Accuracy MeasureAccuracy(const char* name, double (*field)(const Vec3&), int rays) {
  Volume v;
  v.dims = {48, 48, 48};
  v.values.resize(v.VoxelCount());
  for (int z = 0; z < 48; ++z)
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 48; ++x)
        v.values[v.Index(x, y, z)] = static_cast<float>(field(Vec3{x + 0.5, y + 0.5, z + 0.5}));
  Classification cls;
  cls.materials = {Material{.name = name, .min = 0, .max = 1e6}};
  auto scene = Scene::ForSurfaces(v, cls);
  const Bands bands(cls);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit(0, 1), normal(-1, 1);
  Accuracy a;
  constexpr int kSamples = 4096;
  for (int r = 0; r < rays; ++r) {
    // From a random point inside toward a random direction, to the box.
    const Vec3 o{2 + 44 * unit(rng), 2 + 44 * unit(rng), 2 + 44 * unit(rng)};
    Vec3 d{normal(rng), normal(rng), normal(rng)};
    d = Normalize(d);
    auto box = IntersectBox(o, d, v.dims);
    if (!box) continue;
    const double t0 = std::max(0.0, (*box)[0]), t1 = (*box)[1];
    auto g = [&](double t) { return FieldAt(*scene, o + d * t); };
    ++a.rays;
    double truth = -1;
    double prev_t = t0, prev = g(t0);
    for (int k = 1; k <= kSamples && truth < 0; ++k) {
      const double t = t0 + (t1 - t0) * k / kSamples, val = g(t);
      if ((val < 0) != (prev < 0)) {
        double lo = prev_t, hi = t;
        for (int it = 0; it < 80; ++it) {
          const double mid = 0.5 * (lo + hi);
          ((g(mid) < 0) == (prev < 0) ? lo : hi) = mid;
        }
        truth = 0.5 * (lo + hi);
      }
      prev_t = t, prev = val;
    }
    double hit = -1;
    CrossingWalk walk(*scene, bands, o, d, t0, t1, g(t0) >= 0 ? 1 : 0);
    if (auto c = walk.Next()) hit = c->t;
    if (truth >= 0 && hit < 0) ++a.missed;
    if (truth < 0 && hit >= 0) {
      // Dense sampling can miss a crossing too (two roots within one of
      // its steps); a true crossing has the field at zero there.
      if (std::abs(g(hit)) > 1e-6) ++a.spurious;
      continue;
    }
    if (truth >= 0 && hit >= 0) {
      ++a.hits;
      a.worst = std::max(a.worst, std::abs(hit - truth));
    }
  }
  return a;
}

double SphereField(const Vec3& p) { return 17 - Length(p - Vec3{24, 24, 24}); }
double TorusField(const Vec3& p) {
  const Vec3 q = p - Vec3{24, 24, 24};
  const double ring = std::hypot(q.x, q.z) - 14;
  return 6 - std::hypot(ring, q.y);
}
double PlaneField(const Vec3& p) {
  return Dot(p - Vec3{24, 24, 24}, Normalize(Vec3{1, 2, 3})) + 0.37;
}

// Voxel and smooth frames of one view, interleaved; returns false on error.
bool CompareSpeed(const std::string& volume_path, const std::string& materials_path, int threads,
                  int repeat) {
  auto volume = ReadVolume(volume_path);
  auto materials = LoadMaterials(materials_path);
  if (!volume.ok() || !materials.ok()) {
    std::printf("speed: skipped (%s)\n",
                std::string(!volume.ok() ? volume.status().message()
                                         : materials.status().message())
                    .c_str());
    return true;
  }
  Classification voxel = *materials, smooth = *materials;
  voxel.surface = SurfaceModel::kVoxel;
  smooth.surface = SurfaceModel::kSmooth;
  auto t_voxel = std::chrono::steady_clock::now();
  auto voxel_scene = Scene::ForSurfaces(*volume, voxel);
  const double voxel_build = MsSince(t_voxel);
  auto t_smooth = std::chrono::steady_clock::now();
  auto smooth_scene = Scene::ForSurfaces(*volume, smooth);
  const double smooth_build = MsSince(t_smooth);
  if (!voxel_scene.ok() || !smooth_scene.ok()) return false;
  CameraSpec spec;
  spec.azimuth_deg = 45;
  spec.width = spec.height = 400;
  const Vec3 extent{volume->dims[0] * volume->spacing[0], volume->dims[1] * volume->spacing[1],
                    volume->dims[2] * volume->spacing[2]};
  auto camera = Camera::Create(spec, extent);
  if (!camera.ok()) return false;
  RenderSettings settings;
  std::vector<double> ms[2];
  TraceCounters counters[2];
  for (int i = 0; i <= repeat; ++i) {
    for (int m = 0; m < 2; ++m) {
      RenderStats stats;
      if (!RenderLocal(m ? *smooth_scene : *voxel_scene, *camera, settings, threads, &stats).ok())
        return false;
      if (i > 0) ms[m].push_back(stats.frame_ms);
      counters[m] = stats.counters;
    }
  }
  std::printf("\nspeed: %s, 400x400, azimuth 45, shadows on, %d frames each, interleaved\n",
              volume_path.c_str(), repeat);
  std::printf("%-7s %10s %10s %10s %10s %12s %10s %12s\n", "surface", "median ms", "min ms",
              "hits", "shadow", "segments", "sticks", "build ms");
  for (int m = 0; m < 2; ++m) {
    const Scene& scene = m ? *smooth_scene : *voxel_scene;
    std::printf("%-7s %10.1f %10.1f %10llu %10llu %12llu %10zu %12.0f\n", m ? "smooth" : "voxel",
                Median(ms[m]), *std::min_element(ms[m].begin(), ms[m].end()),
                static_cast<unsigned long long>(counters[m].surface_hits),
                static_cast<unsigned long long>(counters[m].shadow),
                static_cast<unsigned long long>(counters[m].segments), scene.sticks().StickCount(),
                m ? smooth_build : voxel_build);
  }
  std::vector<double> ratios;
  for (int i = 0; i < repeat; ++i) ratios.push_back(ms[1][i] / ms[0][i]);
  std::printf("smooth / voxel frame time: median of paired ratios %.2f (min %.2f, max %.2f)\n",
              Median(ratios), *std::min_element(ratios.begin(), ratios.end()),
              *std::max_element(ratios.begin(), ratios.end()));
  return true;
}

int Run(int argc, char** argv) {
  int size = 448, threads = 0, rays = 20000, repeat = 7;
  double radius = 17;
  const char* dir = std::getenv("TRANSTICK_DATA_DIR");
  std::string volume = std::string(dir && *dir ? dir : TRANSTICK_BENCH_DATA_DIR) + "/cthead.nrrd";
  std::string materials = TRANSTICK_BENCH_MATERIALS;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i], value = argv[i + 1];
    if (flag == "--size" && ParseInt(value, 64, 4096, &size)) continue;
    if (flag == "--threads" && ParseInt(value, 0, 256, &threads)) continue;
    if (flag == "--rays" && ParseInt(value, 0, 10000000, &rays)) continue;
    if (flag == "--repeat" && ParseInt(value, 1, 1000, &repeat)) continue;
    if (flag == "--volume") {
      volume = value;
      continue;
    }
    if (flag == "--materials") {
      materials = value;
      continue;
    }
    if (flag == "--radius") {
      radius = std::atof(value.c_str());
      if (radius > 2 && radius < 23.5) continue;
    }
    std::fprintf(stderr,
                 "usage: surface_bench [--size N] [--radius R (2-23.5)] [--threads N] [--rays N]\n"
                 "                     [--volume FILE] [--materials FILE] [--repeat N]\n");
    return 2;
  }
  if (argc % 2 == 0) {
    std::fprintf(stderr, "surface_bench: %s needs a value\n", argv[argc - 1]);
    return 2;
  }

  std::printf("accuracy: first crossing against brute force, 48^3 float fields\n");
  std::printf("%-8s %8s %8s %8s %9s %14s\n", "field", "rays", "hits", "missed", "spurious",
              "worst (voxel)");
  bool accurate = true;
  for (auto [name, f] : {std::pair{"sphere", &SphereField}, std::pair{"torus", &TorusField},
                         std::pair{"plane", &PlaneField}}) {
    const Accuracy a = MeasureAccuracy(name, f, rays);
    std::printf("%-8s %8d %8d %8d %9d %14.2e\n", name, a.rays, a.hits, a.missed, a.spurious,
                a.worst);
    accurate = accurate && a.missed == 0 && a.spurious == 0 && a.worst <= 1e-3;
  }

  Volume v;
  v.dims = {48, 48, 48};
  v.source_type = ScalarType::kInt16;
  v.values.resize(v.VoxelCount());
  const double c = 24;  // the volume's centre, voxel centres at i + 0.5
  for (int z = 0; z < 48; ++z)
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 48; ++x) {
        const double d = std::sqrt((x + 0.5 - c) * (x + 0.5 - c) + (y + 0.5 - c) * (y + 0.5 - c) +
                                   (z + 0.5 - c) * (z + 0.5 - c));
        v.values[v.Index(x, y, z)] = static_cast<float>(std::lround(100 * (radius - d)));
      }
  CameraSpec spec;
  spec.projection = Projection::kOrthographic;
  spec.width = spec.height = size;
  auto camera = Camera::Create(spec, Vec3{48, 48, 48});
  if (!camera.ok()) return 1;
  std::printf("\nlooks: sphere R = %.1f voxels in 48^3 int16, orthographic %dx%d\n", radius, size,
              size);
  std::printf("%-7s %-8s %12s %12s %10s %10s %10s\n", "surface", "shadows", "silhouette",
              "perfect disk", "speckle", "px/voxel", "frame ms");
  for (SurfaceModel model : {SurfaceModel::kVoxel, SurfaceModel::kSmooth}) {
    Classification cls;
    cls.materials = {
        Material{.name = "sphere", .min = 0, .max = 30000, .color = {0.8f, 0.8f, 0.8f}}};
    cls.surface = model;
    auto scene = Scene::ForSurfaces(v, cls);
    if (!scene.ok()) {
      std::fprintf(stderr, "surface_bench: %s\n", std::string(scene.status().message()).c_str());
      return 1;
    }
    for (bool shadows : {true, false}) {
      RenderSettings settings;
      settings.shadows = shadows;
      std::vector<double> times;
      Image img;
      for (int rep = 0; rep < 3; ++rep) {
        RenderStats stats;
        auto rendered = RenderLocal(*scene, *camera, settings, threads, &stats);
        if (!rendered.ok()) return 1;
        img = *std::move(rendered);
        times.push_back(stats.frame_ms);
      }
      const Figures f = Measure(img, radius, Median(times));
      std::printf("%-7s %-8s %9.3f vx %9.3f vx %9.2f%% %10.2f %10.1f\n",
                  SurfaceModelName(model), shadows ? "on" : "off", f.silhouette_voxels,
                  f.disk_voxels, 100 * f.speckle, f.px_per_voxel, f.frame_ms);
    }
  }
  if (!CompareSpeed(volume, materials, threads, repeat)) return 1;
  if (!accurate) {
    std::printf("\nsurface_bench: a hit was missed, spurious or further than 1e-3 voxel\n");
    return 1;
  }
  return 0;
}

}  // namespace
}  // namespace transtick

int main(int argc, char** argv) { return transtick::Run(argc, argv); }
