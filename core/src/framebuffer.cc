#include "transtick/framebuffer.h"

#include <algorithm>
#include <cmath>

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
      sum_(static_cast<size_t>(width) * height, {0, 0, 0}),
      owed_(static_cast<size_t>(width) * height, 0),
      primary_seen_(static_cast<size_t>(width) * height, 0) {}

void Framebuffer::Clear() {
  std::fill(sum_.begin(), sum_.end(), std::array<int64_t, 3>{0, 0, 0});
  std::fill(owed_.begin(), owed_.end(), 0);
  std::fill(primary_seen_.begin(), primary_seen_.end(), 0);
  complete_.store(0, std::memory_order_relaxed);
}

bool Framebuffer::Add(const Deposit& d) {
  auto& s = sum_[d.pixel];
  for (int c = 0; c < 3; ++c) s[c] += ToFixed(d.color[c]);
  if (d.kind == RayKind::kPrimary) {
    primary_seen_[d.pixel] = 1;
    owed_[d.pixel] += d.spawned;
  } else {
    owed_[d.pixel] -= 1;
  }
  if (primary_seen_[d.pixel] && owed_[d.pixel] == 0) {
    complete_.fetch_add(1, std::memory_order_relaxed);
    return true;
  }
  return false;
}

Image Framebuffer::Resolve() const {
  Image img;
  img.width = width_;
  img.height = height_;
  img.rgb.resize(sum_.size() * 3);
  for (size_t i = 0; i < sum_.size(); ++i) {
    for (int c = 0; c < 3; ++c) img.rgb[i * 3 + c] = static_cast<float>(sum_[i][c] / kScale);
  }
  return img;
}

}  // namespace transtick
