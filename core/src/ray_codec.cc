#include "transtick/ray_codec.h"

#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "coding.h"
#include "transtick/check.h"
#include "transtick/framebuffer.h"

namespace transtick {
namespace {

[[maybe_unused]] void PutF32(std::string* out, float v) {
  PutFixed32(out, std::bit_cast<uint32_t>(v));
}

bool GetF64(Decoder& in, double* v) {
  uint32_t lo, hi;
  if (!in.GetFixed32(&lo) || !in.GetFixed32(&hi)) return false;
  *v = std::bit_cast<double>(uint64_t{lo} | (uint64_t{hi} << 32));
  return true;
}
bool GetF32(Decoder& in, float* v) {
  uint32_t bits;
  if (!in.GetFixed32(&bits)) return false;
  *v = std::bit_cast<float>(bits);
  return true;
}

absl::Status CheckSize(std::string_view bytes, size_t record, const char* what) {
  if (bytes.size() % record != 0) {
    return absl::InvalidArgumentError(absl::StrCat(what, " batch of ", bytes.size(),
                                                   " bytes is not a whole number of ", record,
                                                   "-byte records"));
  }
  return absl::OkStatus();
}

}  // namespace

void AppendRay(const RayDescriptor& r, std::string* out) {
  // One record built on the stack, appended at once.
  char b[kRayRecordBytes];
  char* p = b;
  for (int a = 0; a < 3; ++a) p = EncodeFixed64(p, std::bit_cast<uint64_t>(r.origin[a]));
  for (int a = 0; a < 3; ++a) p = EncodeFixed64(p, std::bit_cast<uint64_t>(r.direction[a]));
  p = EncodeFixed64(p, std::bit_cast<uint64_t>(r.t));
  p = EncodeFixed64(p, std::bit_cast<uint64_t>(r.t_start));
  for (int a = 0; a < 3; ++a) p = EncodeFixed32(p, static_cast<uint32_t>(r.cell[a]));
  p = EncodeFixed32(p, r.pixel);
  p = EncodeFixed32(p, r.sample);
  *p++ = static_cast<char>(r.kind);
  *p++ = static_cast<char>(r.material);
  p = EncodeFixed16(p, r.spawned);
  for (int c = 0; c < 3; ++c) p = EncodeFixed32(p, std::bit_cast<uint32_t>(r.color[c]));
  p = EncodeFixed32(p, std::bit_cast<uint32_t>(r.transmittance));
  p = EncodeFixed16(p, r.band);
  out->append(b, p - b);
}

void AppendDeposit(const Deposit& d, std::string* out) {
  char b[kDepositRecordBytes];
  char* p = EncodeFixed32(b, d.pixel);
  *p++ = static_cast<char>(d.kind);
  *p++ = 0;
  p = EncodeFixed16(p, d.spawned);
  for (int c = 0; c < 3; ++c) p = EncodeFixed32(p, std::bit_cast<uint32_t>(d.color[c]));
  out->append(b, p - b);
}

namespace {

// Reads one whole record (kRayRecordBytes at `b`) into `r`; false, with why
// in `*why`, when it breaks the rules of docs/formats.md, "Ray descriptor".
bool ReadRayRecord(const char* b, uint32_t pixel_limit, RayDescriptor* r, std::string* why) {
  Decoder in(std::string_view(b, kRayRecordBytes));
  uint32_t cell[3];
  uint8_t kind;
  bool ok = true;
  for (int a = 0; a < 3; ++a) ok = ok && GetF64(in, &r->origin[a]);
  for (int a = 0; a < 3; ++a) ok = ok && GetF64(in, &r->direction[a]);
  ok = ok && GetF64(in, &r->t) && GetF64(in, &r->t_start);
  for (int a = 0; a < 3; ++a) ok = ok && in.GetFixed32(&cell[a]);
  ok = ok && in.GetFixed32(&r->pixel) && in.GetFixed32(&r->sample) && in.GetByte(&kind) &&
       in.GetByte(&r->material) && in.GetFixed16(&r->spawned);
  for (int c = 0; c < 3; ++c) ok = ok && GetF32(in, &r->color[c]);
  ok = ok && GetF32(in, &r->transmittance) && in.GetFixed16(&r->band);
  TRANSTICK_CHECK(ok);  // a whole record
  for (int a = 0; a < 3; ++a) r->cell[a] = static_cast<int32_t>(cell[a]);
  bool finite = std::isfinite(r->t) && std::isfinite(r->t_start);
  for (int a = 0; a < 3; ++a)
    finite = finite && std::isfinite(r->origin[a]) && std::isfinite(r->direction[a]);
  if (kind > 1 || !finite || r->pixel >= pixel_limit ||
      (r->direction.x == 0 && r->direction.y == 0 && r->direction.z == 0)) {
    *why = absl::StrCat("kind ", int{kind}, ", pixel ", r->pixel, " of ", pixel_limit,
                        finite ? "" : ", non-finite geometry");
    return false;
  }
  r->kind = static_cast<RayKind>(kind);
  return true;
}

// The fields of a packed ray record (docs/formats.md, "Packed rays"): the
// bytes of the fixed record each covers, and how it is written.
enum class FieldCoding : uint8_t { kRaw, kCellDeltas, kPixelDelta, kVarint };
struct PackedField {
  uint8_t offset, size;
  FieldCoding coding;
};
constexpr PackedField kPackedFields[] = {
    {0, 8, FieldCoding::kRaw},          {8, 8, FieldCoding::kRaw},          // origin x, y
    {16, 8, FieldCoding::kRaw},         {24, 8, FieldCoding::kRaw},         // origin z, direction x
    {32, 8, FieldCoding::kRaw},         {40, 8, FieldCoding::kRaw},         // direction y, z
    {48, 8, FieldCoding::kRaw},         {56, 8, FieldCoding::kRaw},         // t, t_start
    {64, 12, FieldCoding::kCellDeltas}, {76, 4, FieldCoding::kPixelDelta},  // cell, pixel
    {80, 4, FieldCoding::kVarint},                                          // sample
    {84, 4, FieldCoding::kRaw},                                       // kind, material, spawned
    {88, 12, FieldCoding::kRaw},        {100, 4, FieldCoding::kRaw},  // color, transmittance
    {104, 2, FieldCoding::kRaw},                                      // band
};
constexpr int kPackedFieldCount = sizeof(kPackedFields) / sizeof(kPackedFields[0]);
static_assert(kPackedFieldCount == 15 && kPackedFields[14].offset + 2 == kRayRecordBytes);
// The mask, every raw field and the widest varints: a record's most bytes.
constexpr size_t kMaxPackedRayBytes = 2 + kRayRecordBytes + 3 * 1 + 1 + 1;

uint32_t LoadU32(const char* p) {
  return uint32_t{static_cast<uint8_t>(p[0])} | uint32_t{static_cast<uint8_t>(p[1])} << 8 |
         uint32_t{static_cast<uint8_t>(p[2])} << 16 | uint32_t{static_cast<uint8_t>(p[3])} << 24;
}
void StoreU32(char* p, uint32_t v) { EncodeFixed32(p, v); }

}  // namespace

absl::StatusOr<std::vector<RayDescriptor>> DecodeRays(std::string_view bytes,
                                                      uint32_t pixel_limit) {
  if (auto s = CheckSize(bytes, kRayRecordBytes, "ray"); !s.ok()) return s;
  std::vector<RayDescriptor> rays(bytes.size() / kRayRecordBytes);
  std::string why;
  for (size_t i = 0; i < rays.size(); ++i) {
    if (!ReadRayRecord(bytes.data() + i * kRayRecordBytes, pixel_limit, &rays[i], &why)) {
      return absl::InvalidArgumentError(
          absl::StrCat("ray batch: record ", i, " is invalid (", why, ")"));
    }
  }
  return rays;
}

namespace {

// One field of a packed ray record, the field number a constant so that
// each compare and copy is of a known size.
template <size_t F>
inline void PackField(const char* record, const char* previous, uint16_t* mask, char** out) {
  constexpr PackedField field = kPackedFields[F];
  const char* now = record + field.offset;
  const char* was = previous + field.offset;
  if (std::memcmp(now, was, field.size) == 0) return;
  *mask |= static_cast<uint16_t>(1u << F);
  char* p = *out;
  if constexpr (field.coding == FieldCoding::kRaw) {
    std::memcpy(p, now, field.size);
    p += field.size;
  } else if constexpr (field.coding == FieldCoding::kCellDeltas) {
    for (int a = 0; a < 3; ++a) {
      p = EncodeVarint64(
          p, ZigZag32(static_cast<int32_t>(LoadU32(now + 4 * a) - LoadU32(was + 4 * a))));
    }
  } else if constexpr (field.coding == FieldCoding::kPixelDelta) {
    p = EncodeVarint64(p, ZigZag32(static_cast<int32_t>(LoadU32(now) - LoadU32(was))));
  } else {
    p = EncodeVarint64(p, LoadU32(now));
  }
  *out = p;
}
template <size_t... F>
inline char* PackFields(const char* record, const char* previous, uint16_t* mask, char* out,
                        std::index_sequence<F...>) {
  (PackField<F>(record, previous, mask, &out), ...);
  return out;
}

// One field of a packed ray record read into `record` when the mask has
// it; false when it is cut short or a varint is too long.
template <size_t F>
inline bool UnpackField(uint16_t mask, Decoder& in, char* record) {
  if (!(mask >> F & 1)) return true;
  constexpr PackedField field = kPackedFields[F];
  char* at = record + field.offset;
  uint32_t v;
  if constexpr (field.coding == FieldCoding::kRaw) {
    return in.GetBytes(at, field.size);
  } else if constexpr (field.coding == FieldCoding::kCellDeltas) {
    for (int a = 0; a < 3; ++a) {
      if (!in.GetVarint32(&v)) return false;
      StoreU32(at + 4 * a, LoadU32(at + 4 * a) + static_cast<uint32_t>(UnZigZag32(v)));
    }
    return true;
  } else if constexpr (field.coding == FieldCoding::kPixelDelta) {
    if (!in.GetVarint32(&v)) return false;
    StoreU32(at, LoadU32(at) + static_cast<uint32_t>(UnZigZag32(v)));
    return true;
  } else {
    if (!in.GetVarint32(&v)) return false;
    StoreU32(at, v);
    return true;
  }
}
// Reads the fields the mask names; -1, or the number of the field that is
// cut short or has a varint too long.
template <size_t... F>
inline int UnpackFields(uint16_t mask, Decoder& in, char* record, std::index_sequence<F...>) {
  int failed = -1;
  (void)((UnpackField<F>(mask, in, record) || (failed = static_cast<int>(F), false)) && ...);
  return failed;
}

}  // namespace

size_t PackRays(std::string_view records, std::string* out) {
  static constexpr char kZero[kRayRecordBytes] = {};
  const size_t count = records.size() / kRayRecordBytes;
  // Written in place, then cut to what was written.
  const size_t start = out->size();
  out->resize(start + count * kMaxPackedRayBytes);
  char* p = out->data() + start;
  const char* previous = kZero;
  for (size_t i = 0; i < count; ++i) {
    const char* r = records.data() + i * kRayRecordBytes;
    uint16_t mask = 0;
    char* end =
        PackFields(r, previous, &mask, p + 2, std::make_index_sequence<kPackedFieldCount>());
    EncodeFixed16(p, mask);
    p = end;
    previous = r;
  }
  out->resize(static_cast<size_t>(p - out->data()));
  return count;
}

DecodedRays DecodePackedRays(std::string_view bytes, uint32_t pixel_limit) {
  DecodedRays result;
  char record[kRayRecordBytes] = {};
  Decoder in(bytes);
  // Rays take about 50 bytes each (at most 2: a mask alone).
  result.rays.reserve(bytes.size() / 48);
  std::string why;
  auto broken = [&](const std::string& what) {
    result.rays.clear();
    result.broken = true;
    result.error = absl::InvalidArgumentError(
        absl::StrCat("packed ray batch: record ", result.records, " ", what));
    return result;
  };
  while (in.remaining() > 0) {
    uint16_t mask;
    if (!in.GetFixed16(&mask)) return broken("is cut short in its mask");
    if (mask >> kPackedFieldCount) {
      return broken(absl::StrCat("has an unknown field (mask ", mask, ")"));
    }
    const int failed =
        UnpackFields(mask, in, record, std::make_index_sequence<kPackedFieldCount>());
    if (failed >= 0) {
      return broken(absl::StrCat("is cut short or has a bad varint in field ", failed));
    }
    RayDescriptor ray;
    if (ReadRayRecord(record, pixel_limit, &ray, &why)) {
      result.rays.push_back(ray);
    } else if (result.invalid++ == 0) {
      result.error = absl::InvalidArgumentError(
          absl::StrCat("packed ray batch: record ", result.records, " is invalid (", why, ")"));
    }
    ++result.records;
  }
  return result;
}

// The widest pixel record: four varints of 32 bits and three of 64; a run
// record has two more of 32 bits.
constexpr size_t kMaxPixelRecordBytes = 4 * 5 + 3 * 10;
constexpr size_t kMaxRecordBytes = kMaxPixelRecordBytes + 2 * 5;
// A queued miss run's kind byte (docs/formats.md, "Deposit").
constexpr uint8_t kMissRunKind = 2;

void AppendMissRun(uint32_t first, uint32_t pixels, int per_pixel,
                   const std::array<float, 3>& color, std::string* out) {
  char b[kDepositRecordBytes];
  char* p = EncodeFixed32(b, first);
  *p++ = static_cast<char>(kMissRunKind);
  *p++ = static_cast<char>(per_pixel);
  p = EncodeFixed16(p, static_cast<uint16_t>(pixels));
  for (int c = 0; c < 3; ++c) p = EncodeFixed32(p, std::bit_cast<uint32_t>(color[c]));
  out->append(b, p - b);
}

std::vector<Deposit> UnpackDepositRecords(std::string_view records) {
  std::vector<Deposit> out;
  Decoder in(records);
  uint32_t pixel, bits;
  uint8_t kind, per_pixel;
  uint16_t field;
  while (in.GetFixed32(&pixel) && in.GetByte(&kind) && in.GetByte(&per_pixel) &&
         in.GetFixed16(&field)) {
    Deposit d;
    d.pixel = pixel;
    for (int c = 0; c < 3; ++c) {
      if (!in.GetFixed32(&bits)) return out;
      d.color[c] = std::bit_cast<float>(bits);
    }
    if (kind != kMissRunKind) {
      d.kind = static_cast<RayKind>(kind);
      d.spawned = field;
      out.push_back(d);
      continue;
    }
    for (uint32_t k = 0; k < field; ++k) {
      d.pixel = pixel + k;
      for (int e = 0; e < per_pixel; ++e) out.push_back(d);
    }
  }
  return out;
}

size_t PackDeposits(std::string_view records, std::string* out, uint64_t* deposits) {
  // The record being gathered: a pixel's deposits, or a run of pixels.
  PixelDeposits run;
  bool open = false;
  uint32_t previous = 0;  // the last pixel of the record written last
  size_t count = 0;
  uint64_t held = 0;
  auto emit = [&] {
    // One record on the stack, appended at once.
    char b[kMaxRecordBytes];
    char* p = EncodeVarint64(b, ZigZag32(static_cast<int32_t>(run.pixel - previous)));
    // A run of one pixel is that pixel's record.
    const bool as_run = run.pixels > 1;
    if (as_run) {
      p = EncodeVarint64(p, 0);
      p = EncodeVarint64(p, 0);
      p = EncodeVarint64(p, 0);
      p = EncodeVarint64(p, run.pixels);
    }
    p = EncodeVarint64(p, run.primaries);
    if (!as_run) {
      p = EncodeVarint64(p, run.spawned);
      p = EncodeVarint64(p, run.shadows);
    }
    for (int64_t v : run.sum) p = EncodeVarint64(p, ZigZag64(v));
    out->append(b, p - b);
    previous = run.pixel + run.pixels - 1;
    held += uint64_t{run.pixels} * (uint64_t{run.primaries} + run.shadows);
    ++count;
  };
  // The record's little-endian fields (docs/formats.md, "Deposit").
  constexpr auto u32 = LoadU32;
  for (size_t at = 0; at + kDepositRecordBytes <= records.size(); at += kDepositRecordBytes) {
    const char* r = records.data() + at;
    const uint32_t pixel = u32(r);
    const uint8_t kind = static_cast<uint8_t>(r[4]);
    const uint16_t field =
        static_cast<uint16_t>(static_cast<uint8_t>(r[6]) | static_cast<uint8_t>(r[7]) << 8);
    const uint32_t bits[3] = {u32(r + 8), u32(r + 12), u32(r + 16)};
    if (kind == kMissRunKind) {
      // Each of `field` pixels takes r[5] deposits of the colour.
      PixelDeposits each;
      each.pixel = pixel;
      each.pixels = field;
      each.primaries = static_cast<uint8_t>(r[5]);
      for (int c = 0; c < 3; ++c) {
        each.sum[c] = static_cast<int64_t>(
            static_cast<uint64_t>(Framebuffer::ToFixed(std::bit_cast<float>(bits[c]))) *
            each.primaries);
      }
      // A run that goes on from the one before, with the same deposits,
      // joins it; a pixel record of exactly those deposits may start it.
      const bool joins = open && run.shadows == 0 && run.spawned == 0 &&
                         run.primaries == each.primaries && run.sum == each.sum &&
                         pixel == run.pixel + run.pixels &&
                         run.pixels + each.pixels <= std::numeric_limits<uint32_t>::max() / 2;
      if (joins) {
        run.pixels += each.pixels;
        continue;
      }
      if (open) emit();
      run = each;
      open = true;
      continue;
    }
    if (open && (pixel != run.pixel || run.pixels > 1)) {
      emit();
      open = false;
    }
    if (!open) {
      run = PixelDeposits{};
      run.pixel = pixel;
      open = true;
    }
    if (kind == static_cast<uint8_t>(RayKind::kPrimary)) {
      ++run.primaries;
      run.spawned += field;
    } else {
      ++run.shadows;
    }
    for (int c = 0; c < 3; ++c) {
      run.sum[c] = static_cast<int64_t>(
          static_cast<uint64_t>(run.sum[c]) +
          static_cast<uint64_t>(Framebuffer::ToFixed(std::bit_cast<float>(bits[c]))));
    }
  }
  if (open) emit();
  if (deposits != nullptr) *deposits += held;
  return count;
}

namespace {

// A varint of at most 8 bytes at p, without bounds checks: the caller
// made sure 8 bytes may be read there. Returns its length, or 0 when it
// is longer (the checked decoder then takes the record). Without branches
// on the length, which varies from pixel to pixel: 8 bytes read at once,
// cut after the first with its top bit clear, their 7-bit groups joined.
inline int ShortVarint(const char* p, uint64_t* v) {
  // Most are one byte (counts, zero sums): that case first.
  if (static_cast<uint8_t>(*p) < 0x80) {
    *v = static_cast<uint8_t>(*p);
    return 1;
  }
  uint64_t x;
  std::memcpy(&x, p, 8);
  const uint64_t last = ~x & 0x8080808080808080ull;
  if (last == 0) return 0;
  const int bytes = (std::countr_zero(last) >> 3) + 1;
  x &= bytes == 8 ? ~0ull : (1ull << (8 * bytes)) - 1;
  x = ((x & 0x7f007f007f007f00ull) >> 1) | (x & 0x007f007f007f007full);
  x = ((x & 0x3fff00003fff0000ull) >> 2) | (x & 0x00003fff00003fffull);
  x = ((x & 0x0fffffff00000000ull) >> 4) | (x & 0x000000000fffffffull);
  *v = x;
  return bytes;
}

// One record at p, its fields in their varints' values (step and sums
// still zigzagged): f[0..3] step, primaries, spawned, shadows; a run
// record's pixels and primaries in f[7], f[8]; the sums in f[4..6]. The
// fast form: every varint short (a 32-bit field below 2^28, a sum below
// 2^56) and at least kMaxRecordBytes + 8 bytes from p on; returns the
// record's end, or null when it is not of that form.
inline const char* ShortRecord(const char* p, uint64_t f[9]) {
  for (int k = 0; k < 4; ++k) {
    const int n = ShortVarint(p, &f[k]);
    if (n == 0 || n > 4) return nullptr;
    p += n;
  }
  if ((f[1] | f[2] | f[3]) == 0) {
    for (int k = 7; k < 9; ++k) {
      const int n = ShortVarint(p, &f[k]);
      if (n == 0 || n > 4) return nullptr;
      p += n;
    }
  }
  for (int k = 4; k < 7; ++k) {
    const int n = ShortVarint(p, &f[k]);
    if (n == 0) return nullptr;
    p += n;
  }
  return p;
}

// Decodes packed deposits into `out` (cleared first, its memory kept).
absl::Status DecodePackedInto(std::string_view bytes, uint32_t pixel_limit,
                              std::vector<PixelDeposits>* out) {
  out->clear();
  // A record takes at least 7 bytes.
  out->reserve(bytes.size() / 7);
  const char* const end = bytes.data() + bytes.size();
  const char* p = bytes.data();
  uint32_t previous = 0;
  while (p < end) {
    uint32_t step, primaries, spawned, shadows, run_pixels = 0, run_primaries = 0;
    uint64_t sum[3];
    uint64_t f[9];
    const char* next = nullptr;
    if constexpr (std::endian::native == std::endian::little) {
      if (static_cast<size_t>(end - p) >= kMaxRecordBytes + 8) next = ShortRecord(p, f);
    }
    if (next != nullptr) {
      step = static_cast<uint32_t>(f[0]);
      primaries = static_cast<uint32_t>(f[1]);
      spawned = static_cast<uint32_t>(f[2]);
      shadows = static_cast<uint32_t>(f[3]);
      if ((primaries | spawned | shadows) == 0) {
        run_pixels = static_cast<uint32_t>(f[7]);
        run_primaries = static_cast<uint32_t>(f[8]);
      }
      for (int c = 0; c < 3; ++c) sum[c] = f[4 + c];
    } else {
      // Near the end, or a long varint: the checked decoder.
      Decoder in(std::string_view(p, static_cast<size_t>(end - p)));
      bool whole = in.GetVarint32(&step) && in.GetVarint32(&primaries) &&
                   in.GetVarint32(&spawned) && in.GetVarint32(&shadows);
      if (whole && (primaries | spawned | shadows) == 0) {
        whole = in.GetVarint32(&run_pixels) && in.GetVarint32(&run_primaries);
      }
      whole =
          whole && in.GetVarint64(&sum[0]) && in.GetVarint64(&sum[1]) && in.GetVarint64(&sum[2]);
      if (!whole) {
        return absl::InvalidArgumentError(absl::StrCat("deposit batch: record ", out->size(),
                                                       " is cut short or has a varint too long"));
      }
      next = end - in.remaining();
    }
    p = next;
    PixelDeposits d;
    d.pixel = previous + static_cast<uint32_t>(UnZigZag32(step));
    for (int c = 0; c < 3; ++c) d.sum[c] = UnZigZag64(sum[c]);
    if ((primaries | spawned | shadows) == 0) {
      // A run record: `run_pixels` pixels from d.pixel on, each with
      // `run_primaries` primary deposits.
      d.pixels = run_pixels;
      d.primaries = run_primaries;
      if (d.pixel >= pixel_limit || run_pixels == 0 || run_pixels > pixel_limit - d.pixel ||
          run_primaries == 0) {
        return absl::InvalidArgumentError(absl::StrCat(
            "deposit batch: run record ", out->size(), " is invalid (pixels ", d.pixel, " + ",
            run_pixels, " of ", pixel_limit, ", ", run_primaries, " primary deposits each)"));
      }
    } else {
      d.primaries = primaries;
      d.spawned = spawned;
      d.shadows = shadows;
      if (d.pixel >= pixel_limit || (d.primaries == 0 && d.spawned != 0)) {
        return absl::InvalidArgumentError(
            absl::StrCat("deposit batch: pixel record ", out->size(), " is invalid (pixel ",
                         d.pixel, " of ", pixel_limit, ", ", d.primaries, " primary and ",
                         d.shadows, " shadow deposits, ", d.spawned, " spawned)"));
      }
    }
    previous = d.pixel + (d.pixels - 1);
    out->push_back(d);
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::vector<PixelDeposits>> DecodePackedDeposits(std::string_view bytes,
                                                                uint32_t pixel_limit) {
  std::vector<PixelDeposits> out;
  if (auto s = DecodePackedInto(bytes, pixel_limit, &out); !s.ok()) return s;
  return out;
}

absl::StatusOr<PackedDepositsAdded> AddPackedDeposits(std::string_view bytes, Framebuffer& fb) {
  // Decoded whole before any is added, so that a bad record leaves fb as it
  // was; into memory this thread keeps from batch to batch.
  thread_local std::vector<PixelDeposits> records;
  const uint32_t limit = static_cast<uint32_t>(fb.width()) * static_cast<uint32_t>(fb.height());
  if (auto s = DecodePackedInto(bytes, limit, &records); !s.ok()) return s;
  PackedDepositsAdded added;
  for (const PixelDeposits& d : records) {
    added.deposits += uint64_t{d.pixels} * (uint64_t{d.primaries} + d.shadows);
  }
  fb.Add(std::span<const PixelDeposits>(records));
  added.records = records.size();
  // A worker's batch (FrameOptions::deposit_batch) fits in what is kept;
  // the memory of a larger one goes back.
  if (records.capacity() > (size_t{1} << 16)) std::vector<PixelDeposits>().swap(records);
  return added;
}

void AppendFloats(const float* values, size_t n, std::string* out) {
  if constexpr (std::endian::native == std::endian::little) {
    out->append(reinterpret_cast<const char*>(values), n * sizeof(float));
  } else {
    out->reserve(out->size() + n * 4);
    for (size_t i = 0; i < n; ++i) PutF32(out, values[i]);
  }
}

void DecodeFloats(std::string_view bytes, float* out) {
  if constexpr (std::endian::native == std::endian::little) {
    std::memcpy(out, bytes.data(), bytes.size() / 4 * sizeof(float));
  } else {
    Decoder in(bytes);
    for (size_t i = 0; i < bytes.size() / 4; ++i) GetF32(in, &out[i]);
  }
}

}  // namespace transtick
