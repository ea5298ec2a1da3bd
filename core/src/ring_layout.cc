#include "transtick/ring_layout.h"

#include <algorithm>
#include <utility>

#include "transtick/partition.h"
#include "transtick/ray_codec.h"
#include "transtick/traversal.h"

namespace transtick {

namespace {

// Row by row, the hull of both spans (an empty span adds nothing).
void Widen(ImageSpans* spans, const ImageSpans& more) {
  for (size_t row = 0; row < spans->rows.size(); ++row) {
    auto& [first, last] = spans->rows[row];
    const auto [f, l] = more.rows[row];
    if (f >= l) continue;
    if (first >= last) {
      first = f;
      last = l;
    } else {
      first = std::min(first, f);
      last = std::max(last, l);
    }
  }
}

}  // namespace

RingLayout::RingLayout(std::vector<int> cuts, const std::array<int, 3>& dims,
                       const std::array<double, 3>& spacing, const Camera& camera)
    : cuts_(std::move(cuts)), dims_(dims), camera_(camera) {
  TRANSTICK_CHECK_GE(cuts_.size(), 2u);
  TRANSTICK_CHECK(ValidCuts(cuts_, dims[1], slabs()));
  const auto& d = dims;
  const auto& sp = spacing;
  // The volume's box in world space (its centre at the origin), and plane
  // y's height there.
  const Vec3 box_lo{-0.5 * d[0] * sp[0], -0.5 * d[1] * sp[1], -0.5 * d[2] * sp[2]};
  const Vec3 box_hi{0.5 * d[0] * sp[0], 0.5 * d[1] * sp[1], 0.5 * d[2] * sp[2]};
  auto plane_y = [&](int y) { return (y - 0.5 * d[1]) * sp[1]; };
  // A ray enters the volume where it first meets the box. When every corner
  // of the box lies ahead of the plane through the eye, every ray starts
  // outside it (a perspective ray at the eye, an orthographic one on that
  // plane) and enters through a face it meets from outside: a face whose
  // plane the eye lies outside of (perspective), or whose outward normal
  // points against the view (orthographic). Otherwise a ray may start
  // inside, and its entry is anywhere in the box.
  bool outside = true;
  for (int corner = 0; corner < 8; ++corner) {
    const Vec3 p{corner & 1 ? box_hi.x : box_lo.x, corner & 2 ? box_hi.y : box_lo.y,
                 corner & 4 ? box_hi.z : box_lo.z};
    const Vec3 v = p - camera_.eye();
    if (!(Dot(v, camera_.forward()) > 1e-6 * (1 + Length(v)))) outside = false;
  }
  // Whether a ray can enter through the face on side `hi` of axis a: not
  // when the eye lies strictly inside that face's plane, or the view runs
  // strictly away from it. Kept when in doubt: the footprints may only
  // grow by it.
  auto enters = [&](int a, bool hi) {
    if (camera_.projection() == Projection::kPerspective) {
      return hi ? camera_.eye()[a] >= box_hi[a] : camera_.eye()[a] <= box_lo[a];
    }
    return hi ? camera_.forward()[a] <= 0 : camera_.forward()[a] >= 0;
  };
  for (int i = 0; i < slabs(); ++i) {
    // The slab's box.
    Vec3 lo = box_lo, hi = box_hi;
    lo.y = plane_y(cuts_[i]);
    hi.y = plane_y(cuts_[i + 1]);
    ImageSpans box = camera_.Footprint(lo, hi);
    std::vector<ImageSpans> parts;
    if (!outside) {
      parts.push_back(box);
    } else {
      // The pixels whose rays may enter in this slab: the parts of the
      // faces they can enter by that lie within the slab's planes, widened
      // by a plane each side against the rounding of the entry cell (the
      // entry's cell is the floor of a point computed in the volume's index
      // space), each within the slab's box, which every ray entering in the
      // slab crosses.
      lo.y = plane_y(std::max(cuts_[i] - 1, 0));
      hi.y = plane_y(std::min(cuts_[i + 1] + 1, d[1]));
      for (int a = 0; a < 3; ++a) {
        for (bool upper : {false, true}) {
          if (!enters(a, upper)) continue;
          Vec3 face_lo = lo, face_hi = hi;
          const double at = upper ? box_hi[a] : box_lo[a];
          // A face across y belongs to the slabs whose planes reach it.
          if (a == 1 && (at < lo.y || at > hi.y)) continue;
          face_lo[a] = face_hi[a] = at;
          ImageSpans part = camera_.Footprint(face_lo, face_hi);
          for (size_t row = 0; row < part.rows.size(); ++row) {
            auto& [first, last] = part.rows[row];
            first = std::max(first, box.rows[row].first);
            last = std::min(last, box.rows[row].second);
            if (first >= last) first = last = 0;
          }
          parts.push_back(std::move(part));
        }
      }
    }
    ImageSpans hull;
    hull.rows.assign(camera_.height(), {0, 0});
    for (const ImageSpans& part : parts) Widen(&hull, part);
    footprints_.push_back(std::move(hull));
    parts_.push_back(std::move(parts));
  }
}

bool RingLayout::Holds(int slab, int col, int row) const {
  if (!footprints_[slab].Contains(col, row)) return false;
  for (const ImageSpans& part : parts_[slab]) {
    if (part.Contains(col, row)) return true;
  }
  return false;
}

int RingLayout::SlabOf(int y) const {
  TRANSTICK_DCHECK_GE(y, 0);
  TRANSTICK_DCHECK_LT(y, dims_[1]);
  // The last cut at or below y begins its slab.
  return static_cast<int>(std::upper_bound(cuts_.begin() + 1, cuts_.end() - 1, y) -
                          (cuts_.begin() + 1));
}

RingLayout::Hop RingLayout::Route(int from, const std::array<int32_t, 3>& cell) const {
  TRANSTICK_DCHECK(from >= 0 && from < slabs());
  if (!Traversal::Inside(cell, dims_)) return Hop::kFinished;
  TRANSTICK_DCHECK(cell[1] < y_begin(from) || cell[1] >= y_end(from));
  return cell[1] < y_begin(from) ? Hop::kLeft : Hop::kRight;
}

int RingLayout::MissSlab(int col, int row) const {
  for (int i = 0; i < slabs(); ++i) {
    if (Holds(i, col, row)) return i;
  }
  return 0;
}

RingLayout::PrimaryRole RingLayout::Primary(int slab, int col, int row, int sample, int samples,
                                            const Tracer& tracer, RayDescriptor* ray) const {
  TRANSTICK_DCHECK(slab >= 0 && slab < slabs());
  if (!Holds(slab, col, row)) {
    // The ray cannot enter this slab. Slab 0 deposits the miss of a pixel
    // in no footprint (MissSlab is then 0; for any other pixel outside
    // slab 0's footprint it names the slab that does).
    return slab == 0 && MissSlab(col, row) == 0 ? PrimaryRole::kMiss : PrimaryRole::kNone;
  }
  // Rays known to meet nothing (Tracer::Void) are not made: their miss is
  // deposited as a miss of the volume's.
  if (tracer.Void(col, row))
    return MissSlab(col, row) == slab ? PrimaryRole::kMiss : PrimaryRole::kNone;
  const uint32_t pixel = static_cast<uint32_t>(row) * camera_.width() + col;
  // The footprints' margin of two pixels holds every sample of a pixel.
  const auto [ox, oy] = SampleOffset(sample, samples);
  if (!tracer.MakePrimary(camera_.GenerateAt(col, row, ox, oy), pixel, ray)) {
    return MissSlab(col, row) == slab ? PrimaryRole::kMiss : PrimaryRole::kNone;
  }
  // MakePrimary clamps the entry cell into the volume.
  return SlabOf(ray->cell[1]) == slab ? PrimaryRole::kTrace : PrimaryRole::kNone;
}

uint64_t RingLayout::Primaries(int slab, int row, int from, int to, int samples,
                               const Tracer& tracer, std::vector<RayDescriptor>* out,
                               std::string* deposits) const {
  TRANSTICK_DCHECK(samples >= 1 && samples <= kMaxDepositsPerRunPixel);
  const uint32_t width = static_cast<uint32_t>(camera_.width());
  uint64_t misses = 0;
  // The pixels whose every sample is this slab's miss, [first, first + run).
  uint32_t first = 0, run = 0;
  auto close = [&] {
    if (run == 0) return;
    AppendMissRun(first, run, samples, tracer.MissDeposit(first).color, deposits);
    run = 0;
  };
  RayDescriptor ray;  // one record for all: Primary fills it whole when it is this slab's
  for (int col = from; col < to; ++col) {
    const uint32_t pixel = static_cast<uint32_t>(row) * width + static_cast<uint32_t>(col);
    int missed = 0;
    for (int s = 0; s < samples; ++s) {
      switch (Primary(slab, col, row, s, samples, tracer, &ray)) {
        case PrimaryRole::kTrace:
          out->push_back(ray);
          break;
        case PrimaryRole::kMiss:
          ++missed;
          break;
        case PrimaryRole::kNone:
          break;
      }
    }
    misses += static_cast<uint64_t>(missed);
    if (missed == samples) {
      if (run == 0) first = pixel;
      if (++run == kMaxRunRecordPixels) close();
      continue;
    }
    close();
    for (int k = 0; k < missed; ++k) AppendDeposit(tracer.MissDeposit(pixel), deposits);
  }
  close();
  return misses;
}

}  // namespace transtick
