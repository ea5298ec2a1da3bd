#include "transtick/isosurface.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#if defined(__SSE__)
#include <immintrin.h>
#endif

#include "transtick/traversal.h"

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

// The root of g in [lo, hi], where g(lo) and g(hi) differ in sign and g
// changes sign once: Newton's method from the secant point, kept inside the
// bracket (a step that would leave it bisects instead), for at most 64
// steps. It ends when a Newton step moves t by at most 1e-12 of the
// piece's length, so that the error left is of the order of that step's
// square, or when bisection has shrunk the bracket as far.
double RefineRoot(const RayCubic& g, double lo, double glo, double hi, double ghi) {
  const double tolerance = (hi - lo) * 1e-12;
  double t = lo - glo * (hi - lo) / (ghi - glo);
  if (!(t > lo && t < hi)) t = 0.5 * (lo + hi);
  for (int step = 0; step < 64; ++step) {
    const double gt = g(t);
    if (gt == 0) return t;
    if ((gt < 0) == (glo < 0)) {
      lo = t;
      glo = gt;
    } else {
      hi = t;
    }
    double next = t - gt / g.Slope(t);
    if (next > lo && next < hi) {
      if (std::abs(next - t) <= tolerance) return next;
    } else {
      // Newton left the bracket (or the slope vanished): bisect.
      next = 0.5 * (lo + hi);
      if (hi - lo <= 2 * tolerance) return next;
    }
    t = next;
  }
  return t;
}

}  // namespace

namespace {

// The cubic, in plain double arithmetic: what every build computes, the
// vector form below included.
TRANSTICK_INLINE RayCubic PortableCubic(const CellCorners& c, const std::array<double, 3>& o,
                                        const std::array<double, 3>& d, double iso) {
  // The interpolant along the ray, one axis at a time (Marmitt et al.):
  // along x each of the four edges (j, k) is linear in t, e = e0 + e1 t;
  // between the two edges of each z face it is quadratic, q = q0 + q1 t +
  // q2 t^2; between the two faces, cubic. About half the operations of
  // expanding the trilinear polynomial.
  double e[4][2];  // edge j + 2k
  for (int jk = 0; jk < 4; ++jk) {
    const double lo = c[2 * jk], delta = c[2 * jk + 1] - lo;
    e[jk][0] = lo + delta * o[0];
    e[jk][1] = delta * d[0];
  }
  double q[2][3];  // face k
  for (int k = 0; k < 2; ++k) {
    const double* a = e[2 * k];
    const double* b = e[2 * k + 1];
    const double u0 = b[0] - a[0], u1 = b[1] - a[1];
    q[k][0] = a[0] + u0 * o[1];
    q[k][1] = a[1] + (u0 * d[1] + u1 * o[1]);
    q[k][2] = u1 * d[1];
  }
  const double w0 = q[1][0] - q[0][0], w1 = q[1][1] - q[0][1], w2 = q[1][2] - q[0][2];
  RayCubic g;
  g.a = w2 * d[2];
  g.b = q[0][2] + (w1 * d[2] + w2 * o[2]);
  g.c = q[0][1] + (w0 * d[2] + w1 * o[2]);
  g.d = q[0][0] + w0 * o[2] - iso;
  return g;
}

// CellCubic, inlined where the walk solves a cell.
TRANSTICK_INLINE RayCubic Cubic(const CellCorners& c, const std::array<double, 3>& o,
                                const std::array<double, 3>& d, double iso) {
#if defined(__SSE2__)
  // The same operations in the same order, the two faces k in the two
  // lanes of a register: the same bits as PortableCubic, in about
  // half the instructions. Edge (j, k) runs from corner 2j + 4k to the next.
  const __m128 lo4 = _mm_loadu_ps(c.data()), hi4 = _mm_loadu_ps(c.data() + 4);
  const __m128 j0 = _mm_unpacklo_ps(lo4, hi4);  // c0 c4 c1 c5: edges j = 0
  const __m128 j1 = _mm_unpackhi_ps(lo4, hi4);  // c2 c6 c3 c7: edges j = 1
  const __m128d o0 = _mm_set1_pd(o[0]), d0 = _mm_set1_pd(d[0]);
  const __m128d o1 = _mm_set1_pd(o[1]), d1 = _mm_set1_pd(d[1]);
  const __m128d a_lo = _mm_cvtps_pd(j0),
                a_delta = _mm_sub_pd(_mm_cvtps_pd(_mm_movehl_ps(j0, j0)), a_lo);
  const __m128d b_lo = _mm_cvtps_pd(j1),
                b_delta = _mm_sub_pd(_mm_cvtps_pd(_mm_movehl_ps(j1, j1)), b_lo);
  const __m128d a0 = _mm_add_pd(a_lo, _mm_mul_pd(a_delta, o0)), a1 = _mm_mul_pd(a_delta, d0);
  const __m128d b0 = _mm_add_pd(b_lo, _mm_mul_pd(b_delta, o0)), b1 = _mm_mul_pd(b_delta, d0);
  const __m128d u0 = _mm_sub_pd(b0, a0), u1 = _mm_sub_pd(b1, a1);
  const __m128d q0 = _mm_add_pd(a0, _mm_mul_pd(u0, o1));  // q[k][0], lane k
  const __m128d q1 = _mm_add_pd(a1, _mm_add_pd(_mm_mul_pd(u0, d1), _mm_mul_pd(u1, o1)));
  const __m128d q2 = _mm_mul_pd(u1, d1);
  const __m128d face0 = _mm_unpacklo_pd(q0, q1);                   // q00 q01
  const __m128d w01 = _mm_sub_pd(_mm_unpackhi_pd(q0, q1), face0);  // w0 w1
  const __m128d w2 = _mm_sub_pd(_mm_shuffle_pd(q2, q2, 1), q2);    // w2 in lane 0
  const __m128d o2 = _mm_set1_pd(o[2]), d2 = _mm_set1_pd(d[2]);
  // g.c and g.b: q + (w d2 + w' o2), lanes (c, b).
  const __m128d cb =
      _mm_add_pd(_mm_shuffle_pd(face0, q2, 1),
                 _mm_add_pd(_mm_mul_pd(w01, d2), _mm_mul_pd(_mm_shuffle_pd(w01, w2, 1), o2)));
  RayCubic g;
  g.a = _mm_cvtsd_f64(w2) * d[2];
  g.b = _mm_cvtsd_f64(_mm_unpackhi_pd(cb, cb));
  g.c = _mm_cvtsd_f64(cb);
  g.d = _mm_cvtsd_f64(face0) + _mm_cvtsd_f64(w01) * o[2] - iso;
  return g;
#else
  return PortableCubic(c, o, d, iso);
#endif
}

}  // namespace

