// The ray-isosurface root finder (isosurface.h) against brute force: the
// cubic agrees with the trilinear interpolant along the ray, and over
// thousands of random cells and rays no crossing that dense sampling sees
// is missed, and every root reported is a root.
#include "transtick/isosurface.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <iterator>
#include <limits>
#include <optional>
#include <random>
#include <vector>

#include "gtest/gtest.h"
#include "transtick/camera.h"
#include "transtick/classification.h"
#include "transtick/field_grid.h"
#include "transtick/field_summary.h"
#include "transtick/tracer.h"
#include "transtick/traversal.h"
#include "transtick/volume.h"

namespace transtick {
namespace {

struct Case {
  CellCorners corners;
  std::array<double, 3> o, d;
  double iso;
};

Case RandomCase(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> unit(0, 1), dir(-1, 1);
  Case c;
  for (float& v : c.corners) v = static_cast<float>(unit(rng) * 1000);
  for (int a = 0; a < 3; ++a) c.o[a] = unit(rng);
  double len = 0;
  for (int a = 0; a < 3; ++a) {
    // Some rays along an axis, or with a component of exactly 0.
    c.d[a] = rng() % 5 == 0 ? 0.0 : dir(rng);
    len += c.d[a] * c.d[a];
  }
  if (len == 0) c.d = {0, 0, 1}, len = 1;
  for (double& x : c.d) x /= std::sqrt(len);
  c.iso = unit(rng) * 1000;
  return c;
}

// The trilinear interpolant of `corners` at `p` (cell coordinates).
double Trilinear(const CellCorners& c, const std::array<double, 3>& p) {
  const double x = p[0], y = p[1], z = p[2];
  const double c00 = c[0] * (1 - x) + c[1] * x, c10 = c[2] * (1 - x) + c[3] * x;
  const double c01 = c[4] * (1 - x) + c[5] * x, c11 = c[6] * (1 - x) + c[7] * x;
  const double c0 = c00 * (1 - y) + c10 * y, c1 = c01 * (1 - y) + c11 * y;
  return c0 * (1 - z) + c1 * z;
}

TEST(IsosurfaceTest, TheCubicIsTheTrilinearFieldAlongTheRay) {
  std::mt19937_64 rng(1);
  for (int i = 0; i < 10000; ++i) {
    const Case c = RandomCase(rng);
    const RayCubic g = CellCubic(c.corners, c.o, c.d, c.iso);
    for (double t : {-0.7, 0.0, 0.3, 1.1}) {
      const std::array<double, 3> p = {c.o[0] + t * c.d[0], c.o[1] + t * c.d[1],
                                       c.o[2] + t * c.d[2]};
      EXPECT_NEAR(g(t), Trilinear(c.corners, p) - c.iso, 1e-9) << i;
    }
  }
}

TEST(IsosurfaceTest, TheVectorCubicIsBitForBitThePortableOne) {
  // Nodes built for different processors must solve a cell alike: the
  // cubic the walk uses (SSE2 where there is one) against the plain double
  // form, over corners and rays of every scale, the odd values included.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  const float odd[] = {
      0.0f, -0.0f, 1e-40f, -3e38f, 3e38f, std::numeric_limits<float>::infinity(), std::nanf("")};
  // Any NaN is every other (it compares false either way; which one an
  // operation returns depends on its operands' order, which the compiler
  // may swap); every other value bit for bit.
  auto bits = [](double v) { return std::isnan(v) ? uint64_t{1} : std::bit_cast<uint64_t>(v); };
  for (int i = 0; i < 200000; ++i) {
    CellCorners corners;
    const double scale = std::pow(10.0, static_cast<int>(rng() % 12) - 3);
    for (float& v : corners) {
      v = rng() % 50 == 0 ? odd[rng() % std::size(odd)] : static_cast<float>(u(rng) * scale);
    }
    std::array<double, 3> o, d;
    for (int a = 0; a < 3; ++a) {
      o[a] = u(rng) * (rng() % 4 == 0 ? 1e6 : 1.5);
      d[a] = rng() % 8 == 0 ? 0.0 : u(rng);
    }
    const double iso = u(rng) * scale;
    const RayCubic v = CellCubic(corners, o, d, iso), p = PortableCellCubic(corners, o, d, iso);
    ASSERT_EQ(bits(v.a), bits(p.a)) << i;
    ASSERT_EQ(bits(v.b), bits(p.b)) << i;
    ASSERT_EQ(bits(v.c), bits(p.c)) << i;
    ASSERT_EQ(bits(v.d), bits(p.d)) << i;
  }
}

TEST(IsosurfaceTest, TheWalksFaceTimesAreEachFromItsPlaneWithTiesToTheLowestAxis) {
  // The walk keeps its leave times in vector registers and makes each next
  // face's time a step early (FaceClock). Over rays with ties (origins on
  // cell corners and faces, directions with equal components), axes not
  // moved along, far origins and steep directions, every step must be the
  // one a walk computing each time from its plane takes: the axis whose
  // face comes first (the lowest on a tie) at (k + 0.5 - o) * (1 / d),
  // bit for bit, for the vector form and the portable one.
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> u(-1, 1);
  int ties = 0;
  for (int i = 0; i < 20000; ++i) {
    Vec3 o, d;
    for (int a = 0; a < 3; ++a) {
      switch (rng() % 4) {
        case 0:
          o[a] = static_cast<double>(static_cast<int>(rng() % 64) - 8);
          break;
        case 1:
          o[a] = static_cast<int>(rng() % 64) - 7.5;
          break;
        case 2:
          o[a] = u(rng) * 1e6;
          break;
        default:
          o[a] = u(rng) * 40;
          break;
      }
    }
    const double shared = u(rng);
    for (int a = 0; a < 3; ++a) {
      switch (rng() % 5) {
        case 0:
          d[a] = 0;
          break;
        case 1:
          d[a] = (rng() % 2 ? 1 : -1) * std::abs(shared);
          break;
        case 2:
          d[a] = u(rng) * 1e-6;
          break;
        default:
          d[a] = u(rng);
          break;
      }
    }
    if (d.x == 0 && d.y == 0 && d.z == 0) d.z = 1;
    d = d * (1 / std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z));
    const RayAxes axes(d);
    std::array<int, 3> cell;
    for (int a = 0; a < 3; ++a) {
      cell[a] = static_cast<int>(std::floor(std::clamp(o[a] + 0.5, -1e9, 1e9)));
    }
    const int steps = 1 + static_cast<int>(rng() % 200);
    const auto vector = FaceSteps(o, axes, cell, steps, false);
    const auto portable = FaceSteps(o, axes, cell, steps, true);
    ASSERT_EQ(vector.size(), static_cast<size_t>(steps));
    ASSERT_EQ(portable.size(), static_cast<size_t>(steps));
    // The reference: per axis the plane of the next face, its time computed
    // from it, the first of the three taken.
    std::array<int, 3> plane;
    for (int a = 0; a < 3; ++a) plane[a] = cell[a] + (axes.step[a] < 0 ? -1 : 0);
    auto time = [&](int a) {
      return axes.step[a] == 0 ? std::numeric_limits<double>::infinity()
                               : (plane[a] + 0.5 - o[a]) * axes.inv[a];
    };
    for (int k = 0; k < steps; ++k) {
      int axis = 0;
      for (int a = 1; a < 3; ++a) axis = time(a) < time(axis) ? a : axis;
      for (int a = 0; a < 3; ++a) ties += a != axis && time(a) == time(axis);
      const double t = time(axis);
      ASSERT_EQ(vector[k].axis, axis) << i << " step " << k;
      ASSERT_EQ(std::bit_cast<uint64_t>(vector[k].t), std::bit_cast<uint64_t>(t)) << i << " " << k;
      ASSERT_EQ(portable[k].axis, axis) << i << " step " << k;
      ASSERT_EQ(std::bit_cast<uint64_t>(portable[k].t), std::bit_cast<uint64_t>(t))
          << i << " " << k;
      plane[axis] += axes.step[axis];
    }
  }
  EXPECT_GT(ties, 1000);  // the ties are exercised
}

