#include "transtick/ring_layout.h"

#include <algorithm>
#include <utility>

#include "transtick/partition.h"
#include "transtick/ray_codec.h"
#include "transtick/traversal.h"

namespace transtick {

RingLayout::RingLayout(std::vector<int> cuts, const std::array<int, 3>& dims,
                       const std::array<double, 3>& spacing, const Camera& camera)
    : cuts_(std::move(cuts)), dims_(dims), camera_(camera) {
  TRANSTICK_CHECK_GE(cuts_.size(), 2u);
  TRANSTICK_CHECK(ValidCuts(cuts_, dims[1], slabs()));
  const auto& d = dims;
  const auto& sp = spacing;
  // Each slab's box in world space (the volume's centre at the origin).
  for (int i = 0; i < slabs(); ++i) {
    const Vec3 lo{-0.5 * d[0] * sp[0], (cuts_[i] - 0.5 * d[1]) * sp[1], -0.5 * d[2] * sp[2]};
    const Vec3 hi{0.5 * d[0] * sp[0], (cuts_[i + 1] - 0.5 * d[1]) * sp[1], 0.5 * d[2] * sp[2]};
    footprints_.push_back(camera_.Footprint(lo, hi));
  }
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
    if (footprints_[i].Contains(col, row)) return i;
  }
  return 0;
}

RingLayout::PrimaryRole RingLayout::Primary(int slab, int col, int row, int sample, int samples,
                                            const Tracer& tracer, RayDescriptor* ray) const {
  TRANSTICK_DCHECK(slab >= 0 && slab < slabs());
  if (!footprints_[slab].Contains(col, row)) {
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
