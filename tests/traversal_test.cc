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
  EXPECT_LT(steps, 80);
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
  EXPECT_GT(resumed, 200);
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