TEST(IsosurfaceTest, NoCrossingIsMissedAndEveryRootIsARoot) {
  std::mt19937_64 rng(2);
  constexpr int kSamples = 2048;
  int crossings = 0, extra = 0;
  for (int i = 0; i < 20000; ++i) {
    const Case c = RandomCase(rng);
    const RayCubic g = CellCubic(c.corners, c.o, c.d, c.iso);
    const double t1 = 1.2;
    // Dense sampling: the first sample interval whose ends lie on different
    // sides (g < 0, g >= 0).
    int first = -1;
    double prev = g(0);
    for (int k = 1; k <= kSamples && first < 0; ++k) {
      const double v = g(t1 * k / kSamples);
      if ((v < 0) != (prev < 0)) first = k;
      prev = v;
    }
    SideChange changes[3];
    const int n = SideChanges(g, t1, changes);
    ASSERT_LE(n, 3);
    const double scale = std::abs(g.a) + std::abs(g.b) + std::abs(g.c) + std::abs(g.d) + 1;
    for (int k = 0; k < n; ++k) {
      ASSERT_GE(changes[k].t, 0) << i;
      ASSERT_LE(changes[k].t, t1) << i;
      if (k > 0) {
        ASSERT_GE(changes[k].t, changes[k - 1].t) << i;
        ASSERT_NE(changes[k].up, changes[k - 1].up) << i;  // sides alternate
      }
      ASSERT_LE(std::abs(g(changes[k].t)), 1e-9 * scale) << "case " << i << " root " << k;
    }
    // The first change enters the side the start is not on.
    if (n > 0) {
      ASSERT_EQ(changes[0].up, g(0) < 0) << i;
    }
    // Deterministic: the same bits again.
    SideChange again[3];
    ASSERT_EQ(SideChanges(g, t1, again), n);
    for (int k = 0; k < n; ++k) {
      ASSERT_EQ(again[k].t, changes[k].t);
    }
    if (first >= 0) {
      ++crossings;
      ASSERT_GT(n, 0) << "case " << i << ": a crossing by sample " << first;
      // Not after the crossing dense sampling found (an earlier pair of
      // crossings between two samples may come first).
      ASSERT_LE(changes[0].t, t1 * first / kSamples + 1e-12) << i;
      if (changes[0].t < t1 * (first - 1) / kSamples) ++extra;
    } else if (n > 0) {
      ++extra;  // two crossings between samples
    }
  }
  // The cases are not degenerate: most rays cross.
  EXPECT_GT(crossings, 5000);
  EXPECT_LT(extra, 200);
}

TEST(IsosurfaceTest, ThinFeaturesBetweenAnySamplingAreFound) {
  // A cubic that dips below zero on (0.5, 0.5 + 1e-4) only: a fixed step of
  // 1e-3 would step over it.
  const double r0 = 0.5, r1 = 0.5 + 1e-4;
  RayCubic g;  // (t - r0)(t - r1)(t - 3), positive before r0
  g.a = -1;
  g.b = r0 + r1 + 3;
  g.c = -(r0 * r1 + 3 * r0 + 3 * r1);
  g.d = 3 * r0 * r1;
  SideChange changes[3];
  ASSERT_EQ(SideChanges(g, 1, changes), 2);
  EXPECT_NEAR(changes[0].t, r0, 1e-12);
  EXPECT_FALSE(changes[0].up);
  EXPECT_NEAR(changes[1].t, r1, 1e-12);
  EXPECT_TRUE(changes[1].up);
  // A ray starting on the surface, going up, is on the side >= 0 already:
  // its first change is where it goes down again.
  RayCubic on;  // t^3 - 2t^2 + t/2: zero at 0, 1 - sqrt(1/2) and 1 + sqrt(1/2)
  on.a = 1;
  on.b = -2;
  on.c = 0.5;
  ASSERT_EQ(SideChanges(on, 1, changes), 1);
  EXPECT_NEAR(changes[0].t, 1 - std::sqrt(0.5), 1e-12);
  EXPECT_FALSE(changes[0].up);
  // One that ends before the feature meets nothing; nor does an empty span.
  EXPECT_EQ(SideChanges(g, 0.4, changes), 0);
  EXPECT_EQ(SideChanges(g, -1, changes), 0);
}


