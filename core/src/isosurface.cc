#include "transtick/isosurface.h"

#include <algorithm>
#include <cmath>
#include <limits>

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
// is monotonic: Newton's method from the secant point, kept inside the
// bracket (a step that would leave it bisects instead), for at most 64
// steps. It ends when a Newton step moves t by at most 1e-12 of the
// piece's length, so that the error left is of the order of that step's
// square, or when bisection has shrunk the bracket as far.
double Refine(const RayCubic& g, double lo, double glo, double hi, double ghi) {
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

RayCubic CellCubic(const CellCorners& c, const std::array<double, 3>& o,
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
    if ((ga < 0) != (gb < 0)) out[count++] = {Refine(g, a, ga, b, gb), gb >= 0};
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
                           const RayAxes& axes, double t0, double t1, int band)
    : scene_(&scene),
      bands_(&bands),
      origin_(origin),
      dir_(axes.dir),
      inv_(axes.inv),
      step_(axes.step),
      t1_(t1),
      band_(band),
      t_(t0) {
  const Vec3 start = origin + axes.direction * t0;
  double moves = 0;
  for (int a = 0; a < 3; ++a) {
    moves += std::abs(dir_[a]);
    // The cell of the field holding the start: corners at voxel centres
    // base + 0.5 and base + 1.5; base runs from -1 to dims - 1 inside the
    // volume (the half cells at the faces). Clamped only against overflow:
    // beyond the faces the corners clamp as the field does.
    base_[a] = FloorClamped(start[a] - 0.5, -(1 << 30), 1 << 30);
  }
  for (int a = 0; a < 3; ++a) {
    if (step_[a] == 0) {
      enter_[a] = -std::numeric_limits<double>::infinity();
      leave_[a] = std::numeric_limits<double>::infinity();
    } else {
      enter_[a] = PlaneTime(a, step_[a] > 0 ? base_[a] : base_[a] + 1);
      leave_[a] = PlaneTime(a, step_[a] > 0 ? base_[a] + 1 : base_[a]);
    }
  }
  // The cells a ray can cross in [t0, t1): one more per unit it moves
  // along each axis, and a few for the ends.
  const double span = t1 - t0;
  max_cells_ = 4 + static_cast<int>(span > 0 ? std::min(span * moves, 1e7) : 0);
  // An empty segment (a ray through an edge or a corner of its column)
  // holds no crossing, but a walk extended from it must go on as one begun
  // at t0 with the new end would: done at its end, with no cell entered.
  at_end_ = !(t0 < t1);
  done_ = at_end_ || !EnterCell();
}

bool CrossingWalk::EnterCell() {
  for (;;) {
    if (++cells_ > max_cells_) return false;
    // The cell's span along the ray: the last of the entry times of the
    // axes the ray moves on, the first of their exit times (the lowest axis
    // on a tie, so that every node takes the same path).
    const double t_in = std::max({enter_[0], enter_[1], enter_[2]});
    int exit_axis = 0;
    if (leave_[1] < leave_[exit_axis]) exit_axis = 1;
    if (leave_[2] < leave_[exit_axis]) exit_axis = 2;
    const double t_out = leave_[exit_axis];
    if (step_[exit_axis] == 0) return false;  // a ray along no axis
    t_in_ = t_in;
    t_out_ = t_out;
    exit_axis_ = exit_axis;
    const double lo = std::max(t_in, t_), hi = std::min(t_out, t1_);
    // A cell the ray only touches at an edge or a corner (t_in = t_out)
    // holds no root of its own; the walk goes on through it.
    if (t_in < t_out && lo < hi) {
      scene_->Corners(base_[0], base_[1], base_[2], corners_.data());
      // Branch-free (minss, maxss): which corner is least is random.
      float mn = corners_[0], mx = corners_[0];
      for (int k = 1; k < 8; ++k) {
        mn = corners_[k] < mn ? corners_[k] : mn;
        mx = corners_[k] > mx ? corners_[k] : mx;
      }
      lo_value_ = mn;
      hi_value_ = mx;
      hi_ = hi;
      loaded_ = true;
      solved_ = false;
      cache_[0].edge = cache_[1].edge = -1;
      last_edge_ = -1;
      return true;
    }
    loaded_ = false;
    if (t_out >= t1_) {
      at_end_ = true;
      return false;
    }
    Step(exit_axis);
  }
}

void CrossingWalk::Step(int a) {
  // Each time from its plane between voxel centres, never by adding up
  // steps: the entry plane is the exit plane the ray just crossed.
  base_[a] += step_[a];
  enter_[a] = leave_[a];
  leave_[a] = PlaneTime(a, step_[a] > 0 ? base_[a] + 1 : base_[a]);
}

void CrossingWalk::Extend(double new_t1) {
  if (!(new_t1 > t1_)) return;
  const double old_t1 = t1_;
  t1_ = new_t1;
  const double moves = (new_t1 - old_t1) * (std::abs(dir_[0]) + std::abs(dir_[1]) + std::abs(dir_[2]));
  max_cells_ += 4 + static_cast<int>(std::min(moves, 1e7));
  if (!done_) {
    hi_ = std::min(t_out_, t1_);
  } else if (at_end_) {
    done_ = false;
    at_end_ = false;
    if (loaded_ && old_t1 < t_out_) {
      // The current cell goes on into the new part: its roots up to the
      // new end become eligible.
      hi_ = std::min(t_out_, t1_);
    } else if (loaded_) {
      done_ = !AdvanceCell();
    } else {
      // The same cell again, now with a part before the new end (none yet
      // when the walk began empty).
      if (cells_ > 0) --cells_;
      done_ = !EnterCell();
    }
  }
}

bool CrossingWalk::AdvanceCell() {
  if (t_out_ >= t1_) {
    at_end_ = true;
    return false;
  }
  loaded_ = false;
  Step(exit_axis_);
  return EnterCell();
}

const CrossingWalk::EdgeRoots& CrossingWalk::Roots(int edge) {
  // The two edges of a band differ in parity: one slot each.
  EdgeRoots& r = cache_[edge & 1];
  if (r.edge == edge) return r;
  const double span = t_out_ - t_in_;
  if (!solved_) {
    // The field along the ray in s = t - t_in, from the entry point in
    // cell coordinates, so that the coefficients stay well scaled however
    // far the ray's origin lies; and its Bernstein coefficients on
    // [0, span], whose hull holds the cubic there.
    const Vec3 p = origin_ + Vec3{dir_[0], dir_[1], dir_[2]} * t_in_;
    const std::array<double, 3> entry = {p.x - (base_[0] + 0.5), p.y - (base_[1] + 0.5),
                                         p.z - (base_[2] + 0.5)};
    cubic_ = CellCubic(corners_, entry, dir_, 0);
    const double p1 = cubic_.c * span, p2 = cubic_.b * span * span,
                 p3 = cubic_.a * span * span * span;
    hull_[0] = cubic_.d;
    hull_[1] = cubic_.d + p1 / 3;
    hull_[2] = cubic_.d + (2 * p1 + p2) / 3;
    hull_[3] = cubic_.d + p1 + p2 + p3;
    solved_ = true;
  }
  const double e = bands_->edges()[edge];
  r.edge = edge;
  r.count = 0;
  // Most cells whose corners straddle an edge are crossed by the ray
  // without a root: when every Bernstein coefficient lies on one side of
  // the edge, so does the cubic, and no extremum is needed.
  const bool below = hull_[0] - e < 0;
  if ((hull_[1] - e < 0) == below && (hull_[2] - e < 0) == below && (hull_[3] - e < 0) == below) {
    return r;
  }
  RayCubic g = cubic_;
  g.d -= e;
  r.count = SideChanges(g, span, r.at);
  for (int k = 0; k < r.count; ++k) r.at[k].t += t_in_;
  return r;
}

std::optional<std::pair<double, int>> CrossingWalk::Candidate(int edge, bool up) {
  const EdgeRoots& r = Roots(edge);
  for (int k = 0; k < r.count; ++k) {
    if (r.at[k].up != up) continue;
    // One edge's roots alternate in direction: past the one just taken
    // by index, so that a double root (up and down at one t) is taken twice.
    if (edge == last_edge_ ? k > last_index_ : r.at[k].t >= t_) return std::pair{r.at[k].t, k};
  }
  return std::nullopt;
}

std::optional<Crossing> CrossingWalk::Next() {
  const std::vector<float>& edges = bands_->edges();
  while (!done_) {
    // Band b lies between edge b - 1 below and edge b above. An edge the
    // corners do not straddle (lo < e <= hi) is not crossed in this cell.
    const int down = band_ - 1, up = band_;
    std::optional<std::pair<double, int>> best;
    bool best_up = false;
    if (down >= 0 && edges[down] > lo_value_ && edges[down] <= hi_value_) {
      best = Candidate(down, false);
    }
    if (up < static_cast<int>(edges.size()) && edges[up] > lo_value_ && edges[up] <= hi_value_) {
      auto c = Candidate(up, true);
      if (c && (!best || c->first < best->first)) best = c, best_up = true;
    }
    // A root on the cell's far plane is the cell's; one at t1 is the next
    // segment's.
    if (best && (best->first < hi_ || (best->first == hi_ && hi_ < t1_))) {
      t_ = best->first;
      last_edge_ = best_up ? up : down;
      last_index_ = best->second;
      band_ = best_up ? Bands::Above(up) : Bands::Below(down);
      return Crossing{t_, band_};
    }
    done_ = !AdvanceCell();
  }
  return std::nullopt;
}

}  // namespace transtick
