#include "transtick/traversal.h"

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
    Traversal trav(scene, origin, dir);
    auto cell = CellAt(origin, dir, (*box)[0], dims);
    double t = (*box)[0];
    std::vector<Segment> segs;
    while (auto seg = trav.Next(cell, t)) segs.push_back(*seg);
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
  Scene scene = *Scene::ForSurfaces(v, c);
  Vec3 dir = Normalize(Vec3{1, 1, 1});
  Vec3 origin = Vec3{64.5, 64.5, 64.5} - dir * 300.0;
  auto box = IntersectBox(origin, dir, dims);
  Traversal trav(scene, origin, dir);
  auto cell = CellAt(origin, dir, (*box)[0], dims);
  double t = (*box)[0];
  int steps = 0, hits = 0;
  while (auto seg = trav.Next(cell, t)) {
    ++steps;
    hits += seg->material == 1;
  }
  EXPECT_EQ(hits, 1);
  EXPECT_LT(steps, 80);
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