// Through whole volumes, cell after cell of the field (including rays
// that leave the volume, where the field is clamped): the first crossing
// dense sampling sees is never missed, every crossing reported is one and
// enters the band on the side the field moves to, and cutting the ray's
// span into pieces (as segments and slabs do) changes no crossing by a bit.
TEST(IsosurfaceTest, CrossingWalkWalksTheFieldsCells) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> unit(0, 1), dir(-1, 1);
  constexpr int kSamples = 4096;
  int crossings = 0, cut_rays = 0;
  for (int trial = 0; trial < 200; ++trial) {
    Volume v;
    v.dims = {5 + static_cast<int>(rng() % 4), 5 + static_cast<int>(rng() % 4),
              5 + static_cast<int>(rng() % 4)};
    v.values.resize(v.VoxelCount());
    for (float& x : v.values) x = static_cast<float>(unit(rng) * 1000);
    const float iso = static_cast<float>(200 + unit(rng) * 600);
    Classification c;
    // One edge inside the values (iso), one above them all.
    c.materials = {Material{.name = "m", .min = iso, .max = 5000}};
    const Bands bands(c);
    auto scene = Scene::ForSurfaces(v, c);
    ASSERT_TRUE(scene.ok()) << scene.status();
    for (int r = 0; r < 50; ++r) {
      Vec3 o{unit(rng) * v.dims[0], unit(rng) * v.dims[1], unit(rng) * v.dims[2]};
      Vec3 d{rng() % 4 == 0 ? 0.0 : dir(rng), rng() % 4 == 0 ? 0.0 : dir(rng), dir(rng)};
      const double len = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
      d = d * (1 / len);
      const double t1 = 0.5 + unit(rng) * 6;
      auto g = [&](double t) {
        const Vec3 p = o + d * t;
        return FieldAt(*scene, p) - iso;
      };
      int first = -1;
      double prev = g(0);
      for (int k = 1; k <= kSamples && first < 0; ++k) {
        const double val = g(t1 * k / kSamples);
        if ((val < 0) != (prev < 0)) first = k;
        prev = val;
      }
      std::vector<Crossing> all;
      const int start_band = g(0) >= 0 ? 1 : 0;
      CrossingWalk walk(*scene, bands, o, d, 0, t1, start_band);
      while (auto x = walk.Next()) all.push_back(*x);
      for (size_t k = 0; k < all.size(); ++k) {
        const Crossing& x = all[k];
        ASSERT_GE(x.t, 0);
        ASSERT_LT(x.t, t1);
        if (k > 0) {
          ASSERT_GE(x.t, all[k - 1].t);
        }
        ASSERT_LE(std::abs(g(x.t)), 1e-6) << "trial " << trial << " ray " << r;
        ASSERT_TRUE(x.band == 0 || x.band == 1);
        // Crossings alternate: each leaves the band the last entered.
        ASSERT_NE(x.band, k == 0 ? start_band : all[k - 1].band);
        // Just past the crossing the field lies on the band's side.
        const double after = g(x.t + 1e-7);
        if (std::abs(after) > 1e-6) {
          ASSERT_EQ(after >= 0, x.band == 1) << trial << " " << r;
        }
      }
      if (first >= 0) {
        ++crossings;
        ASSERT_FALSE(all.empty()) << "trial " << trial << " ray " << r;
        ASSERT_LE(all[0].t, t1 * first / kSamples + 1e-12) << "trial " << trial << " ray " << r;
      }
      // The same crossings, bit for bit, with the span cut at random points.
      std::vector<double> cuts = {0, t1};
      for (int k = rng() % 5; k > 0; --k) cuts.push_back(unit(rng) * t1);
      // Empty pieces too: a ray through an edge or a corner of its column
      // has a segment of length 0.
      if (rng() % 3 == 0) cuts.push_back(cuts[rng() % cuts.size()]);
      std::sort(cuts.begin(), cuts.end());
      std::vector<Crossing> pieces;
      int band = start_band;
      for (size_t k = 0; k + 1 < cuts.size(); ++k) {
        CrossingWalk piece(*scene, bands, o, d, cuts[k], cuts[k + 1], band);
        while (auto x = piece.Next()) {
          pieces.push_back(*x);
          band = x->band;
        }
      }
      // And as the tracer walks consecutive candidate segments: one walk
      // extended piece by piece, begun afresh now and then.
      std::vector<Crossing> extended;
      std::optional<CrossingWalk> walker;
      band = start_band;
      for (size_t k = 0; k + 1 < cuts.size(); ++k) {
        if (!walker || rng() % 4 == 0) {
          walker.emplace(*scene, bands, o, d, cuts[k], cuts[k + 1], band);
        } else {
          walker->Extend(cuts[k + 1]);
        }
        while (auto x = walker->Next()) {
          extended.push_back(*x);
          band = x->band;
        }
      }
      cut_rays += cuts.size() > 2;
      ASSERT_EQ(pieces.size(), all.size()) << "trial " << trial << " ray " << r;
      ASSERT_EQ(extended.size(), all.size()) << "trial " << trial << " ray " << r;
      for (size_t k = 0; k < all.size(); ++k) {
        ASSERT_EQ(pieces[k].t, all[k].t);
        ASSERT_EQ(pieces[k].band, all[k].band);
        ASSERT_EQ(extended[k].t, all[k].t);
        ASSERT_EQ(extended[k].band, all[k].band);
      }
    }
  }
  EXPECT_GT(crossings, 5000);
  EXPECT_GT(cut_rays, 5000);
}

// A smooth volume with plateaus (values rounded to steps of 25, so that
// whole regions share a band and some values fall exactly on an edge) and
// three materials: wide uniform space for the grid to jump, and surfaces.
Volume BlobVolume(std::mt19937_64& rng, std::array<int, 3> dims, Classification* c) {
  std::uniform_real_distribution<double> unit(0, 1);
  Volume v;
  v.dims = dims;
  v.values.resize(v.VoxelCount());
  double centre[3][3], radius[3];
  for (int b = 0; b < 3; ++b) {
    for (int a = 0; a < 3; ++a) centre[b][a] = unit(rng) * dims[a];
    radius[b] = 2 + unit(rng) * dims[0] / 3.0;
  }
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x) {
        double f = 0;
        for (int b = 0; b < 3; ++b) {
          const double r = std::hypot(x - centre[b][0], y - centre[b][1], z - centre[b][2]);
          f += 1000 * std::max(0.0, 1 - r / radius[b]);
        }
        v.values[v.Index(x, y, z)] = static_cast<float>(25 * std::round(f / 25));
      }
  c->materials = {Material{.name = "a", .min = 200, .max = 500},
                  Material{.name = "b", .min = 500, .max = 800, .opacity = 0.5f},
                  Material{.name = "c", .min = 900, .max = 5000}};
  return v;
}

// A cell the grid labels with a band has the field in that band
// throughout (dense sampling, faces included), and the grid both labels
// and leaves enough cells mixed to matter.
TEST(IsosurfaceTest, FieldGridLabelsOnlyCellsOfOneBand) {
  std::mt19937_64 rng(11);
  size_t uniform = 0, mixed = 0;
  for (int trial = 0; trial < 12; ++trial) {
    Classification c;
    const Volume v = BlobVolume(rng, {12 + static_cast<int>(rng() % 6), 10, 9}, &c);
    const Bands bands(c);
    auto scene = Scene::ForSurfaces(v, c);
    ASSERT_TRUE(scene.ok()) << scene.status();
    const FieldGrid& grid = scene->field();
    ASSERT_FALSE(grid.empty());
    ASSERT_EQ(grid.cells()[0], v.dims[0] + 1);
    for (int z = 0; z <= v.dims[2]; ++z)
      for (int y = 0; y <= v.dims[1]; ++y)
        for (int x = 0; x <= v.dims[0]; ++x) {
          ASSERT_TRUE(grid.Holds(x, y, z));
          const uint8_t label = grid.Label(x, y, z);
          if (label == FieldGrid::kMixed) {
            ++mixed;
            continue;
          }
          ++uniform;
          for (int k = 0; k < 64; ++k) {
            const Vec3 p{x - 0.5 + (k & 3) / 3.0, y - 0.5 + (k >> 2 & 3) / 3.0,
                         z - 0.5 + (k >> 4) / 3.0};
            ASSERT_EQ(bands.Of(static_cast<float>(FieldAt(*scene, p))), label)
                << "trial " << trial << " cell " << x << "," << y << "," << z;
          }
        }
  }
  EXPECT_GT(mixed, uniform / 50);
  EXPECT_GT(uniform, mixed);
}

