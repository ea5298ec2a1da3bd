#include "transtick/framebuffer.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "transtick/check.h"

namespace transtick {
namespace {

// Sums wrap modulo 2^64 (and counts modulo 2^32) instead of overflowing,
// which is undefined: deposits no renderer makes (a hostile peer's huge
// colours, a pixel's primary sent again and again) can otherwise reach it.
// Wrapping addition is still associative, so the order of arrival still
// does not matter, and sums that fit are unchanged.
inline int64_t WrappingAdd(int64_t a, int64_t b) {
  return static_cast<int64_t>(static_cast<uint64_t>(a) + static_cast<uint64_t>(b));
}
inline int32_t WrappingAdd(int32_t a, int32_t b) {
  return static_cast<int32_t>(static_cast<uint32_t>(a) + static_cast<uint32_t>(b));
}

}  // namespace

Framebuffer::Framebuffer(int width, int height, int samples)
    : width_(width),
      height_(height),
      samples_(samples),
      pixels_(static_cast<size_t>(width) * height, Pixel{{0, 0, 0}, 0, 0, 0}) {}

void Framebuffer::Clear(int samples) {
  samples_ = samples;
  // All bytes zero is Pixel{} (checked where Pixel is declared). memset
  // writes 32 bytes at a time; std::fill wrote each field, and the display
  // clears 5 MB of a 400x400 frame's pixels each frame.
  std::memset(static_cast<void*>(pixels_.data()), 0, pixels_.size() * sizeof(Pixel));
  complete_.store(0, std::memory_order_relaxed);
  complete_prefix_ = 0;
}

int Framebuffer::CompleteRows() {
  while (complete_prefix_ < pixels_.size() && pixels_[complete_prefix_].counted) ++complete_prefix_;
  return width_ > 0 ? static_cast<int>(complete_prefix_ / static_cast<size_t>(width_)) : height_;
}

bool Framebuffer::Add(const Deposit& d) {
  const bool completed = AddUncounted(d);
  CountCompleted(completed);
  return completed;
}

bool Framebuffer::AddUncounted(const Deposit& d) {
  TRANSTICK_DCHECK_LT(d.pixel, pixels_.size());
  Pixel& p = pixels_[d.pixel];
  for (int c = 0; c < 3; ++c) p.sum[c] = WrappingAdd(p.sum[c], ToFixed(d.color[c]));
  if (d.kind == RayKind::kPrimary) {
    if (p.primary_seen < 255) ++p.primary_seen;
    p.owed = WrappingAdd(p.owed, int32_t{d.spawned});
  } else {
    p.owed = WrappingAdd(p.owed, int32_t{-1});
  }
  return Completes(p);
}

inline void Framebuffer::Merge(Pixel& p, const PixelDeposits& d) {
  for (int c = 0; c < 3; ++c) p.sum[c] = WrappingAdd(p.sum[c], d.sum[c]);
  // As one at a time: the count saturates at 255, the debt wraps.
  p.primary_seen = static_cast<uint8_t>(
      std::min<uint32_t>(255, p.primary_seen + std::min<uint32_t>(d.primaries, 255)));
  p.owed = WrappingAdd(p.owed, static_cast<int32_t>(d.spawned - d.shadows));
}

bool Framebuffer::Add(const PixelDeposits& d) {
  return Add(std::span<const PixelDeposits>(&d, 1)) > 0;
}

uint64_t Framebuffer::Add(std::span<const PixelDeposits> batch) {
  // One atomic addition for the batch, not one per pixel completed.
  uint64_t completed = 0;
  for (const PixelDeposits& d : batch) {
    TRANSTICK_DCHECK_LE(d.pixels, pixels_.size());
    TRANSTICK_DCHECK_LE(d.pixel, pixels_.size() - d.pixels);
    Pixel* p = &pixels_[d.pixel];
    for (Pixel* const end = p + d.pixels; p != end; ++p) {
      Merge(*p, d);
      completed += Completes(*p);
    }
  }
  CountCompleted(completed);
  return completed;
}

Image Framebuffer::Resolve() const {
  Image img;
  img.width = width_;
  img.height = height_;
  img.rgb.resize(pixels_.size() * 3);
  ResolveRows(0, height_, img.rgb.data());
  return img;
}

void Framebuffer::ResolveRows(int row_begin, int row_end, float* rgb) const {
  TRANSTICK_DCHECK_LE(0, row_begin);
  TRANSTICK_DCHECK_LE(row_begin, row_end);
  TRANSTICK_DCHECK_LE(row_end, height_);
  const size_t begin = static_cast<size_t>(row_begin) * width_;
  const size_t end = static_cast<size_t>(row_end) * width_;
  // The mean of the samples; one sample is its sum as it stands.
  const double scale = kScale * samples_;
  if ((samples_ & (samples_ - 1)) == 0) {
    // A power of two: multiplying by its reciprocal (exact) is the same
    // bits as dividing, and a division is several multiplications' time.
    const double inverse = 1.0 / scale;
    for (size_t i = begin; i < end; ++i) {
      for (int c = 0; c < 3; ++c) {
        *rgb++ = static_cast<float>(static_cast<double>(pixels_[i].sum[c]) * inverse);
      }
    }
    return;
  }
  for (size_t i = begin; i < end; ++i) {
    for (int c = 0; c < 3; ++c) *rgb++ = static_cast<float>(pixels_[i].sum[c] / scale);
  }
}

}  // namespace transtick