RayCubic CellCubic(const CellCorners& c, const std::array<double, 3>& o,
                   const std::array<double, 3>& d, double iso) {
  return Cubic(c, o, d, iso);
}

RayCubic PortableCellCubic(const CellCorners& c, const std::array<double, 3>& o,
                           const std::array<double, 3>& d, double iso) {
  return PortableCubic(c, o, d, iso);
}

double FieldAt(const Scene& scene, const Vec3& p) {
  const double q[3] = {p.x - 0.5, p.y - 0.5, p.z - 0.5};
  int i0[3];
  double f[3];
  for (int a = 0; a < 3; ++a) {
    i0[a] = static_cast<int>(std::floor(q[a]));
    f[a] = q[a] - i0[a];
  }
  double v = 0;
  for (int k = 0; k < 8; ++k) {
    const int dx = k & 1, dy = (k >> 1) & 1, dz = k >> 2;
    const double w = (dx ? f[0] : 1 - f[0]) * (dy ? f[1] : 1 - f[1]) * (dz ? f[2] : 1 - f[2]);
    v += w * scene.Scalar(i0[0] + dx, i0[1] + dy, i0[2] + dz);
  }
  return v;
}

int SideChanges(const RayCubic& g, double span, SideChange out[3]) {
  if (!(span >= 0)) return 0;  // also NaN
  double splits[2];
  const int n = SlopeRoots(g, 0, span, splits);
  int count = 0;
  double a = 0, ga = g(a);
  for (int k = 0; k <= n; ++k) {
    const double b = k < n ? splits[k] : span;
    const double gb = g(b);
    if ((ga < 0) != (gb < 0)) out[count++] = {RefineRoot(g, a, ga, b, gb), gb >= 0};
    a = b;
    ga = gb;
  }
  return count;
}

RayAxes::RayAxes(const Vec3& d) : direction(d) {
  for (int a = 0; a < 3; ++a) {
    const bool along = MovesAlong(d[a]);
    step[a] = along ? (d[a] > 0 ? 1 : -1) : 0;
    dir[a] = along ? d[a] : 0.0;
    inv[a] = along ? 1.0 / d[a] : 0.0;
  }
}

CrossingWalk::CrossingWalk(const Scene& scene, const Bands& bands, const Vec3& origin,
                           const RayAxes& axes, double t0, double t1, int band,
                           const WalkWork& work)
    : scene_(&scene),
      bands_(&bands),
      grid_(scene.field().empty() ? nullptr : &scene.field()),
      work_(work),
      origin_{origin.x, origin.y, origin.z},
      dir_(axes.dir),
      inv_(axes.inv),
      step_(axes.step),
      octant_(BrickMap::OctantOf(axes.step.data())),
      t1_(t1),
      t_(t0) {
  SetBand(band);
  start_ = band < 0;
  // The scalars the corners of a cell are read from (Load).
  const auto& dims = scene.dims();
  scalars_ = scene.scalars().data();
  scalar_y_begin_ = scene.scalar_y_begin();
  row_ = dims[0];
  plane_ = static_cast<ptrdiff_t>(dims[0]) * (scene.scalar_y_end() - scene.scalar_y_begin());
  corner_span_ = {static_cast<unsigned>(dims[0] - 1),
                  static_cast<unsigned>(scene.scalar_y_end() - scene.scalar_y_begin() - 1),
                  static_cast<unsigned>(dims[2] - 1)};
  for (int a = 0; a < 3; ++a) {
    // The face ahead of cell c and the one behind it: moving up, faces c
    // and c - 1; moving down, c - 1 and c.
    ahead_[a] = step_[a] < 0 ? -1 : 0;
    behind_[a] = step_[a] < 0 ? 0 : -1;
  }
  if (grid_) {
    grid_groups_ = grid_->group_data();
    grid_first_ = {0, grid_->row_begin(), 0};
    grid_count_ = grid_->cells();
    const auto& g = grid_->groups();
    group_stride_[0] = 1;
    group_stride_[1] = static_cast<size_t>(g[0]);
    group_stride_[2] = static_cast<size_t>(g[0]) * g[1];
    for (int a = 0; a < 3; ++a)
      group_step_[a] = step_[a] * static_cast<ptrdiff_t>(group_stride_[a]);
  }
  // The cells a ray can cross in [t0, t1): one more per unit it moves
  // along each axis, and a few for the ends.
  const double moves = std::abs(dir_[0]) + std::abs(dir_[1]) + std::abs(dir_[2]);
  const double span = t1 - t0;
  max_steps_ = 4 + static_cast<int>(span > 0 ? std::min(span * moves, 1e7) : 0);
  // The cell the ray is in at t0: every face crossed before t0 crossed.
  // Its span begins at the last of its entry faces, the time a walk from
  // earlier would have entered it.
  t_in_ = -std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (step_[a] == 0) {
      constexpr double kFar = 1 << 30;
      c_[a] = static_cast<int>(std::floor(std::clamp(origin_[a] + 0.5, -kFar, kFar)));
      leave_[a] = std::numeric_limits<double>::infinity();
    } else {
      t_in_ = std::max(t_in_, Land<false>(a, t0, &c_[a], &leave_[a]));
    }
  }
  SetExit();
}

