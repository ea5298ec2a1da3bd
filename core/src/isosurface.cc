#include "transtick/isosurface.h"

#include <algorithm>
#include <cmath>

namespace transtick {
namespace {

// The roots of the slope 3a t^2 + 2b t + c strictly inside (lo, hi), in
// increasing order; returns how many (0-2).
int SlopeRoots(const RayCubic& g, double lo, double hi, double out[2]) {
  const double qa = 3 * g.a, qb = 2 * g.b, qc = g.c;
  double r[2];
  int n = 0;
  if (qa == 0) {
    if (qb != 0) r[n++] = -qc / qb;
  } else {
    const double disc = qb * qb - 4 * qa * qc;
    if (disc >= 0) {
      // The stable form: no cancellation between -qb and the root.
      const double s = std::sqrt(disc);
      const double q = -0.5 * (qb + (qb >= 0 ? s : -s));
      if (q != 0) {
        r[n++] = q / qa;
        r[n++] = qc / q;
      } else {
        r[n++] = 0;  // qb = 0 and disc = 0: qc = 0 too, a double root at 0
      }
    }
  }
  if (n == 2 && r[1] < r[0]) std::swap(r[0], r[1]);
  int kept = 0;
  for (int i = 0; i < n; ++i) {
    if (r[i] > lo && r[i] < hi && (kept == 0 || r[i] > out[kept - 1])) out[kept++] = r[i];
  }
  return kept;
}

// The root of g in [lo, hi], where g(lo) and g(hi) differ in sign: the
// Illinois variant of regula falsi, falling back to bisection when it
// stalls, for at most 64 steps (bisection alone halves 2^-64 of the
// interval's length).
double Refine(const RayCubic& g, double lo, double glo, double hi, double ghi) {
  const double tolerance = (hi - lo) * 1e-12;
  int side = 0;
  for (int step = 0; step < 64 && hi - lo > tolerance; ++step) {
    double t = lo - glo * (hi - lo) / (ghi - glo);
    // A secant point outside, or too near an end, is replaced by the middle.
    if (!(t > lo && t < hi)) t = 0.5 * (lo + hi);
    const double gt = g(t);
    if (gt == 0) return t;
    if ((gt < 0) == (glo < 0)) {
      lo = t;
      glo = gt;
      if (side == -1) ghi *= 0.5;  // Illinois: the end that stays is halved
      side = -1;
    } else {
      hi = t;
      ghi = gt;
      if (side == 1) glo *= 0.5;
      side = 1;
    }
  }
  return glo == 0 ? lo : (ghi == 0 ? hi : lo - glo * (hi - lo) / (ghi - glo));
}

}  // namespace

RayCubic CellCubic(const CellCorners& c, const std::array<double, 3>& o,
                   const std::array<double, 3>& d, double iso) {
  // Weight of corner side 0 or 1 along an axis: u + t v.
  double u[3][2], v[3][2];
  for (int a = 0; a < 3; ++a) {
    u[a][0] = 1 - o[a];
    v[a][0] = -d[a];
    u[a][1] = o[a];
    v[a][1] = d[a];
  }
  RayCubic g;
  for (int k = 0; k < 2; ++k) {
    for (int j = 0; j < 2; ++j) {
      for (int i = 0; i < 2; ++i) {
        const double value = c[i + 2 * j + 4 * k];
        const double ux = u[0][i], vx = v[0][i], uy = u[1][j], vy = v[1][j], uz = u[2][k],
                     vz = v[2][k];
        g.d += value * ux * uy * uz;
        g.c += value * (vx * uy * uz + ux * vy * uz + ux * uy * vz);
        g.b += value * (vx * vy * uz + vx * uy * vz + ux * vy * vz);
        g.a += value * vx * vy * vz;
      }
    }
  }
  g.d -= iso;
  return g;
}

double Trilinear(const CellCorners& c, const std::array<double, 3>& p) {
  const double x = p[0], y = p[1], z = p[2];
  const double c00 = c[0] * (1 - x) + c[1] * x, c10 = c[2] * (1 - x) + c[3] * x;
  const double c01 = c[4] * (1 - x) + c[5] * x, c11 = c[6] * (1 - x) + c[7] * x;
  const double c0 = c00 * (1 - y) + c10 * y, c1 = c01 * (1 - y) + c11 * y;
  return c0 * (1 - z) + c1 * z;
}

std::optional<double> FirstRoot(const RayCubic& g, double t_begin, double t_end) {
  if (!(t_begin <= t_end)) return std::nullopt;  // also NaN
  double splits[2];
  const int n = SlopeRoots(g, t_begin, t_end, splits);
  double lo = t_begin, glo = g(lo);
  if (glo == 0) return lo;
  for (int i = 0; i <= n; ++i) {
    const double hi = i < n ? splits[i] : t_end;
    const double ghi = g(hi);
    if (ghi == 0) return hi;
    if ((ghi < 0) != (glo < 0)) return Refine(g, lo, glo, hi, ghi);
    lo = hi;
    glo = ghi;
  }
  return std::nullopt;
}

std::optional<double> FirstCrossing(const Scene& scene, const Vec3& origin, const Vec3& dir,
                                    double t_begin, double t_end, double iso) {
  if (!(t_begin <= t_end)) return std::nullopt;
  // The cell of the field holding the start: corners at voxel centres
  // base + 0.5 .. base + 1.5 along each axis.
  std::array<int, 3> base;
  std::array<double, 3> next;
  std::array<int, 3> step;
  // The t of the next plane between cells along axis a, from the plane
  // itself (never by adding up steps, whose rounding would depend on how
  // far the ray has come).
  auto plane_t = [&](int a) {
    const double plane = base[a] + 0.5 + (step[a] > 0 ? 1 : 0);
    return step[a] == 0 ? INFINITY : (plane - origin[a]) / dir[a];
  };
  const Vec3 start = origin + dir * t_begin;
  for (int a = 0; a < 3; ++a) {
    base[a] = static_cast<int>(std::floor(start[a] - 0.5));
    step[a] = dir[a] > 0 ? 1 : (dir[a] < 0 ? -1 : 0);
    next[a] = plane_t(a);
  }
  double t = t_begin;
  // A ray crosses at most this many cells between t_begin and t_end.
  const double span = (t_end - t_begin);
  const int max_cells =
      4 + static_cast<int>(std::min(1e6, span * (std::abs(dir.x) + std::abs(dir.y) + std::abs(dir.z))));
  for (int n = 0; n < max_cells && t <= t_end; ++n) {
    const double t_exit = std::min({next[0], next[1], next[2], t_end});
    CellCorners corners;
    for (int k = 0; k < 8; ++k) {
      corners[k] = scene.Scalar(base[0] + (k & 1), base[1] + ((k >> 1) & 1), base[2] + (k >> 2));
    }
    const std::array<double, 3> o = {origin.x - (base[0] + 0.5), origin.y - (base[1] + 0.5),
                                     origin.z - (base[2] + 0.5)};
    if (auto root = FirstRoot(CellCubic(corners, o, {dir.x, dir.y, dir.z}, iso), t, t_exit)) {
      return root;
    }
    if (t_exit >= t_end) break;
    // Into the next cell along the axis whose plane comes first (the lowest
    // axis on a tie, so that every node takes the same path).
    int a = 0;
    if (next[1] < next[a]) a = 1;
    if (next[2] < next[a]) a = 2;
    base[a] += step[a];
    t = std::max(t, next[a]);
    next[a] = plane_t(a);
  }
  return std::nullopt;
}

}  // namespace transtick
