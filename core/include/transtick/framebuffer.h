// Accumulates deposits into pixels in fixed point, so the sum does not depend
// on the order deposits arrive in: one node or many, any thread schedule,
// the same bits. Tracks per-pixel completion (see Deposit).
#ifndef TRANSTICK_FRAMEBUFFER_H_
#define TRANSTICK_FRAMEBUFFER_H_

#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <span>
#include <type_traits>
#include <vector>

#include "transtick/ray.h"

namespace transtick {

// A float RGB image, rows top to bottom.
struct Image {
  int width = 0;
  int height = 0;
  std::vector<float> rgb;  // width * height * 3
};

// Threads may add deposits at once only for disjoint pixels; Resolve and
// the accessors need the writers stopped.
class Framebuffer {
 public:
  // 2^-32 per unit: far below any output precision; a pixel can take 2^31
  // units before overflow, so sums of many contributions are safe.
  static constexpr double kScale = 4294967296.0;

  // A pixel is complete after `samples` primary deposits and the shadow
  // deposits they announce; its value is their sum over `samples`.
  Framebuffer(int width, int height, int samples = 1);

  // The memory a framebuffer of `width` x `height` holds: what the display
  // counts against its limit before it makes one.
  static uint64_t MemoryBytes(int width, int height) {
    return static_cast<uint64_t>(width) * static_cast<uint64_t>(height) * sizeof(Pixel);
  }

  // Back to no deposits, keeping the memory, for frames of `samples`.
  void Clear(int samples = 1);
  // For frames of `samples`.
  // REQUIRES: no deposits since the last Clear (or construction).
  void SetSamples(int samples) { samples_ = samples; }

  // Adds a deposit. Returns true when this deposit completed its pixel;
  // each pixel completes once, whatever arrives after (sums wrap rather
  // than overflow on deposits no renderer makes).
  // REQUIRES: deposit.pixel < width * height (decoders check pixels from
  // the network against the image before they get here).
  bool Add(const Deposit& deposit);
  // The same, but a pixel it completes is left for the caller to count
  // with CountCompleted: threads that add to one framebuffer at once then
  // share no counter while they trace.
  bool AddUncounted(const Deposit& deposit);
  void CountCompleted(uint64_t pixels) {
    if (pixels > 0) complete_.fetch_add(pixels, std::memory_order_relaxed);
  }
  // Adds deposits of one pixel merged (PixelDeposits, ray.h), or of each
  // pixel of a run: the same state as adding each of them. Returns true
  // when they completed a pixel.
  // REQUIRES: deposits.pixel + deposits.pixels <= width * height.
  bool Add(const PixelDeposits& deposits);
  // Adds a batch of them, as one by one; returns how many pixels they
  // completed.
  // REQUIRES: every pixel + pixels <= width * height.
  uint64_t Add(std::span<const PixelDeposits> batch);

  // A colour in the sums' fixed point: round(c * kScale), halves away from
  // zero, saturated beyond what an int64 holds, 0 for NaN. What
  // std::llround gives, without the library call: a float times 2^32 has 24
  // significant bits, so adding 0.5 is exact while |c| < 2^20, and
  // truncation then rounds.
  static int64_t ToFixed(float c) {
    const double v = static_cast<double>(c) * kScale;
    if (!(std::fabs(v) < 0x1p52)) {
      // Huge or NaN: the slow path, which saturates what no int64 holds.
      if (std::isnan(v)) return 0;
      if (!(std::fabs(v) < 0x1p63)) return v < 0 ? INT64_MIN : INT64_MAX;
      return std::llround(v);
    }
    return static_cast<int64_t>(v < 0 ? v - 0.5 : v + 0.5);
  }

  uint64_t complete_pixels() const { return complete_.load(std::memory_order_relaxed); }
  // How many rows from the top have every pixel complete: rows whose
  // values no deposit of a correct renderer changes any more, so that
  // they may be resolved and sent before the frame is complete. Advances
  // a cursor, so the pixels of a frame are looked at once in all.
  // REQUIRES: no Add while it runs.
  int CompleteRows();
  bool Complete() const { return complete_pixels() == static_cast<uint64_t>(width_) * height_; }
  int width() const { return width_; }
  int height() const { return height_; }
  int samples() const { return samples_; }

  Image Resolve() const;
  // Rows [row_begin, row_end) of Resolve()'s image into `rgb`, which holds
  // (row_end - row_begin) * width * 3 floats: an image sent in chunks is
  // resolved a chunk at a time, never whole.
  // REQUIRES: 0 <= row_begin <= row_end <= height.
  void ResolveRows(int row_begin, int row_end, float* rgb) const;

 private:
  int width_, height_;
  int samples_;
  // Everything a deposit touches, in one 32-byte record: one cache line
  // per deposit, however the pixels of different workers interleave.
  struct alignas(32) Pixel {
    std::array<int64_t, 3> sum;
    // Shadow deposits still owed: the primary's count minus shadows seen.
    int32_t owed;
    uint8_t primary_seen;  // primary deposits, up to 255
    uint8_t counted;  // in complete_ already
  };
  static_assert(std::is_trivially_copyable_v<Pixel>, "Clear zeroes pixels with memset");
  // Whether this deposit completes p: then it is marked, and the caller
  // counts it in complete_. A pixel completes once: deposits after its
  // last one (which no renderer sends) must not count it again, or
  // complete_pixels() could reach the image's size with pixels missing.
  bool Completes(Pixel& p) const {
    if (p.primary_seen == samples_ && p.owed == 0 && !p.counted) {
      p.counted = 1;
      return true;
    }
    return false;
  }
  // The merged deposits of d into p (Add(PixelDeposits)), without counting.
  static void Merge(Pixel& p, const PixelDeposits& d);
  std::vector<Pixel> pixels_;
  std::atomic<uint64_t> complete_{0};
  size_t complete_prefix_ = 0;  // pixels from the first on seen complete (CompleteRows)
};

}  // namespace transtick

#endif  // TRANSTICK_FRAMEBUFFER_H_
