// Where a ray first meets an isosurface of the trilinear field inside one
// cell: the exact root of a cubic, after Marmitt et al., "Fast and Accurate
// Ray-Voxel Intersection Techniques for Iso-Surface Ray Tracing" (2004).
//
// A cell spans [0, 1]^3 between the eight samples at its corners; along a
// ray p(t) = o + t d the interpolant is a cubic in t. Its extrema split
// [t_begin, t_end] into pieces on which it is monotonic; the first piece
// whose ends differ in sign around the threshold holds the first root,
// which a bounded number of safeguarded Newton steps then pin down. No
// fixed step: a thin feature between two samples of the ray is not missed.
//
// A pure function of its arguments in double precision, with a fixed
// sequence of operations: every node that solves the same cell for the
// same ray gets the same bits.
#ifndef TRANSTICK_ISOSURFACE_H_
#define TRANSTICK_ISOSURFACE_H_

#include <array>
#include <optional>

#include "transtick/classification.h"
#include "transtick/scene.h"
#include "transtick/vec.h"

namespace transtick {

// f(t) - iso = a t^3 + b t^2 + c t + d along the ray.
struct RayCubic {
  double a = 0, b = 0, c = 0, d = 0;
  double operator()(double t) const { return ((a * t + b) * t + c) * t + d; }
  double Slope(double t) const { return (3 * a * t + 2 * b) * t + c; }
};

// The corners' values, indexed x + 2y + 4z (corner (1, 0, 1) is 5).
using CellCorners = std::array<float, 8>;

// The cubic of `corners` minus `iso` along o + t d, in the cell's own
// coordinates (o need not lie in the cell).
RayCubic CellCubic(const CellCorners& corners, const std::array<double, 3>& o,
                   const std::array<double, 3>& d, double iso);

// The trilinear field of `scene`'s scalars at index-space point p, in
// double: samples at voxel centres, indices clamped at the faces (what
// Tracer::Sample reads, without its float rounding, and what the cubics
// describe). A reference for tests and benchmarks.
// REQUIRES: the planes around p are stored.
double FieldAt(const Scene& scene, const Vec3& p);

// Where a cubic changes side between g < 0 and g >= 0 (a value of 0 is on
// the side >= 0, as a value on an edge is in the band above).
struct SideChange {
  double t;
  bool up;  // into g >= 0
};

// Every change of side of g in [0, span], in increasing t; returns how many
// (at most three). The cubic's extrema split [0, span] into monotonic
// pieces; a piece whose ends lie on different sides holds one change,
// which Newton steps from the secant point refine (bisection when a step
// would leave the piece; at most 64 steps, until a step moves t by at most
// 1e-12 of the piece). No fixed step: a thin feature between any
// two samples is found. A pure function of its arguments with a fixed
// sequence of operations.
int SideChanges(const RayCubic& g, double span, SideChange out[3]);

// Where a ray's field changes band (classification.h, Bands): at t the
// field crosses an interval edge and the ray enters `band`.
struct Crossing {
  double t;
  int band;
};

// The crossings a ray meets in [t0, t1), in order, as the band it is in
// changes: from band b the next crossing is the first root, at or after
// where the ray is, of edge b - 1 going down or edge b going up (a value
// exactly on an edge belongs to the band above, as in Bands::Of). The walk
// goes through the cells of the field (corners at voxel centres, clamped at
// the volume's faces, as Tracer::Sample reads it) that the ray crosses.
//
// Each cell's roots are those of its cubic over the cell's whole span
// [t_in, t_out] along the ray (SideChanges): a function of the ray and the cell's eight samples
// only, the same for every node and every segment that touches the cell.
// So the crossings a ray meets do not depend on how its walk is cut into
// segments or slabs, as long as each piece starts in the band the last
// ended in.
//
//   CrossingWalk walk(scene, bands, origin, dir, t0, t1, band);
//   while (auto c = walk.Next()) { ... c->t, c->band ... }
//
// A value type made per segment on the stack. Not thread-safe; the scene
// and bands must outlive it.
// REQUIRES: the scalar planes the cells touch are stored in `scene` (a
// slab's own planes and one ghost plane each side), band < bands.size().
// A ray's direction as a walk steps along it, made once per ray: per axis
// the step (-1, 0 or +1), the component (0 on an axis the ray does not move
// along, as MovesAlong says) and its reciprocal (0 there too).
struct RayAxes {
  explicit RayAxes(const Vec3& direction);
  Vec3 direction;  // as given
  std::array<int, 3> step;
  std::array<double, 3> dir;
  std::array<double, 3> inv;
};

class CrossingWalk {
 public:
  CrossingWalk(const Scene& scene, const Bands& bands, const Vec3& origin, const Vec3& dir,
               double t0, double t1, int band)
      : CrossingWalk(scene, bands, origin, RayAxes(dir), t0, t1, band) {}
  // The same walk, with the ray's axes made once for all its walks.
  CrossingWalk(const Scene& scene, const Bands& bands, const Vec3& origin, const RayAxes& axes,
               double t0, double t1, int band);

