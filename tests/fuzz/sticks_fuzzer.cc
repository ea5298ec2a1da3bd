// libFuzzer entry for the slab a worker receives (LoadSlab, FetchPlanes):
// sticks blocks (docs/formats.md, "Sticks block") and the brick map. The
// input edits the real blocks of a small synthetic slab (so that most
// inputs get past the first checks): it overwrites bytes at chosen offsets,
// truncates or drops blocks, and changes the slab's range and the largest
// material. Sticks::FromBlocks must give a status or sticks whose every
// track is sorted, disjoint and in range, and that encode and decode again
// to the same bytes; BrickMap::FromBytes must refuse any size but its own,
// and a map it accepts must encode to the same bytes and keep Reach's
// promise. The whole input is also read as a field summary
// (FieldSummary::FromBytes), which must refuse any size but its own and any
// byte naming no band; of one it accepts, every brick a ray's path passes
// through must have the band Clear accepted the path for. And it is read
// as a message's slab scalars (CheckScalars).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <vector>

#include "transtick/check.h"
#include "transtick/field_summary.h"
#include "transtick/isosurface.h"
#include "transtick/scalar_codec.h"
#include "transtick/scene.h"
#include "transtick/sticks.h"
#include "transtick/traversal.h"

namespace transtick::fuzz {
namespace {

constexpr std::array<int, 3> kDims = {40, 70, 36};
constexpr int kSummaryBands = 4;  // as fuzz_seeds.cc writes them

// The input as a message's slab scalars (docs/formats.md, "Slab
// scalars"): byte 0 the coding (3: one this build does not know), byte 1
// the room left, the rest the bytes. DecodeScalars must refuse them, saying
// why, or give samples that code back to the same bytes in their coding,
// and bit for bit through the narrowest coding of them.
void CheckScalars(const uint8_t* data, size_t size) {
  if (size < 2) return;
  const int coding = data[0] % 4;
  const std::string_view bytes(reinterpret_cast<const char*>(data) + 2, size - 2);
  std::vector<float> out(bytes.size() + 1);
  const size_t room = data[1] == 255 ? bytes.size() : data[1];
  auto n = DecodeScalars(bytes, coding, out.data(), room);
  if (!n.ok()) {
    TRANSTICK_CHECK(!n.status().message().empty());
    TRANSTICK_CHECK(coding == 3 || bytes.size() % ScalarsCodingBytes(ScalarsCoding(coding)) != 0 ||
                    bytes.size() / ScalarsCodingBytes(ScalarsCoding(coding)) > room);
    return;
  }
  TRANSTICK_CHECK(coding != 3 && *n <= room);
  std::string again;
  AppendScalars(out.data(), *n, ScalarsCoding(coding), &again);
  TRANSTICK_CHECK(again == bytes);
  const ScalarsCoding narrow = NarrowestCoding(out.data(), *n);
  TRANSTICK_CHECK(ScalarsCodingBytes(narrow) <= ScalarsCodingBytes(ScalarsCoding(coding)));
  std::string narrowed;
  AppendScalars(out.data(), *n, narrow, &narrowed);
  std::vector<float> back(*n + 1);
  auto m = DecodeScalars(narrowed, static_cast<int>(narrow), back.data(), *n);
  TRANSTICK_CHECK(m.ok() && *m == *n);
  TRANSTICK_CHECK(std::memcmp(back.data(), out.data(), *n * sizeof(float)) == 0);
}

// A summary read from the input: as FromBytes says, and the paths Clear
// accepts lie in bricks of their band (points 1/4 voxel apart, away from
// the bricks' faces, where the brick walk's rounding may go either way).
void CheckSummary(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  auto summary = FieldSummary::FromBytes(kDims, kSummaryBands, bytes);
  if (!summary.ok()) {
    TRANSTICK_CHECK(!summary.status().message().empty());
    return;
  }
  TRANSTICK_CHECK(std::string_view(reinterpret_cast<const char*>(summary->bytes().data()),
                                   summary->bytes().size()) == bytes);
  uint32_t state = 7;
  for (size_t i = 0; i < std::min<size_t>(size, 64); ++i) state = state * 31 + data[i];
  auto unit = [&] {
    state = state * 1664525u + 1013904223u;
    return (state >> 8) / 16777216.0;
  };
  for (int r = 0; r < 32; ++r) {
    const Vec3 o{unit() * kDims[0], unit() * kDims[1], unit() * kDims[2]};
    Vec3 d{unit() - 0.5, unit() - 0.5, unit() - 0.5};
    if (r % 4 == 0) d = {0, r % 8 ? 1.0 : -1.0, 0};
    d = d * (1 / Length(d));
    const RayAxes axes(d);
    const auto box = IntersectBox(o, d, kDims);
    if (!box) continue;
    const double t0 = std::max(0.0, (*box)[0]), t1 = (*box)[1];
    const Vec3 p0 = o + d * t0;
    int b0[3];
    for (int a = 0; a < 3; ++a) {
      b0[a] = std::clamp(static_cast<int>(std::floor((p0[a] + 0.5) / 8)), 0,
                         summary->brick_dims()[a] - 1);
    }
    const int band = summary->At(b0[0], b0[1], b0[2]);
    if (!summary->Clear(o, axes, t0, t1, band)) continue;
    for (double t = t0; t <= t1; t += 0.25) {
      const Vec3 p = o + d * t;
      int b[3];
      bool near_face = false;
      for (int a = 0; a < 3; ++a) {
        const double u = (p[a] + 0.5) / 8;
        near_face |= std::abs(u - std::round(u)) < 1e-9;
        b[a] = std::clamp(static_cast<int>(std::floor(u)), 0, summary->brick_dims()[a] - 1);
      }
      if (!near_face) TRANSTICK_CHECK_EQ(int{summary->At(b[0], b[1], b[2])}, band);
    }
  }
}

struct Base {
  std::vector<uint8_t> labels;
  std::vector<std::string> blocks;  // of the slab [10, 60)
};

const Base& GetBase() {
  static const Base* base = [] {
    auto* b = new Base;
    b->labels.resize(static_cast<size_t>(kDims[0]) * kDims[1] * kDims[2]);
    uint32_t state = 12345;
    for (int z = 0; z < kDims[2]; ++z)
      for (int y = 0; y < kDims[1]; ++y)
        for (int x = 0; x < kDims[0]; ++x) {
          state = state * 1664525u + 1013904223u;
          // Shells of three materials, and noise that makes short sticks.
          const int r2 = (x - 20) * (x - 20) + (y - 35) * (y - 35) + (z - 18) * (z - 18);
          uint8_t m = r2 < 100 ? 3 : (r2 < 225 ? 2 : (r2 < 400 ? 1 : 0));
          if ((state >> 28) == 0) m = static_cast<uint8_t>((state >> 20) % 4);
          b->labels[(static_cast<size_t>(z) * kDims[1] + y) * kDims[0] + x] = m;
        }
    b->blocks = Sticks::Encode(b->labels, kDims, 0, kDims[1]).EncodeRows(10, 60);
    return b;
  }();
  return *base;
}

void CheckSticks(const Sticks& s, int y_begin, int y_end, int max_material) {
  for (int y = y_begin; y < y_end; ++y) {
    for (int x = 0; x < kDims[0]; ++x) {
      int end = 0;
      for (const Stick& st : s.Track(x, y)) {
        TRANSTICK_CHECK_LE(end, static_cast<int>(st.begin));
        TRANSTICK_CHECK_LT(st.begin, st.end);
        TRANSTICK_CHECK_LE(static_cast<int>(st.end), kDims[2]);
        TRANSTICK_CHECK_GE(st.material, 1);
        TRANSTICK_CHECK_LE(static_cast<int>(st.material), max_material);
        end = st.end;
      }
    }
  }
  // Encoded and decoded again: the same sticks, the same bytes.
  const std::vector<std::string> once = s.EncodeRows(y_begin, y_end);
  auto again = Sticks::FromBlocks(kDims, y_begin, y_end, max_material, once);
  TRANSTICK_CHECK(again.ok());
  TRANSTICK_CHECK(again->EncodeRows(y_begin, y_end) == once);
}

}  // namespace
}  // namespace transtick::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace transtick;
  using namespace transtick::fuzz;
  const Base& base = GetBase();
  CheckSummary(data, size);
  CheckScalars(data, size);
  if (size < 2) return 0;
  // Byte 0: the slab asked for (inside, or past, the blocks' [10, 60)) and
  // the largest material; byte 1: blocks dropped or truncated.
  const int y_begin = 10 + (data[0] & 3) * 5 - 5;  // 5 .. 20
  const int y_end = 50 + ((data[0] >> 2) & 3) * 5;  // 50 .. 65
  const int max_material = 1 + ((data[0] >> 4) & 3);  // 1 .. 4
  std::vector<std::string> blocks = base.blocks;
  if (data[1] & 1) blocks.erase(blocks.begin() + (data[1] >> 1) % blocks.size());
  if (data[1] & 2 && !blocks.empty()) {
    std::string& b = blocks[(data[1] >> 2) % blocks.size()];
    b.resize(b.size() * ((data[1] >> 4) & 7) / 8);
  }
  // Then edits of 4 bytes each: block, offset (2 bytes), value.
  for (size_t i = 2; i + 4 <= size && !blocks.empty(); i += 4) {
    std::string& b = blocks[data[i] % blocks.size()];
    if (b.empty()) continue;
    b[(data[i + 1] | (data[i + 2] << 8)) % b.size()] = static_cast<char>(data[i + 3]);
  }
  auto sticks = Sticks::FromBlocks(kDims, y_begin, y_end, max_material, blocks);
  if (sticks.ok()) {
    CheckSticks(*sticks, y_begin, y_end, max_material);
  } else {
    TRANSTICK_CHECK(!sticks.status().message().empty());
  }
  // The brick map from the input's bytes: only its own size is accepted.
  std::vector<uint8_t> bytes(data, data + size);
  auto bricks = BrickMap::FromBytes(kDims, bytes);
  if (!bricks.ok()) {
    TRANSTICK_CHECK(!bricks.status().message().empty());
    return 0;
  }
  // An accepted map encodes to the same bytes, and a uniform cell's reach
  // holds: every cell of its box (up to 3 ahead, for speed) has its
  // material.
  TRANSTICK_CHECK(bricks->bytes() == bytes);
  for (int z = 0; z < kDims[2]; z += 2)
    for (int y = 0; y < kDims[1]; y += 2)
      for (int x = (y + z) % 14; x < kDims[0]; x += 14) {
        const uint8_t m = bricks->Cell(x, y, z);
        const int octant = (x + y + z) & 7;
        const int r = bricks->Reach(x, y, z, octant);
        TRANSTICK_CHECK(r >= 0 && r <= BrickMap::kMaxReach);
        if (m == BrickMap::kMixed) {
          TRANSTICK_CHECK(r == 0);
          continue;
        }
        const int reach = std::min(r, 3);
        const int s[3] = {octant & 1 ? -2 : 2, octant & 2 ? -2 : 2, octant & 4 ? -2 : 2};
        for (int k = 0; k <= reach; ++k)
          for (int j = 0; j <= reach; ++j)
            for (int i = 0; i <= reach; ++i) {
              const int qx = x + s[0] * i, qy = y + s[1] * j, qz = z + s[2] * k;
              if (qx < 0 || qy < 0 || qz < 0 || qx >= kDims[0] || qy >= kDims[1] ||
                  qz >= kDims[2])
                continue;
              TRANSTICK_CHECK(bricks->Cell(qx, qy, qz) == m);
            }
      }
  return 0;
}
