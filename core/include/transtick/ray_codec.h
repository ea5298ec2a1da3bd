// The wire form of ray descriptors and deposits: fixed-size little-endian
// records, every field bit for bit (docs/formats.md, "Ray descriptor"), so a
// ray resumed on another node continues exactly as it would have here.
#ifndef TRANSTICK_RAY_CODEC_H_
#define TRANSTICK_RAY_CODEC_H_

#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "transtick/ray.h"

namespace transtick {

inline constexpr size_t kRayRecordBytes = 106;
inline constexpr size_t kDepositRecordBytes = 20;

void AppendRay(const RayDescriptor& ray, std::string* out);
void AppendDeposit(const Deposit& deposit, std::string* out);

// Decodes a batch of records. Fails when the size is not a whole number of
// records or a record is invalid (unknown kind, non-finite geometry, pixel
// at or beyond `pixel_limit`), naming the record.
absl::StatusOr<std::vector<RayDescriptor>> DecodeRays(std::string_view bytes, uint32_t pixel_limit);
absl::StatusOr<std::vector<Deposit>> DecodeDeposits(std::string_view bytes, uint32_t pixel_limit);

// Float arrays on the wire (slab scalars, image rows): little-endian f32.
void AppendFloats(const float* values, size_t n, std::string* out);
// Decodes bytes.size() / 4 floats into `out`.
// REQUIRES: bytes.size() is a multiple of 4; `out` holds that many floats.
void DecodeFloats(std::string_view bytes, float* out);

}  // namespace transtick

#endif  // TRANSTICK_RAY_CODEC_H_