template <bool kInclusive>
TRANSTICK_INLINE double CrossingWalk::Land(int a, double t, int* cell, double* leave_time) const {
  // The cell holding the point, then corrected by the face times
  // themselves, which rounding may put on the other side of t (by far less
  // than a cell: Tracer::Validate keeps origins within 1e9 voxels).
  constexpr double kFar = 1 << 30;  // beyond any volume; no overflow in c + 1
  const double p = origin_[a] + dir_[a] * t + 0.5;
  int c = static_cast<int>(std::floor(p > -kFar ? (p < kFar ? p : kFar) : -kFar));  // NaN: -kFar
  auto crossed = [t](double tk) { return kInclusive ? tk <= t : tk < t; };
  double leave = FaceTime(a, c + ahead_[a]);
  double enter = FaceTime(a, c + behind_[a]);
  if (crossed(leave)) {
    c += step_[a];
    enter = leave;
    leave = FaceTime(a, c + ahead_[a]);
  } else if (!crossed(enter)) {
    c -= step_[a];
    leave = enter;
    enter = FaceTime(a, c + behind_[a]);
  }
  *cell = c;
  *leave_time = leave;
  return enter;
}

TRANSTICK_INLINE void CrossingWalk::SetExit() {
  // The first of the exit times (the lowest axis on a tie, so that every
  // node takes the same path).
  int e = 0;
  if (leave_[1] < leave_[e]) e = 1;
  if (leave_[2] < leave_[e]) e = 2;
  exit_axis_ = e;
  t_out_ = leave_[e];
}

TRANSTICK_INLINE void CrossingWalk::Step() {
  // Scan's step, on the members: leaving a cell after its roots here costs
  // less than entering Scan to leave it (182 M instructions a 200x200 frame
  // against 185 M). Each time from its plane, never by adding up steps. The
  // new cell is entered across the face just left, so its span begins
  // there: that is the last of its entry faces, as a walk begun in it finds.
  const int a = exit_axis_;
  t_in_ = t_out_;
  c_[a] += step_[a];
  leave_[a] = FaceTime(a, c_[a] + ahead_[a]);
  SetExit();
  loaded_ = false;
  pending_ = -1;  // its time is never needed past the cell (NextRoot)
  if (work_.planes) Count(c_[1], work_.step);
}

TRANSTICK_INLINE void CrossingWalk::Count(int y, uint64_t units) {
  work_.planes[std::clamp(y, work_.y_begin, work_.y_end - 1) - work_.y_begin] += units;
}

TRANSTICK_INLINE void CrossingWalk::Load() {
  // Corner i + 2j + 4k is voxel (c - 1) + (i, j, k): away from the volume's
  // faces and the slab's last planes, four pairs from one pointer;
  // elsewhere clamped as Scene::Scalar does.
  const int x = c_[0] - 1, y = c_[1] - 1, z = c_[2] - 1;
  const bool inside = static_cast<unsigned>(x) < corner_span_[0] &&
                      static_cast<unsigned>(y - scalar_y_begin_) < corner_span_[1] &&
                      static_cast<unsigned>(z) < corner_span_[2];
#if defined(__SSE__)
  __m128 a, b;
  if (inside) {
    const float* p = scalars_ + z * plane_ + (y - scalar_y_begin_) * row_ + x;
    const float* q = p + plane_;
    a = _mm_loadh_pi(_mm_loadl_pi(_mm_setzero_ps(), reinterpret_cast<const __m64*>(p)),
                     reinterpret_cast<const __m64*>(p + row_));
    b = _mm_loadh_pi(_mm_loadl_pi(_mm_setzero_ps(), reinterpret_cast<const __m64*>(q)),
                     reinterpret_cast<const __m64*>(q + row_));
    _mm_storeu_ps(corners_.data(), a);
    _mm_storeu_ps(corners_.data() + 4, b);
  } else {
    scene_->Corners(x, y, z, corners_.data());
    a = _mm_loadu_ps(corners_.data());
    b = _mm_loadu_ps(corners_.data() + 4);
  }
  // Four lanes at a time (minps, maxps); a NaN corner gives a NaN or a
  // number here, and no root either way.
  __m128 mn = _mm_min_ps(a, b), mx = _mm_max_ps(a, b);
  mn = _mm_min_ps(mn, _mm_movehl_ps(mn, mn));
  mx = _mm_max_ps(mx, _mm_movehl_ps(mx, mx));
  mn = _mm_min_ss(mn, _mm_shuffle_ps(mn, mn, 1));
  mx = _mm_max_ss(mx, _mm_shuffle_ps(mx, mx, 1));
  lo_value_ = _mm_cvtss_f32(mn);
  hi_value_ = _mm_cvtss_f32(mx);
#else
  scene_->Corners(x, y, z, corners_.data());
  (void)inside;
  float mn = corners_[0], mx = corners_[0];
  for (int k = 1; k < 8; ++k) {
    mn = corners_[k] < mn ? corners_[k] : mn;
    mx = corners_[k] > mx ? corners_[k] : mx;
  }
  lo_value_ = mn;
  hi_value_ = mx;
#endif
  loaded_ = true;
  solved_ = false;
  cache_[0].edge = cache_[1].edge = -1;
  last_edge_ = -1;
  pending_ = -1;
  ++loads_;
  if (work_.planes) Count(c_[1], work_.cell);
}

