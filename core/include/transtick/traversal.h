// Traversal: the walk of a ray through the cells of a scene, one segment of
// constant material at a time. Uniform space (void, or one material) is
// crossed a box of uniform 2^3 cells at a time (BrickMap::Reach), along a
// track a stick or a gap at a time, and elsewhere in mixed bricks the walk
// moves from track to track (an Amanatides-Woo walk over columns).
//
// Determinism is the contract here: the next segment is a pure function of
// (ray origin, direction, cell, t) and the global volume data, every t is a
// plane-crossing time computed directly from the plane's coordinate (never
// accumulated), and cell indices off the stepping axis are derived from the
// point and clamped to what the brick or stick guarantees. So a ray stopped
// when its cell leaves a slab and resumed on another node takes exactly the
// steps it would have taken on one node.
#ifndef TRANSTICK_TRAVERSAL_H_
#define TRANSTICK_TRAVERSAL_H_

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>

#include "transtick/check.h"
#include "transtick/ray.h"
#include "transtick/scene.h"

// Hot-path functions the compiler must inline: out of line they cost a
// traversal step about 40% (measured with bench/render_bench).
#define TRANSTICK_INLINE inline __attribute__((always_inline))

namespace transtick {

struct Segment {
  double t0;
  double t1;
  uint8_t material;  // 0 for void
};

// Intersects a ray with the box [0, dims] in index space. Returns the
// parameter interval, or nullopt when the ray misses or only touches it.
std::optional<std::array<double, 2>> IntersectBox(const Vec3& origin, const Vec3& direction,
                                                  const std::array<int, 3>& dims);

// Whether a ray moves along an axis with direction component d: d is
// non-zero and 1/d is finite. A denormal component (1/d overflows) is taken
// as parallel to the axis: across the whole volume it moves the ray by less
// than 1e-300 voxels. IntersectBox and Traversal agree on this.
inline bool MovesAlong(double d) { return d != 0 && std::isfinite(1.0 / d); }

// floor(p) clamped to [lo, hi], computed in double so that a huge or NaN p
// (NaN gives lo) never reaches an undefined float-to-int conversion.
inline int FloorClamped(double p, int lo, int hi) {
  double f = std::floor(p);
  f = f > lo ? f : lo;  // branch-free (maxsd, minsd); NaN takes lo here
  f = f < hi ? f : hi;
  return static_cast<int>(f);
}

// The cell containing the point at `t`, clamped to the volume.
std::array<int32_t, 3> CellAt(const Vec3& origin, const Vec3& direction, double t,
                              const std::array<int, 3>& dims);

// The walk of one ray as an iterator that owns its state: the ray's origin
// and direction and where it is now, (cell, t). Each Next() returns the
// segment that starts there and moves the state to the start of the next:
//
//   Traversal it(scene, ray);
//   while (auto seg = it.Next()) { ... }
//   ray.cell = it.cell(), ray.t = it.t();  // to resume elsewhere
//
// A small value type, made per ray on the stack: no allocation and no
// virtual call per step, and the state stays in registers while the walk
// is inlined into its loop. A copy resumes from the same state. Not
// thread-safe (one ray, one thread); the scene must outlive it.
class Traversal {
 public:
  // Starts from (cell, t). Components for which !MovesAlong(d) are taken
  // as parallel.
  // REQUIRES: the point at t lies within a cell of `cell` and the origin
  // within 1e9 of the volume (Tracer::Validate checks both for rays from
  // elsewhere). The scene's tracer walks its brick map (Scene::WalksBricks:
  // voxel surfaces and dvr; a scene of smooth surfaces holds no reach).
  Traversal(const Scene& scene, const Vec3& origin, const Vec3& direction,
            const std::array<int32_t, 3>& cell, double t)
      : scene_(&scene), origin_(origin), cell_(cell), t_(t) {
    // Checked once a ray, not at each step: a walk of a map without its
    // reach would read past it.
    TRANSTICK_CHECK(scene.bricks().HoldsReach() || scene.y_begin() >= scene.y_end());
    for (int a = 0; a < 3; ++a) {
      const double d = direction[a];
      const bool moves = MovesAlong(d);
      step_[a] = moves ? (d > 0 ? 1 : -1) : 0;
      inv_[a] = moves ? 1.0 / d : 0.0;
      dir_[a] = moves ? d : 0.0;
      moves_[a] = std::abs(dir_[a]);
      TRANSTICK_DCHECK(std::abs(origin[a]) <= 1e9 + scene.dims()[a]);
      TRANSTICK_DCHECK(origin[a] + direction[a] * t >= cell[a] - 1.0 &&
                       origin[a] + direction[a] * t <= cell[a] + 2.0);
    }
    across_tracks_ = moves_[2] <= std::max(moves_[0], moves_[1]);
    octant_ = BrickMap::OctantOf(step_);
  }
  // Resumes a ray from its descriptor's origin, direction, cell and t.
  Traversal(const Scene& scene, const RayDescriptor& ray)
      : Traversal(scene, ray.origin, ray.direction, ray.cell, ray.t) {}

