#include "transtick/traversal.h"

#include <algorithm>
#include <cmath>
#include <random>

#include "gtest/gtest.h"
#include "transtick/synthetic.h"

namespace transtick {
namespace {

// A scene whose labels are `levels`-valued noise in a few blobs, leaving
// empty bricks between them so both skip paths run.
Scene BlobScene(std::array<int, 3> dims, uint32_t seed) {
  Volume v = MakeRandom(dims, seed, 3);
  Volume ball = MakeSphere(dims, {dims[0] * 0.4, dims[1] * 0.5, dims[2] * 0.6}, dims[0] * 0.3);
  for (size_t i = 0; i < v.values.size(); ++i) {
    if (ball.values[i] == 0) v.values[i] = 0;
  }
  Classification c;
  c.materials = {{.name = "a", .min = 0.5f, .max = 1.5f}, {.name = "b", .min = 1.5f, .max = 2.5f}};
  c.surface = SurfaceModel::kVoxel;  // the walk over the materials themselves
  return *Scene::ForSurfaces(v, c);
}

uint8_t LabelAt(const Scene& s, const Vec3& p) {
  std::array<int, 3> c;
  for (int a = 0; a < 3; ++a) c[a] = static_cast<int>(std::floor(p[a]));
  for (int a = 0; a < 3; ++a)
    if (c[a] < 0 || c[a] >= s.dims()[a]) return 255;
  return s.sticks().MaterialAt(c[0], c[1], c[2]);
}

TEST(TraversalTest, MatchesBruteForceSampling) {
  std::array<int, 3> dims = {40, 37, 45};
  Scene scene = BlobScene(dims, 5);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  int checked = 0;
  for (int r = 0; r < 400; ++r) {
    // Rays from outside toward random points inside, some axis-aligned.
    Vec3 target{(u(rng) + 1) * 0.5 * dims[0], (u(rng) + 1) * 0.5 * dims[1],
                (u(rng) + 1) * 0.5 * dims[2]};
    Vec3 dir = Normalize(Vec3{u(rng), u(rng), u(rng)});
    if (r % 10 == 0) dir = Vec3{0, 0, r % 20 == 0 ? 1.0 : -1.0};
    if (r % 10 == 1) dir = Vec3{0, r % 20 == 1 ? 1.0 : -1.0, 0};
    Vec3 origin = target - dir * 200.0;
    auto box = IntersectBox(origin, dir, dims);
    ASSERT_TRUE(box.has_value());
    Traversal trav(scene, origin, dir, CellAt(origin, dir, (*box)[0], dims), (*box)[0]);
    std::vector<Segment> segs;
    while (auto seg = trav.Next()) segs.push_back(*seg);
    ASSERT_FALSE(segs.empty());
    // Segments tile the ray's stay in the box.
    EXPECT_EQ(segs.front().t0, (*box)[0]);
    EXPECT_NEAR(segs.back().t1, (*box)[1], 1e-9);
    for (size_t i = 1; i < segs.size(); ++i) {
      ASSERT_EQ(segs[i].t0, segs[i - 1].t1);
      ASSERT_LE(segs[i].t0, segs[i].t1);
    }
    // Fine samples agree with the segment that holds them.
    size_t k = 0;
    for (double ts = (*box)[0]; ts < (*box)[1]; ts += 0.013) {
      while (k < segs.size() && segs[k].t1 <= ts) ++k;
      if (k == segs.size()) break;
      const Segment& s = segs[k];
      if (ts - s.t0 < 1e-7 || s.t1 - ts < 1e-7) continue;  // on a face
      uint8_t want = LabelAt(scene, origin + dir * ts);
      ASSERT_EQ(s.material, want) << "ray " << r << " t " << ts;
      ++checked;
    }
  }
  EXPECT_GT(checked, 100000);
}

TEST(TraversalTest, SkipsEmptySpaceInFewSteps) {
  // A single voxel in a large empty volume: a ray along a diagonal crosses
  // hundreds of voxels but only a few dozen bricks.
  std::array<int, 3> dims = {128, 128, 128};
  Volume v = MakeSlab(dims, 0, 64, 65);
  for (size_t i = 0; i < v.values.size(); ++i) v.values[i] = 0;
  v.values[v.Index(64, 64, 64)] = 100;
  Classification c;
  c.materials = {{.name = "dot", .min = 50, .max = 150}};
  c.surface = SurfaceModel::kVoxel;
  Scene scene = *Scene::ForSurfaces(v, c);
  Vec3 dir = Normalize(Vec3{1, 1, 1});
  Vec3 origin = Vec3{64.5, 64.5, 64.5} - dir * 300.0;
  auto box = IntersectBox(origin, dir, dims);
  Traversal trav(scene, origin, dir, CellAt(origin, dir, (*box)[0], dims), (*box)[0]);
  int steps = 0, hits = 0;
  while (auto seg = trav.Next()) {
    ++steps;
    hits += seg->material == 1;
  }
  EXPECT_EQ(hits, 1);
  // Through cubes of void bricks toward the dot, bricks near it, and its
  // brick's 4^3 and 2^3 cells: before the cubes it took 60 to 80 steps.
  EXPECT_LT(steps, 30) << steps;
}

// The iterator's state is the whole state: a walk stopped after any
// segment and resumed from cell() and t() (as a descriptor carries them to
// another node) gives the same segments, bit for bit, as the walk that
// went on; a copy of the iterator does too. Once Next has returned
// nullopt, the state stays where the ray left the volume.
TEST(TraversalTest, ResumedFromCellAndTGivesTheSameSegments) {
  std::array<int, 3> dims = {40, 37, 45};
  Scene scene = BlobScene(dims, 8);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  int resumed = 0;
  for (int r = 0; r < 300; ++r) {
    Vec3 target{(u(rng) + 1) * 0.5 * dims[0], (u(rng) + 1) * 0.5 * dims[1],
                (u(rng) + 1) * 0.5 * dims[2]};
    Vec3 dir = Normalize(Vec3{u(rng), u(rng), u(rng)});
    if (r % 7 == 0) dir = Vec3{0, r % 14 == 0 ? 1.0 : -1.0, 0};
    const Vec3 origin = target - dir * 200.0;
    auto box = IntersectBox(origin, dir, dims);
    ASSERT_TRUE(box.has_value());
    Traversal whole(scene, origin, dir, CellAt(origin, dir, (*box)[0], dims), (*box)[0]);
    std::vector<Segment> want;
    while (auto seg = whole.Next()) want.push_back(*seg);
    ASSERT_FALSE(want.empty());
    EXPECT_FALSE(Traversal::Inside(whole.cell(), dims));
    EXPECT_EQ(whole.t(), want.back().t1);
    EXPECT_FALSE(whole.Next().has_value());
    // Stop after `stop` segments, resume in a fresh iterator (through a
    // descriptor) and in a copy.
    const size_t stop = rng() % want.size();
    Traversal first(scene, origin, dir, CellAt(origin, dir, (*box)[0], dims), (*box)[0]);
    for (size_t i = 0; i < stop; ++i) ASSERT_TRUE(first.Next().has_value());
    RayDescriptor ray;
    ray.origin = origin;
    ray.direction = dir;
    ray.cell = first.cell();
    ray.t = first.t();
    Traversal again(scene, ray);
    Traversal copy = first;
    for (size_t i = stop; i < want.size(); ++i) {
      for (Traversal* it : {&again, &copy}) {
        auto seg = it->Next();
        ASSERT_TRUE(seg.has_value()) << "ray " << r << " segment " << i;
        ASSERT_EQ(seg->t0, want[i].t0);
        ASSERT_EQ(seg->t1, want[i].t1);
        ASSERT_EQ(seg->material, want[i].material);
      }
      ASSERT_EQ(again.cell(), copy.cell());
    }
    EXPECT_FALSE(again.Next().has_value());
    EXPECT_EQ(again.cell(), whole.cell());
    resumed += stop > 0;
  }
  // Rays through void cross it in a segment or two, so not every ray has a
  // segment to resume from.
  EXPECT_GT(resumed, 150);
}

// A scene of isolated voxels (about one in `every`) of two materials, so
// that most mixed bricks are mostly void: the 2^3 and 4^3 skips run.
Scene SparseScene(std::array<int, 3> dims, uint32_t seed, int every) {
  Volume v = MakeRandom(dims, seed, 3);
  std::mt19937 rng(seed);
  for (float& x : v.values) {
    if (rng() % every != 0) x = 0;
  }
  Classification c;
  c.materials = {{.name = "a", .min = 0.5f, .max = 1.5f}, {.name = "b", .min = 1.5f, .max = 2.5f}};
  c.surface = SurfaceModel::kVoxel;
  return *Scene::ForSurfaces(v, c);
}

// Every segment's material is the label of the voxels it crosses, on
// scenes where the walk skips void by whole cubes of bricks, 4^3 and 2^3
// cells of mixed bricks, and gaps of tracks; rays run in every direction,
// along the axes and along the tracks.
TEST(TraversalTest, SparseScenesMatchBruteForceSampling) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> u(-1, 1);
  int checked = 0;
  for (int scene_index = 0; scene_index < 6; ++scene_index) {
    const std::array<int, 3> dims = {17 + static_cast<int>(rng() % 60),
                                     1 + static_cast<int>(rng() % 70),
                                     9 + static_cast<int>(rng() % 50)};
    Scene scene = SparseScene(dims, 100 + scene_index, 20 + 200 * (scene_index % 3));
    for (int r = 0; r < 300; ++r) {
      Vec3 target{(u(rng) + 1) * 0.5 * dims[0], (u(rng) + 1) * 0.5 * dims[1],
                  (u(rng) + 1) * 0.5 * dims[2]};
      Vec3 dir = Normalize(Vec3{u(rng), u(rng), u(rng)});
      if (r % 9 == 0) dir = Normalize(Vec3{0.05 * u(rng), 0.05 * u(rng), 1});  // along tracks
      if (r % 9 == 1) dir = Vec3{r % 2 ? 1.0 : -1.0, 0, 0};
      const Vec3 origin = target - dir * 300.0;
      auto box = IntersectBox(origin, dir, dims);
      if (!box) continue;
      Traversal trav(scene, origin, dir, CellAt(origin, dir, (*box)[0], dims), (*box)[0]);
      std::vector<Segment> segs;
      while (auto seg = trav.Next()) segs.push_back(*seg);
      ASSERT_FALSE(segs.empty());
      EXPECT_NEAR(segs.back().t1, (*box)[1], 1e-9);
      size_t k = 0;
      for (double ts = (*box)[0]; ts < (*box)[1]; ts += 0.017) {
        while (k < segs.size() && segs[k].t1 <= ts) ++k;
        if (k == segs.size()) break;
        const Segment& s = segs[k];
        if (ts - s.t0 < 1e-7 || s.t1 - ts < 1e-7) continue;  // on a face
        ASSERT_EQ(s.material, LabelAt(scene, origin + dir * ts))
            << "scene " << scene_index << " ray " << r << " t " << ts;
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 200000);
}

// Cell and Reach (each octant) against their definitions, on random brick
// maps of random sizes with a few materials; the serialised map decodes to the
// same, and a map of any other size is refused.
TEST(BrickMapTest, CellsAndReachMatchTheirDefinitions) {
  std::mt19937 rng(5);
  for (int trial = 0; trial < 40; ++trial) {
    const std::array<int, 3> dims = {1 + static_cast<int>(rng() % 50),
                                     1 + static_cast<int>(rng() % 50),
                                     1 + static_cast<int>(rng() % 50)};
    const size_t n = static_cast<size_t>(dims[0]) * dims[1] * dims[2];
    // Voxels of material 1 or 2 in a few clusters, sometimes inside a
    // block of material 1, or none at all.
    const bool dvr = trial % 2 == 1;
    std::vector<uint8_t> labels(n, 0);
    if (trial % 3 == 0) {
      const int x0 = rng() % dims[0], y0 = rng() % dims[1], z0 = rng() % dims[2];
      for (int z = z0; z < dims[2]; ++z)
        for (int y = y0; y < dims[1]; ++y)
          for (int x = x0; x < dims[0]; ++x)
            labels[(static_cast<size_t>(z) * dims[1] + y) * dims[0] + x] = 1;
    }
    const int clusters = static_cast<int>(rng() % 4);
    for (int c = 0; c < clusters; ++c) {
      const int cx = rng() % dims[0], cy = rng() % dims[1], cz = rng() % dims[2];
      for (int k = 0; k < 30; ++k) {
        const int x = std::clamp(cx + static_cast<int>(rng() % 9) - 4, 0, dims[0] - 1);
        const int y = std::clamp(cy + static_cast<int>(rng() % 9) - 4, 0, dims[1] - 1);
        const int z = std::clamp(cz + static_cast<int>(rng() % 9) - 4, 0, dims[2] - 1);
        labels[(static_cast<size_t>(z) * dims[1] + y) * dims[0] + x] = rng() % 3;
      }
    }
    const BrickMap map = BrickMap::Build(labels, dims, /*uniform_materials=*/!dvr);
    auto label = [&](int x, int y, int z) -> uint8_t {
      const uint8_t m = labels[(static_cast<size_t>(z) * dims[1] + y) * dims[0] + x];
      return dvr && m != 0 ? BrickMap::kMixed : m;
    };
    // At: the one material of the brick's voxels inside the volume, or
    // kMixed.
    for (int bz = 0; bz < dims[2]; bz += 8)
      for (int by = 0; by < dims[1]; by += 8)
        for (int bx = 0; bx < dims[0]; bx += 8) {
          int m = -1;
          for (int z = bz; z < std::min(bz + 8, dims[2]); ++z)
            for (int y = by; y < std::min(by + 8, dims[1]); ++y)
              for (int x = bx; x < std::min(bx + 8, dims[0]); ++x) {
                const int l = label(x, y, z);
                m = m < 0 || m == l ? l : BrickMap::kMixed;
              }
          ASSERT_EQ(map.At(bx, by, bz), m) << "brick at " << bx << " " << by << " " << bz;
        }
    // Cell: the one material of the voxels of the 2^3 cell inside the
    // volume, or kMixed.
    const std::array<int, 3> cd = {(dims[0] + 1) / 2, (dims[1] + 1) / 2, (dims[2] + 1) / 2};
    std::vector<int> cell(static_cast<size_t>(cd[0]) * cd[1] * cd[2]);
    auto at = [&](int cx, int cy, int cz) -> int& {
      return cell[(static_cast<size_t>(cz) * cd[1] + cy) * cd[0] + cx];
    };
    for (int cz = 0; cz < cd[2]; ++cz)
      for (int cy = 0; cy < cd[1]; ++cy)
        for (int cx = 0; cx < cd[0]; ++cx) {
          int m = -1;
          for (int k = 0; k < 8; ++k) {
            const int x = 2 * cx + (k & 1), y = 2 * cy + ((k >> 1) & 1), z = 2 * cz + (k >> 2);
            if (x >= dims[0] || y >= dims[1] || z >= dims[2]) continue;
            const int l = label(x, y, z);
            m = m < 0 || m == l ? l : BrickMap::kMixed;
          }
          at(cx, cy, cz) = m;
          ASSERT_EQ(map.Cell(2 * cx, 2 * cy, 2 * cz), m) << cx << " " << cy << " " << cz;
        }
    // Reach: the largest r for which every cell of the box of side r + 1
    // toward the octant (inside the volume) has the cell's material; 0 for
    // a mixed cell.
    for (int cz = 0; cz < cd[2]; ++cz)
      for (int cy = 0; cy < cd[1]; ++cy)
        for (int cx = 0; cx < cd[0]; ++cx) {
          const int m = at(cx, cy, cz);
          for (int octant = 0; octant < 8; ++octant) {
            const int s[3] = {octant & 1 ? -1 : 1, octant & 2 ? -1 : 1, octant & 4 ? -1 : 1};
            int want = 0;
            if (m != BrickMap::kMixed) {
              // The box grows while its new shell is all m.
              auto uniform = [&](int r) {
                for (int k = 0; k <= r; ++k)
                  for (int j = 0; j <= r; ++j)
                    for (int i = 0; i <= r; ++i) {
                      if (i < r && j < r && k < r) continue;
                      const int qx = cx + s[0] * i, qy = cy + s[1] * j, qz = cz + s[2] * k;
                      if (qx < 0 || qy < 0 || qz < 0 || qx >= cd[0] || qy >= cd[1] ||
                          qz >= cd[2])
                        continue;
                      if (at(qx, qy, qz) != m) return false;
                    }
                return true;
              };
              // Once the box holds the volume's corner toward the octant,
              // every larger one clips to it.
              auto corner = [&](int r) {
                return (s[0] > 0 ? cx + r >= cd[0] - 1 : cx - r <= 0) &&
                       (s[1] > 0 ? cy + r >= cd[1] - 1 : cy - r <= 0) &&
                       (s[2] > 0 ? cz + r >= cd[2] - 1 : cz - r <= 0);
              };
              while (want < BrickMap::kMaxReach && uniform(want + 1)) {
                ++want;
                if (corner(want)) want = BrickMap::kMaxReach;
              }
            }
            ASSERT_EQ(map.Reach(2 * cx, 2 * cy, 2 * cz, octant), want)
                << cx << " " << cy << " " << cz << " octant " << octant;
          }
        }
    // A slab's map: the same reach for the cells of its planes.
    {
      const int y0 = static_cast<int>(rng() % dims[1]);
      const int y1 = y0 + 1 + static_cast<int>(rng() % (dims[1] - y0));
      const BrickMap slab = map.ForSlab(y0, y1);
      EXPECT_TRUE(slab.ReachCovers(y0, y1));
      EXPECT_LT(slab.MemoryBytes(), map.MemoryBytes() + 1);
      auto from_bytes = BrickMap::FromBytes(dims, map.bytes(), y0, y1);
      ASSERT_TRUE(from_bytes.ok()) << from_bytes.status();
      for (int z = 0; z < dims[2]; z += 2)
        for (int y = y0; y < y1; ++y)
          for (int x = 0; x < dims[0]; x += 2)
            for (int octant = 0; octant < 8; ++octant) {
              ASSERT_EQ(slab.Reach(x, y, z, octant), map.Reach(x, y, z, octant))
                  << "slab [" << y0 << ", " << y1 << ") " << x << " " << y << " " << z;
              ASSERT_EQ(from_bytes->Reach(x, y, z, octant), map.Reach(x, y, z, octant));
            }
    }
    std::vector<uint8_t> bytes = map.bytes();
    auto decoded = BrickMap::FromBytes(dims, bytes);
    ASSERT_TRUE(decoded.ok()) << decoded.status();
    EXPECT_EQ(decoded->bytes(), bytes);
    for (int z = 0; z < dims[2]; z += 2)
      for (int y = 0; y < dims[1]; y += 2)
        for (int x = 0; x < dims[0]; x += 2) {
          ASSERT_EQ(decoded->At(x, y, z), map.At(x, y, z));
          ASSERT_EQ(decoded->Cell(x, y, z), map.Cell(x, y, z));
          for (int octant = 0; octant < 8; ++octant)
            ASSERT_EQ(decoded->Reach(x, y, z, octant), map.Reach(x, y, z, octant));
        }
    for (int cut : {-1, 1, 64}) {
      std::vector<uint8_t> wrong = bytes;
      if (cut < 0) {
        wrong.pop_back();
      } else {
        wrong.resize(wrong.size() + cut, 0);
      }
      auto refused = BrickMap::FromBytes(dims, wrong);
      ASSERT_FALSE(refused.ok());
      EXPECT_NE(refused.status().message().find("brick map"), std::string::npos);
    }
  }
}

TEST(TraversalTest, BoxIntersection) {
  std::array<int, 3> dims = {10, 20, 30};
  auto hit = IntersectBox({-5, 10, 15}, {1, 0, 0}, dims);
  ASSERT_TRUE(hit);
  EXPECT_DOUBLE_EQ((*hit)[0], 5);
  EXPECT_DOUBLE_EQ((*hit)[1], 15);
  EXPECT_FALSE(IntersectBox({-5, 25, 15}, {1, 0, 0}, dims));
  EXPECT_FALSE(IntersectBox({-5, 10, 15}, {-1, 0, 0}, dims));
  // A ray starting inside begins at t = 0.
  auto inside = IntersectBox({5, 10, 15}, {0, 0, 1}, dims);
  ASSERT_TRUE(inside);
  EXPECT_DOUBLE_EQ((*inside)[0], 0);
  EXPECT_DOUBLE_EQ((*inside)[1], 15);
}

}  // namespace
}  // namespace transtick