int CrossingWalk::StartBand() {
  // The field at the ray's point, from the cell the walk is in (the point
  // kept in it against rounding), in double.
  if (grid_ && grid_->Holds(c_[0], c_[1], c_[2])) {
    const uint8_t label = grid_->Label(c_[0], c_[1], c_[2]);
    if (label != FieldGrid::kMixed) return label;
  }
  CellCorners k;
  scene_->Corners(c_[0] - 1, c_[1] - 1, c_[2] - 1, k.data());
  double f[3];
  for (int a = 0; a < 3; ++a) {
    f[a] = std::clamp(origin_[a] + dir_[a] * t_ - (c_[a] - 0.5), 0.0, 1.0);
  }
  double v = 0;
  double lo = k[0], hi = k[0];
  for (int i = 0; i < 8; ++i) {
    v += (i & 1 ? f[0] : 1 - f[0]) * (i & 2 ? f[1] : 1 - f[1]) * (i & 4 ? f[2] : 1 - f[2]) * k[i];
    lo = std::min<double>(lo, k[i]);
    hi = std::max<double>(hi, k[i]);
  }
  // Within the corners' range, as the field is, whatever the rounding: so
  // a cell's label and the band found in it agree.
  v = std::max(lo, std::min(hi, v));
  int band = 0;
  for (float e : bands_->edges()) band += e <= v;
  return band;
}

void CrossingWalk::Extend(double new_t1) {
  if (!(new_t1 > t1_)) return;
  const double moves = (new_t1 - t1_) * (std::abs(dir_[0]) + std::abs(dir_[1]) + std::abs(dir_[2]));
  max_steps_ += 4 + static_cast<int>(std::min(moves, 1e7));
  t1_ = new_t1;
  if (!at_end_) return;
  // The walk ended in its current cell: that cell's part grows. Its roots,
  // once read, are kept (one may have been taken already).
  at_end_ = done_ = false;
  if (loaded_) {
    hi_ = std::min(t_out_, t1_);
    state_ = State::kRoots;
  } else {
    state_ = State::kExamine;
  }
}

TRANSTICK_INLINE void CrossingWalk::Solve() {
  // The field along the ray in s = t - t_in, from the entry point in
  // cell coordinates, so that the coefficients stay well scaled however
  // far the ray's origin lies; and its Bernstein coefficients on
  // [0, span], whose hull holds the cubic there.
  const double span = t_out_ - t_in_;
  std::array<double, 3> entry;
#if defined(__SSE2__)
  // x and y in the two lanes, the same operations as z's.
  const __m128d corner =
      _mm_sub_pd(_mm_cvtepi32_pd(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(c_.data()))),
                 _mm_set1_pd(0.5));
  _mm_storeu_pd(entry.data(),
                _mm_sub_pd(_mm_add_pd(_mm_loadu_pd(origin_.data()),
                                      _mm_mul_pd(_mm_loadu_pd(dir_.data()), _mm_set1_pd(t_in_))),
                           corner));
  entry[2] = origin_[2] + dir_[2] * t_in_ - (c_[2] - 0.5);
#else
  for (int a = 0; a < 3; ++a) entry[a] = origin_[a] + dir_[a] * t_in_ - (c_[a] - 0.5);
#endif
  cubic_ = Cubic(corners_, entry, dir_, 0);
  const double p1 = cubic_.c * span, p2 = cubic_.b * span * span,
               p3 = cubic_.a * span * span * span;
  // The middle two times 3, so that no division waits on the hull test.
  hull_[0] = cubic_.d;
  hull_[1] = 3 * cubic_.d + p1;
  hull_[2] = 3 * cubic_.d + (2 * p1 + p2);
  hull_[3] = cubic_.d + p1 + p2 + p3;
  solved_ = true;
}

TRANSTICK_INLINE unsigned CrossingWalk::HullBelow(double e) const {
  // h - e < 0 is h < e, for every double and infinity (a difference rounds
  // to its sign, and is 0 only when the two are equal), and false for NaN.
  // The middle two are 3 times theirs, against 3e (exact: e is a float).
#if defined(__SSE2__)
  const __m128d v = _mm_set_sd(e), v3 = _mm_set_sd(3 * e);
  return static_cast<unsigned>(
      _mm_movemask_pd(_mm_cmplt_pd(_mm_loadu_pd(hull_), _mm_unpacklo_pd(v, v3))) |
      _mm_movemask_pd(_mm_cmplt_pd(_mm_loadu_pd(hull_ + 2), _mm_unpacklo_pd(v3, v))) << 2);
#else
  return static_cast<unsigned>(hull_[0] < e) | static_cast<unsigned>(hull_[1] < 3 * e) << 1 |
         static_cast<unsigned>(hull_[2] < 3 * e) << 2 | static_cast<unsigned>(hull_[3] < e) << 3;
#endif
}