  static bool Inside(const std::array<int32_t, 3>& cell, const std::array<int, 3>& dims) {
    return cell[0] >= 0 && cell[1] >= 0 && cell[2] >= 0 && cell[0] < dims[0] && cell[1] < dims[1] &&
           cell[2] < dims[2];
  }

  // Returns the segment that starts at (cell(), t()) and moves the state
  // to the start of the next one; nullopt, leaving the state as it is, once
  // the cell has left the volume, or when the ray cannot leave its box (no
  // axis it moves along: a hostile descriptor), which the caller treats as
  // finished.
  //
  // Termination (docs/design.md, "Why every ray ends"): each returned
  // segment moves the cell at least one cell along an axis the ray moves on,
  // in the ray's direction, and no coordinate ever moves against it. So the
  // potential sum_a step_a * cell_a rises by at least 1 per segment and a
  // ray takes at most MaxSegments(dims) segments in all, on however many
  // nodes, whatever state it starts from.
  // REQUIRES: cell() inside the volume implies its track lies in the
  // scene's slab when its brick is occupied (callers stop at the slab's
  // planes).
  TRANSTICK_INLINE std::optional<Segment> Next() {
    if (!Inside(cell_, scene_->dims())) return std::nullopt;
    return NextInside();
  }
  // Next() for a caller that has checked that cell() is inside the volume
  // (the tracer's walk does, before it looks at the slab).
  // REQUIRES: Inside(cell(), dims).
  TRANSTICK_INLINE std::optional<Segment> NextInside() {
    const auto& dims = scene_->dims();
    TRANSTICK_DCHECK(Inside(cell_, dims));
    // A uniform 2^3 cell is left by the box of cells of its material ahead
    // of it (a uniform brick by the brick, when that reaches further),
    // unless the ray runs mostly along the track in a mixed brick, where the
    // track's stick or gap reaches further.
    const BrickMap& bricks = scene_->bricks();
    const uint8_t brick = bricks.At(cell_[0], cell_[1], cell_[2]);
    if (brick != BrickMap::kMixed || across_tracks_) {
      const uint8_t m = bricks.Cell(cell_[0], cell_[1], cell_[2]);
      if (m != BrickMap::kMixed) {
        const int r = bricks.Reach(cell_[0], cell_[1], cell_[2], octant_);
        std::array<int, 3> lo, hi;
        if (brick != BrickMap::kMixed && r < 3) {
          for (int a = 0; a < 3; ++a) {
            lo[a] = cell_[a] & ~(BrickMap::kBrick - 1);
            hi[a] = std::min(lo[a] + BrickMap::kBrick, dims[a]);
          }
        } else {
          for (int a = 0; a < 3; ++a) {
            const int c = cell_[a] >> 1;
            lo[a] = (step_[a] < 0 ? std::max(c - r, 0) : c) << 1;
            hi[a] = std::min((step_[a] < 0 ? c + 1 : c + r + 1) << 1, dims[a]);
          }
        }
        return Leave(lo, hi, m);
      }
    }
    StickSpan span = scene_->sticks().Find(cell_[0], cell_[1], cell_[2]);
    std::array<int, 3> lo = {cell_[0], cell_[1], span.begin};
    std::array<int, 3> hi = {cell_[0] + 1, cell_[1] + 1, span.end};
    return Leave(lo, hi, span.material);
  }

