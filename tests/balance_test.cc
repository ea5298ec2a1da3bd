// The core of static load balancing: cuts from measured costs
// (partition.h) and slabs rebuilt from planes gathered from other slabs
// (Scene::Reslab), as workers do when cuts move.
#include "transtick/partition.h"

#include <numeric>
#include <random>

#include "gtest/gtest.h"
#include "testing.h"
#include "transtick/scene.h"
#include "transtick/synthetic.h"

namespace transtick {
namespace {

TEST(PartitionTest, UniformCutsCoverEveryPlaneOnce) {
  EXPECT_EQ(UniformCuts(256, 4), (std::vector<int>{0, 64, 128, 192, 256}));
  EXPECT_EQ(UniformCuts(10, 3), (std::vector<int>{0, 3, 6, 10}));
  EXPECT_EQ(UniformCuts(5, 5), (std::vector<int>{0, 1, 2, 3, 4, 5}));
  for (int n = 1; n <= 9; ++n) EXPECT_TRUE(ValidCuts(UniformCuts(113, n), 113, n));
  EXPECT_FALSE(ValidCuts({0, 5, 5, 10}, 10, 3));
  EXPECT_FALSE(ValidCuts({0, 5, 10}, 11, 2));
}

TEST(PartitionTest, CostRuleEqualisesPiecewiseUniformCost) {
  // 4 slabs of 25 planes; all the cost in the last slab, uniform there:
  // the new slabs split those 25 planes evenly (the others keep a sliver
  // each, since empty space is never quite free).
  auto cuts = BalancedCuts({0, 25, 50, 75, 100}, {0, 0, 0, 40}, BalanceRule::kCost);
  ASSERT_TRUE(ValidCuts(cuts, 100, 4));
  EXPECT_NEAR(cuts[1], 81, 1);
  EXPECT_NEAR(cuts[2], 88, 1);
  EXPECT_NEAR(cuts[3], 94, 1);
  // Equal costs keep equal slabs; a known two-slab case moves the cut to
  // where the running cost is half: slab costs 30 and 10 over 50 planes
  // each -> density 0.6 and 0.2, half of 40 = 20 at plane 33.3.
  EXPECT_EQ(BalancedCuts({0, 25, 50, 75, 100}, {5, 5, 5, 5}, BalanceRule::kCost),
            (std::vector<int>{0, 25, 50, 75, 100}));
  EXPECT_EQ(BalancedCuts({0, 50, 100}, {30, 10}, BalanceRule::kCost),
            (std::vector<int>{0, 33, 100}));
}

// With a work profile, the cost of a slab goes to its planes in
// proportion to their work: a slab whose cost sits in a few of its planes
// is cut there, not evenly.
TEST(PartitionTest, CostRuleFollowsTheWorkProfile) {
  // Two slabs of 50 planes, costs 30 and 10; the first slab's work all in
  // planes 40-49, the second's even: per-plane costs 3 (x10) then 0.2
  // (x50), total 40, so the cut at 20 falls two thirds into plane 46.
  std::vector<double> first(50, 0.0), second(50, 1.0);
  for (int k = 40; k < 50; ++k) first[k] = 7;
  EXPECT_EQ(BalancedCuts({0, 50, 100}, {30, 10}, BalanceRule::kCost, {first, second}),
            (std::vector<int>{0, 47, 100}));
  // A profile of the wrong size, negative or all zero counts as even.
  for (const auto& bad : {std::vector<double>(49, 1.0), std::vector<double>(50, 0.0),
                          std::vector<double>(50, -1.0)}) {
    EXPECT_EQ(BalancedCuts({0, 50, 100}, {30, 10}, BalanceRule::kCost, {bad, second}),
              (std::vector<int>{0, 33, 100}));
  }
}

// Property: for random slabs, costs and profiles, every new slab's cost
// (the per-plane costs the rule assumes, summed) is within one plane's
// cost of the mean.
TEST(PartitionTest, CostRuleWithProfilesEqualisesWithinAPlane) {
  std::mt19937 rng(9);
  for (int trial = 0; trial < 2000; ++trial) {
    const int n = 2 + static_cast<int>(rng() % 7);
    const int planes = n + static_cast<int>(rng() % 300);
    std::vector<int> cuts = UniformCuts(planes, n);
    std::vector<double> costs(n);
    std::vector<std::vector<double>> profiles(n);
    std::vector<double> plane_cost(planes);
    double total = 0;
    for (int i = 0; i < n; ++i) {
      costs[i] = 1 + rng() % 1000;
      total += costs[i];
      const int size = cuts[i + 1] - cuts[i];
      double weight = 0;
      for (int k = 0; k < size; ++k) {
        profiles[i].push_back(rng() % 4 == 0 ? 0.0 : static_cast<double>(rng() % 100));
        weight += profiles[i].back();
      }
      for (int k = 0; k < size; ++k) {
        plane_cost[cuts[i] + k] =
            costs[i] * (weight > 0 ? profiles[i][k] / weight : 1.0 / size);
      }
    }
    const std::vector<int> got = BalancedCuts(cuts, costs, BalanceRule::kCost, profiles);
    ASSERT_TRUE(ValidCuts(got, planes, n));
    double biggest = 0;
    for (double c : plane_cost) biggest = std::max(biggest, c);
    const double floor = 1e-3 * total / planes;
    for (int i = 0; i < n; ++i) {
      double c = 0;
      for (int y = got[i]; y < got[i + 1]; ++y) c += std::max(plane_cost[y], floor);
      // Rounding moves each cut by at most half a plane, and a slab kept
      // one plane thick may hold more.
      if (got[i + 1] - got[i] > 1) {
        EXPECT_LE(std::abs(c - total / n), biggest + floor * planes + 1e-9)
            << "trial " << trial << " slab " << i;
      }
    }
  }
}

TEST(PartitionTest, PaperRuleIsTheLinearUpdate) {
  // size[i] += (t_mean - t_i) / t_plane, t_plane = 40 / 100 = 0.4:
  // sizes 50 + (20 - 30) / 0.4 = 25 and 50 + (20 - 10) / 0.4 = 75.
  EXPECT_EQ(BalancedCuts({0, 50, 100}, {30, 10}, BalanceRule::kPaper),
            (std::vector<int>{0, 25, 100}));
  // Overshooting sizes are clamped to one plane and the rest rescaled:
  // sizes 50, 50, 50, 1 of 151 -> the content stays in one slab, which is
  // why the cost rule is the default (docs/balancing.md).
  EXPECT_EQ(BalancedCuts({0, 25, 50, 75, 100}, {0, 0, 0, 40}, BalanceRule::kPaper),
            (std::vector<int>{0, 33, 66, 99, 100}));
}

TEST(PartitionTest, UselessCostsKeepTheCutsAndSlabsKeepAPlane) {
  const std::vector<int> cuts = {0, 10, 20, 30};
  EXPECT_EQ(BalancedCuts(cuts, {0, 0, 0}, BalanceRule::kCost), cuts);
  EXPECT_EQ(BalancedCuts(cuts, {1, -1, 1}, BalanceRule::kCost), cuts);
  EXPECT_EQ(BalancedCuts(cuts, {1, NAN, 1}, BalanceRule::kPaper), cuts);
  // Everything in one plane: every slab still gets at least one.
  for (BalanceRule rule : {BalanceRule::kCost, BalanceRule::kPaper}) {
    auto c = BalancedCuts({0, 1, 2, 3, 300}, {1e6, 0, 0, 0}, rule);
    EXPECT_TRUE(ValidCuts(c, 300, 4)) << ::testing::PrintToString(c);
  }
}

TEST(ReslabTest, PlanesFromNeighboursRebuildTheSlabExactly) {
  std::array<int, 3> dims = {30, 70, 26};
  Volume v = MakeNoisyPhantom(dims, 5);
  Classification c;
  c.materials = {{.name = "a", .min = 20, .max = 45}, {.name = "b", .min = 45, .max = 1000}};
  auto whole = Scene::ForSurfaces(v, c);
  ASSERT_TRUE(whole.ok()) << whole.status();
  // Three workers hold [0, 20), [20, 41), [41, 70); the middle one moves to
  // [12, 55), taking sticks and scalars from both neighbours.
  Scene left = whole->Slab(0, 20), mid = whole->Slab(20, 41), right = whole->Slab(41, 70);
  std::vector<std::string> blocks = mid.sticks().EncodeRows(20, 41);
  for (auto& b : left.sticks().EncodeRows(12, 20)) blocks.push_back(b);
  for (auto& b : right.sticks().EncodeRows(41, 55)) blocks.push_back(b);
  std::vector<ScalarPlanes> planes = {left.CopyScalars(10, 20), mid.CopyScalars(18, 43),
                                      right.CopyScalars(43, 57)};
  auto moved = mid.Reslab(12, 55, blocks, planes);
  ASSERT_TRUE(moved.ok()) << moved.status();
  Scene want = whole->Slab(12, 55);
  EXPECT_EQ(moved->y_begin(), 12);
  EXPECT_EQ(moved->y_end(), 55);
  EXPECT_EQ(moved->scalar_y_begin(), want.scalar_y_begin());
  EXPECT_EQ(moved->scalars(), want.scalars());
  for (int y = 12; y < 55; ++y)
    for (int x = 0; x < dims[0]; ++x)
      for (int z = 0; z < dims[2]; ++z)
        ASSERT_EQ(moved->sticks().MaterialAt(x, y, z), want.sticks().MaterialAt(x, y, z));
  // A missing ghost plane is named.
  planes.back() = right.CopyScalars(43, 56);
  auto short_of_one = mid.Reslab(12, 55, blocks, planes);
  ASSERT_FALSE(short_of_one.ok());
  EXPECT_NE(short_of_one.status().message().find("plane 56"), std::string::npos);
}

}  // namespace
}  // namespace transtick