TRANSTICK_INLINE bool CrossingWalk::HullStraddles(double e) const {
  // Some coefficients below e and some not: 1 .. 14.
  return HullBelow(e) - 1 < 14;
}

TRANSTICK_INLINE CrossingWalk::EdgeRoots& CrossingWalk::Roots(int edge) {
  // The two edges of a band differ in parity: one slot each.
  EdgeRoots& r = cache_[edge & 1];
  if (r.edge == edge) return r;
  const double span = t_out_ - t_in_;
  if (!solved_) Solve();
  const double e = bands_->edges()[edge];
  r.edge = edge;
  r.count = 0;
  r.refined = true;
  // Most cells whose corners straddle an edge are crossed by the ray
  // without a root: when every Bernstein coefficient lies on one side of
  // the edge, so does the cubic, and no extremum is needed.
  if (!HullStraddles(e)) return r;
  RayCubic g = cubic_;
  g.d -= e;
  // One change of sign among the coefficients, none of them 0, leaves the
  // cubic one simple root in the span (Bernstein polynomials diminish
  // variation): bracketed by the span's ends, with no extrema to find.
  const double b0 = hull_[0] - e, b1 = hull_[1] - 3 * e, b2 = hull_[2] - 3 * e, b3 = hull_[3] - e;
  const int changes = ((b0 < 0) != (b1 < 0)) + ((b1 < 0) != (b2 < 0)) + ((b2 < 0) != (b3 < 0));
  const double g_end = g(span);
  if (changes == 1 && b0 != 0 && b1 != 0 && b2 != 0 && b3 != 0 && (g.d < 0) != (g_end < 0)) {
    r.count = 1;
    r.refined = false;
    r.end = g_end;
    r.at[0].up = g_end >= 0;
    return r;
  }
  r.count = SideChanges(g, span, r.at);
  for (int k = 0; k < r.count; ++k) r.at[k].t += t_in_;
  return r;
}

TRANSTICK_INLINE void CrossingWalk::Refine(int edge) {
  EdgeRoots& r = cache_[edge & 1];
  if (r.refined) return;
  RayCubic g = cubic_;
  g.d -= bands_->edges()[edge];
  r.at[0].t = RefineRoot(g, 0, g.d, t_out_ - t_in_, r.end) + t_in_;
  r.refined = true;
}

TRANSTICK_INLINE void CrossingWalk::Settle() {
  if (pending_ < 0) return;
  Refine(pending_);
  t_ = cache_[pending_ & 1].at[0].t;
  pending_ = -1;
}

double CrossingWalk::t() {
  Settle();
  return t_;
}

TRANSTICK_INLINE std::optional<std::pair<double, int>> CrossingWalk::Candidate(int edge, bool up,
                                                                               bool defer) {
  EdgeRoots& r = Roots(edge);
  for (int k = 0; k < r.count; ++k) {
    if (r.at[k].up != up) continue;
    // One edge's roots alternate in direction: past the one just taken
    // by index, so that a double root (up and down at one t) is taken
    // twice. That needs no time; another edge's root is compared with t_.
    if (edge == last_edge_) {
      if (k <= last_index_) continue;
      Refine(edge);
      return std::pair{r.at[k].t, k};
    }
    if (!r.refined) {
      // The one root of this edge, inside the cell's span (see NextRoot).
      if (defer) return std::pair{std::numeric_limits<double>::quiet_NaN(), kDeferred};
      Refine(edge);
    }
    Settle();
    if (r.at[k].t >= t_) return std::pair{r.at[k].t, k};
  }
  return std::nullopt;
}

std::optional<Crossing> CrossingWalk::NextRoot() {
  // Band b lies between edge b - 1 below and edge b above. An edge the
  // corners do not straddle (lo < e <= hi) is not crossed in this cell.
  const int down = band_ - 1, up = band_;
  // An unrefined root lies in (t_in, t_in + span] (RefineRoot keeps to its
  // bracket, and rounding is monotonic). When the walk is at or before t_in
  // and that bound lies before t1 and within the cell, it is a crossing here
  // whatever its exact time, and the first unless the other edge has one:
  // its time can wait until asked (DeferTimes).
  const double span = t_out_ - t_in_;
  const bool defer =
      defer_ && pending_ < 0 && t_ <= t_in_ && t_out_ < t1_ && t_in_ + span <= t_out_;
  std::optional<std::pair<double, int>> best;
  bool best_up = false;
  if (Straddles(down_edge_, lo_value_, hi_value_)) best = Candidate(down, false, defer);
  if (Straddles(up_edge_, lo_value_, hi_value_)) {
    auto c = Candidate(up, true, defer);
    if (c && best) {
      // Two edges' roots: the first is taken, so both times are needed.
      for (auto* x : {&best, &c}) {
        if ((*x)->second != kDeferred) continue;
        const int edge = x == &best ? down : up;
        Refine(edge);
        **x = {cache_[edge & 1].at[0].t, 0};
      }
    }
    if (c && (!best || c->first < best->first)) best = c, best_up = true;
  }
  if (best && best->second == kDeferred) {
    last_edge_ = best_up ? up : down;
    last_index_ = 0;
    pending_ = last_edge_;
    ++deferred_;
    // Until refined, a bound below it: every later cell's span begins after
    // the root, so that Scan's start at max(t_in, t_) is the same.
    t_ = t_in_;
    SetBand(best_up ? Bands::Above(up) : Bands::Below(down));
    return Crossing{std::numeric_limits<double>::quiet_NaN(), band_, true};
  }
  // A root on the cell's far face is the cell's; one at t1 is the next
  // walk's.
  if (best && (best->first < hi_ || (best->first == hi_ && hi_ < t1_))) {
    t_ = best->first;
    last_edge_ = best_up ? up : down;
    last_index_ = best->second;
    SetBand(best_up ? Bands::Above(up) : Bands::Below(down));
    return Crossing{t_, band_, true};
  }
  return std::nullopt;
}

