// A scene built on any number of threads is the scene built on one, part
// for part and bit for bit (parallel.h), and ParallelFor hands out each
// item exactly once. A scene built to cut into slabs (SceneUse::kCut) gives
// the slabs a scene to trace gives, and knows what those will hold.
#include "transtick/parallel.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <random>
#include <thread>
#include <vector>

#include "gtest/gtest.h"
#include "transtick/brick_map.h"
#include "transtick/classification.h"
#include "transtick/field_grid.h"
#include "transtick/scene.h"
#include "transtick/volume.h"

namespace transtick {
namespace {

// Restores the default thread count when a test ends, however it ends.
class BuildThreadsTest : public ::testing::Test {
 protected:
  void TearDown() override { SetBuildThreads(0); }
};

// Ranges cover [0, n) once, in order, at most BuildThreads() of them, none
// below the grain unless alone, the first on the calling thread: over
// random sizes, grains and thread counts.
TEST_F(BuildThreadsTest, ParallelForHandsOutEveryItemOnce) {
  std::mt19937_64 rng(3);
  int split = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const int threads = 1 + static_cast<int>(rng() % 9);
    SetBuildThreads(threads);
    ASSERT_EQ(BuildThreads(), threads);
    const size_t n = trial % 10 == 0 ? rng() % 3 : rng() % 5000;
    const size_t grain = rng() % 4 == 0 ? 0 : 1 + rng() % 200;
    std::vector<std::atomic<int>> hits(n);
    std::mutex mu;
    std::vector<std::pair<size_t, size_t>> ranges;
    bool first_here = n == 0;
    const auto caller = std::this_thread::get_id();
    ParallelFor(n, grain, [&](size_t begin, size_t end) {
      for (size_t i = begin; i < end; ++i) hits[i].fetch_add(1);
      std::lock_guard<std::mutex> lock(mu);
      ranges.push_back({begin, end});
      if (begin == 0) first_here = std::this_thread::get_id() == caller;
    });
    for (size_t i = 0; i < n; ++i)
      ASSERT_EQ(hits[i].load(), 1) << "trial " << trial << ", item " << i;
    EXPECT_TRUE(first_here);
    if (n == 0) {
      EXPECT_TRUE(ranges.empty());
      continue;
    }
    std::sort(ranges.begin(), ranges.end());
    ASSERT_LE(ranges.size(), static_cast<size_t>(threads));
    split += ranges.size() > 1;
    for (size_t k = 0; k < ranges.size(); ++k) {
      EXPECT_EQ(ranges[k].first, k == 0 ? 0 : ranges[k - 1].second);
      EXPECT_LT(ranges[k].first, ranges[k].second);
      if (ranges.size() > 1) {
        EXPECT_GE(ranges[k].second - ranges[k].first, std::max<size_t>(grain, 1));
      }
    }
    EXPECT_EQ(ranges.back().second, n);
  }
  EXPECT_GT(split, 200);
  SetBuildThreads(0);
  EXPECT_EQ(BuildThreads(), static_cast<int>(std::max(1u, std::thread::hardware_concurrency())));
}

// A volume of blobs, plateaus and noise, and now and then the values a
// file may hold that compare oddly: NaN, -0 and +0, the infinities, the
// largest floats.
Volume RandomVolume(std::mt19937_64& rng, std::array<int, 3> dims) {
  std::uniform_real_distribution<double> unit(0, 1);
  Volume v;
  v.dims = dims;
  v.spacing = {0.5 + unit(rng), 0.5 + unit(rng), 0.5 + 2 * unit(rng)};
  v.values.resize(v.VoxelCount());
  double centre[3][3], radius[3];
  for (int b = 0; b < 3; ++b) {
    for (int a = 0; a < 3; ++a) centre[b][a] = unit(rng) * dims[a];
    radius[b] = 1 + unit(rng) * std::max({dims[0], dims[1], dims[2]}) / 2.0;
  }
  const bool odd_values = rng() % 3 == 0;
  const float odd[] = {std::numeric_limits<float>::quiet_NaN(),
                       -0.0f,
                       0.0f,
                       std::numeric_limits<float>::infinity(),
                       -std::numeric_limits<float>::infinity(),
                       std::numeric_limits<float>::max(),
                       std::numeric_limits<float>::lowest()};
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x) {
        double f = 40 * unit(rng);
        for (int b = 0; b < 3; ++b) {
          const double r = std::hypot(x - centre[b][0], y - centre[b][1], z - centre[b][2]);
          f += 1000 * std::max(0.0, 1 - r / radius[b]);
        }
        float value = static_cast<float>(rng() % 2 ? 25 * std::round(f / 25) : f);
        if (odd_values && rng() % 50 == 0) value = odd[rng() % std::size(odd)];
        v.values[v.Index(x, y, z)] = value;
      }
  return v;
}

