// surface_bench: how clean the surfaces look, in numbers.
//
//   surface_bench [--size N] [--radius R] [--threads N]
//
// An analytic sphere f = R - |x - c| in a 48^3 int16 volume (100 units per
// voxel), classified as one opaque material at f >= 0, rendered
// orthographically from the front (about 5.4 pixels per voxel at the
// default 448x448), with shadows on and off. It prints:
//   silhouette: the RMS distance of the silhouette's boundary pixels (hit
//     pixels with a 4-neighbour that missed) from their least-squares
//     circle, in voxels, beside the same figure for a perfect disk of that
//     circle rasterised at pixel centres (the best a 1-sample image can do);
//   speckle: the fraction of interior pixels (more than 3 pixels inside the
//     circle) whose luminance differs from the median of their 5x5
//     neighbourhood by more than 8% of full scale: striping, acne and
//     speckles, which a smooth sphere has none of;
//   the frame time.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "bench_util.h"
#include "transtick/camera.h"
#include "transtick/render.h"
#include "transtick/scene.h"

namespace transtick {
namespace {

using bench::Median;
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

int Run(int argc, char** argv) {
  int size = 448, threads = 0;
  double radius = 17;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i], value = argv[i + 1];
    if (flag == "--size" && ParseInt(value, 64, 4096, &size)) continue;
    if (flag == "--threads" && ParseInt(value, 0, 256, &threads)) continue;
    if (flag == "--radius") {
      radius = std::atof(value.c_str());
      if (radius > 2 && radius < 23.5) continue;
    }
    std::fprintf(stderr, "usage: surface_bench [--size N] [--radius R (2-23.5)] [--threads N]\n");
    return 2;
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
  Classification cls;
  cls.materials = {Material{.name = "sphere", .min = 0, .max = 30000, .color = {0.8f, 0.8f, 0.8f}}};
  auto scene = Scene::ForSurfaces(v, cls);
  if (!scene.ok()) {
    std::fprintf(stderr, "surface_bench: %s\n", std::string(scene.status().message()).c_str());
    return 1;
  }
  CameraSpec spec;
  spec.projection = Projection::kOrthographic;
  spec.width = spec.height = size;
  auto camera = Camera::Create(spec, Vec3{48, 48, 48});
  if (!camera.ok()) return 1;
  std::printf("surface_bench: sphere R = %.1f voxels in 48^3 int16, orthographic %dx%d\n", radius,
              size, size);
  std::printf("%-8s %12s %12s %10s %10s %10s\n", "shadows", "silhouette", "perfect disk",
              "speckle", "px/voxel", "frame ms");
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
    std::printf("%-8s %9.3f vx %9.3f vx %9.2f%% %10.2f %10.1f\n", shadows ? "on" : "off",
                f.silhouette_voxels, f.disk_voxels, 100 * f.speckle, f.px_per_voxel, f.frame_ms);
  }
  return 0;
}

}  // namespace
}  // namespace transtick

int main(int argc, char** argv) { return transtick::Run(argc, argv); }