std::optional<Crossing> CrossingWalk::Next() {
  if (start_) {
    start_ = false;
    SetBand(StartBand());
    return Crossing{t_, band_, false};
  }
  while (!done_) {
    if (state_ == State::kRoots) {
      if (auto c = NextRoot()) return c;
      state_ = State::kLeave;
    }
    if (state_ == State::kLeave) {
      if (t_out_ >= t1_) {
        at_end_ = done_ = true;
        break;
      }
      if (++steps_ > max_steps_) {
        truncated_ = done_ = true;
        break;
      }
      Step();
      state_ = State::kExamine;
    }
    if (auto c = Scan()) return c;
  }
  return std::nullopt;
}

namespace {

// When a walk's ray leaves its cell across each axis's face ahead, which
// face it leaves by, and the face after each: a walk's steps from cell to
// cell are one chain of dependent operations (the exit face's time, the
// comparisons that find the next exit, the time of the face after it), so
// this keeps the times in registers and has each next face's time made one
// step early, off that chain. Every time is FaceTime's, (k + 0.5 - o) * (1 / d),
// from its plane k (k + 0.5 is kept exactly, whole numbers and halves
// being exact in double), and the exit is SetExit's, the lowest axis on a
// tie: the same bits and path as a walk computing them one at a time. An
// axis the ray does not move along leaves at +inf and is never the exit.
#if defined(__SSE2__)
class FaceClock {
 public:
  TRANSTICK_INLINE FaceClock(const std::array<double, 3>& origin, const std::array<double, 3>& inv,
                             const std::array<int, 3>& step)
      : o_xy_(_mm_loadu_pd(origin.data())),
        o_z_(_mm_load_sd(&origin[2])),
        i_xy_(_mm_loadu_pd(inv.data())),
        i_z_(_mm_load_sd(&inv[2])),
        s_xy_(_mm_cvtepi32_pd(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(step.data())))),
        s_z_(_mm_set_sd(step[2])) {}

  // The walk in cell c, whose faces ahead are c + ahead, leaving it at
  // leave (per axis).
  TRANSTICK_INLINE void Set(const double leave[3], const std::array<int, 3>& c,
                            const int ahead[3]) {
    l_xy_ = _mm_loadu_pd(leave);
    l_z_ = _mm_load_sd(&leave[2]);
    const __m128d half = _mm_set1_pd(0.5);
    p_xy_ = _mm_add_pd(
        _mm_add_pd(_mm_cvtepi32_pd(_mm_setr_epi32(c[0] + ahead[0], c[1] + ahead[1], 0, 0)), half),
        s_xy_);
    p_z_ = _mm_add_sd(_mm_add_sd(_mm_set_sd(c[2] + ahead[2]), half), s_z_);
    Next();
    Choose();
  }
  // Across the exit face into the next cell.
  TRANSTICK_INLINE void Advance() {
    l_xy_ = Select(m_xy_, n_xy_, l_xy_);
    l_z_ = Select(m_z_, n_z_, l_z_);
    p_xy_ = _mm_add_pd(p_xy_, _mm_and_pd(m_xy_, s_xy_));
    p_z_ = _mm_add_sd(p_z_, _mm_and_pd(m_z_, s_z_));
    Choose();
    Next();
  }
  TRANSTICK_INLINE void Store(double leave[3]) const {
    _mm_storeu_pd(leave, l_xy_);
    _mm_store_sd(&leave[2], l_z_);
  }
  int exit() const { return exit_; }
  double t_out() const { return t_out_; }

 private:
  static TRANSTICK_INLINE __m128d Select(__m128d mask, __m128d a, __m128d b) {
#if defined(__SSE4_1__)
    return _mm_blendv_pd(b, a, mask);
#else
    return _mm_or_pd(_mm_and_pd(mask, a), _mm_andnot_pd(mask, b));
#endif
  }
  // The face after the one ahead, along each axis.
  TRANSTICK_INLINE void Next() {
    n_xy_ = _mm_mul_pd(_mm_sub_pd(p_xy_, o_xy_), i_xy_);
    n_z_ = _mm_mul_sd(_mm_sub_sd(p_z_, o_z_), i_z_);
  }
  // The exit: y before x only when strictly sooner, z before both so,
  // the comparisons side by side (z before both is z before the sooner of
  // the two: no time is NaN), and the masks of its lanes. Only lane 0 of a
  // scalar comparison is a mask; lane 1 of the z registers stays 0.
  TRANSTICK_INLINE void Choose() {
    const __m128d l_y = _mm_unpackhi_pd(l_xy_, l_xy_);
    const __m128d before_x = _mm_cmplt_pd(_mm_shuffle_pd(l_xy_, l_z_, 1),  // (y, z) < (x, x)
                                          _mm_unpacklo_pd(l_xy_, l_xy_));
    const __m128d z_first =
        _mm_and_pd(_mm_unpackhi_pd(before_x, before_x), _mm_cmplt_sd(l_z_, l_y));
    const __m128d y_not_x = _mm_unpacklo_pd(
        _mm_andnot_pd(before_x, _mm_castsi128_pd(_mm_set1_epi32(-1))), before_x);  // (!y, y)
    m_xy_ = _mm_andnot_pd(_mm_unpacklo_pd(z_first, z_first), y_not_x);
    m_z_ = z_first;
    t_out_ = _mm_cvtsd_f64(Select(z_first, l_z_, Select(before_x, l_y, l_xy_)));
    const int y = _mm_movemask_pd(before_x) & 1, z = _mm_movemask_pd(z_first) & 1;
    exit_ = z ? 2 : y;
  }

