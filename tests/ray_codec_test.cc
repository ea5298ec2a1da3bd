#include "transtick/ray_codec.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "gtest/gtest.h"
#include "transtick/framebuffer.h"
#include "transtick/scalar_codec.h"

namespace transtick {
namespace {

RayDescriptor Sample(uint32_t pixel) {
  RayDescriptor r;
  r.origin = {1.0 / 3, -2.5e-300, 7e12};
  r.direction = {-0.1, 0.2, std::nextafter(1.0, 2.0)};
  r.t = 12.000000000000002;
  r.t_start = 3.25;
  r.cell = {-1, 70000, 5};
  r.pixel = pixel;
  r.sample = 123456;
  r.kind = RayKind::kShadow;
  r.material = 254;
  r.spawned = 65535;
  r.color = {0.1f, std::numeric_limits<float>::denorm_min(), -0.0f};
  r.transmittance = 0.999999f;
  return r;
}

TEST(RayCodecTest, RoundTripsBitForBit) {
  std::string wire;
  for (uint32_t p = 0; p < 5; ++p) AppendRay(Sample(p), &wire);
  ASSERT_EQ(wire.size(), 5 * kRayRecordBytes);
  auto rays = DecodeRays(wire, 5);
  ASSERT_TRUE(rays.ok()) << rays.status();
  for (uint32_t p = 0; p < 5; ++p) {
    RayDescriptor want = Sample(p);
    const RayDescriptor& got = (*rays)[p];
    for (int a = 0; a < 3; ++a) {
      EXPECT_EQ(std::bit_cast<uint64_t>(want.origin[a]), std::bit_cast<uint64_t>(got.origin[a]));
      EXPECT_EQ(std::bit_cast<uint64_t>(want.direction[a]),
                std::bit_cast<uint64_t>(got.direction[a]));
      EXPECT_EQ(want.cell[a], got.cell[a]);
    }
    EXPECT_EQ(std::memcmp(&want.t, &got.t, 8), 0);
    EXPECT_EQ(want.pixel, got.pixel);
    EXPECT_EQ(want.sample, got.sample);
    EXPECT_EQ(want.kind, got.kind);
    EXPECT_EQ(want.material, got.material);
    EXPECT_EQ(want.spawned, got.spawned);
    EXPECT_EQ(std::memcmp(want.color.data(), got.color.data(), 12), 0);
    EXPECT_EQ(want.transmittance, got.transmittance);
  }
}

// The byte offsets of docs/formats.md, little-endian whatever the host.
TEST(RayCodecTest, FieldsSitAtTheDocumentedOffsets) {
  auto u32 = [](const std::string& w, size_t at) {
    uint32_t v = 0;
    for (int i = 0; i < 4; ++i) v |= uint32_t{static_cast<uint8_t>(w[at + i])} << (8 * i);
    return v;
  };
  auto u64 = [&](const std::string& w, size_t at) {
    return uint64_t{u32(w, at)} | (uint64_t{u32(w, at + 4)} << 32);
  };
  RayDescriptor r = Sample(3);
  r.t = 2.5;
  r.cell = {7, -1, 9};
  r.pixel = 0x01020304;
  r.kind = RayKind::kShadow;
  r.material = 5;
  r.spawned = 0x0a0b;
  r.transmittance = 0.25f;
  r.band = 0x0c0d;
  std::string w;
  AppendRay(r, &w);
  ASSERT_EQ(w.size(), 106u);
  EXPECT_EQ(u64(w, 0), std::bit_cast<uint64_t>(r.origin[0]));
  EXPECT_EQ(u64(w, 24), std::bit_cast<uint64_t>(r.direction[0]));
  EXPECT_EQ(u64(w, 48), std::bit_cast<uint64_t>(2.5));
  EXPECT_EQ(u32(w, 64), 7u);
  EXPECT_EQ(u32(w, 68), 0xffffffffu);
  EXPECT_EQ(u32(w, 76), 0x01020304u);
  EXPECT_EQ(w[84], 1);
  EXPECT_EQ(w[85], 5);
  EXPECT_EQ(u32(w, 86) & 0xffff, 0x0a0bu);
  EXPECT_EQ(u32(w, 100), std::bit_cast<uint32_t>(0.25f));
  EXPECT_EQ(static_cast<uint8_t>(w[104]) | (static_cast<uint8_t>(w[105]) << 8), 0x0c0d);
  std::string d;
  AppendDeposit(Deposit{0x00ab00cd, RayKind::kPrimary, 3, {1.0f, 0.5f, 0.0f}}, &d);
  ASSERT_EQ(d.size(), 20u);
  EXPECT_EQ(u32(d, 0), 0x00ab00cdu);
  EXPECT_EQ(d[4], 0);
  EXPECT_EQ(d[5], 0);
  EXPECT_EQ(u32(d, 6) & 0xffff, 3u);
  EXPECT_EQ(u32(d, 8), 0x3f800000u);
  EXPECT_EQ(u32(d, 12), 0x3f000000u);
  std::string f;
  const float values[2] = {1.0f, -2.0f};
  AppendFloats(values, 2, &f);
  EXPECT_EQ(f, std::string("\x00\x00\x80\x3f\x00\x00\x00\xc0", 8));
  float back[2];
  DecodeFloats(f, back);
  EXPECT_EQ(back[0], 1.0f);
  EXPECT_EQ(back[1], -2.0f);
}

TEST(RayCodecTest, RejectsBadBatches) {
  std::string wire;
  AppendRay(Sample(3), &wire);
  EXPECT_NE(DecodeRays(wire.substr(0, 50), 10).status().message().find("whole number"),
            std::string::npos);
  EXPECT_NE(DecodeRays(wire, 3).status().message().find("pixel 3 of 3"), std::string::npos);
  std::string bad_kind = wire;
  bad_kind[84] = 7;  // the kind byte
  EXPECT_FALSE(DecodeRays(bad_kind, 10).ok());
  RayDescriptor nan = Sample(0);
  nan.t = std::nan("");
  std::string w2;
  AppendRay(nan, &w2);
  EXPECT_NE(DecodeRays(w2, 10).status().message().find("non-finite"), std::string::npos);
  EXPECT_TRUE(DecodeRays("", 10).ok());
}

// ---------------------------------------------------------------- packed rays

// Packed rays read byte by byte as docs/formats.md ("Packed rays") describes
// them, independent of the codec: the 106-byte records rebuilt, or why the
// batch is broken. Records are not checked here (the fixed decoder does it).
struct ReferenceRays {
  std::vector<std::string> records;
  bool broken = false;
};
ReferenceRays ReferencePackedRays(std::string_view bytes) {
  ReferenceRays out;
  std::string record(kRayRecordBytes, '\0');
  size_t at = 0;
  auto varint32 = [&](uint32_t* v) {
    uint64_t x = 0;
    for (int shift = 0; at < bytes.size(); shift += 7) {
      const uint64_t b = static_cast<uint8_t>(bytes[at++]);
      if (shift >= 32 || (shift == 28 && (b & 0x7f) >> 4 != 0)) return false;
      x |= (b & 0x7f) << shift;
      if (b < 0x80) {
        *v = static_cast<uint32_t>(x);
        return true;
      }
    }
    return false;
  };
  auto u32 = [&](size_t o) {
    uint32_t v = 0;
    for (int i = 0; i < 4; ++i) v |= uint32_t{static_cast<uint8_t>(record[o + i])} << (8 * i);
    return v;
  };
  auto put32 = [&](size_t o, uint32_t v) {
    for (int i = 0; i < 4; ++i) record[o + i] = static_cast<char>(v >> (8 * i));
  };
  auto unzigzag = [](uint32_t z) { return (z >> 1) ^ (0u - (z & 1)); };
  // bit -> (offset, size); cell, pixel and sample are varints.
  const int offset[15] = {0, 8, 16, 24, 32, 40, 48, 56, 64, 76, 80, 84, 88, 100, 104};
  const int size[15] = {8, 8, 8, 8, 8, 8, 8, 8, 12, 4, 4, 4, 12, 4, 2};
  while (at < bytes.size()) {
    if (bytes.size() - at < 2) return {out.records, true};
    const uint32_t mask = static_cast<uint8_t>(bytes[at]) | static_cast<uint8_t>(bytes[at + 1])
                                                                << 8;
    at += 2;
    if (mask & 0x8000) return {out.records, true};
    for (int bit = 0; bit < 15; ++bit) {
      if (!(mask >> bit & 1)) continue;
      uint32_t v;
      if (bit == 8) {
        for (int a = 0; a < 3; ++a) {
          if (!varint32(&v)) return {out.records, true};
          put32(64 + 4 * a, u32(64 + 4 * a) + unzigzag(v));
        }
      } else if (bit == 9) {
        if (!varint32(&v)) return {out.records, true};
        put32(76, u32(76) + unzigzag(v));
      } else if (bit == 10) {
        if (!varint32(&v)) return {out.records, true};
        put32(80, v);
      } else {
        if (bytes.size() - at < static_cast<size_t>(size[bit])) return {out.records, true};
        record.replace(offset[bit], size[bit], bytes.substr(at, size[bit]));
        at += size[bit];
      }
    }
    out.records.push_back(record);
  }
  return out;
}

// A valid record with random bits in every field that allows them.
RayDescriptor RandomRay(std::mt19937_64& rng, uint32_t pixels) {
  auto f64 = [&] {
    for (;;) {
      const double d = std::bit_cast<double>(rng());
      if (std::isfinite(d)) return d;
    }
  };
  auto f32 = [&] { return std::bit_cast<float>(static_cast<uint32_t>(rng())); };
  RayDescriptor r;
  for (int a = 0; a < 3; ++a) {
    r.origin[a] = f64();
    r.direction[a] = f64();
    r.cell[a] = static_cast<int32_t>(rng());
  }
  if (r.direction.x == 0) r.direction.x = 1;
  r.t = f64();
  r.t_start = f64();
  r.pixel = static_cast<uint32_t>(rng() % pixels);
  r.sample = static_cast<uint32_t>(rng() >> (rng() % 64));
  r.kind = static_cast<RayKind>(rng() & 1);
  r.material = static_cast<uint8_t>(rng());
  r.spawned = static_cast<uint16_t>(rng());
  r.color = {f32(), f32(), f32()};
  r.transmittance = f32();
  r.band = static_cast<uint16_t>(rng());
  return r;
}

// Batches as a worker's neighbours see them: rays that share some fields
// with the ray before (the eye, the light, the plane) and change others, by
// a little or at random.
std::string RandomRayRecords(std::mt19937_64& rng, uint32_t pixels, int count) {
  std::string records;
  RayDescriptor r = RandomRay(rng, pixels);
  for (int i = 0; i < count; ++i) {
    const RayDescriptor fresh = RandomRay(rng, pixels);
    const uint64_t change = rng();
    for (int a = 0; a < 3; ++a) {
      if (change >> a & 1) r.origin[a] = fresh.origin[a];
      if (change >> (3 + a) & 1) r.direction[a] = fresh.direction[a];
      if (change >> (6 + a) & 1) r.cell[a] += static_cast<int32_t>(rng() % 5) - 2;
    }
    if (change >> 9 & 1) r.cell = fresh.cell;
    if (change >> 10 & 1) r.t = fresh.t;
    if (change >> 11 & 1) r.t_start = fresh.t_start;
    if (change >> 12 & 1) r.pixel = (r.pixel + 1 + rng() % 3) % pixels;
    if (change >> 13 & 1) r.pixel = fresh.pixel;
    if (change >> 14 & 1) r.sample = fresh.sample;
    if (change >> 15 & 1) r.kind = fresh.kind;
    if (change >> 16 & 1) r.material = fresh.material;
    if (change >> 17 & 1) r.spawned = fresh.spawned;
    if (change >> 18 & 1) r.color = fresh.color;
    if (change >> 19 & 1) r.transmittance = fresh.transmittance;
    if (change >> 20 & 1) r.band = fresh.band;
    AppendRay(r, &records);
  }
  return records;
}

std::string Records(const std::vector<RayDescriptor>& rays) {
  std::string out;
  for (const RayDescriptor& r : rays) AppendRay(r, &out);
  return out;
}

TEST(RayCodecTest, PackedRaysRebuildEveryRecordBitForBit) {
  std::mt19937_64 rng(20261206);
  size_t records = 0, packed_bytes = 0, batches_with_omissions = 0;
  for (int batch = 0; batch < 3000; ++batch) {
    const uint32_t pixels = 1 + static_cast<uint32_t>(rng() % 100000);
    const int count = static_cast<int>(rng() % 40);
    const std::string in = RandomRayRecords(rng, pixels, count);
    std::string wire = "kept";  // packing appends
    ASSERT_EQ(PackRays(in, &wire), static_cast<size_t>(count));
    ASSERT_EQ(wire.substr(0, 4), "kept");
    wire.erase(0, 4);
    const DecodedRays got = DecodePackedRays(wire, pixels);
    ASSERT_FALSE(got.broken) << got.error;
    ASSERT_EQ(got.invalid, 0u) << got.error;
    ASSERT_EQ(got.records, static_cast<size_t>(count));
    ASSERT_EQ(Records(got.rays), in) << "batch " << batch;
    // The reference reads the same records from the same bytes.
    const ReferenceRays want = ReferencePackedRays(wire);
    ASSERT_FALSE(want.broken);
    ASSERT_EQ(want.records.size(), static_cast<size_t>(count));
    for (int i = 0; i < count; ++i) {
      ASSERT_EQ(want.records[i], in.substr(i * kRayRecordBytes, kRayRecordBytes));
    }
    records += count;
    packed_bytes += wire.size();
    batches_with_omissions += wire.size() < in.size();
  }
  // Shared fields were left out: well under the fixed records' size.
  EXPECT_GT(records, 50000u);
  EXPECT_LT(packed_bytes, records * kRayRecordBytes * 3 / 4);
  EXPECT_GT(batches_with_omissions, 2500u);
}

TEST(RayCodecTest, PackedRaysKnownBytes) {
  RayDescriptor a;  // zero but for its direction and pixel
  a.origin = {0, 0, 0};
  a.direction = {1, 0, 0};
  a.t = 0;
  a.pixel = 3;
  a.kind = RayKind::kPrimary;
  a.transmittance = 0;
  a.band = 0;
  RayDescriptor b = a;
  b.pixel = 2;
  b.cell = {0, 5, -1};
  std::string wire;
  ASSERT_EQ(PackRays(Records({a, b, b}), &wire), 3u);
  const std::string want = std::string("\x08\x02", 2) +                       // direction x, pixel
                           std::string("\0\0\0\0\0\0\xf0\x3f", 8) + "\x06" +  // 1.0; +3
                           std::string("\x00\x03", 2) + std::string("\x00\x0a\x01", 3) +
                           "\x01" +                 // cell +0 +5 -1, pixel -1
                           std::string("\0\0", 2);  // the same record again
  EXPECT_EQ(wire, want);
  const DecodedRays got = DecodePackedRays(wire, 4);
  ASSERT_TRUE(got.error.ok()) << got.error;
  EXPECT_EQ(Records(got.rays), Records({a, b, b}));
}

TEST(RayCodecTest, BrokenPackedRayBatchesAreRefusedByName) {
  RayDescriptor a = Sample(1);
  std::string wire;
  PackRays(Records({a, a}), &wire);  // a whole record, then a mask of 0
  ASSERT_EQ(wire.substr(wire.size() - 2), std::string("\0\0", 2));
  auto refused = [](std::string_view bytes, const std::string& why) {
    const DecodedRays got = DecodePackedRays(bytes, 10);
    EXPECT_TRUE(got.broken) << why;
    EXPECT_TRUE(got.rays.empty());
    EXPECT_NE(got.error.message().find(why), std::string::npos) << got.error;
  };
  refused(wire.substr(0, wire.size() - 1), "record 1 is cut short in its mask");
  refused(wire.substr(0, 30), "record 0 is cut short or has a bad varint in field 3");
  refused(wire + std::string("\x00\x80", 2), "record 2 has an unknown field (mask 32768)");
  // Cell deltas whose varint runs past 32 bits, or past the end.
  refused(std::string("\x00\x01\xff\xff\xff\xff\x7f\x00\x00", 9), "bad varint in field 8");
  refused(std::string("\x00\x02\x80", 3), "record 0 is cut short or has a bad varint in field 9");
  // A record that breaks the rules is dropped alone: the one after it is
  // read against its bytes and kept.
  std::string records = Records({a});
  records[84] = 7;  // kind
  RayDescriptor c = a;
  c.pixel = 2;
  records += Records({c});
  std::string mixed;
  PackRays(records, &mixed);
  const DecodedRays got = DecodePackedRays(mixed, 10);
  EXPECT_FALSE(got.broken);
  EXPECT_EQ(got.records, 2u);
  EXPECT_EQ(got.invalid, 1u);
  EXPECT_NE(got.error.message().find("record 0 is invalid (kind 7"), std::string::npos)
      << got.error;
  ASSERT_EQ(got.rays.size(), 1u);
  EXPECT_EQ(Records(got.rays), Records({c}));
  EXPECT_TRUE(DecodePackedRays("", 10).error.ok());
}

// Hostile bytes: random batches cut, flipped and padded. The codec reads
// what the reference reads, refuses what it refuses, and keeps only valid
// records in the image.
TEST(RayCodecTest, PackedRaysDecodeAsTheFormatReadsOnAnyBytes) {
  std::mt19937_64 rng(7);
  int broken = 0, whole = 0, with_invalid = 0;
  for (int batch = 0; batch < 20000; ++batch) {
    const uint32_t pixels = 1 + static_cast<uint32_t>(rng() % 5000);
    std::string wire;
    PackRays(RandomRayRecords(rng, pixels + pixels / 8 * static_cast<uint32_t>(rng() % 2),
                              1 + static_cast<int>(rng() % 12)),
             &wire);
    switch (rng() % 4) {
      case 0:
        wire.resize(rng() % (wire.size() + 1));
        break;
      case 1:
        for (int k = 0; k < 3; ++k)
          wire[rng() % wire.size()] ^= static_cast<char>(1 << (rng() % 8));
        break;
      case 2:
        wire.insert(rng() % (wire.size() + 1), 1, static_cast<char>(rng()));
        break;
      default:
        break;
    }
    const ReferenceRays want = ReferencePackedRays(wire);
    const DecodedRays got = DecodePackedRays(wire, pixels);
    ASSERT_EQ(got.broken, want.broken) << batch << ": " << got.error;
    if (got.broken) {
      ASSERT_EQ(got.records, want.records.size()) << batch;
      ASSERT_NE(got.error.message().find(absl::StrCat("record ", got.records, " ")),
                std::string::npos)
          << got.error;
      ++broken;
      continue;
    }
    ++whole;
    ASSERT_EQ(got.records, want.records.size());
    // The kept records are exactly the reference's records that the fixed
    // decoder accepts.
    std::string kept;
    size_t invalid = 0;
    for (const std::string& r : want.records) {
      if (DecodeRays(r, pixels).ok()) {
        kept += r;
      } else {
        ++invalid;
      }
    }
    ASSERT_EQ(got.invalid, invalid) << batch;
    ASSERT_EQ(Records(got.rays), kept) << batch;
    for (const RayDescriptor& r : got.rays) ASSERT_LT(r.pixel, pixels);
    with_invalid += invalid > 0;
  }
  EXPECT_GT(broken, 3000);
  EXPECT_GT(whole, 8000);
  EXPECT_GT(with_invalid, 1000);
}

// Two framebuffers hold the same sums, counts and completions.
void ExpectSameFramebuffers(const Framebuffer& a, const Framebuffer& b) {
  ASSERT_EQ(a.complete_pixels(), b.complete_pixels());
  const Image x = a.Resolve(), y = b.Resolve();
  ASSERT_EQ(x.rgb.size(), y.rgb.size());
  for (size_t i = 0; i < x.rgb.size(); ++i) {
    ASSERT_EQ(std::bit_cast<uint32_t>(x.rgb[i]), std::bit_cast<uint32_t>(y.rgb[i])) << i;
  }
}

TEST(RayCodecTest, PackedDepositsAddUpToTheDepositsBitForBit) {
  // Random frames of deposits (runs of one pixel, as a primary and its
  // shadows come; odd colours among them), queued as records in batches
  // cut anywhere, packed, decoded and added: the same image, completions
  // and pixels as adding every deposit, in far fewer bytes.
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0, 1);
  const float odd[] = {0.0f,  -0.0f,  1e-30f,        -2.5f,
                       3e38f, -3e38f, std::nanf(""), std::numeric_limits<float>::infinity()};
  size_t records_bytes = 0, packed_bytes = 0;
  for (int frame = 0; frame < 300; ++frame) {
    const int width = 1 + rng() % 40, height = 1 + rng() % 40, samples = 1 + rng() % 3;
    const uint32_t pixels = static_cast<uint32_t>(width * height);
    std::vector<Deposit> all;
    for (uint32_t p = 0; p < pixels; ++p) {
      for (int s = 0; s < samples; ++s) {
        Deposit primary{p, RayKind::kPrimary, static_cast<uint16_t>(rng() % 4), {}};
        for (float& c : primary.color) c = rng() % 40 == 0 ? odd[rng() % 8] : u(rng);
        all.push_back(primary);
        for (int k = 0; k < primary.spawned; ++k) {
          Deposit shadow{p, RayKind::kShadow, 0, {u(rng), u(rng), rng() % 3 ? u(rng) : 0.0f}};
          all.push_back(shadow);
        }
      }
    }
    // Some deposits of a pixel come apart, as from other nodes.
    for (int k = 0; k < static_cast<int>(all.size()) / 8; ++k) {
      std::swap(all[rng() % all.size()], all[rng() % all.size()]);
    }
    Framebuffer direct(width, height, samples), packed(width, height, samples);
    for (const Deposit& d : all) direct.Add(d);
    size_t at = 0;
    while (at < all.size()) {
      const size_t n = std::min(all.size() - at, size_t{1} + rng() % 64);
      std::string records, wire;
      for (size_t i = at; i < at + n; ++i) AppendDeposit(all[i], &records);
      at += n;
      const size_t count = PackDeposits(records, &wire);
      records_bytes += records.size();
      packed_bytes += wire.size();
      auto decoded = DecodePackedDeposits(wire, pixels);
      ASSERT_TRUE(decoded.ok()) << decoded.status();
      ASSERT_EQ(decoded->size(), count);
      for (const PixelDeposits& d : *decoded) packed.Add(d);
    }
    ExpectSameFramebuffers(direct, packed);
    ASSERT_TRUE(packed.Complete());
  }
  EXPECT_LT(packed_bytes, records_bytes * 6 / 10) << packed_bytes << " of " << records_bytes;
}

// Packed deposits as docs/formats.md reads them, a byte at a time: the
// reference the display's decoder must agree with on any bytes.
absl::StatusOr<std::vector<PixelDeposits>> ReferenceDecode(std::string_view bytes, uint32_t limit) {
  std::vector<PixelDeposits> out;
  size_t at = 0;
  // A varint of at most `bits` bits; false when cut short or longer.
  auto varint = [&](int bits, uint64_t* v) {
    *v = 0;
    for (int shift = 0; at < bytes.size(); shift += 7) {
      const uint64_t b = static_cast<uint8_t>(bytes[at++]);
      if (shift >= bits || (shift + 7 > bits && (b & 0x7f) >> (bits - shift) != 0)) return false;
      *v |= (b & 0x7f) << shift;
      if (b < 0x80) return true;
    }
    return false;
  };
  uint32_t previous = 0;
  while (at < bytes.size()) {
    // step, primaries, spawned, shadows; a run's pixels and primaries when
    // those three are 0; the sums.
    uint64_t f[4], run[2] = {0, 0}, sum[3];
    bool whole = true;
    for (int k = 0; k < 4 && whole; ++k) whole = varint(32, &f[k]);
    const bool is_run = whole && (f[1] | f[2] | f[3]) == 0;
    for (int k = 0; k < 2 && whole && is_run; ++k) whole = varint(32, &run[k]);
    for (int k = 0; k < 3 && whole; ++k) whole = varint(64, &sum[k]);
    if (!whole) {
      return absl::InvalidArgumentError(absl::StrCat("deposit batch: record ", out.size(),
                                                     " is cut short or has a varint too long"));
    }
    PixelDeposits d;
    const uint32_t z = static_cast<uint32_t>(f[0]);
    d.pixel = previous + static_cast<uint32_t>((z >> 1) ^ (0u - (z & 1)));
    for (int c = 0; c < 3; ++c)
      d.sum[c] = static_cast<int64_t>((sum[c] >> 1) ^ (0ull - (sum[c] & 1)));
    if (is_run) {
      d.pixels = static_cast<uint32_t>(run[0]);
      d.primaries = static_cast<uint32_t>(run[1]);
      if (d.pixel >= limit || d.pixels == 0 || uint64_t{d.pixel} + d.pixels > limit ||
          d.primaries == 0) {
        return absl::InvalidArgumentError(absl::StrCat(
            "deposit batch: run record ", out.size(), " is invalid (pixels ", d.pixel, " + ",
            d.pixels, " of ", limit, ", ", d.primaries, " primary deposits each)"));
      }
    } else {
      d.primaries = static_cast<uint32_t>(f[1]);
      d.spawned = static_cast<uint32_t>(f[2]);
      d.shadows = static_cast<uint32_t>(f[3]);
      if (d.pixel >= limit || (d.primaries == 0 && d.spawned != 0)) {
        return absl::InvalidArgumentError(
            absl::StrCat("deposit batch: pixel record ", out.size(), " is invalid (pixel ", d.pixel,
                         " of ", limit, ", ", d.primaries, " primary and ", d.shadows,
                         " shadow deposits, ", d.spawned, " spawned)"));
      }
    }
    previous = d.pixel + d.pixels - 1;
    out.push_back(d);
  }
  return out;
}

// A varint of v in `extra` more bytes than it needs (zero groups with the
// continuation bit: still a valid varint when it stays within its width).
void PutVarintPadded(uint64_t v, int extra, std::string* out) {
  do {
    const bool more = (v >> 7) != 0 || extra > 0;
    out->push_back(static_cast<char>((v & 0x7f) | (more ? 0x80 : 0)));
    v >>= 7;
  } while (v != 0);
  for (int k = 0; k < extra; ++k) out->push_back(static_cast<char>(k + 1 < extra ? 0x80 : 0));
}

TEST(RayCodecTest, PackedDepositsDecodeAsTheFormatReadsOnAnyBytes) {
  // The display's decoder reads most records without bounds checks, eight
  // bytes at a time. On 30,000 batches of records whose fields take every
  // length (padded varints, 32-bit fields of 5 bytes, sums of 10, some too
  // long), cut anywhere and with bytes changed, it must give what the
  // format's byte-at-a-time reading gives: the same records, or the same
  // error naming the same record.
  std::mt19937_64 rng(11);
  const uint32_t limit = 1000;
  int ok = 0, failed = 0, runs = 0;
  for (int batch = 0; batch < 30000; ++batch) {
    std::string bytes;
    const int records = static_cast<int>(rng() % 40);
    uint32_t previous = 0;
    for (int r = 0; r < records; ++r) {
      const uint32_t pixel = static_cast<uint32_t>(rng() % (limit + 2));
      const int32_t step = static_cast<int32_t>(pixel - previous);
      previous = pixel;
      uint64_t f[7] = {
          (static_cast<uint32_t>(step) << 1) ^ (0u - (static_cast<uint32_t>(step) >> 31)),
          1 + rng() % 3,
          rng() % 4,
          rng() % 4,
          0,
          0,
          0};
      // A run record now and then: three zeros, then its pixels (some
      // past the image, some none) and primaries (some none).
      const bool run = rng() % 6 == 0;
      uint64_t run_fields[2] = {rng() % 16 == 0 ? 0 : 1 + rng() % (rng() % 16 == 0 ? limit : 30),
                                rng() % 16 == 0 ? 0 : 1 + rng() % 3};
      if (run) {
        f[1] = f[2] = f[3] = 0;
        if (run_fields[0] > 0) previous += static_cast<uint32_t>(run_fields[0] - 1);
      }
      for (int c = 4; c < 7; ++c) {
        switch (rng() % 4) {
          case 0:
            f[c] = 0;
            break;
          case 1:
            f[c] = rng() % (uint64_t{1} << 34);
            break;
          case 2:
            f[c] = rng() >> (rng() % 64);
            break;
          default:
            f[c] = rng();
            break;
        }
      }
      if (rng() % 50 == 0) f[rng() % 4] = rng() >> 32;  // a 32-bit field of 5 bytes
      for (int k = 0; k < 7; ++k) {
        // Mostly minimal; sometimes padded, within the width or past it.
        const int extra = rng() % 10 == 0 ? static_cast<int>(rng() % 6) : 0;
        PutVarintPadded(f[k], extra, &bytes);
        if (k == 3 && run) {
          for (uint64_t v : run_fields) PutVarintPadded(v, rng() % 20 == 0 ? 1 : 0, &bytes);
        }
      }
    }
    for (int k = rng() % 3 == 0 ? static_cast<int>(rng() % 4) : 0; k > 0 && !bytes.empty(); --k) {
      bytes[rng() % bytes.size()] = static_cast<char>(rng());
    }
    if (rng() % 4 == 0) bytes.resize(rng() % (bytes.size() + 1));
    const auto want = ReferenceDecode(bytes, limit);
    const auto got = DecodePackedDeposits(bytes, limit);
    ASSERT_EQ(got.ok(), want.ok()) << batch << ": " << got.status() << " / " << want.status();
    if (!want.ok()) {
      ASSERT_EQ(got.status().message(), want.status().message()) << batch;
      ++failed;
      continue;
    }
    ++ok;
    ASSERT_EQ(got->size(), want->size()) << batch;
    for (size_t i = 0; i < want->size(); ++i) {
      const PixelDeposits &a = (*got)[i], &b = (*want)[i];
      ASSERT_TRUE(a.pixel == b.pixel && a.pixels == b.pixels && a.primaries == b.primaries &&
                  a.spawned == b.spawned && a.shadows == b.shadows && a.sum == b.sum)
          << batch << " record " << i;
      runs += a.pixels > 1;
    }
  }
  // Both outcomes were tried many times, and runs among what decoded.
  EXPECT_GT(ok, 3000);
  EXPECT_GT(failed, 3000);
  EXPECT_GT(runs, 1000);
}

TEST(RayCodecTest, AddPackedDepositsAddsAWholeBatchOrNothing) {
  // A batch added by AddPackedDeposits gives the framebuffer (sums,
  // completions) of its records added one at a time; a batch with a bad
  // record anywhere leaves the framebuffer as it was.
  std::mt19937 rng(12);
  for (int round = 0; round < 200; ++round) {
    const int width = 1 + rng() % 30, height = 1 + rng() % 30;
    const uint32_t pixels = static_cast<uint32_t>(width * height);
    Framebuffer one(width, height), batched(width, height);
    uint64_t completed_one = 0;
    for (int b = 0; b < 4; ++b) {
      std::string records, wire;
      for (uint32_t p = 0; p < pixels; ++p) {
        if (rng() % 2) continue;
        AppendDeposit(Deposit{p, RayKind::kPrimary, 0, {0.25f * (rng() % 5), 0.5f, 1.0f}},
                      &records);
      }
      PackDeposits(records, &wire);
      if (rng() % 3 == 0 && !wire.empty()) {
        // A bad record at the end: a pixel past the image.
        PutVarintPadded(uint64_t{pixels} * 4, 0, &wire);
        wire += std::string("\x01\x00\x00\x00\x00\x00", 6);
        const Image before = batched.Resolve();
        const uint64_t complete = batched.complete_pixels();
        auto added = AddPackedDeposits(wire, batched);
        ASSERT_FALSE(added.ok());
        EXPECT_NE(added.status().message().find("invalid"), std::string::npos);
        ASSERT_EQ(batched.complete_pixels(), complete);
        ASSERT_EQ(batched.Resolve().rgb, before.rgb);
        continue;
      }
      auto decoded = DecodePackedDeposits(wire, pixels);
      ASSERT_TRUE(decoded.ok());
      uint64_t deposits = 0;
      for (const PixelDeposits& d : *decoded) {
        completed_one += one.Add(d);
        deposits += d.primaries + d.shadows;
      }
      auto added = AddPackedDeposits(wire, batched);
      ASSERT_TRUE(added.ok()) << added.status();
      EXPECT_EQ(added->records, decoded->size());
      EXPECT_EQ(added->deposits, deposits);
    }
    EXPECT_EQ(one.complete_pixels(), completed_one);
    ExpectSameFramebuffers(one, batched);
  }
}

TEST(RayCodecTest, PackedDepositsKnownBytes) {
  std::string records, wire;
  AppendDeposit(Deposit{7, RayKind::kPrimary, 1, {0.5f, 0.25f, 1}}, &records);
  AppendDeposit(Deposit{7, RayKind::kShadow, 0, {0.125f, 0, 0}}, &records);
  AppendDeposit(Deposit{5, RayKind::kPrimary, 0, {0, 0, 0}}, &records);
  ASSERT_EQ(PackDeposits(records, &wire), 2u);
  // Pixel 7 (step +7: zigzag 14), 1 primary, 1 spawned, 1 shadow, red
  // 0.625 * 2^32 (zigzag 0x140000000: 5 bytes), green 2^30, blue 2^32;
  // then pixel 5 (step -2: zigzag 3), 1 primary, nothing else.
  const std::string expected =
      std::string("\x0e\x01\x01\x01", 4) + std::string("\x80\x80\x80\x80\x14", 5) +
      std::string("\x80\x80\x80\x80\x08", 5) + std::string("\x80\x80\x80\x80\x20", 5) +
      std::string("\x03\x01\x00\x00\x00\x00\x00", 7);
  EXPECT_EQ(wire, expected);
  auto d = DecodePackedDeposits(wire, 8);
  ASSERT_TRUE(d.ok()) << d.status();
  ASSERT_EQ(d->size(), 2u);
  EXPECT_EQ((*d)[0].pixel, 7u);
  EXPECT_EQ((*d)[0].sum[0], Framebuffer::ToFixed(0.5f) + Framebuffer::ToFixed(0.125f));
  EXPECT_EQ((*d)[1].pixel, 5u);
  EXPECT_EQ((*d)[1].primaries, 1u);
}

TEST(RayCodecTest, MissRunsPackAsRunRecordsThatAddAsTheirDeposits) {
  // A node queues the misses of a row's pixels as miss runs among its other
  // deposits (RingLayout::Primaries). Packed in batches of any size and
  // added by the display, they must leave the framebuffer each deposit
  // added one by one leaves, count every deposit, and take a few bytes a
  // run however many pixels it covers.
  std::mt19937 rng(21);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  uint64_t run_pixels = 0;
  for (int frame = 0; frame < 300; ++frame) {
    const int width = 1 + rng() % 60, height = 1 + rng() % 30, samples = 1 + rng() % 4;
    const uint32_t pixels = static_cast<uint32_t>(width * height);
    const std::array<float, 3> background = {u(rng), rng() % 2 ? 0.0f : u(rng), 0.25f};
    std::string records;
    std::vector<Deposit> all;  // the same deposits one by one
    for (uint32_t p = 0; p < pixels;) {
      if (rng() % 3 == 0) {
        const uint32_t n = std::min<uint32_t>(pixels - p, 1 + rng() % 40);
        AppendMissRun(p, n, samples, background, &records);
        for (uint32_t k = 0; k < n; ++k) {
          for (int s = 0; s < samples; ++s)
            all.push_back({p + k, RayKind::kPrimary, 0, background});
        }
        run_pixels += n;
        p += n;
        continue;
      }
      for (int s = 0; s < samples; ++s) {
        // Some traced misses too, with the background's very deposit.
        Deposit primary{p, RayKind::kPrimary, static_cast<uint16_t>(rng() % 3), {}};
        if (rng() % 4 == 0) primary = {p, RayKind::kPrimary, 0, background};
        for (float& c : primary.color) c = primary.spawned ? u(rng) : c;
        AppendDeposit(primary, &records);
        all.push_back(primary);
        for (int k = 0; k < primary.spawned; ++k) {
          const Deposit shadow{p, RayKind::kShadow, 0, {u(rng), u(rng), u(rng)}};
          AppendDeposit(shadow, &records);
          all.push_back(shadow);
        }
      }
      ++p;
    }
    Framebuffer direct(width, height, samples), packed(width, height, samples);
    for (const Deposit& d : all) direct.Add(d);
    uint64_t deposits = 0, added_deposits = 0;
    for (size_t at = 0; at < records.size();) {
      const size_t n = std::min(records.size() - at, kDepositRecordBytes * (1 + rng() % 50));
      std::string wire;
      const size_t count = PackDeposits(std::string_view(records).substr(at, n), &wire, &deposits);
      at += n;
      auto added = AddPackedDeposits(wire, packed);
      ASSERT_TRUE(added.ok()) << added.status();
      ASSERT_EQ(added->records, count);
      added_deposits += added->deposits;
    }
    ASSERT_EQ(deposits, all.size());
    ASSERT_EQ(added_deposits, all.size());
    ExpectSameFramebuffers(direct, packed);
    ASSERT_TRUE(packed.Complete());
  }
  EXPECT_GT(run_pixels, 20000u);
}

TEST(RayCodecTest, MissRunsKnownBytes) {
  // Two runs that follow one another with the same deposits become one run
  // record; the next record's step counts from its last pixel.
  std::string records, wire;
  AppendMissRun(3, 4, 2, {0.5f, 0, 0}, &records);
  AppendMissRun(7, 2, 2, {0.5f, 0, 0}, &records);
  AppendDeposit(Deposit{9, RayKind::kPrimary, 0, {0, 0, 0}}, &records);
  AppendMissRun(10, 1, 1, {0.5f, 0, 0}, &records);
  uint64_t deposits = 0;
  ASSERT_EQ(PackDeposits(records, &wire, &deposits), 3u);
  EXPECT_EQ(deposits, 12u + 1u + 1u);
  // Pixel 3 (zigzag 6), 0, 0, 0, 6 pixels, 2 primaries each, red
  // 2 * 0.5 * 2^32 (zigzag 2^33: 5 bytes), green, blue 0; pixel 9 (step +1
  // from pixel 8), 1 primary; pixel 10, a run of one as a pixel record.
  const std::string expected =
      std::string("\x06\x00\x00\x00\x06\x02", 6) + std::string("\x80\x80\x80\x80\x20\x00\x00", 7) +
      std::string("\x02\x01\x00\x00\x00\x00\x00", 7) + std::string("\x02\x01\x00\x00", 4) +
      std::string("\x80\x80\x80\x80\x10\x00\x00", 7);
  EXPECT_EQ(wire, expected);
  auto d = DecodePackedDeposits(wire, 11);
  ASSERT_TRUE(d.ok()) << d.status();
  ASSERT_EQ(d->size(), 3u);
  EXPECT_EQ((*d)[0].pixel, 3u);
  EXPECT_EQ((*d)[0].pixels, 6u);
  EXPECT_EQ((*d)[0].primaries, 2u);
  EXPECT_EQ((*d)[0].sum[0], 2 * Framebuffer::ToFixed(0.5f));
  EXPECT_EQ((*d)[1].pixel, 9u);
  EXPECT_EQ((*d)[2].pixel, 10u);
  EXPECT_EQ((*d)[2].pixels, 1u);
  EXPECT_FALSE(DecodePackedDeposits(wire, 10).ok());
  // However many pixels, a run takes a record: 65,535 pixels of a grey
  // background in 24 bytes.
  records.clear();
  wire.clear();
  AppendMissRun(1000, kMaxRunRecordPixels, 1, {0.25f, 0.25f, 0.25f}, &records);
  ASSERT_EQ(PackDeposits(records, &wire), 1u);
  EXPECT_EQ(wire.size(), 24u);
}

TEST(RayCodecTest, PackedDepositsRefuseBadRecordsByName) {
  std::string records, wire;
  AppendDeposit(Deposit{7, RayKind::kPrimary, 2, {0.5f, 0.25f, 1}}, &records);
  PackDeposits(records, &wire);
  auto message = [](std::string_view bytes, uint32_t limit) {
    auto d = DecodePackedDeposits(bytes, limit);
    return d.ok() ? std::string("ok") : std::string(d.status().message());
  };
  EXPECT_NE(message(wire, 7).find("pixel 7 of 7"), std::string::npos);
  for (size_t n = 1; n < wire.size(); ++n) {
    EXPECT_NE(message(wire.substr(0, n), 8).find("cut short"), std::string::npos) << n;
  }
  // A run of no pixel, of no deposit, past the image, or wrapping past
  // 2^32; spawned without a primary; a varint of 11 bytes; a 32-bit
  // varint with a 33rd bit; a step below pixel 0.
  const std::string sums("\x00\x00\x00", 3);
  EXPECT_NE(
      message(std::string("\x02\x00\x00\x00\x00\x01", 6) + sums, 8).find("run record 0 is invalid"),
      std::string::npos);
  EXPECT_NE(
      message(std::string("\x02\x00\x00\x00\x02\x00", 6) + sums, 8).find("run record 0 is invalid"),
      std::string::npos);
  EXPECT_EQ(message(std::string("\x02\x00\x00\x00\x07\x01", 6) + sums, 8), "ok");
  EXPECT_NE(message(std::string("\x02\x00\x00\x00\x08\x01", 6) + sums, 8).find("pixels 1 + 8 of 8"),
            std::string::npos);
  EXPECT_NE(message(std::string("\x02\x00\x00\x00\xff\xff\xff\xff\x0f\x01", 10) + sums, 8)
                .find("run record 0 is invalid"),
            std::string::npos);
  EXPECT_NE(message(std::string("\x02\x00\x00\x00\x02\x01", 6), 8).find("cut short"),
            std::string::npos);
  EXPECT_NE(message(std::string("\x02\x00\x01\x01\x00\x00\x00", 7), 8).find("invalid"),
            std::string::npos);
  EXPECT_NE(message(std::string("\x02\x01\x00\x00", 4) + std::string(10, '\xff') + "\x01" +
                        std::string("\x00\x00", 2),
                    8)
                .find("too long"),
            std::string::npos);
  EXPECT_NE(
      message(std::string("\x02\xff\xff\xff\xff\x1f\x00\x00\x00\x00\x00", 11), 8).find("too long"),
      std::string::npos);
  EXPECT_NE(message(std::string("\x01\x01\x00\x00\x00\x00\x00", 7), 8).find("pixel 4294967295"),
            std::string::npos);
  EXPECT_EQ(message("", 8), "ok");
  // Hostile bytes: never a crash; what decodes is in the image and holds a
  // deposit.
  std::mt19937 rng(4);
  for (int i = 0; i < 20000; ++i) {
    std::string bytes = wire + wire;
    for (int k = 0; k < 1 + static_cast<int>(rng() % 4); ++k) {
      bytes[rng() % bytes.size()] = static_cast<char>(rng());
    }
    bytes.resize(rng() % (bytes.size() + 1));
    auto d = DecodePackedDeposits(bytes, 64);
    if (!d.ok()) continue;
    for (const PixelDeposits& r : *d) {
      ASSERT_LT(r.pixel, 64u);
      ASSERT_GE(r.pixels, 1u);
      ASSERT_LE(uint64_t{r.pixel} + r.pixels, 64u);
      ASSERT_GT(uint64_t{r.primaries} + r.shadows, 0u);
    }
  }
}

// The coding docs/formats.md ("Slab scalars") gives `values`, worked out in
// double: integers in [0, 255], else in [-32768, 32767], else floats; -0,
// NaN and infinities are floats.
ScalarsCoding ExpectedCoding(const std::vector<float>& values) {
  ScalarsCoding c = ScalarsCoding::kU8;
  for (float v : values) {
    const double d = v;
    if (!std::isfinite(d) || d != std::trunc(d) || (d == 0 && std::signbit(d)) || d < -32768 ||
        d > 32767) {
      return ScalarsCoding::kF32;
    }
    if (d < 0 || d > 255) c = ScalarsCoding::kI16;
  }
  return c;
}

// The bytes of `values` in `coding`, written out as the format says.
std::string ExpectedBytes(const std::vector<float>& values, ScalarsCoding coding) {
  std::string out;
  for (float v : values) {
    uint32_t bits = coding == ScalarsCoding::kF32
                        ? std::bit_cast<uint32_t>(v)
                        : static_cast<uint32_t>(static_cast<int32_t>(std::lround(v)));
    for (size_t k = 0; k < ScalarsCodingBytes(coding); ++k) {
      out.push_back(static_cast<char>((bits >> (8 * k)) & 0xff));
    }
  }
  return out;
}

TEST(ScalarCodecTest, EachPieceTakesTheNarrowestCodingThatGivesItBackBitForBit) {
  // Values on and past every coding's edges, the signed zeros, NaNs with
  // payloads, infinities, fractions a float away from integers, denormals
  // and the ends of int32, mixed into runs of every length modulo the
  // vector loops.
  const float nan_payload = std::bit_cast<float>(0x7fc01234u);
  const float neg_nan = std::bit_cast<float>(0xffc00000u);
  const std::vector<float> special = {0.0f,
                                      -0.0f,
                                      1.0f,
                                      255.0f,
                                      256.0f,
                                      -1.0f,
                                      32767.0f,
                                      32768.0f,
                                      -32768.0f,
                                      -32769.0f,
                                      65535.0f,
                                      0.5f,
                                      std::nextafter(255.0f, 0.0f),
                                      std::nextafter(1.0f, 2.0f),
                                      std::numeric_limits<float>::quiet_NaN(),
                                      nan_payload,
                                      neg_nan,
                                      std::numeric_limits<float>::infinity(),
                                      -std::numeric_limits<float>::infinity(),
                                      std::numeric_limits<float>::denorm_min(),
                                      2147483648.0f,
                                      -2147483648.0f,
                                      4294967296.0f,
                                      1e30f,
                                      -1e30f};
  std::mt19937 rng(20261207);
  int seen[3] = {0, 0, 0};
  for (int round = 0; round < 3000; ++round) {
    const size_t n = rng() % (round % 10 == 0 ? 5000 : 70);
    const int kind = round % 4;  // bytes, shorts, anything, bytes with one odd value
    std::vector<float> values(n);
    for (float& v : values) {
      if (kind == 0) {
        v = static_cast<float>(rng() % 256);
      } else if (kind == 1) {
        v = static_cast<float>(static_cast<int>(rng() % 65536) - 32768);
      } else {
        v = rng() % 3 == 0 ? special[rng() % special.size()]
                           : std::bit_cast<float>(static_cast<uint32_t>(rng()));
      }
    }
    if (kind == 3 && n > 0) values[rng() % n] = special[rng() % special.size()];
    const ScalarsCoding expected = ExpectedCoding(values);
    ASSERT_EQ(NarrowestCoding(values.data(), n), expected) << "round " << round << ", n " << n;
    ++seen[static_cast<int>(expected)];
    // In its own coding and every wider one: the format's bytes, and back
    // bit for bit.
    std::vector<ScalarsCoding> codings = {expected};
    if (expected == ScalarsCoding::kU8) codings.push_back(ScalarsCoding::kI16);
    if (expected != ScalarsCoding::kF32) codings.push_back(ScalarsCoding::kF32);
    for (ScalarsCoding c : codings) {
      std::string bytes = "prefix";
      AppendScalars(values.data(), n, c, &bytes);
      ASSERT_EQ(bytes.substr(6), ExpectedBytes(values, c)) << "round " << round;
      std::vector<float> back(n + 3, 7.0f);
      auto got =
          DecodeScalars(std::string_view(bytes).substr(6), static_cast<int>(c), back.data(), n);
      ASSERT_TRUE(got.ok()) << got.status();
      ASSERT_EQ(*got, n);
      for (size_t i = 0; i < n; ++i) {
        ASSERT_EQ(std::bit_cast<uint32_t>(back[i]), std::bit_cast<uint32_t>(values[i]))
            << "round " << round << " sample " << i;
      }
      EXPECT_EQ(back[n], 7.0f);  // nothing written past the samples
    }
  }
  for (int c = 0; c < 3; ++c) EXPECT_GT(seen[c], 100) << "coding " << c;
}

TEST(ScalarCodecTest, EveryByteAndShortDecodesToItsInteger) {
  std::string bytes;
  for (int v = 0; v < 65536; ++v) {
    bytes.push_back(static_cast<char>(v & 0xff));
    bytes.push_back(static_cast<char>(v >> 8));
  }
  std::vector<float> out(65536 * 2);
  auto n = DecodeScalars(bytes, static_cast<int>(ScalarsCoding::kI16), out.data(), out.size());
  ASSERT_TRUE(n.ok());
  ASSERT_EQ(*n, 65536u);
  for (int v = 0; v < 65536; ++v) ASSERT_EQ(out[v], static_cast<float>(static_cast<int16_t>(v)));
  n = DecodeScalars(bytes, static_cast<int>(ScalarsCoding::kU8), out.data(), out.size());
  ASSERT_TRUE(n.ok());
  ASSERT_EQ(*n, 131072u);
  for (size_t i = 0; i < bytes.size(); ++i) {
    ASSERT_EQ(out[i], static_cast<float>(static_cast<uint8_t>(bytes[i])));
  }
}

TEST(ScalarCodecTest, BrokenScalarsAreRefusedByName) {
  std::vector<float> out(4);
  auto refused = [&](std::string_view bytes, int coding, size_t room, std::string_view why) {
    auto n = DecodeScalars(bytes, coding, out.data(), room);
    ASSERT_FALSE(n.ok()) << "coding " << coding << ", " << bytes.size() << " bytes";
    EXPECT_EQ(n.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(std::string(n.status().message()).find(why), std::string::npos) << n.status();
  };
  refused("abcd", 3, 4, "unknown coding 3");
  refused("abcd", -1, 4, "unknown coding -1");
  refused("abc", static_cast<int>(ScalarsCoding::kI16), 4, "3 bytes are not a whole number of 2");
  refused("abcdef", static_cast<int>(ScalarsCoding::kF32), 4, "not a whole number of 4");
  refused("abcde", static_cast<int>(ScalarsCoding::kU8), 4, "5 samples where 4 were left");
  refused("abcdefghij", static_cast<int>(ScalarsCoding::kI16), 4, "5 samples where 4");
  auto none = DecodeScalars("", static_cast<int>(ScalarsCoding::kI16), out.data(), 0);
  ASSERT_TRUE(none.ok());
  EXPECT_EQ(*none, 0u);
}

}  // namespace
}  // namespace transtick