// Each cell's label is the rule's (field_grid.h), computed here the plain
// way: kMixed when a corner is NaN or the least and greatest corner's bands
// differ or reach 255, else that band. Over random slabs of random volumes
// whose values sit on the edges, a float either side, at -0, infinities and
// NaN, with 1-400 edges (past 255 bands too) and rows of any width.
TEST(IsosurfaceTest, FieldGridLabelsAreTheirCornersBand) {
  std::mt19937_64 rng(41);
  constexpr float kInf = std::numeric_limits<float>::infinity();
  size_t mixed = 0, banded = 0;
  for (int trial = 0; trial < 300; ++trial) {
    Classification c;
    const int materials = std::array<int, 5>{1, 2, 5, 100, 200}[rng() % 5];
    for (int m = 0; m < materials; ++m) {
      c.materials.push_back(Material{.name = "m", .min = 4.0f * m, .max = 4.0f * m + 3});
    }
    const Bands bands(c);
    const std::vector<float>& edges = bands.edges();
    const std::array<int, 3> dims = {1 + static_cast<int>(rng() % 37),
                                     1 + static_cast<int>(rng() % 9),
                                     1 + static_cast<int>(rng() % 7)};
    const int row_begin = static_cast<int>(rng() % (dims[1] + 1));
    const int row_end = row_begin + 1 + static_cast<int>(rng() % (dims[1] + 1 - row_begin));
    // The planes the rows read, and a random plane more either side.
    const int y0 =
        std::max(0, std::clamp(row_begin - 1, 0, dims[1] - 1) - static_cast<int>(rng() % 2));
    const int y1 = std::min(dims[1] - 1,
                            std::clamp(row_end - 1, 0, dims[1] - 1) + static_cast<int>(rng() % 2));
    const int planes = y1 - y0 + 1;
    std::vector<float> scalars(static_cast<size_t>(dims[0]) * planes * dims[2]);
    // Mostly long runs of one value, so that cells of one band are common.
    float run = 0;
    for (float& x : scalars) {
      if (rng() % 6 == 0) {
        const float e = edges[rng() % edges.size()];
        switch (rng() % 6) {
          case 0:
            run = std::nextafter(e, -kInf);
            break;
          case 1:
            run = std::nextafter(e, kInf);
            break;
          case 2:
            run = std::bit_cast<float>(rng() % 2 ? 0x7fc00000u : 0x80000000u);
            break;
          case 3:
            run = rng() % 2 ? kInf : -kInf;
            break;
          case 4:
            run = e;
            break;
          default:
            run = static_cast<float>(static_cast<int>(rng() % (4 * materials + 4)) - 2);
        }
      }
      x = run;
    }
    const FieldGrid grid = FieldGrid::Build(scalars, dims, y0, planes, row_begin, row_end, bands);
    auto at = [&](int x, int y, int z) {
      x = std::clamp(x, 0, dims[0] - 1);
      y = std::clamp(y, 0, dims[1] - 1);
      z = std::clamp(z, 0, dims[2] - 1);
      return scalars[(static_cast<size_t>(z) * planes + (y - y0)) * dims[0] + x];
    };
    for (int z = 0; z <= dims[2]; ++z)
      for (int y = row_begin; y < row_end; ++y)
        for (int x = 0; x <= dims[0]; ++x) {
          float lo = kInf, hi = -kInf;
          bool nan = false;
          for (int k = 0; k < 8; ++k) {
            const float v = at(x - 1 + (k & 1), y - 1 + (k >> 1 & 1), z - 1 + (k >> 2));
            nan |= std::isnan(v);
            lo = std::min(lo, v);
            hi = std::max(hi, v);
          }
          const int bl = bands.Of(lo), bh = bands.Of(hi);
          const uint8_t want = nan || bl != bh || bl >= FieldGrid::kMixed
                                   ? FieldGrid::kMixed
                                   : static_cast<uint8_t>(bl);
          ASSERT_TRUE(grid.Holds(x, y, z));
          ASSERT_EQ(grid.Label(x, y, z), want) << "trial " << trial << " cell " << x << "," << y
                                               << "," << z << ", " << edges.size() << " edges";
          (want == FieldGrid::kMixed ? mixed : banded) += 1;
        }
  }
  // Both kinds of cell are common.
  EXPECT_GT(banded, (banded + mixed) / 10);
  EXPECT_GT(mixed, (banded + mixed) / 10);
}