  const __m128d o_xy_, o_z_, i_xy_, i_z_, s_xy_, s_z_;  // origin, 1 / d, step (per axis)
  __m128d l_xy_, l_z_;  // when the ray leaves the cell along each axis
  __m128d p_xy_, p_z_;  // the plane after the one ahead, + 0.5
  __m128d n_xy_, n_z_;  // when it crosses that plane
  __m128d m_xy_, m_z_;  // all ones on the exit axis
  int exit_ = 0;
  double t_out_ = 0;
};
#endif

// FaceClock in plain double arithmetic, one axis at a time: what a
// processor without SSE2 runs, and the reference the tests hold the vector
// form to.
class PortableFaceClock {
 public:
  PortableFaceClock(const std::array<double, 3>& origin, const std::array<double, 3>& inv,
                    const std::array<int, 3>& step)
      : origin_(origin), inv_(inv), step_(step) {}
  void Set(const double leave[3], const std::array<int, 3>& c, const int ahead[3]) {
    for (int a = 0; a < 3; ++a) {
      leave_[a] = leave[a];
      plane_[a] = c[a] + ahead[a];
    }
    Choose();
  }
  void Advance() {
    const int a = exit_;
    plane_[a] += step_[a];
    leave_[a] = (plane_[a] + 0.5 - origin_[a]) * inv_[a];
    Choose();
  }
  void Store(double leave[3]) const {
    for (int a = 0; a < 3; ++a) leave[a] = leave_[a];
  }
  int exit() const { return exit_; }
  double t_out() const { return t_out_; }

 private:
  void Choose() {
    const double l01 = leave_[1] < leave_[0] ? leave_[1] : leave_[0];
    const int e01 = leave_[1] < leave_[0] ? 1 : 0;
    exit_ = leave_[2] < l01 ? 2 : e01;
    t_out_ = leave_[2] < l01 ? leave_[2] : l01;
  }
  const std::array<double, 3> origin_, inv_;
  const std::array<int, 3> step_;
  double leave_[3];
  int plane_[3];  // the face ahead along each axis
  int exit_ = 0;
  double t_out_ = 0;
};
#if !defined(__SSE2__)
using FaceClock = PortableFaceClock;
#endif

}  // namespace