Classification RandomMaterials(std::mt19937_64& rng) {
  Classification c;
  c.surface = rng() % 2 ? SurfaceModel::kSmooth : SurfaceModel::kVoxel;
  float at = 100 + static_cast<float>(rng() % 300);
  const int n = 1 + static_cast<int>(rng() % 4);
  for (int m = 0; m < n; ++m) {
    const float width = 50 + static_cast<float>(rng() % 400);
    c.materials.push_back(Material{.name = "m" + std::to_string(m), .min = at, .max = at + width});
    at += width + (rng() % 2 ? 0 : static_cast<float>(rng() % 200));
  }
  return c;
}

// A volume, its materials and a transfer function, and which of them a
// trial builds: random sizes (1 voxel to 70 on an axis, odd and even; 1 to
// 3 every tenth trial), smooth and voxel surfaces, and dvr every fourth.
struct Case {
  Volume v;
  Classification c;
  TransferFunction t;
  bool dvr = false;
  absl::StatusOr<Scene> Build(SceneUse use) const {
    return dvr ? Scene::ForDvr(v, t, use) : Scene::ForSurfaces(v, c, use);
  }
};

Case RandomCase(std::mt19937_64& rng, int trial) {
  std::array<int, 3> dims;
  for (int a = 0; a < 3; ++a)
    dims[a] = trial % 10 == 0 ? 1 + static_cast<int>(rng() % 3) : 2 + static_cast<int>(rng() % 69);
  Case k;
  k.v = RandomVolume(rng, dims);
  k.c = RandomMaterials(rng);
  k.t.points = {{150, {1, 0, 0, 0}}, {400, {1, 1, 0, 0.4f}}, {900, {1, 1, 1, 0.9f}}};
  k.dvr = trial % 4 == 3;
  return k;
}

// Every part of a scene, and of its slabs, is the same whether built on 1
// thread or on 2 to 8: random sizes (1 voxel to 70 on an axis, odd and
// even), values, smooth and voxel surfaces, and dvr.
TEST_F(BuildThreadsTest, ScenesAreTheSameOnAnyNumberOfThreads) {
  std::mt19937_64 rng(5);
  int smooth = 0, voxel = 0, dvr = 0;
  for (int trial = 0; trial < 60; ++trial) {
    const Case k = RandomCase(rng, trial);
    const auto& dims = k.v.dims;
    auto build = [&](int threads) {
      SetBuildThreads(threads);
      return k.Build(SceneUse::kTrace);
    };
    auto one = build(1);
    ASSERT_TRUE(one.ok()) << one.status();
    (k.dvr ? dvr : k.c.surface == SurfaceModel::kSmooth ? smooth : voxel) += 1;
    const int y0 = static_cast<int>(rng() % dims[1]);
    const int y1 = y0 + 1 + static_cast<int>(rng() % (dims[1] - y0));
    SetBuildThreads(1);
    const Scene one_slab = one->Slab(y0, y1);
    for (int threads : {2, 3, 5, 8}) {
      auto many = build(threads);
      ASSERT_TRUE(many.ok()) << many.status();
      ASSERT_TRUE(one->SameParts(*many)) << "trial " << trial << ", " << threads << " threads";
      ASSERT_TRUE(one_slab.SameParts(many->Slab(y0, y1)))
          << "trial " << trial << ", " << threads << " threads, slab [" << y0 << ", " << y1 << ")";
    }
  }
  EXPECT_GT(smooth, 10);
  EXPECT_GT(voxel, 10);
  EXPECT_GT(dvr, 10);
}

