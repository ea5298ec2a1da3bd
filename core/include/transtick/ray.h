// The ray descriptor: the whole state of a ray in flight, self-contained so
// that a ray stopped at a slab plane resumes elsewhere with bit-identical
// results. Its wire form (docs/formats.md, "Ray descriptor") carries every
// field below bit for bit.
#ifndef TRANSTICK_RAY_H_
#define TRANSTICK_RAY_H_

#include <array>
#include <cstdint>

#include "transtick/vec.h"

namespace transtick {

enum class RayKind : uint8_t {
  kPrimary = 0,  // from the eye; continues through non-opaque surfaces
  kShadow = 1,   // from a shaded point toward the light
};

// All geometry is in index space (voxel (i, j, k) covers [i, i+1) x ...),
// but the parameter t measures world distance: direction is the unit world
// direction divided by the spacing.
struct RayDescriptor {
  Vec3 origin;
  Vec3 direction;
  double t = 0;                             // where the ray is now: the entry into `cell`
  double t_start = 0;                       // dvr: sample k lies at t_start + k * step
  std::array<int32_t, 3> cell = {0, 0, 0};  // the cell the ray is in
  uint32_t pixel = 0;                       // y * width + x
  uint32_t sample = 0;                      // dvr: next sample index
  RayKind kind = RayKind::kPrimary;
  uint8_t material = 0;  // material of the last cell crossed (0 = void)
  uint16_t spawned = 0;  // primary: shadow rays spawned so far
  // Primary: colour accumulated front to back (premultiplied) and the
  // transmittance left. Shadow: the light the shaded point would receive
  // unoccluded (already weighted by the primary's transmittance and the
  // surface's opacity) and the transmittance toward the light so far.
  std::array<float, 3> color = {0, 0, 0};
  float transmittance = 1;
  // Smooth surfaces: the band of the field (classification.h, Bands) the
  // ray is in, or kNoBand until its first segment tells.
  static constexpr uint16_t kNoBand = 0xFFFF;
  uint16_t band = kNoBand;
};

// What a finished ray leaves in its pixel. Every ray ends in exactly one
// deposit; a primary's deposit says how many shadow rays it spawned, so the
// display knows a pixel is complete when the primary's deposit and that many
// shadow deposits have arrived, in whatever order.
struct Deposit {
  uint32_t pixel = 0;
  RayKind kind = RayKind::kPrimary;
  uint16_t spawned = 0;
  std::array<float, 3> color = {0, 0, 0};
};

// Consecutive deposits of one pixel merged, as a worker packs them for the
// display (docs/formats.md, "Packed deposits"): the counts, and the colours
// summed in the framebuffer's fixed point (Framebuffer::ToFixed) modulo
// 2^64, which adds in any order to the same bits.
// A run record covers `pixels` consecutive pixels from `pixel` on, each
// taking these deposits (a worker's misses: formats.md, "Packed deposits").
struct PixelDeposits {
  uint32_t pixel = 0;
  uint32_t pixels = 1;
  uint32_t primaries = 0;
  uint32_t spawned = 0;  // by those primaries, summed
  uint32_t shadows = 0;
  std::array<int64_t, 3> sum = {0, 0, 0};
};

}  // namespace transtick

#endif  // TRANSTICK_RAY_H_