std::optional<Crossing> CrossingWalk::Scan() {
  // The walk's state in locals while it moves (written back whenever it
  // stops), so that it stays in registers.
  std::array<int, 3> c = c_;
  FaceClock clock(origin_, inv_, step_);
  clock.Set(leave_, c, ahead_);
  double t_in = t_in_;
  int steps = steps_;
  bool loaded = false;  // the current cell's corners were read
  auto stop = [&] {
    c_ = c;
    clock.Store(leave_);
    t_in_ = t_in;
    t_out_ = clock.t_out();
    exit_axis_ = clock.exit();
    steps_ = steps;
    loaded_ = loaded;
  };
  // The walk's constants, read once: no store in the loop below may alias
  // them, so they stay in registers.
  const double t1 = t1_, t_here = t_;
  const int max_steps = max_steps_;
  const int band = label_band_;
  const int octant = octant_;
  const FieldGrid::Group* const groups = grid_groups_;
  // A group all of the ray's band has these eight labels (none can match
  // a ray without a band's label: a group all kMixed reaches nowhere).
  const uint64_t all_band = band >= 0 ? 0x0101010101010101ull * static_cast<uint64_t>(band) : ~0ull;
  uint64_t* const planes = work_.planes;
  // While the cell is in the grid: its group's index and its place there.
  size_t gi = 0;
  int sub = 0;
  bool held = false;
  auto locate = [&] {
    // FieldGrid::Holds, GroupIndex and Sub, without branches, from the
    // walk's copies of the grid's shape (no grid: no cell is held).
    const unsigned x = c[0] - grid_first_[0], y = c[1] - grid_first_[1], z = c[2] - grid_first_[2];
    held = x < static_cast<unsigned>(grid_count_[0]) && y < static_cast<unsigned>(grid_count_[1]) &&
           z < static_cast<unsigned>(grid_count_[2]);
    gi = (z >> 1) * group_stride_[2] + (y >> 1) * group_stride_[1] + (x >> 1);
    sub = static_cast<int>((x & 1) | (y & 1) << 1 | (z & 1) << 2);
  };
  locate();
  for (;;) {
    // The cell's part of [t0, t1): [from, to), and its far face when that
    // lies before t1. A cell the ray only touches at an edge or a corner
    // (t_in = t_out) has none.
    const double t_out = clock.t_out();
    const double from = std::max(t_in, t_here), to = std::min(t_out, t1);
    bool mixed = true;
    if (held) {
      const FieldGrid::Group& group = groups[gi];
      uint64_t labels;
      std::memcpy(&labels, group.label, sizeof(labels));
      int r;
      if (labels == all_band && (r = group.reach[octant]) > 0) {
        // A box of groups of the ray's band ahead (its reach toward the
        // ray's octant): nothing in it. On past it, or to t1 when it
        // reaches that far. (A box of one group holds a few cells: they
        // are stepped.)
        if (++steps > max_steps) {
          stop();
          truncated_ = done_ = true;
          return std::nullopt;
        }
        // The face it leaves by (cells [lo, hi) lie between faces lo - 1
        // and hi - 1), the lowest axis on a tie.
        double t = std::numeric_limits<double>::infinity();
        int out = 0, face = 0;
        for (int a = 0; a < 3; ++a) {
          if (step_[a] == 0) continue;
          const int g = (c[a] - grid_first_[a]) >> 1;
          const int f = grid_first_[a] + (step_[a] > 0 ? std::min((g + r + 1) << 1, grid_count_[a]) - 1
                                                       : (std::max(g - r, 0) << 1) - 1);
          const double ta = FaceTime(a, f);
          if (ta < t) t = ta, out = a, face = f;
        }
        if (!(t < t1)) {
          stop();
          at_end_ = done_ = true;
          return std::nullopt;
        }
        // Every face crossed up to t, the box's own included: the cell a
        // walk stepping cell by cell would be in after leaving the box,
        // entered at t.
        double leave[3];
        clock.Store(leave);
        for (int a = 0; a < 3; ++a) {
          if (a == out) {
            c[a] = face - ahead_[a] + step_[a];
            leave[a] = FaceTime(a, c[a] + ahead_[a]);
          } else if (step_[a] != 0) {
            Land<true>(a, t, &c[a], &leave[a]);
          }
        }
        t_in = t;
        clock.Set(leave, c, ahead_);
        ++jumps_;
        if (planes) Count(c[1], work_.step);
        locate();
        continue;
      }
      const uint8_t label = group.label[sub];
      if (label == band) {
        mixed = false;  // nothing to find here
      } else if (label != FieldGrid::kMixed) {
        mixed = false;
        if (t_in < t_out && from < to) {
          // All of one band, not the ray's: the ray takes it here.
          stop();
          SetBand(label);
          t_ = from;
          last_edge_ = -1;
          state_ = State::kLeave;
          return Crossing{from, band_, false};
        }
      }
    }
    if (mixed && t_in < t_out && (from < to || (from == t_out && t_out < t1))) {
      // A cell whose roots to look for: the walk stops only at one.
      c_ = c;
      t_in_ = t_in;
      t_out_ = t_out;
      Load();
      loaded = true;
      hi_ = to;
      // Most such cells hold no root of the edges next to the ray's band:
      // the hull of the cubic says so here, without NextRoot's search.
      const bool down = Straddles(down_edge_, lo_value_, hi_value_);
      const bool up = Straddles(up_edge_, lo_value_, hi_value_);
      // One branch on both edges' hull tests: which way it goes is hard to
      // foretell.
      bool look = false;
      if (down || up) {
        Solve();
        look = (down & HullStraddles(down_edge_)) | (up & HullStraddles(up_edge_));
      }
      if (look) {
        if (auto crossing = NextRoot()) {
          stop();
          state_ = State::kRoots;
          return crossing;
        }
      }
    }
    // On to the next cell, across the face the ray leaves by: its span
    // begins there, the last of its entry faces, as a walk begun in it
    // finds. Each time from its plane, never by adding up steps.
    if (t_out >= t1) {
      stop();
      at_end_ = done_ = true;
      return std::nullopt;
    }
    if (++steps > max_steps) {
      stop();
      truncated_ = done_ = true;
      return std::nullopt;
    }
    const int a = clock.exit();
    t_in = t_out;
    c[a] += step_[a];
    clock.Advance();
    loaded = false;
    if (held) {
      // Into the next group when the new cell is its first along a.
      const int local = c[a] - grid_first_[a];
      sub ^= 1 << a;
      gi += group_step_[a] & -static_cast<ptrdiff_t>(((local ^ ahead_[a]) & 1) == 0);
      held = static_cast<unsigned>(local) < static_cast<unsigned>(grid_count_[a]);
    } else {
      locate();
    }
    if (planes) Count(c[1], work_.step);
  }
}

std::vector<FaceStep> FaceSteps(const Vec3& origin, const RayAxes& axes,
                                const std::array<int, 3>& cell, int steps, bool portable) {
  const std::array<double, 3> o = {origin.x, origin.y, origin.z};
  double leave[3];
  int ahead[3];
  for (int a = 0; a < 3; ++a) {
    ahead[a] = axes.step[a] < 0 ? -1 : 0;
    leave[a] = axes.step[a] == 0 ? std::numeric_limits<double>::infinity()
                                 : (cell[a] + ahead[a] + 0.5 - o[a]) * axes.inv[a];
  }
  std::vector<FaceStep> out;
  auto walk = [&](auto& clock) {
    clock.Set(leave, cell, ahead);
    for (int k = 0; k < steps; ++k) {
      out.push_back({clock.exit(), clock.t_out()});
      clock.Advance();
    }
  };
  if (portable) {
    PortableFaceClock clock(o, axes.inv, axes.step);
    walk(clock);
  } else {
    FaceClock clock(o, axes.inv, axes.step);
    walk(clock);
  }
  return out;
}

}  // namespace transtick