// A scene that takes the volume's samples (Scene::ForSurfaces and ForDvr of
// a Volume&&) is the scene of a copy, part for part, for tracing and for
// cutting; it leaves the volume without values but its other fields, and a
// volume it refuses (an invalid classification) keeps its values.
TEST_F(BuildThreadsTest, ATakenVolumeGivesTheSameScene) {
  std::mt19937_64 rng(23);
  for (int trial = 0; trial < 40; ++trial) {
    const Case k = RandomCase(rng, trial);
    for (SceneUse use : {SceneUse::kTrace, SceneUse::kCut}) {
      auto copied = k.Build(use);
      ASSERT_TRUE(copied.ok()) << copied.status();
      Volume taken = k.v;
      auto built = k.dvr ? Scene::ForDvr(std::move(taken), k.t, use)
                         : Scene::ForSurfaces(std::move(taken), k.c, use);
      ASSERT_TRUE(built.ok()) << built.status();
      EXPECT_TRUE(copied->SameParts(*built)) << "trial " << trial;
      // Bit for bit: the values hold NaN.
      ASSERT_EQ(built->scalars().size(), k.v.values.size());
      EXPECT_EQ(std::memcmp(built->scalars().data(), k.v.values.data(),
                            k.v.values.size() * sizeof(float)),
                0)
          << "trial " << trial;
      EXPECT_TRUE(taken.values.empty());
      EXPECT_EQ(taken.dims, k.v.dims);
    }
  }
  Case k = RandomCase(rng, 1);
  k.c.materials.push_back(Material{.name = "backwards", .min = 9, .max = 3});
  Volume kept = k.v;
  EXPECT_FALSE(Scene::ForSurfaces(std::move(kept), k.c).ok());
  ASSERT_EQ(kept.values.size(), k.v.values.size());
  EXPECT_EQ(std::memcmp(kept.values.data(), k.v.values.data(), k.v.values.size() * sizeof(float)),
            0);
}

