#include "transtick/volume.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <mutex>

#include "transtick/check.h"
#include "transtick/parallel.h"

#if defined(__SSE2__)
#include <immintrin.h>
#endif

namespace transtick {

std::string_view ScalarTypeName(ScalarType type) {
  switch (type) {
    case ScalarType::kUint8:
      return "uint8";
    case ScalarType::kInt8:
      return "int8";
    case ScalarType::kUint16:
      return "uint16";
    case ScalarType::kInt16:
      return "int16";
    case ScalarType::kUint32:
      return "uint32";
    case ScalarType::kInt32:
      return "int32";
    case ScalarType::kFloat32:
      return "float";
    case ScalarType::kFloat64:
      return "double";
  }
  return "unknown";
}

size_t ScalarTypeSize(ScalarType type) {
  switch (type) {
    case ScalarType::kUint8:
    case ScalarType::kInt8:
      return 1;
    case ScalarType::kUint16:
    case ScalarType::kInt16:
      return 2;
    case ScalarType::kUint32:
    case ScalarType::kInt32:
    case ScalarType::kFloat32:
      return 4;
    case ScalarType::kFloat64:
      return 8;
  }
  return 0;
}

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// The least and greatest finite value of p[0, n), as one pass from p[0]
// keeping the first of equal extremes gives them ({inf, -inf} for none).
std::array<float, 2> RangeOf(const float* p, size_t n) {
  float lo = kInf;
  float hi = -kInf;
  size_t i = 0;
#if defined(__SSE2__)
  // Four lanes, each a pass of its own: _mm_min_ps(v, lo) is v < lo ? v :
  // lo, the scalar rule, and keeps lo when v is NaN. -inf is taken out of
  // the least and +inf out of the greatest.
  const __m128 pinf = _mm_set1_ps(kInf), ninf = _mm_set1_ps(-kInf);
  __m128 vlo = pinf, vhi = ninf;
  for (; i + 4 <= n; i += 4) {
    const __m128 v = _mm_loadu_ps(p + i);
    const __m128 is_ninf = _mm_cmpeq_ps(v, ninf), is_pinf = _mm_cmpeq_ps(v, pinf);
    vlo = _mm_min_ps(_mm_or_ps(_mm_andnot_ps(is_ninf, v), _mm_and_ps(is_ninf, pinf)), vlo);
    vhi = _mm_max_ps(_mm_or_ps(_mm_andnot_ps(is_pinf, v), _mm_and_ps(is_pinf, ninf)), vhi);
  }
  alignas(16) float l[4], h[4];
  _mm_store_ps(l, vlo);
  _mm_store_ps(h, vhi);
  for (int k = 0; k < 4; ++k) {
    if (l[k] < lo) lo = l[k];
    if (h[k] > hi) hi = h[k];
  }
#endif
  for (; i < n; ++i) {
    const float v = p[i];
    if (v < lo && v != -kInf) lo = v;
    if (v > hi && v != kInf) hi = v;
  }
  // The lanes agree with one pass on every value but the sign of a zero:
  // one pass keeps the first zero when the extreme is zero.
  if (lo == 0 || hi == 0) {
    const float* z = std::find(p, p + n, 0.0f);
    if (lo == 0) lo = *z;
    if (hi == 0) hi = *z;
  }
  return {lo, hi};
}

}  // namespace

std::array<float, 2> Volume::Range() const {
  // NaN compares false both ways, so NaN samples never become the min or max;
  // infinities are left out too, so that the range has a width (a dvr table
  // from -inf or to +inf was NaN throughout). A volume with no finite
  // sample reports {0, 0} like an empty one.
  // In ranges on as many threads, joined in order by the same rule, so
  // that of equal extremes (-0 and +0) the first is kept, as in one pass.
  std::mutex mu;
  std::map<size_t, std::array<float, 2>> parts;  // by the range's start
  ParallelFor(values.size(), size_t{1} << 18, [&](size_t begin, size_t end) {
    const std::array<float, 2> part = RangeOf(values.data() + begin, end - begin);
    std::lock_guard<std::mutex> lock(mu);
    parts[begin] = part;
  });
  float lo = kInf;
  float hi = -kInf;
  for (const auto& [begin, part] : parts) {
    if (part[0] < lo) lo = part[0];
    if (part[1] > hi) hi = part[1];
  }
  if (lo > hi) return {0.0f, 0.0f};
  return {lo, hi};
}

namespace {

// Adds the bins of p[0, n) to counts (4 * bins: four tallies, each taking
// every fourth sample, so that a run of samples in one bin does not wait on
// each increment of the last).
void CountBins(const float* p, size_t n, double lo, double width, int bins, uint64_t* counts) {
  // Clamped before the conversion, so that a sample outside the range
  // cannot overflow the int; the same bins for samples inside it.
  const double top = bins - 1;
  auto bin = [&](float v) { return static_cast<int>(std::clamp((v - lo) / width, 0.0, top)); };
  size_t i = 0;
  for (; i + 4 <= n; i += 4) {
    for (int k = 0; k < 4; ++k) {
      const float v = p[i + k];
      if (std::isfinite(v)) ++counts[k * bins + bin(v)];
    }
  }
  for (; i < n; ++i) {
    if (std::isfinite(p[i])) ++counts[bin(p[i])];
  }
}

}  // namespace

std::vector<uint64_t> Histogram(std::span<const float> values, std::array<float, 2> range,
                                int bins) {
  TRANSTICK_CHECK(bins >= 1);
  // In double: a float volume's range may span nearly all of float.
  const double lo = range[0], hi = range[1];
  const double width = hi > lo ? (hi - lo) / bins : 1;
  std::vector<uint64_t> total(bins, 0);
  std::mutex mu;
  ParallelFor(values.size(), size_t{1} << 18, [&](size_t begin, size_t end) {
    std::vector<uint64_t> counts(4 * static_cast<size_t>(bins), 0);
    CountBins(values.data() + begin, end - begin, lo, width, bins, counts.data());
    std::lock_guard<std::mutex> lock(mu);
    for (size_t k = 0; k < counts.size(); ++k) total[k % bins] += counts[k];
  });
  return total;
}

}  // namespace transtick