  // Where the walk is: the cell the next segment starts in, and the time
  // it starts at (a ray's descriptor stores both to resume it).
  const std::array<int32_t, 3>& cell() const { return cell_; }
  double t() const { return t_; }

  // The most segments a ray can take through a volume of `dims`.
  static int64_t MaxSegments(const std::array<int, 3>& dims) {
    return int64_t{dims[0]} + dims[1] + dims[2];
  }

 private:
  double PlaneTime(int axis, int lo, int hi) const {
    if (step_[axis] == 0) return std::numeric_limits<double>::infinity();
    double plane = step_[axis] > 0 ? hi : lo;
    return (plane - origin_[axis]) * inv_[axis];
  }

  // Moves from the box [lo, hi) of constant material to the cell beyond its
  // exit face.
  TRANSTICK_INLINE std::optional<Segment> Leave(const std::array<int, 3>& lo,
                                                const std::array<int, 3>& hi, uint8_t material) {
    // The termination argument rests on this: the exit face lies strictly
    // ahead of the cell on its axis.
    for (int a = 0; a < 3; ++a) {
      TRANSTICK_DCHECK_LE(lo[a], cell_[a]);
      TRANSTICK_DCHECK_LT(cell_[a], hi[a]);
    }
    double tx = PlaneTime(0, lo[0], hi[0]);
    double ty = PlaneTime(1, lo[1], hi[1]);
    double tz = PlaneTime(2, lo[2], hi[2]);
    int axis = 0;
    double t1 = tx;
    if (ty < t1) axis = 1, t1 = ty;
    if (tz < t1) axis = 2, t1 = tz;
    // No face ahead (every axis parallel, or times that overflowed): the ray
    // would never leave this box.
    if (!(t1 <= std::numeric_limits<double>::max())) return std::nullopt;
    // Guard against a plane behind the current position (rounding at a start
    // point lying on the plane): never move backwards.
    if (t1 < t_) t1 = t_;
    Segment seg{t_, t1, material};
    for (int a = 0; a < 3; ++a) {
      if (a == axis) {
        // Strictly forward: the box holds the cell, so hi > cell >= lo.
        cell_[a] = step_[a] > 0 ? hi[a] : lo[a] - 1;
      } else {
        // From the point, clamped to the box, and never back against the
        // ray's direction: at a point on an edge or a corner, rounding could
        // otherwise move a coordinate back and forth between two cells for
        // ever (seen on cthead at azimuth 90). On an axis the ray does not
        // move along, the point's coordinate is the origin's and the cell
        // stays.
        // p lies on the box's boundary give or take rounding, so the
        // conversion is in range (FloorClamped's double clamps cost a
        // traversal step 7%).
        const double p = origin_[a] + dir_[a] * t1;
        const int c = std::clamp(static_cast<int>(std::floor(p)), lo[a], hi[a] - 1);
        cell_[a] = step_[a] > 0 ? std::max(cell_[a], c) : std::min(cell_[a], c);
      }
    }
    t_ = t1;
    return seg;
  }

  const Scene* scene_;
  Vec3 origin_;
  Vec3 dir_;
  Vec3 inv_;
  int step_[3];
  double moves_[3];     // |dir_|
  bool across_tracks_;  // the ray moves along x or y at least as fast as along z
  int octant_;          // the octant it moves into (BrickMap::Reach)
  // Where the walk is.
  std::array<int32_t, 3> cell_;
  double t_;
};

}  // namespace transtick

#endif  // TRANSTICK_TRAVERSAL_H_