// The root's scene (SceneUse::kCut) leaves out what only walks look up:
// the field's grid and the brick map's reach. It sends the same parts (the
// brick map's bytes, sticks, summary, scalars), a slab cut from it is the
// slab cut from a scene to trace, bit for bit, and TracingBytes counts
// exactly what a scene to trace holds. Smooth surfaces hold no reach at
// all; voxel surfaces and dvr hold their slab's. Random volumes as above.
TEST_F(BuildThreadsTest, CutScenesGiveTheSameSlabs) {
  std::mt19937_64 rng(11);
  int smooth = 0, voxel = 0, dvr = 0;
  for (int trial = 0; trial < 60; ++trial) {
    const Case k = RandomCase(rng, trial);
    const auto& dims = k.v.dims;
    auto traced = k.Build(SceneUse::kTrace);
    auto cut = k.Build(SceneUse::kCut);
    ASSERT_TRUE(traced.ok()) << traced.status();
    ASSERT_TRUE(cut.ok()) << cut.status();
    const bool walks = k.dvr || k.c.surface == SurfaceModel::kVoxel;
    (k.dvr ? dvr : walks ? voxel : smooth) += 1;
    EXPECT_EQ(walks, Scene::WalksBricks(traced->mode(), traced->classification()));
    EXPECT_EQ(traced->bricks().HoldsReach(), walks) << "trial " << trial;
    EXPECT_EQ(traced->field().empty(), walks) << "trial " << trial;
    EXPECT_FALSE(cut->bricks().HoldsReach()) << "trial " << trial;
    EXPECT_TRUE(cut->field().empty()) << "trial " << trial;
    // What the root sends.
    EXPECT_EQ(cut->bricks().bytes(), traced->bricks().bytes()) << "trial " << trial;
    EXPECT_EQ(cut->sticks(), traced->sticks()) << "trial " << trial;
    EXPECT_EQ(cut->summary(), traced->summary()) << "trial " << trial;
    EXPECT_EQ(cut->scalars().size(), traced->scalars().size());
    EXPECT_EQ(0, std::memcmp(cut->scalars().data(), traced->scalars().data(),
                             traced->scalars().size() * sizeof(float)));
    // What the workers hold.
    EXPECT_EQ(traced->TracingBytes(), traced->MemoryBytes()) << "trial " << trial;
    EXPECT_EQ(cut->TracingBytes(), traced->MemoryBytes()) << "trial " << trial;
    if (walks) {
      EXPECT_LT(cut->MemoryBytes(), traced->MemoryBytes()) << "trial " << trial;
    }
    for (int slab = 0; slab < 3; ++slab) {
      const int y0 = static_cast<int>(rng() % dims[1]);
      const int y1 = y0 + 1 + static_cast<int>(rng() % (dims[1] - y0));
      const Scene a = traced->Slab(y0, y1), b = cut->Slab(y0, y1);
      ASSERT_TRUE(a.SameParts(b)) << "trial " << trial << ", slab [" << y0 << ", " << y1 << ")";
      EXPECT_EQ(a.bricks().HoldsReach(), walks);
      EXPECT_EQ(a.bricks().ReachCovers(y0, y1), walks);
      EXPECT_EQ(a.TracingBytes(), a.MemoryBytes()) << "trial " << trial;
      // A worker's assembly from the parts the root sends, with the whole
      // map's reach or none: the reach its walks look up, no more.
      for (bool with_reach : {false, true}) {
        auto map = BrickMap::FromBytes(dims, traced->bricks().bytes(), 0, with_reach ? dims[1] : 0);
        ASSERT_TRUE(map.ok());
        std::vector<float> scalars(a.scalars());
        auto parts = Scene::FromParts(a.mode(), dims, a.spacing(), a.value_range(), a.sticks(),
                                      std::move(scalars), *std::move(map), a.classification(),
                                      a.transfer(), a.summary());
        ASSERT_TRUE(parts.ok()) << parts.status();
        EXPECT_EQ(parts->bricks().HoldsReach(), walks);
        if (!with_reach || !walks) {
          EXPECT_TRUE(a.SameParts(*parts)) << "trial " << trial;
        }
      }
    }
  }
  EXPECT_GT(smooth, 10);
  EXPECT_GT(voxel, 10);
  EXPECT_GT(dvr, 10);
}

// The reach of any planes takes ReachBytes, and none is built (nor any
// time spent on it) for an empty range.
TEST_F(BuildThreadsTest, ReachBytesCountsTheReach) {
  std::mt19937_64 rng(13);
  for (int trial = 0; trial < 40; ++trial) {
    std::array<int, 3> dims;
    for (int a = 0; a < 3; ++a) dims[a] = 1 + static_cast<int>(rng() % 40);
    std::vector<uint8_t> labels(static_cast<size_t>(dims[0]) * dims[1] * dims[2]);
    for (auto& l : labels) l = rng() % 5 == 0 ? static_cast<uint8_t>(rng() % 3) : 0;
    const BrickMap none = BrickMap::Build(labels, dims, true, 0, 0);
    EXPECT_FALSE(none.HoldsReach());
    EXPECT_EQ(none, BrickMap::Build(labels, dims, true, dims[1] / 2, dims[1] / 2));
    const int y0 = static_cast<int>(rng() % dims[1]);
    const int y1 = y0 + 1 + static_cast<int>(rng() % (dims[1] - y0));
    const BrickMap some = BrickMap::Build(labels, dims, true, y0, y1);
    EXPECT_TRUE(some.HoldsReach());
    EXPECT_TRUE(some.ReachCovers(y0, y1));
    EXPECT_EQ(some.MemoryBytes() - none.MemoryBytes(), BrickMap::ReachBytes(dims, y0, y1));
    EXPECT_EQ(some, none.ForSlab(y0, y1));
    EXPECT_EQ(some.bytes(), none.bytes());
  }
}

