#include "transtick/ray_codec.h"

#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include "gtest/gtest.h"

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

TEST(RayCodecTest, Deposits) {
  std::string wire;
  AppendDeposit(Deposit{7, RayKind::kPrimary, 3, {0.5f, 0.25f, 1}}, &wire);
  AppendDeposit(Deposit{7, RayKind::kShadow, 0, {0.125f, 0, 0}}, &wire);
  auto d = DecodeDeposits(wire, 8);
  ASSERT_TRUE(d.ok()) << d.status();
  ASSERT_EQ(d->size(), 2u);
  EXPECT_EQ((*d)[0].spawned, 3);
  EXPECT_EQ((*d)[1].kind, RayKind::kShadow);
  EXPECT_EQ((*d)[0].color[1], 0.25f);
  EXPECT_FALSE(DecodeDeposits(wire, 7).ok());
  EXPECT_FALSE(DecodeDeposits(wire.substr(1), 8).ok());
}

}  // namespace
}  // namespace transtick