// Rays through the whole volume, walked once on the whole scene and again
// piece by piece on slabs of it (Scene::Slab: each with its own grid, which
// jumps other boxes), each piece from where the last stopped, at the slab's
// plane, in the band it ended in: the same crossings, bit for bit. Rays
// along axes and through the cells' faces and edges (half-integer
// coordinates) are among them.
TEST(IsosurfaceTest, CrossingsDoNotDependOnTheSlabsAGridIsCutInto) {
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<double> unit(0, 1), dir(-1, 1);
  size_t crossings = 0, jumps = 0, pieces = 0;
  for (int trial = 0; trial < 10; ++trial) {
    Classification c;
    const Volume v = BlobVolume(rng, {20, 24, 16}, &c);
    const Bands bands(c);
    auto whole = Scene::ForSurfaces(v, c);
    ASSERT_TRUE(whole.ok()) << whole.status();
    // Random cuts along y, slabs one plane thick among them.
    std::vector<int> cuts = {0, v.dims[1]};
    for (int k = 2 + static_cast<int>(rng() % 4); k > 0; --k) {
      cuts.push_back(1 + static_cast<int>(rng() % (v.dims[1] - 1)));
    }
    if (trial % 3 == 0) cuts.push_back(cuts.back() + 1);
    std::sort(cuts.begin(), cuts.end());
    cuts.erase(std::unique(cuts.begin(), cuts.end()), cuts.end());
    std::vector<Scene> slabs;
    for (size_t k = 0; k + 1 < cuts.size(); ++k) slabs.push_back(whole->Slab(cuts[k], cuts[k + 1]));
    for (int r = 0; r < 300; ++r) {
      Vec3 o{unit(rng) * v.dims[0], unit(rng) * v.dims[1], unit(rng) * v.dims[2]};
      Vec3 d{dir(rng), dir(rng), dir(rng)};
      if (r % 5 == 0) o = {std::floor(o.x) + 0.5, std::floor(o.y) + 0.5, o.z};
      if (r % 7 == 0) d = {r % 2 ? 1.0 : -1.0, 0, 0};
      if (r % 11 == 0) d = {0, r % 2 ? 1.0 : -1.0, 0};
      if (r % 13 == 0) d = {1, r % 2 ? 1.0 : -1.0, 0};
      d = d * (1 / Length(d));
      const auto box = IntersectBox(o, d, v.dims);
      if (!box) continue;
      const double t0 = std::max(0.0, (*box)[0]), t1 = (*box)[1];
      std::vector<Crossing> all;
      CrossingWalk walk(*whole, bands, o, d, t0, t1, -1);
      while (auto x = walk.Next()) all.push_back(*x);
      jumps += walk.jumps();
      // The same ray slab by slab, as the ring hands it on.
      std::vector<Crossing> cut;
      int band = -1;
      double t = t0;
      // The slab holding the start, then the next one along y each time,
      // as the ring hands a ray on.
      const Vec3 start = o + d * t0;
      int s = 0;
      while (s + 1 < static_cast<int>(slabs.size()) && start.y >= cuts[s + 1]) ++s;
      for (; s >= 0 && s < static_cast<int>(slabs.size()); s += d.y > 0 ? 1 : -1) {
        double end = t1;
        if (d.y > 0 && s + 1 < static_cast<int>(slabs.size())) end = (cuts[s + 1] - o.y) / d.y;
        if (d.y < 0 && s > 0) end = (cuts[s] - o.y) / d.y;
        end = std::max(std::min(end, t1), t);
        CrossingWalk piece(slabs[s], bands, o, d, t, end, band);
        while (auto x = piece.Next()) {
          cut.push_back(*x);
          band = x->band;
        }
        ++pieces;
        t = end;
        if (d.y == 0) break;
      }
      ASSERT_EQ(cut.size(), all.size()) << "trial " << trial << " ray " << r;
      for (size_t k = 0; k < all.size(); ++k) {
        ASSERT_EQ(cut[k].t, all[k].t) << "trial " << trial << " ray " << r << " crossing " << k;
        ASSERT_EQ(cut[k].band, all[k].band);
        ASSERT_EQ(cut[k].root, all[k].root);
      }
      crossings += all.size();
    }
  }
  EXPECT_GT(crossings, 3000u);
  EXPECT_GT(jumps, 500u);
  EXPECT_GT(pieces, 3000u);
}

// A walk that defers its crossings' times (DeferTimes, as the tracer's
// walks do) meets the same crossings, bands and cells as one that does
// not, and each time it is asked for is the other's bit for bit; asked or
// not, a deferred time changes nothing after it (the next crossing in the
// same cell compares with it, later cells start past it). Random rays
// through blob volumes with plateaus (three materials: two edges of a
// band in one cell) and through noise (several roots a cell), whole and as
// a walk extended piece by piece.
TEST(IsosurfaceTest, ADeferredTimeIsTheOneTheWalkWouldHaveGiven) {
  std::mt19937_64 rng(29);
  std::uniform_real_distribution<double> unit(0, 1), dir(-1, 1);
  size_t crossings = 0, deferred = 0, asked = 0, same_cell = 0, extended = 0;
  for (int trial = 0; trial < 24; ++trial) {
    Classification c;
    Volume v = BlobVolume(rng, {14 + static_cast<int>(rng() % 8), 12, 11}, &c);
    if (trial % 3 == 2) {
      for (float& x : v.values) x = static_cast<float>(unit(rng) * 1000);
    }
    const Bands bands(c);
    auto scene = Scene::ForSurfaces(v, c);
    ASSERT_TRUE(scene.ok()) << scene.status();
    for (int r = 0; r < 400; ++r) {
      Vec3 o{unit(rng) * v.dims[0], unit(rng) * v.dims[1], unit(rng) * v.dims[2]};
      Vec3 d{dir(rng), dir(rng), dir(rng)};
      if (r % 7 == 0) d = {0, 0, r % 2 ? 1.0 : -1.0};
      if (r % 11 == 0) d = {1, r % 2 ? 1.0 : -1.0, 0};
      if (r % 13 == 0) o = {std::floor(o.x) + 0.5, std::floor(o.y) + 0.5, o.z};
      d = d * (1 / Length(d));
      const auto box = IntersectBox(o, d, v.dims);
      if (!box) continue;
      const double t0 = std::max(0.0, (*box)[0]), t1 = (*box)[1];
      struct Seen {
        Crossing x;
        std::array<int, 3> cell;
      };
      std::vector<Seen> eager;
      CrossingWalk walk(*scene, bands, o, d, t0, t1, -1);
      while (auto x = walk.Next()) {
        ASSERT_FALSE(std::isnan(x->t));
        ASSERT_EQ(std::bit_cast<uint64_t>(walk.t()), std::bit_cast<uint64_t>(x->t));
        eager.push_back({*x, walk.cell()});
      }
      ASSERT_EQ(walk.deferred(), 0);
      // Deferring, the range cut at random points and the walk extended
      // over them (or begun afresh).
      std::vector<double> cuts = {t0, t1};
      for (int k = r % 3 == 0 ? 1 + static_cast<int>(rng() % 4) : 0; k > 0; --k) {
        cuts.push_back(t0 + unit(rng) * (t1 - t0));
      }
      std::sort(cuts.begin(), cuts.end());
      std::optional<CrossingWalk> lazy;
      int band = -1;
      size_t k = 0;
      bool unasked = false;  // the last crossing's time was deferred and not asked
      std::array<int, 3> last_cell = {0, 0, 0};
      for (size_t piece = 0; piece + 1 < cuts.size(); ++piece) {
        if (!lazy || rng() % 4 == 0) {
          if (lazy) deferred += lazy->deferred();
          lazy.emplace(*scene, bands, o, d, cuts[piece], cuts[piece + 1], band);
          lazy->DeferTimes();
          unasked = false;
        } else {
          lazy->Extend(cuts[piece + 1]);
          ++extended;
        }
        while (auto x = lazy->Next()) {
          ASSERT_LT(k, eager.size()) << "trial " << trial << " ray " << r;
          const Seen& e = eager[k++];
          ASSERT_EQ(x->band, e.x.band) << "trial " << trial << " ray " << r << " crossing " << k;
          ASSERT_EQ(x->root, e.x.root);
          ASSERT_EQ(lazy->cell(), e.cell);
          if (unasked && lazy->cell() == last_cell) ++same_cell;
          unasked = std::isnan(x->t);
          last_cell = lazy->cell();
          if (unasked) {
            ASSERT_TRUE(x->root);
            if (rng() % 2 == 0) continue;
            ++asked;
            unasked = false;
          }
          ASSERT_EQ(std::bit_cast<uint64_t>(lazy->t()), std::bit_cast<uint64_t>(e.x.t))
              << "trial " << trial << " ray " << r << " crossing " << k;
          if (!std::isnan(x->t))
            ASSERT_EQ(std::bit_cast<uint64_t>(x->t), std::bit_cast<uint64_t>(e.x.t));
          band = x->band;
        }
        if (k > 0) band = eager[k - 1].x.band;
      }
      deferred += lazy->deferred();
      ASSERT_EQ(k, eager.size()) << "trial " << trial << " ray " << r;
      ASSERT_EQ(lazy->truncated(), walk.truncated());
      crossings += eager.size();
    }
  }
  EXPECT_GT(crossings, 20000u);
  EXPECT_GT(deferred, crossings / 10);
  EXPECT_GT(asked, deferred / 4);
  EXPECT_GT(same_cell, 50u);
  EXPECT_GT(extended, 500u);
}