// The comparison sees a single changed voxel (so the test above can fail).
TEST_F(BuildThreadsTest, SamePartsSeesOneVoxel) {
  std::mt19937_64 rng(7);
  const Volume v = RandomVolume(rng, {30, 20, 10});
  Classification c = RandomMaterials(rng);
  for (SurfaceModel model : {SurfaceModel::kSmooth, SurfaceModel::kVoxel}) {
    c.surface = model;
    auto a = Scene::ForSurfaces(v, c);
    ASSERT_TRUE(a.ok());
    for (float value : {c.materials[0].min + 1, -0.0f, 12345.0f}) {
      Volume w = v;
      w.values[w.Index(17, 9, 4)] = value;
      if (std::memcmp(&w.values[w.Index(17, 9, 4)], &v.values[v.Index(17, 9, 4)], 4) == 0) continue;
      auto b = Scene::ForSurfaces(w, c);
      ASSERT_TRUE(b.ok());
      EXPECT_FALSE(a->SameParts(*b)) << value;
    }
  }
}

// The value range in parallel ranges keeps, of equal extremes, the first,
// as one pass does: -0 or +0, whichever comes first, on any thread count.
TEST_F(BuildThreadsTest, RangeKeepsTheFirstOfEqualExtremes) {
  Volume v;
  v.dims = {1000, 1000, 1};
  v.values.assign(1000000, 7.0f);
  for (int threads : {1, 2, 3, 4, 8}) {
    SetBuildThreads(threads);
    for (bool negative_first : {false, true}) {
      v.values[10] = negative_first ? -0.0f : 0.0f;
      v.values[900000] = negative_first ? 0.0f : -0.0f;
      const auto range = v.Range();
      EXPECT_EQ(std::signbit(range[0]), negative_first) << threads << " threads";
      EXPECT_EQ(range[1], 7.0f);
    }
    v.values[10] = v.values[900000] = 7.0f;
    v.values[999999] = std::numeric_limits<float>::quiet_NaN();
    v.values[500000] = -std::numeric_limits<float>::infinity();
    v.values[3] = 9.5f;
    EXPECT_EQ(v.Range(), (std::array<float, 2>{7.0f, 9.5f})) << threads << " threads";
    v.values[999999] = v.values[500000] = v.values[3] = 7.0f;
  }
}

// The value range is one pass's, bit for bit (the sign of a zero
// included), over random volumes of zeros of both signs, NaN, infinities and
// ordinary values, of every length modulo the lanes, on any thread count.
TEST_F(BuildThreadsTest, RangeIsOnePasssBitForBit) {
  std::mt19937_64 rng(29);
  constexpr float kInf = std::numeric_limits<float>::infinity();
  const float kinds[] = {0.0f, -0.0f,  kInf,  -kInf, std::numeric_limits<float>::quiet_NaN(),
                         1.5f, -2.25f, 3e38f, -3e38f};
  for (int trial = 0; trial < 600; ++trial) {
    Volume v;
    v.dims = {1 + static_cast<int>(rng() % (trial < 300 ? 40 : 4000)), 1,
              1 + static_cast<int>(rng() % (trial < 300 ? 3 : 300))};
    v.values.resize(v.VoxelCount());
    const int mix = 1 + static_cast<int>(rng() % 9);  // how many kinds appear
    for (float& x : v.values) x = kinds[rng() % mix];
    float lo = kInf, hi = -kInf;
    for (float x : v.values) {
      if (x < lo && x != -kInf) lo = x;
      if (x > hi && x != kInf) hi = x;
    }
    const std::array<float, 2> expected =
        lo > hi ? std::array<float, 2>{0.0f, 0.0f} : std::array<float, 2>{lo, hi};
    for (int threads : {1, 2, 5}) {
      SetBuildThreads(threads);
      const auto range = v.Range();
      ASSERT_EQ(std::bit_cast<uint32_t>(range[0]), std::bit_cast<uint32_t>(expected[0]))
          << "trial " << trial << ", " << threads << " threads";
      ASSERT_EQ(std::bit_cast<uint32_t>(range[1]), std::bit_cast<uint32_t>(expected[1]))
          << "trial " << trial << ", " << threads << " threads";
    }
  }
}

