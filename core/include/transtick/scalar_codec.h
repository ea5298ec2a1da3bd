// A slab's scalars on the wire (docs/formats.md, "Slab scalars"): pieces of
// samples, each in the narrowest of three codings that gives back every
// float bit for bit.
#ifndef TRANSTICK_SCALAR_CODEC_H_
#define TRANSTICK_SCALAR_CODEC_H_

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "absl/status/statusor.h"

namespace transtick {

// The values of ScalarsCoding in proto/cluster.proto. Each coding holds
// every value the one before it in this order does (kF32 all of them).
enum class ScalarsCoding : int { kF32 = 0, kU8 = 1, kI16 = 2 };

// Bytes a sample: 4, 1, 2.
size_t ScalarsCodingBytes(ScalarsCoding coding);

// The most samples a sender puts in one piece of one coding.
inline constexpr size_t kScalarsPiece = size_t{1} << 18;

// The narrowest coding in which each of `values` comes back bit for bit:
// kU8 when every value is an integer in [0, 255], else kI16 when every one
// is an integer in [-32768, 32767], else kF32 (-0, NaN, infinities and
// fractions are kF32 only). kU8 for no values.
ScalarsCoding NarrowestCoding(const float* values, size_t n);

// Appends `n` values in `coding`.
// REQUIRES: `coding` gives each of them back (it is NarrowestCoding's
// answer for them, or kI16 where that is kU8, or kF32).
void AppendScalars(const float* values, size_t n, ScalarsCoding coding, std::string* out);

// Decodes `bytes` coded in `coding` (a ScalarsCoding value, as it arrived)
// into out[0 .. k) and returns k, the samples they hold; an error naming
// the fault for a coding this build does not know, bytes that are not a
// whole number of samples, or more than `room` samples.
absl::StatusOr<size_t> DecodeScalars(std::string_view bytes, int coding, float* out, size_t room);

}  // namespace transtick

#endif  // TRANSTICK_SCALAR_CODEC_H_