// A brick of the field summary has a band exactly when every cell of the
// field within one cell of it (as the whole volume's grid labels them)
// has that band; volumes as small as one voxel and with no band at all
// among them.
TEST(IsosurfaceTest, FieldSummaryLabelsABrickByItsCellsAndTheirNeighbours) {
  std::mt19937_64 rng(21);
  size_t banded = 0, mixed = 0;
  for (int trial = 0; trial < 16; ++trial) {
    Classification c;
    std::array<int, 3> dims = {1 + static_cast<int>(rng() % 30), 1 + static_cast<int>(rng() % 30),
                               1 + static_cast<int>(rng() % 30)};
    if (trial == 0) dims = {1, 1, 1};
    Volume v = BlobVolume(rng, dims, &c);
    if (trial == 1) v.values[v.values.size() / 2] = std::nanf("");
    const Bands bands(c);
    auto scene = Scene::ForSurfaces(v, c);
    ASSERT_TRUE(scene.ok()) << scene.status();
    const FieldGrid& grid = scene->field();
    const FieldSummary& summary = scene->summary();
    ASSERT_FALSE(summary.empty());
    for (int a = 0; a < 3; ++a) ASSERT_EQ(summary.brick_dims()[a], (dims[a] + 8) / 8);
    for (int bz = 0; bz < summary.brick_dims()[2]; ++bz)
      for (int by = 0; by < summary.brick_dims()[1]; ++by)
        for (int bx = 0; bx < summary.brick_dims()[0]; ++bx) {
          const int b[3] = {bx, by, bz};
          int lo[3], hi[3];
          for (int a = 0; a < 3; ++a) {
            lo[a] = std::max(8 * b[a] - 1, 0);
            hi[a] = std::min(8 * b[a] + 8, dims[a]);
          }
          int want = -1;
          for (int z = lo[2]; z <= hi[2] && want != FieldGrid::kMixed; ++z)
            for (int y = lo[1]; y <= hi[1] && want != FieldGrid::kMixed; ++y)
              for (int x = lo[0]; x <= hi[0]; ++x) {
                const int label = grid.Label(x, y, z);
                if (want == -1) want = label;
                if (label != want) {
                  want = FieldGrid::kMixed;
                  break;
                }
              }
          ASSERT_EQ(summary.At(bx, by, bz), want)
              << "trial " << trial << " brick " << bx << "," << by << "," << bz;
          (want == FieldGrid::kMixed ? mixed : banded) += 1;
        }
  }
  EXPECT_GT(banded, 50u);
  EXPECT_GT(mixed, 50u);
}

// Whenever the summary says a ray's path holds only the ray's band, a walk
// of the field's cells over that path finds no crossing: random rays from
// random points, rays along the axes and through the bricks' faces and
// corners among them. And it says so often enough to matter.
TEST(IsosurfaceTest, APathTheSummaryClearsHoldsNoCrossing) {
  std::mt19937_64 rng(22);
  std::uniform_real_distribution<double> unit(0, 1), dir(-1, 1);
  size_t cleared = 0, refused = 0;
  for (int trial = 0; trial < 12; ++trial) {
    Classification c;
    const std::array<int, 3> dims = {24 + static_cast<int>(rng() % 20), 40, 17};
    const Volume v = BlobVolume(rng, dims, &c);
    const Bands bands(c);
    auto scene = Scene::ForSurfaces(v, c);
    ASSERT_TRUE(scene.ok()) << scene.status();
    const FieldSummary& summary = scene->summary();
    for (int r = 0; r < 2000; ++r) {
      Vec3 o{unit(rng) * dims[0], unit(rng) * dims[1], unit(rng) * dims[2]};
      Vec3 d{dir(rng), dir(rng), dir(rng)};
      if (r % 5 == 0) o = {8 * std::round(o.x / 8) - 0.5, 8 * std::round(o.y / 8) - 0.5, o.z};
      if (r % 7 == 0) d = {r % 2 ? 1.0 : -1.0, 0, 0};
      if (r % 11 == 0) d = {0, r % 2 ? 1.0 : -1.0, 0};
      if (r % 13 == 0) d = {1, r % 2 ? 1.0 : -1.0, 0};
      d = d * (1 / Length(d));
      const auto box = IntersectBox(o, d, dims);
      if (!box) continue;
      const double t0 = std::max(0.0, (*box)[0]), t1 = (*box)[1];
      const RayAxes axes(d);
      CrossingWalk walk(*scene, bands, o, axes, t0, t1, -1);
      const auto start = walk.Next();  // the field's band at t0
      ASSERT_TRUE(start.has_value());
      ASSERT_FALSE(start->root);
      if (!summary.Clear(o, axes, t0, t1, start->band)) {
        ++refused;
        continue;
      }
      ++cleared;
      const auto next = walk.Next();
      ASSERT_FALSE(next.has_value()) << "trial " << trial << " ray " << r << ": band "
                                     << start->band << " cleared, crossing at " << next->t
                                     << " into band " << next->band;
      // Any other band is refused on the same path.
      ASSERT_FALSE(summary.Clear(o, axes, t0, t1, (start->band + 1) % bands.size()));
    }
  }
  EXPECT_GT(cleared, 2000u);
  EXPECT_GT(refused, 2000u);
}