// The histogram counts each finite sample in the bin of the division rule
// (volume.h), on any thread count: over random volumes whose values sit on
// the bins' edges, a float below and above them, at the range's ends, at
// -0, near the largest float and among denormals, with NaN and infinities.
TEST_F(BuildThreadsTest, HistogramCountsAsTheDivisionDoes) {
  std::mt19937_64 rng(17);
  constexpr float kInf = std::numeric_limits<float>::infinity();
  constexpr float kMax = std::numeric_limits<float>::max();
  constexpr float kTiny = std::numeric_limits<float>::denorm_min();
  const std::vector<std::array<float, 2>> spans = {
      {0, 1},          {-1024, 3071}, {0, 255},      {-kMax, kMax},    {-3e38f, 1},
      {0, 64 * kTiny}, {5, 5},        {-0.0f, 0.0f}, {1e-30f, 1e-29f}, {-7.25f, 1e6f}};
  int checked = 0;
  for (int trial = 0; trial < 120; ++trial) {
    const auto span = spans[trial % spans.size()];
    const int bins = std::array<int, 6>{1, 2, 7, 16, 64, 1000}[rng() % 6];
    const double lo = span[0], hi = span[1];
    const double width = hi > lo ? (hi - lo) / bins : 1;
    Volume v;
    v.dims = {1 + static_cast<int>(rng() % 300), 1 + static_cast<int>(rng() % 40),
              1 + static_cast<int>(rng() % 30)};
    v.values.resize(v.VoxelCount());
    std::uniform_real_distribution<double> unit(0, 1);
    for (float& x : v.values) {
      switch (rng() % 8) {
        case 0: {  // on an edge, or a float either side of it
          const float e = static_cast<float>(lo + static_cast<double>(rng() % (bins + 1)) * width);
          const int side = static_cast<int>(rng() % 3) - 1;
          x = side == 0 ? e : std::nextafter(e, side < 0 ? -kInf : kInf);
          break;
        }
        case 1:
          x = rng() % 2 ? span[0] : span[1];
          break;
        case 2: {
          const uint32_t kinds[] = {0x7fc00000u, 0x7f800000u, 0xff800000u, 0x80000000u};
          x = std::bit_cast<float>(kinds[rng() % 4]);
          break;
        }
        default:
          x = static_cast<float>(lo + unit(rng) * (hi - lo));
      }
      // Samples stay within the span, as Range() would give it.
      if (std::isfinite(x)) x = std::clamp(x, span[0], span[1]);
    }
    std::vector<uint64_t> expected(bins, 0);
    for (float x : v.values) {
      if (!std::isfinite(x)) continue;
      const double q = (x - lo) / width;
      ++expected[std::clamp(static_cast<int>(q), 0, bins - 1)];
    }
    for (int threads : {1, 3}) {
      SetBuildThreads(threads);
      ASSERT_EQ(Histogram(v.values, span, bins), expected)
          << "span " << span[0] << " .. " << span[1] << ", " << bins << " bins, " << threads
          << " threads";
      ++checked;
    }
  }
  EXPECT_EQ(checked, 240);
}

}  // namespace
}  // namespace transtick
