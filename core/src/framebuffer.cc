#include "transtick/framebuffer.h"

#include <cmath>

namespace transtick {

Framebuffer::Framebuffer(int width, int height)
    : width_(width),
      height_(height),
      sum_(static_cast<size_t>(width) * height, {0, 0, 0}),
      owed_(static_cast<size_t>(width) * height, 0),
      primary_seen_(static_cast<size_t>(width) * height, 0) {}

bool Framebuffer::Add(const Deposit& d) {
  auto& s = sum_[d.pixel];
  for (int c = 0; c < 3; ++c) s[c] += std::llround(static_cast<double>(d.color[c]) * kScale);
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
