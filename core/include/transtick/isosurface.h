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
#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <vector>

#include "transtick/classification.h"
#include "transtick/field_grid.h"
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
// The same in plain double arithmetic, without the vector instructions
// CellCubic may use: bit for bit the same (the nodes of one cluster may be
// built for different processors). For tests.
RayCubic PortableCellCubic(const CellCorners& corners, const std::array<double, 3>& o,
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

// The faces a walk from `cell` crosses, one a step: the axis of each (the
// lowest on a tie) and its time, each from its plane. What CrossingWalk's
// vector registers compute or, with `portable`, the same in plain double
// arithmetic, bit for bit alike. For tests.
struct FaceStep {
  int axis;
  double t;
};
std::vector<FaceStep> FaceSteps(const Vec3& origin, const RayAxes& axes,
                                const std::array<int, 3>& cell, int steps, bool portable);

// Where a ray's band changes: at t the ray enters `band`. Most are roots,
// where the field crosses an interval edge. The others (root false) take
// the band the field has where the walk found the ray in another: at the
// start of a ray that has no band yet, or in a cell all of one band that
// is not the ray's (rounding at a crossing just before it).
struct Crossing {
  double t;
  int band;
  bool root = true;
};

// Where a walk adds its work, per plane of a slab (TraceCounters::plane_work
// in tracer.h): `step` units per cell stepped into or box jumped, `cell`
// more per cell whose corners it reads.
struct WalkWork {
  uint64_t* planes = nullptr;  // planes[y - y_begin]; null: not counted
  int y_begin = 0;
  int y_end = 0;
  uint64_t step = 0;
  uint64_t cell = 0;
};

// The crossings a ray meets in [t0, t1), in order, as the band it is in
// changes: from band b the next crossing is the first root, at or after
// where the ray is, of edge b - 1 going down or edge b going up (a value
// exactly on an edge belongs to the band above, as in Bands::Of). The walk
// goes through the cells of the field (field_grid.h: corners at voxel
// centres, clamped at the volume's faces, as Tracer::Sample reads them)
// that the ray crosses, in the order of the times it crosses their faces
// (the lowest axis first on a tie), each time computed from its plane.
//
// Each cell's roots are those of its cubic over the cell's whole span
// [t_in, t_out] along the ray (SideChanges): a function of the ray and the
// cell's eight samples only. A root on a cell's far face is the cell's; one
// at t1 is left to whoever walks on from t1. A walk begun at t (a new node,
// a new segment) starts in the cell the walk from earlier would be in at
// t: the one whose faces crossed before t are exactly the planes crossed
// before t. So the crossings a ray meets do not depend on where its walk is
// cut, as long as each piece starts in the band the last ended in. The
// scene's FieldGrid only lets the walk jump boxes of cells of the ray's
// band, where it would find nothing (field_grid.h).
//
//   CrossingWalk walk(scene, bands, origin, dir, t0, t1, band);
//   while (auto c = walk.Next()) { ... c->t, c->band ... }
//
// A value type made per ray on the stack. Not thread-safe; the scene and
// bands must outlive it.
// REQUIRES: the scalar planes the cells touch are stored in `scene` (a
// slab's own planes and one ghost plane each side), band < bands.size().
class CrossingWalk {
 public:
  // `band` is the band the ray is in at t0, or -1 when it has none yet:
  // the first crossing is then the field's band at t0 (root false).
  CrossingWalk(const Scene& scene, const Bands& bands, const Vec3& origin, const Vec3& dir,
               double t0, double t1, int band)
      : CrossingWalk(scene, bands, origin, RayAxes(dir), t0, t1, band) {}
  // The same walk, with the ray's axes made once for all its walks.
  CrossingWalk(const Scene& scene, const Bands& bands, const Vec3& origin, const RayAxes& axes,
               double t0, double t1, int band, const WalkWork& work = {});

  std::optional<Crossing> Next();

  // From now on a root crossing's time may be left unrefined when taking
  // the crossing does not need it: Next returns it with t NaN, and t(),
  // asked before the next Next, refines it to the bits Next would have
  // returned. The crossings and their bands are the same. (A shadow ray
  // counts the materials it enters, not where; a primary ray needs the
  // time only of the crossings it shades.)
  void DeferTimes() { defer_ = true; }
  // The time of the crossing Next last returned.
  double t();

  // Goes on past t1 to a new end, as a walk begun with that end would.
  // REQUIRES: every crossing before t1 was taken.
  void Extend(double new_t1);
  double t1() const { return t1_; }

  // The cell of the field the walk is in (per axis c, spanning [c - 0.5,
  // c + 0.5]), and the cells stepped into, boxes jumped and cells whose
  // corners were read so far.
  const std::array<int, 3>& cell() const { return c_; }
  int cells() const { return steps_; }
  int jumps() const { return jumps_; }
  int solved() const { return loads_; }
  // Root crossings returned with their time left unrefined (DeferTimes).
  int deferred() const { return deferred_; }
  // Whether the walk stopped at its bound on steps before t1 (never, by
  // the argument in docs/design.md, "Why every ray ends").
  bool truncated() const { return truncated_; }

 private:
  enum class State : uint8_t { kExamine, kRoots, kLeave };
  // The roots of one edge in the current cell, in increasing t.
  struct EdgeRoots {
    int edge = -1;
    int count = 0;
    // The one root of a cubic whose Bernstein coefficients change sign
    // once is refined only when a crossing in its direction is looked for
    // (a shadow ray leaving the surface it starts on never looks).
    bool refined = true;
    double end = 0;    // unrefined: the cubic less the edge at the span's end
    SideChange at[3];  // t along the ray
  };
  // The time the ray crosses the plane through the voxel centres of index
  // k on `axis`: the face between cells k and k + 1.
  double FaceTime(int axis, int k) const { return (k + 0.5 - origin_[axis]) * inv_[axis]; }
  // Puts the walk's cell on `axis` where it is at t, once every face
  // crossed before t (at or before t, when kInclusive) has been crossed;
  // returns the time of the face it entered that cell by.
  template <bool kInclusive>
  double Land(int axis, double t, int* cell, double* leave) const;
  void SetExit();     // exit_axis_ and t_out_ from leave_
  void Step();        // to the next cell, across the face the ray leaves by
  // Examines the current cell and walks on, jumping boxes of the ray's
  // band, to the first cell with something to do: a crossing into the band
  // of a cell all of one band (returned), a cell whose roots to look for
  // (read, state kRoots), or the end (done_).
  std::optional<Crossing> Scan();
  void Count(int y, uint64_t units);  // adds work at plane y (work_.planes set)
  void Load();        // reads the current cell's corners
  int StartBand();    // the field's band at t_
  EdgeRoots& Roots(int edge);
  // The first root of `edge` going `up` at or after t_, past the root just
  // taken when it is this edge's: its time and index, or {NaN, kDeferred}
  // when `defer` lets an unrefined root's time wait (NextRoot says when).
  std::optional<std::pair<double, int>> Candidate(int edge, bool up, bool defer);
  static constexpr int kDeferred = -1;
  void Refine(int edge);  // the loaded cell's unrefined root of `edge`, if any, refined
  void Settle();          // t_ made exact when a crossing's time was deferred
  std::optional<Crossing> NextRoot();
  // The field along the ray in the loaded cell: cubic_ and hull_.
  void Solve();
  // Whether the hull of the loaded cell's cubic (Solve) leaves a root of
  // edge value `e` possible: its coefficients are not all on one side.
  bool HullStraddles(double e) const;
  unsigned HullBelow(double e) const;  // bit i set: hull_[i] < e
  void SetBand(int band) {
    band_ = band;
    label_band_ = band >= 0 && band < FieldGrid::kMixed ? band : -1;
    const std::vector<float>& edges = bands_->edges();
    const int n = static_cast<int>(edges.size());
    down_edge_ = band - 1 >= 0 && band - 1 < n ? edges[band - 1] : kNoEdge;
    up_edge_ = band >= 0 && band < n ? edges[band] : kNoEdge;
  }
  // Whether a cell whose corners range over [lo, hi] may hold a root of
  // edge value `e` (NaN, kNoEdge: never).
  static bool Straddles(float e, float lo, float hi) { return e > lo && e <= hi; }
  static constexpr float kNoEdge = std::numeric_limits<float>::quiet_NaN();

  const Scene* scene_;
  const Bands* bands_;
  const FieldGrid* grid_;  // null when the scene has none: every cell is read
  // The scene's scalars: planes from scalar_y_begin_, rows of row_ values,
  // planes of plane_; a cell's corners come from one pointer when its first
  // voxel (c - 1) lies below corner_span_ on each axis (y from
  // scalar_y_begin_).
  const float* scalars_;
  int scalar_y_begin_;
  ptrdiff_t row_, plane_;
  std::array<unsigned, 3> corner_span_;
  // The grid's groups, where its cells begin (y: the first row) and how
  // many there are per axis, and what a step along each axis adds to a
  // group's index.
  const FieldGrid::Group* grid_groups_ = nullptr;
  std::array<int, 3> grid_first_ = {0, 0, 0};
  std::array<int, 3> grid_count_ = {0, 0, 0};
  size_t group_stride_[3] = {0, 0, 0};  // groups per step along each axis
  ptrdiff_t group_step_[3] = {0, 0, 0};
  WalkWork work_;
  std::array<double, 3> origin_;  // an array: indexed by a variable axis without branches
  std::array<double, 3> dir_;
  std::array<double, 3> inv_;  // 1 / dir_, 0 where the ray does not move
  std::array<int, 3> step_;
  int octant_;
  double t1_;
  int max_steps_;
  int steps_ = 0;
  int jumps_ = 0;
  int loads_ = 0;
  bool truncated_ = false;
  bool done_ = false;
  bool at_end_ = false;    // done because the current cell reaches t1
  bool start_ = false;     // the ray has no band yet
  bool loaded_ = false;    // the current cell's corners are read
  State state_ = State::kExamine;
  int band_ = 0;
  int label_band_ = -1;    // band_ as a FieldGrid label, -1 if none can be
  // The values of the edges below and above band_ (kNoEdge where none).
  float down_edge_ = kNoEdge, up_edge_ = kNoEdge;
  double t_;               // where the ray is: crossings before it are behind
  int last_edge_ = -1;     // the edge of the crossing just taken, in this cell
  int last_index_ = -1;    // and its index among that edge's roots
  bool defer_ = false;     // DeferTimes
  int pending_ = -1;       // the edge whose root, just taken, is unrefined (t_ below it)
  int deferred_ = 0;
  // Per axis, the face ahead of cell c (c + ahead_) and behind it.
  int ahead_[3], behind_[3];
  // The current cell, and along each axis when the ray leaves its slab of
  // cells (inf on an axis it does not move along).
  std::array<int, 3> c_;
  double leave_[3];
  double t_in_ = 0, t_out_ = 0, hi_ = 0;  // its span, and the end of its part in [t0, t1)
  int exit_axis_ = 0;
  float lo_value_ = 0, hi_value_ = 0;  // its corners' least and greatest value
  bool solved_ = false;                // cubic_ and hull_ are set
  RayCubic cubic_;                     // the field along the ray, s = t - t_in
  double hull_[4];  // its Bernstein coefficients on [0, t_out - t_in], the middle two times 3
  CellCorners corners_;
  EdgeRoots cache_[2];
};

}  // namespace transtick

#endif  // TRANSTICK_ISOSURFACE_H_
