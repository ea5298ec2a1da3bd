#include "transtick/ray_codec.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "transtick/framebuffer.h"

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

}  // namespace
}  // namespace transtick