// The summary's bytes round-trip; a wrong size or a byte naming no band is
// refused with the reason, whatever the dimensions claim.
TEST(IsosurfaceTest, FieldSummaryBytesAreChecked) {
  std::mt19937_64 rng(23);
  Classification c;
  const Volume v = BlobVolume(rng, {20, 9, 33}, &c);
  const Bands bands(c);
  auto scene = Scene::ForSurfaces(v, c);
  ASSERT_TRUE(scene.ok()) << scene.status();
  const std::vector<uint8_t>& bytes = scene->summary().bytes();
  const std::string wire(bytes.begin(), bytes.end());
  auto back = FieldSummary::FromBytes(v.dims, bands.size(), wire);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->bytes(), bytes);
  auto short_by_one = FieldSummary::FromBytes(v.dims, bands.size(), wire.substr(1));
  ASSERT_FALSE(short_by_one.ok());
  EXPECT_NE(short_by_one.status().message().find("expected"), std::string::npos);
  std::string bad = wire;
  bad[3] = static_cast<char>(bands.size());
  auto no_band = FieldSummary::FromBytes(v.dims, bands.size(), bad);
  ASSERT_FALSE(no_band.ok());
  EXPECT_NE(no_band.status().message().find("band"), std::string::npos);
  EXPECT_FALSE(FieldSummary::FromBytes({1 << 30, 1 << 30, 1 << 30}, 3, wire).ok());
  EXPECT_FALSE(FieldSummary::FromBytes({0, 4, 4}, 3, "").ok());
  // A slab keeps the whole volume's summary.
  EXPECT_EQ(scene->Slab(3, 5).summary().bytes(), bytes);
}

// A random orbit view of an image of size + [0, range) pixels a side, from
// any direction, zoomed by 0.5 + [0, zoom_range); orthographic one trial in
// three.
CameraSpec RandomView(std::mt19937_64& rng, int trial, int size, int range, double zoom_range) {
  std::uniform_real_distribution<double> unit(0, 1);
  CameraSpec spec;
  spec.width = size + static_cast<int>(rng() % range);
  spec.height = size + static_cast<int>(rng() % range);
  spec.azimuth_deg = 360 * unit(rng);
  spec.elevation_deg = 170 * unit(rng) - 85;
  spec.projection = trial % 3 == 2 ? Projection::kOrthographic : Projection::kPerspective;
  spec.zoom = 0.5 + zoom_range * unit(rng);
  return spec;
}

// The rays of a pixel the tracer knows to be void (Tracer::Void), traced
// all the same, leave exactly the miss's deposit: no material met, no
// shadow ray, the background bit for bit. Random blob volumes, spacings
// and views (perspective and orthographic, near and far, several samples
// a pixel); void pixels whose rays enter the volume must be common enough
// to matter. A view from inside the volume, or a material in band 0, knows
// no void pixel.
TEST(IsosurfaceTest, AVoidPixelsRaysMeetNothing) {
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<double> unit(0, 1);
  size_t void_rays = 0, void_pixels = 0, other_pixels = 0;
  for (int trial = 0; trial < 200; ++trial) {
    Classification c;
    const std::array<int, 3> dims = {20 + static_cast<int>(rng() % 30),
                                     20 + static_cast<int>(rng() % 30),
                                     12 + static_cast<int>(rng() % 20)};
    Volume v = BlobVolume(rng, dims, &c);
    v.spacing = {0.6 + unit(rng), 0.6 + unit(rng), 0.6 + 2 * unit(rng)};
    auto scene = Scene::ForSurfaces(v, c);
    ASSERT_TRUE(scene.ok()) << scene.status();
    const CameraSpec spec = RandomView(rng, trial, 30, 40, 3);
    auto camera = Camera::Create(
        spec, Vec3{dims[0] * v.spacing[0], dims[1] * v.spacing[1], dims[2] * v.spacing[2]});
    ASSERT_TRUE(camera.ok()) << camera.status();
    RenderSettings settings;
    settings.shadows = trial % 2 == 0;
    settings.samples = trial % 4 == 1 ? 4 : 1;
    const Tracer tracer(*scene, settings, *camera);
    for (int row = 0; row < spec.height; ++row) {
      for (int col = 0; col < spec.width; ++col) {
        if (!tracer.Void(col, row)) {
          ++other_pixels;
          continue;
        }
        ++void_pixels;
        const uint32_t pixel = static_cast<uint32_t>(row) * spec.width + col;
        for (int sample = 0; sample < settings.samples; ++sample) {
          const auto [ox, oy] = SampleOffset(sample, settings.samples);
          RayDescriptor ray;
          if (!tracer.MakePrimary(camera->GenerateAt(col, row, ox, oy), pixel, &ray)) continue;
          ++void_rays;
          std::vector<RayDescriptor> spawned;
          Deposit deposit;
          TraceCounters counters;
          ASSERT_EQ(tracer.Trace(ray, spawned, deposit, counters), Tracer::Outcome::kFinished);
          const Deposit miss = tracer.MissDeposit(pixel);
          ASSERT_EQ(counters.surface_hits, 0u)
              << "trial " << trial << ", pixel " << col << "," << row;
          ASSERT_TRUE(spawned.empty());
          ASSERT_EQ(deposit.pixel, miss.pixel);
          ASSERT_EQ(deposit.kind, miss.kind);
          ASSERT_EQ(deposit.spawned, miss.spawned);
          ASSERT_EQ(std::memcmp(deposit.color.data(), miss.color.data(), sizeof(miss.color)), 0)
              << "trial " << trial << ", pixel " << col << "," << row;
        }
      }
    }
  }
  EXPECT_GT(void_rays, 25000u);
  EXPECT_GT(other_pixels, 150000u);
  EXPECT_GT(void_pixels, 50000u);

  // Known answers: none from inside the volume, nor with band 0 a material.
  std::mt19937_64 rng2(5);
  Classification c;
  const Volume v = BlobVolume(rng2, {30, 30, 30}, &c);
  CameraSpec spec;
  spec.width = spec.height = 40;
  auto outside = Camera::Create(spec, Vec3{30, 30, 30});
  spec.view = ExplicitView{.eye = {0, 0, 0}, .target = {1, 0, 0}};
  auto inside = Camera::Create(spec, Vec3{30, 30, 30});
  ASSERT_TRUE(outside.ok() && inside.ok());
  auto count_void = [](const Tracer& tracer) {
    int n = 0;
    for (int row = 0; row < 40; ++row)
      for (int col = 0; col < 40; ++col) n += tracer.Void(col, row);
    return n;
  };
  auto scene = Scene::ForSurfaces(v, c);
  ASSERT_TRUE(scene.ok());
  EXPECT_GT(count_void(Tracer(*scene, RenderSettings{}, *outside)), 0);
  EXPECT_EQ(count_void(Tracer(*scene, RenderSettings{}, *inside)), 0);
  Classification low = c;
  low.materials[0].min = -1000;  // band 0 now holds material a
  auto low_scene = Scene::ForSurfaces(v, low);
  ASSERT_TRUE(low_scene.ok()) << low_scene.status();
  EXPECT_EQ(count_void(Tracer(*low_scene, RenderSettings{}, *outside)), 0);
}

