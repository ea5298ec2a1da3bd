// Where a ray first meets an isosurface of the trilinear field inside one
// cell: the exact root of a cubic, after Marmitt et al., "Fast and Accurate
// Ray-Voxel Intersection Techniques for Iso-Surface Ray Tracing" (2004).
//
// A cell spans [0, 1]^3 between the eight samples at its corners; along a
// ray p(t) = o + t d the interpolant is a cubic in t. Its extrema split
// [t_begin, t_end] into pieces on which it is monotonic; the first piece
// whose ends differ in sign around the threshold holds the first root,
// which a bounded number of safeguarded secant steps then pin down. No
// fixed step: a thin feature between two samples of the ray is not missed.
//
// A pure function of its arguments in double precision, with a fixed
// sequence of operations: every node that solves the same cell for the
// same ray gets the same bits.
#ifndef TRANSTICK_ISOSURFACE_H_
#define TRANSTICK_ISOSURFACE_H_

#include <array>
#include <optional>

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

// The trilinear interpolant of `corners` at `p` (cell coordinates).
double Trilinear(const CellCorners& corners, const std::array<double, 3>& p);

// The first t in [t_begin, t_end] where the cubic is zero or changes sign,
// or none. A root exactly at t_begin counts (a ray that starts on the
// surface); a double root that only touches zero counts only where a
// split point lands on it exactly. Within the interval found, the answer
// is within 1e-9 of the interval's length of the root.
std::optional<double> FirstRoot(const RayCubic& g, double t_begin, double t_end);

// The first t in [t_begin, t_end] where the trilinear field of `scene`'s
// scalars (samples at voxel centres, index space, as Tracer::Sample reads
// them, clamped at the volume's faces) along origin + t dir meets `iso`.
// The ray is cut at the planes between voxel centres into the cells of
// that field, and each piece is solved by FirstRoot in order. Each piece's
// root depends only on the ray and the cell's eight samples.
// REQUIRES: the scalar planes the pieces touch are stored in `scene` (a
// slab's own planes and its ghost planes).
std::optional<double> FirstCrossing(const Scene& scene, const Vec3& origin, const Vec3& dir,
                                    double t_begin, double t_end, double iso);

}  // namespace transtick

#endif  // TRANSTICK_ISOSURFACE_H_
