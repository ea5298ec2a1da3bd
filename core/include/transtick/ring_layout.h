// Where rays go on a ring of slabs. The one place that knows how a frame's
// cuts divide the volume along Y and the image among the slabs: which slab
// holds a plane, where a ray that leaves a slab goes next, and which slab
// makes each pixel's primary ray or deposits its miss. The worker
// (services/worker/frame.cc) and the tests' in-process ring
// (tests/testing.cc) both route through it, so the tests exercise the rule
// the cluster runs.
#ifndef TRANSTICK_RING_LAYOUT_H_
#define TRANSTICK_RING_LAYOUT_H_

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "transtick/camera.h"
#include "transtick/check.h"
#include "transtick/ray.h"
#include "transtick/tracer.h"

namespace transtick {

// The slabs of one ring for one frame's view: slab i holds the planes
// [cuts[i], cuts[i + 1]) and its neighbours are slabs i - 1 (left) and
// i + 1 (right). Immutable after construction and thread-safe; a value
// (the cuts, one footprint per slab and a copy of the camera), built once
// per frame.
class RingLayout {
 public:
  // REQUIRES: cuts valid for dims[1] planes (partition.h ValidCuts):
  // cuts[0] == 0, strictly increasing, cuts.back() == dims[1]. Checked: a
  // caller holding cuts from the network validates them first.
  RingLayout(std::vector<int> cuts, const std::array<int, 3>& dims,
             const std::array<double, 3>& spacing, const Camera& camera);

  int slabs() const { return static_cast<int>(cuts_.size()) - 1; }
  const std::vector<int>& cuts() const { return cuts_; }
  // REQUIRES (these three): 0 <= slab < slabs().
  int y_begin(int slab) const { return cuts_[slab]; }
  int y_end(int slab) const { return cuts_[slab + 1]; }

  // The slab holding plane y. REQUIRES: 0 <= y < dims[1].
  int SlabOf(int y) const;

  // Where a ray goes that slab `from` has stopped with its cell at `cell`
  // (Tracer::Trace returned kLeftSlab): to the neighbour on the side of the
  // cell's plane, or nowhere (finished) once the cell is off the volume.
  // The neighbour need not hold the cell either: a uniform brick is crossed
  // in one segment, over any thin slab in between, and each slab on the way
  // passes the ray on by this same rule, one hop at a time.
  enum class Hop { kLeft, kRight, kFinished };
  // REQUIRES: 0 <= from < slabs(); an in-volume cell lies outside slab
  // `from`.
  Hop Route(int from, const std::array<int32_t, 3>& cell) const;
  // The slab a hop leads to. REQUIRES: kLeft with from > 0 or kRight with
  // from + 1 < slabs() (Route gives only those).
  static int Neighbour(int from, Hop hop) {
    TRANSTICK_DCHECK(hop != Hop::kFinished);
    return hop == Hop::kLeft ? from - 1 : from + 1;
  }

  // The pixels whose primary rays may first enter the volume in the slab,
  // conservative. Seen from outside the volume's box, a ray enters through
  // a face it meets from outside: the projections (Camera::Footprint) of
  // those faces' parts within the slab's planes, one plane more each side,
  // each cut to the projection of the slab's box. When a ray may start
  // inside the box (a corner of it lies behind the plane through the eye),
  // the projection of the slab's box. Holds says whether a pixel is among
  // them; Footprint gives, row by row, the columns from the first to the
  // last of them.
  bool Holds(int slab, int col, int row) const;
  const ImageSpans& Footprint(int slab) const { return footprints_[slab]; }

  // What slab `slab` does about the primary ray of pixel (col, row), the
  // paper's distributed policy narrowed by the footprints:
  //   kTrace  the ray enters the volume in this slab; *ray holds it.
  //   kMiss   the ray misses the volume, or meets nothing in it
  //           (Tracer::Void), and this slab deposits the background
  //           (Tracer::MissDeposit of row * width + col).
  //   kNone   another slab takes care of the pixel.
  // Over all slabs, every pixel gets exactly one kTrace or one kMiss. A slab
  // makes rays only for the pixels it Holds (a ray entering the volume in
  // the slab is among them), and keeps those whose entry cell it holds. A
  // miss is deposited by MissSlab(col, row).
  // REQUIRES: 0 <= slab < slabs(), the pixel inside the image, `tracer`
  // traces a scene of this layout's dims and spacing.
  enum class PrimaryRole { kNone, kTrace, kMiss };
  // Of primary ray `sample` of `samples` (SampleOffset) of the pixel.
  PrimaryRole Primary(int slab, int col, int row, int sample, int samples, const Tracer& tracer,
                      RayDescriptor* ray) const;

  // Primary for every sample of the pixels [from, to) of `row`: the rays
  // this slab traces go onto `out`, and the misses it deposits onto
  // `deposits` as queued records (ray_codec.h), a pixel whose every sample
  // is this slab's miss in a miss run with its neighbours of the same
  // kind. Returns the miss deposits queued.
  // REQUIRES: as Primary's, for each pixel; 0 <= from <= to <= width;
  // 1 <= samples <= kMaxDepositsPerRunPixel.
  uint64_t Primaries(int slab, int row, int from, int to, int samples, const Tracer& tracer,
                     std::vector<RayDescriptor>* out, std::string* deposits) const;

  // The slab that deposits the miss of pixel (col, row): the first slab
  // that Holds the pixel, which makes its ray and finds the
  // miss; or slab 0 for a pixel in no footprint, whose ray meets no slab
  // and is never made.
  int MissSlab(int col, int row) const;

 private:
  std::vector<int> cuts_;
  std::array<int, 3> dims_;
  std::vector<ImageSpans> footprints_;          // one per slab: its parts' hull, row by row
  std::vector<std::vector<ImageSpans>> parts_;  // one per slab: its faces' parts, or its box
  Camera camera_;
};

}  // namespace transtick

#endif  // TRANSTICK_RING_LAYOUT_H_
