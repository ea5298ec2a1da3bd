// The wire form of ray descriptors and deposits: fixed-size little-endian
// records, every field bit for bit (docs/formats.md, "Ray descriptor"), which
// a node queues and packs for its neighbour as the fields that differ from
// the record before, so that a ray resumed on another node continues
// exactly as it would have here; and deposits packed per pixel for the
// display.
#ifndef TRANSTICK_RAY_CODEC_H_
#define TRANSTICK_RAY_CODEC_H_

#include <array>
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
// A miss run as one queued record (docs/formats.md, "Deposit"): `pixels`
// consecutive pixels from `first` on, each with `per_pixel` primary
// deposits of `color` that spawned nothing.
// REQUIRES: 1 <= pixels <= 65535, 1 <= per_pixel <= kMaxDepositsPerRunPixel.
void AppendMissRun(uint32_t first, uint32_t pixels, int per_pixel,
                   const std::array<float, 3>& color, std::string* out);
inline constexpr int kMaxDepositsPerRunPixel = 64;
// The deposits queued records stand for, one by one: a miss run as the
// deposits of each of its pixels. For checks and benches (the display
// receives them packed). REQUIRES: whole records, as the two above write.
std::vector<Deposit> UnpackDepositRecords(std::string_view records);
inline constexpr uint32_t kMaxRunRecordPixels = 65535;

// Decodes a batch of ray records. Fails when the size is not a whole number
// of records or a record is invalid (unknown kind, non-finite geometry,
// pixel at or beyond `pixel_limit`), naming the record. (Ray and deposit
// records stay on their node: neighbours and the display receive them
// packed, below.)
absl::StatusOr<std::vector<RayDescriptor>> DecodeRays(std::string_view bytes, uint32_t pixel_limit);

// Packs queued ray records (AppendRay's) for a neighbour: each record as the
// fields that differ from the record before it (docs/formats.md, "Packed
// rays"), appended to `out`. Returns the number of records.
// REQUIRES: `records` is whole records.
size_t PackRays(std::string_view records, std::string* out);
// A batch of packed rays, decoded.
struct DecodedRays {
  std::vector<RayDescriptor> rays;  // the valid records, in order
  size_t records = 0;               // records read, valid or not
  size_t invalid = 0;               // records that break the rules, dropped
  // The batch's structure is broken (a record cut short, an unknown field,
  // a varint too long): nothing of it is kept, and `records` is the number
  // read before the broken one.
  bool broken = false;
  absl::Status error;  // the broken record, or the first invalid one, by number
};
// Rebuilds each record bit for bit and checks it as DecodeRays does.
DecodedRays DecodePackedRays(std::string_view bytes, uint32_t pixel_limit);

// Packs a batch of deposit records (AppendDeposit's and AppendMissRun's)
// for the display: consecutive deposits of one pixel merged into one pixel
// record, colours summed in the framebuffer's fixed point, and miss runs
// as run records, consecutive ones merged (docs/formats.md, "Packed
// deposits"), appended to `out`. Returns the number of records written;
// adds the deposits they hold to `*deposits` when it is given.
// REQUIRES: `records` is whole records of valid deposits and miss runs.
size_t PackDeposits(std::string_view records, std::string* out, uint64_t* deposits = nullptr);
// Decodes packed deposits (a run record as one PixelDeposits of its
// `pixels`). Fails, naming the record, when one is cut short or invalid (a
// varint too long, a pixel at or beyond `pixel_limit`, no deposit, spawned
// rays without a primary, a run of no pixel or past the limit).
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
