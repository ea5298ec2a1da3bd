#include "transtick/scalar_codec.h"

#include <algorithm>
#include <bit>
#include <cstring>

#if defined(__SSE2__)
#include <immintrin.h>
#endif

#include "absl/strings/str_cat.h"
#include "transtick/check.h"

namespace transtick {
namespace {

// The vector loops below store and load the machine's own byte order.
constexpr bool kVectors =
#if defined(__SSE2__)
    std::endian::native == std::endian::little;
#else
    false;
#endif

// Whether x is the float of an integer, bit for bit (not -0, NaN, an
// infinity or a fraction); if so, that integer in *k.
inline bool AsInteger(float x, int32_t* k) {
  if (!(x >= -2147483648.0f && x < 2147483648.0f)) return false;
  *k = static_cast<int32_t>(x);
  return std::bit_cast<uint32_t>(static_cast<float>(*k)) == std::bit_cast<uint32_t>(x);
}

ScalarsCoding CodingOfRange(int32_t lo, int32_t hi) {
  if (lo >= 0 && hi <= 255) return ScalarsCoding::kU8;
  if (lo >= -32768 && hi <= 32767) return ScalarsCoding::kI16;
  return ScalarsCoding::kF32;
}

}  // namespace

size_t ScalarsCodingBytes(ScalarsCoding coding) {
  switch (coding) {
    case ScalarsCoding::kU8:
      return 1;
    case ScalarsCoding::kI16:
      return 2;
    case ScalarsCoding::kF32:
      break;
  }
  return 4;
}

ScalarsCoding NarrowestCoding(const float* values, size_t n) {
  // The least and greatest integer seen (0 counts: it lies in every
  // coding's range, so it changes no answer).
  int32_t lo = 0, hi = 0;
  size_t i = 0;
#if defined(__SSE4_1__)
  // Each value to an int32 (a value out of range, or NaN, gives INT32_MIN)
  // and back: the float of its integer equals it bit for bit when it is
  // one. Blocks of 1,024 values, so that a float volume stops early.
  __m128i vlo = _mm_setzero_si128(), vhi = _mm_setzero_si128();
  while (i + 4 <= n) {
    const size_t end = i + std::min<size_t>(1024, (n - i) & ~size_t{3});
    __m128i differ = _mm_setzero_si128();
    for (; i < end; i += 4) {
      const __m128 x = _mm_loadu_ps(values + i);
      const __m128i k = _mm_cvttps_epi32(x);
      differ = _mm_or_si128(
          differ, _mm_xor_si128(_mm_castps_si128(_mm_cvtepi32_ps(k)), _mm_castps_si128(x)));
      vlo = _mm_min_epi32(vlo, k);
      vhi = _mm_max_epi32(vhi, k);
    }
    if (!_mm_testz_si128(differ, differ)) return ScalarsCoding::kF32;
  }
  vlo = _mm_min_epi32(vlo, _mm_shuffle_epi32(vlo, _MM_SHUFFLE(1, 0, 3, 2)));
  vlo = _mm_min_epi32(vlo, _mm_shuffle_epi32(vlo, _MM_SHUFFLE(2, 3, 0, 1)));
  vhi = _mm_max_epi32(vhi, _mm_shuffle_epi32(vhi, _MM_SHUFFLE(1, 0, 3, 2)));
  vhi = _mm_max_epi32(vhi, _mm_shuffle_epi32(vhi, _MM_SHUFFLE(2, 3, 0, 1)));
  lo = _mm_cvtsi128_si32(vlo);
  hi = _mm_cvtsi128_si32(vhi);
#endif
  for (; i < n; ++i) {
    int32_t k;
    if (!AsInteger(values[i], &k)) return ScalarsCoding::kF32;
    lo = std::min(lo, k);
    hi = std::max(hi, k);
  }
  return CodingOfRange(lo, hi);
}

void AppendScalars(const float* values, size_t n, ScalarsCoding coding, std::string* out) {
  const size_t at = out->size();
  out->resize(at + n * ScalarsCodingBytes(coding));
  char* dst = out->data() + at;
  switch (coding) {
    case ScalarsCoding::kF32:
      if constexpr (std::endian::native == std::endian::little) {
        std::memcpy(dst, values, n * 4);
      } else {
        for (size_t i = 0; i < n; ++i) {
          const uint32_t b = std::bit_cast<uint32_t>(values[i]);
          for (int k = 0; k < 4; ++k) dst[4 * i + k] = static_cast<char>(b >> (8 * k));
        }
      }
      return;
    case ScalarsCoding::kU8: {
      size_t i = 0;
#if defined(__SSE2__)
      // Integers 0..255: saturating packs leave them as they are.
      for (; i + 16 <= n; i += 16) {
        const __m128i a = _mm_cvttps_epi32(_mm_loadu_ps(values + i));
        const __m128i b = _mm_cvttps_epi32(_mm_loadu_ps(values + i + 4));
        const __m128i c = _mm_cvttps_epi32(_mm_loadu_ps(values + i + 8));
        const __m128i d = _mm_cvttps_epi32(_mm_loadu_ps(values + i + 12));
        _mm_storeu_si128(reinterpret_cast<__m128i*>(dst + i),
                         _mm_packus_epi16(_mm_packs_epi32(a, b), _mm_packs_epi32(c, d)));
      }
#endif
      for (; i < n; ++i) dst[i] = static_cast<char>(static_cast<uint8_t>(values[i]));
      return;
    }
    case ScalarsCoding::kI16: {
      size_t i = 0;
      if constexpr (kVectors) {
#if defined(__SSE2__)
        for (; i + 8 <= n; i += 8) {
          const __m128i a = _mm_cvttps_epi32(_mm_loadu_ps(values + i));
          const __m128i b = _mm_cvttps_epi32(_mm_loadu_ps(values + i + 4));
          _mm_storeu_si128(reinterpret_cast<__m128i*>(dst + 2 * i), _mm_packs_epi32(a, b));
        }
#endif
      }
      for (; i < n; ++i) {
        const uint16_t v = static_cast<uint16_t>(static_cast<int16_t>(values[i]));
        dst[2 * i] = static_cast<char>(v & 0xff);
        dst[2 * i + 1] = static_cast<char>(v >> 8);
      }
      return;
    }
  }
  TRANSTICK_CHECK(false);
}

absl::StatusOr<size_t> DecodeScalars(std::string_view bytes, int coding, float* out, size_t room) {
  if (coding != static_cast<int>(ScalarsCoding::kF32) &&
      coding != static_cast<int>(ScalarsCoding::kU8) &&
      coding != static_cast<int>(ScalarsCoding::kI16)) {
    return absl::InvalidArgumentError(absl::StrCat("slab scalars: unknown coding ", coding));
  }
  const ScalarsCoding c = static_cast<ScalarsCoding>(coding);
  const size_t width = ScalarsCodingBytes(c);
  if (bytes.size() % width != 0) {
    return absl::InvalidArgumentError(absl::StrCat("slab scalars: ", bytes.size(),
                                                   " bytes are not a whole number of ", width,
                                                   "-byte samples"));
  }
  const size_t n = bytes.size() / width;
  if (n > room) {
    return absl::InvalidArgumentError(
        absl::StrCat("slab scalars: ", n, " samples where ", room, " were left to fill"));
  }
  const auto* src = reinterpret_cast<const uint8_t*>(bytes.data());
  size_t i = 0;
  switch (c) {
    case ScalarsCoding::kF32:
      if constexpr (std::endian::native == std::endian::little) {
        std::memcpy(out, src, n * 4);
      } else {
        for (; i < n; ++i) {
          const uint32_t b = uint32_t{src[4 * i]} | uint32_t{src[4 * i + 1]} << 8 |
                             uint32_t{src[4 * i + 2]} << 16 | uint32_t{src[4 * i + 3]} << 24;
          out[i] = std::bit_cast<float>(b);
        }
      }
      break;
    case ScalarsCoding::kU8:
#if defined(__SSE2__)
      for (; i + 16 <= n; i += 16) {
        const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(src + i));
        const __m128i zero = _mm_setzero_si128();
        const __m128i lo = _mm_unpacklo_epi8(v, zero), hi = _mm_unpackhi_epi8(v, zero);
        _mm_storeu_ps(out + i, _mm_cvtepi32_ps(_mm_unpacklo_epi16(lo, zero)));
        _mm_storeu_ps(out + i + 4, _mm_cvtepi32_ps(_mm_unpackhi_epi16(lo, zero)));
        _mm_storeu_ps(out + i + 8, _mm_cvtepi32_ps(_mm_unpacklo_epi16(hi, zero)));
        _mm_storeu_ps(out + i + 12, _mm_cvtepi32_ps(_mm_unpackhi_epi16(hi, zero)));
      }
#endif
      for (; i < n; ++i) out[i] = static_cast<float>(src[i]);
      break;
    case ScalarsCoding::kI16:
      if constexpr (kVectors) {
#if defined(__SSE2__)
        for (; i + 8 <= n; i += 8) {
          // Each i16 into the high half of a lane, then shifted down with
          // its sign.
          const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(src + 2 * i));
          _mm_storeu_ps(out + i, _mm_cvtepi32_ps(_mm_srai_epi32(_mm_unpacklo_epi16(v, v), 16)));
          _mm_storeu_ps(out + i + 4, _mm_cvtepi32_ps(_mm_srai_epi32(_mm_unpackhi_epi16(v, v), 16)));
        }
#endif
      }
      for (; i < n; ++i) {
        const uint16_t b = static_cast<uint16_t>(src[2 * i] | src[2 * i + 1] << 8);
        out[i] = static_cast<float>(static_cast<int16_t>(b));
      }
      break;
  }
  return n;
}

}  // namespace transtick