  std::optional<Crossing> Next();

  // Goes on past t1 to a new end: the crossings of [t1, new_t1) follow as
  // a walk started at t1 in the band the last crossing entered would give
  // them, but the cell the walk is in keeps its solved roots (consecutive
  // segments of a ray share the cells across the planes between them).
  // REQUIRES: new_t1 >= t1(), and every crossing before t1 was taken.
  void Extend(double new_t1);
  double t1() const { return t1_; }
  // The cells of the field the walk has entered so far.
  int cells() const { return cells_; }

 private:
  // The roots of one edge in the current cell, in increasing t.
  struct EdgeRoots {
    int edge = -1;
    int count = 0;
    SideChange at[3];  // t along the ray
  };
  bool EnterCell();    // sets up the current cell; false when the walk is done
  bool AdvanceCell();  // to the next cell; false when the walk is done
  void Step(int axis);  // base_ one cell along `axis`, and its plane times
  // When the ray crosses the plane between voxel centres k + 0.5.
  double PlaneTime(int axis, int k) const { return (k + 0.5 - origin_[axis]) * inv_[axis]; }
  const EdgeRoots& Roots(int edge);
  // The first root of `edge` going `up` at or after t_, past the root just
  // taken when it is this edge's.
  std::optional<std::pair<double, int>> Candidate(int edge, bool up);

  const Scene* scene_;
  const Bands* bands_;
  Vec3 origin_;
  std::array<double, 3> dir_;
  std::array<double, 3> inv_;  // 1 / dir_, 0 where the ray does not move
  std::array<int, 3> step_;
  double t1_;
  int max_cells_;
  int cells_ = 0;
  bool done_ = false;
  bool at_end_ = false;  // done because the current cell reaches past t1
  bool loaded_ = false;  // the current cell's corners are read
  int band_;
  double t_;               // where the ray is: crossings before it are behind
  int last_edge_ = -1;     // the edge of the crossing just taken, in this cell
  int last_index_ = -1;    // and its index among that edge's roots
  // The current cell.
  std::array<int, 3> base_;
  // Along each axis, when the ray enters and leaves the cell's slab
  // (-inf and inf on an axis it does not move along).
  double enter_[3], leave_[3];
  double t_in_ = 0, t_out_ = 0, hi_ = 0;  // its span, and the end of its part in [t0, t1)
  int exit_axis_ = -1;
  float lo_value_ = 0, hi_value_ = 0;  // its corners' least and greatest value
  bool solved_ = false;                // cubic_ and hull_ are set
  RayCubic cubic_;                     // the field along the ray, s = t - t_in
  double hull_[4];                     // its Bernstein coefficients on [0, t_out - t_in]
  CellCorners corners_;
  EdgeRoots cache_[2];
};

}  // namespace transtick

#endif  // TRANSTICK_ISOSURFACE_H_
