#include "transtick/framebuffer.h"

#include <algorithm>
#include <cmath>

#include "transtick/check.h"

namespace transtick {
namespace {

// round(c * 2^32), halves away from zero: what std::llround gives, without
// the library call. Exact: a float times 2^32 has 24 significant bits, so
// adding 0.5 is exact while |c| < 2^20, and truncation then rounds.
inline int64_t ToFixed(float c) {
  const double v = static_cast<double>(c) * Framebuffer::kScale;
  if (!(std::fabs(v) < 0x1p52)) return std::llround(v);  // huge or NaN: the slow path
  return static_cast<int64_t>(v < 0 ? v - 0.5 : v + 0.5);
}

}  // namespace

Framebuffer::Framebuffer(int width, int height)
    : width_(width),
      height_(height),
      pixels_(static_cast<size_t>(width) * height, Pixel{{0, 0, 0}, 0, 0}) {}

void Framebuffer::Clear() {
  std::fill(pixels_.begin(), pixels_.end(), Pixel{{0, 0, 0}, 0, 0});
  complete_.store(0, std::memory_order_relaxed);
}

bool Framebuffer::Add(const Deposit& d) {
  TRANSTICK_DCHECK_LT(d.pixel, pixels_.size());
  Pixel& p = pixels_[d.pixel];
  for (int c = 0; c < 3; ++c) p.sum[c] += ToFixed(d.color[c]);
  if (d.kind == RayKind::kPrimary) {
    p.primary_seen = 1;
    p.owed += d.spawned;
  } else {
    p.owed -= 1;
  }
  if (p.primary_seen && p.owed == 0) {
    complete_.fetch_add(1, std::memory_order_relaxed);
    return true;
  }
  return false;
}

Image Framebuffer::Resolve() const {
  Image img;
  img.width = width_;
  img.height = height_;
  img.rgb.resize(pixels_.size() * 3);
  for (size_t i = 0; i < pixels_.size(); ++i) {
    for (int c = 0; c < 3; ++c) img.rgb[i * 3 + c] = static_cast<float>(pixels_[i].sum[c] / kScale);
  }
  return img;
}

}  // namespace transtick
