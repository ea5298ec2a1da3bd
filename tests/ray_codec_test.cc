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
  // No deposit; spawned without a primary; a varint of 11 bytes; a 32-bit
  // varint with a 33rd bit; a step below pixel 0.
  EXPECT_NE(message(std::string("\x02\x00\x00\x00\x00\x00\x00", 7), 8).find("invalid"),
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
      ASSERT_GT(uint64_t{r.primaries} + r.shadows, 0u);
    }
  }
}

}  // namespace
}  // namespace transtick
