// The wire form of ray descriptors and deposits: fixed-size little-endian
// records, every field bit for bit (docs/formats.md, "Ray descriptor"), so a
// ray resumed on another node continues exactly as it would have here; and
// deposits packed per pixel for the display.
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

// Decodes a batch of ray records. Fails when the size is not a whole number
// of records or a record is invalid (unknown kind, non-finite geometry,
// pixel at or beyond `pixel_limit`), naming the record. (Deposit records
// stay on their node: the display receives them packed, below.)
absl::StatusOr<std::vector<RayDescriptor>> DecodeRays(std::string_view bytes, uint32_t pixel_limit);

// Packs a batch of deposit records (AppendDeposit's) for the display:
// consecutive deposits of one pixel merged into one pixel record, colours
// summed in the framebuffer's fixed point (docs/formats.md, "Packed
// deposits"), appended to `out`. Returns the number of pixel records.
// REQUIRES: `records` is whole records of valid deposits.
size_t PackDeposits(std::string_view records, std::string* out);
// Decodes packed deposits. Fails, naming the record, when one is cut short
// or invalid (a varint too long, a pixel at or beyond `pixel_limit`, no
// deposit, spawned rays without a primary).
absl::StatusOr<std::vector<PixelDeposits>> DecodePackedDeposits(std::string_view bytes,
                                                                 uint32_t pixel_limit);

class Framebuffer;
// What one batch of packed deposits added to a framebuffer.
struct PackedDepositsAdded {
  uint64_t records = 0;   // pixel records
  uint64_t deposits = 0;  // the deposits they merge
};
// The display's ingest: adds a batch of packed deposits to `fb`, all of it
// when every record is valid (as DecodePackedDeposits checks them, with
// fb's pixels as the limit), else none of it, and an error naming the
// record.
absl::StatusOr<PackedDepositsAdded> AddPackedDeposits(std::string_view bytes, Framebuffer& fb);

// Float arrays on the wire (slab scalars, image rows): little-endian f32.
void AppendFloats(const float* values, size_t n, std::string* out);
// Decodes bytes.size() / 4 floats into `out`.
// REQUIRES: bytes.size() is a multiple of 4; `out` holds that many floats.
void DecodeFloats(std::string_view bytes, float* out);

}  // namespace transtick

#endif  // TRANSTICK_RAY_CODEC_H_