// A shell projected in coarser boxes (to bound the cost on large volumes)
// marks every pixel the brick by brick projection marks, and fewer than
// all of them while the boxes are small: random volumes and views, from
// one box to a few hundred.
TEST(IsosurfaceTest, PixelsMeetingInCoarseBoxesHoldsTheExactOnes) {
  std::mt19937_64 rng(37);
  size_t exact_total = 0, coarse_total = 0, pixels = 0;
  for (int trial = 0; trial < 60; ++trial) {
    Classification c;
    const std::array<int, 3> dims = {30 + static_cast<int>(rng() % 60),
                                     30 + static_cast<int>(rng() % 60),
                                     20 + static_cast<int>(rng() % 40)};
    const Volume v = BlobVolume(rng, dims, &c);
    auto scene = Scene::ForSurfaces(v, c);
    ASSERT_TRUE(scene.ok()) << scene.status();
    const CameraSpec spec = RandomView(rng, trial, 40, 60, 2);
    auto camera = Camera::Create(spec, Vec3{double(dims[0]), double(dims[1]), double(dims[2])});
    ASSERT_TRUE(camera.ok());
    const FieldSummary& summary = scene->summary();
    const PixelMask exact =
        summary.PixelsMeeting(*camera, v.spacing, std::numeric_limits<size_t>::max());
    const size_t max_boxes = size_t{1} << (rng() % 9);
    const PixelMask coarse = summary.PixelsMeeting(*camera, v.spacing, max_boxes);
    if (exact.empty()) {
      EXPECT_TRUE(coarse.empty());
      continue;
    }
    if (coarse.empty()) continue;  // every pixel may meet: it holds them
    for (int row = 0; row < spec.height; ++row) {
      for (int col = 0; col < spec.width; ++col) {
        ASSERT_TRUE(!exact.Get(col, row) || coarse.Get(col, row))
            << "trial " << trial << ", " << max_boxes << " boxes: pixel " << col << "," << row;
      }
    }
    exact_total += exact.Count();
    coarse_total += coarse.Count();
    pixels += static_cast<size_t>(spec.width) * spec.height;
  }
  EXPECT_GT(exact_total, 10000u);
  EXPECT_GT(coarse_total, exact_total);
  EXPECT_LT(coarse_total, pixels);
}

// Ties on purpose: the field 100 (x - 0.5) has its roots on the cells'
// faces (x = k + 0.5 for edges 100 k), and a ray from (a + 0.5, b, z)
// along (1, +-1, 0) crosses each x face at the very time it crosses a y
// plane, where slabs one plane thick cut it. A walk resumed at a plane
// must begin in the cell the whole walk is in there (not the next one),
// or the root on that cell's far face is lost.
TEST(IsosurfaceTest, CrossingsOnFacesAtSlabPlanesAreTakenOnce) {
  Volume v;
  v.dims = {16, 16, 4};
  v.values.resize(v.VoxelCount());
  for (int z = 0; z < v.dims[2]; ++z)
    for (int y = 0; y < v.dims[1]; ++y)
      for (int x = 0; x < v.dims[0]; ++x) v.values[v.Index(x, y, z)] = 100.0f * x;
  Classification c;
  c.materials = {Material{.name = "a", .min = 300, .max = 600},
                 Material{.name = "b", .min = 600, .max = 1100, .opacity = 0.5f}};
  const Bands bands(c);
  auto whole = Scene::ForSurfaces(v, c);
  ASSERT_TRUE(whole.ok()) << whole.status();
  std::vector<Scene> slabs;
  for (int y = 0; y < v.dims[1]; ++y) slabs.push_back(whole->Slab(y, y + 1));
  int rays = 0;
  for (int a = 0; a < 4; ++a) {
    for (int b = 0; b < v.dims[1]; ++b) {
      for (const double dy : {1.0, -1.0}) {
        const Vec3 o{a + 0.5, b + 0.0, 1.3};
        const Vec3 d = Vec3{1, dy, 0} * (1 / std::sqrt(2.0));
        const auto box = IntersectBox(o, d, v.dims);
        if (!box) continue;
        const double t0 = (*box)[0], t1 = (*box)[1];
        std::vector<Crossing> all;
        CrossingWalk walk(*whole, bands, o, d, t0, t1, -1);
        while (auto x = walk.Next()) all.push_back(*x);
        std::vector<Crossing> cut;
        int band = -1;
        double t = t0;
        // Slab b (the plane the ray starts on) and on, as the ring hands it.
        int s = dy > 0 ? b : b - 1;
        for (; s >= 0 && s < v.dims[1]; s += dy > 0 ? 1 : -1) {
          double end = (dy > 0 ? s + 1 - o.y : s - o.y) / d.y;
          end = std::max(std::min(end, t1), t);
          CrossingWalk piece(slabs[s], bands, o, d, t, end, band);
          while (auto x = piece.Next()) {
            cut.push_back(*x);
            band = x->band;
          }
          t = end;
        }
        // The ray meets each edge on an x face: 300, 600 and 1100 at x =
        // 3.5, 6.5 and 11.5 (those ahead of its start), once each. (A root
        // that rounds to just past its cell's far face is taken as the
        // next cell's band, at the same t: root false.)
        std::vector<std::pair<double, int>> faces;  // x, and the band beyond it
        int beyond = 1;
        for (double e : {3.5, 6.5, 11.5}) {
          if (e > o.x && (o + d * t1).x > e) faces.push_back({e, beyond});
          ++beyond;
        }
        ASSERT_EQ(all.size(), faces.size() + 1) << "a " << a << " b " << b << " dy " << dy;
        for (size_t k = 0; k < faces.size(); ++k) {
          EXPECT_NEAR((o + d * all[k + 1].t).x, faces[k].first, 1e-12);
          EXPECT_EQ(all[k + 1].band, faces[k].second);
        }
        ASSERT_EQ(cut.size(), all.size()) << "a " << a << " b " << b << " dy " << dy;
        for (size_t k = 0; k < all.size(); ++k) {
          EXPECT_EQ(cut[k].t, all[k].t);
          EXPECT_EQ(cut[k].band, all[k].band);
        }
        ++rays;
      }
    }
  }
  EXPECT_GT(rays, 100);
}

}  // namespace
}  // namespace transtick
