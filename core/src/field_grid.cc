#include "transtick/field_grid.h"

#include <algorithm>

#include "transtick/brick_map.h"
#include "transtick/check.h"
#include "transtick/parallel.h"

namespace transtick {

FieldGrid FieldGrid::Build(const std::vector<float>& scalars, std::array<int, 3> dims,
                           int scalar_y_begin, int scalar_planes, int row_begin, int row_end,
                           const Bands& bands) {
  TRANSTICK_CHECK(0 <= row_begin && row_begin < row_end && row_end <= dims[1] + 1);
  FieldGrid g;
  const int nx = dims[0], ny = dims[1], nz = dims[2];
  g.cells_ = {nx + 1, row_end - row_begin, nz + 1};
  g.row_begin_ = row_begin;
  std::vector<uint8_t> labels(static_cast<size_t>(g.cells_[0]) * g.cells_[1] * g.cells_[2]);
  const std::vector<float>& edges = bands.edges();
  // The band of a value: how many edges lie at or below it (Bands::Of).
  auto band = [&](float v) {
    if (edges.size() <= 8) {
      int b = 0;
      for (float e : edges) b += e <= v;
      return b;
    }
    return static_cast<int>(std::upper_bound(edges.begin(), edges.end(), v) - edges.begin());
  };
  const size_t row = nx, plane = row * scalar_planes;
  auto voxel_row = [&](int y, int z) {
    y = std::clamp(y, 0, ny - 1);
    z = std::clamp(z, 0, nz - 1);
    TRANSTICK_CHECK(y >= scalar_y_begin && y < scalar_y_begin + scalar_planes);
    return scalars.data() + z * plane + (y - scalar_y_begin) * row;
  };
  // Per row of cells: the least and greatest of the four voxel rows its
  // corners read, then of each pair along x (clamped at the faces). Planes
  // of cells on as many threads.
  const size_t plane_cells = static_cast<size_t>(g.cells_[0]) * g.cells_[1];
  ParallelFor(nz + 1, 4, [&](size_t z_begin, size_t z_end) {
    std::vector<float> lo(nx), hi(nx);
    std::vector<uint8_t> nan(nx);
    uint8_t* out = labels.data() + z_begin * plane_cells;
    for (int cz = static_cast<int>(z_begin); cz < static_cast<int>(z_end); ++cz) {
      for (int cy = row_begin; cy < row_end; ++cy) {
        const float* r[4] = {voxel_row(cy - 1, cz - 1), voxel_row(cy, cz - 1),
                             voxel_row(cy - 1, cz), voxel_row(cy, cz)};
        for (int x = 0; x < nx; ++x) {
          const float a = r[0][x], b = r[1][x], c = r[2][x], d = r[3][x];
          lo[x] = std::min(std::min(a, b), std::min(c, d));
          hi[x] = std::max(std::max(a, b), std::max(c, d));
          // A NaN corner makes the cell mixed: its cubic finds no root there,
          // as it would without the label.
          nan[x] = (a != a) | (b != b) | (c != c) | (d != d);
        }
        for (int cx = 0; cx <= nx; ++cx) {
          const int x0 = std::max(cx - 1, 0), x1 = std::min(cx, nx - 1);
          const float l = std::min(lo[x0], lo[x1]), h = std::max(hi[x0], hi[x1]);
          const int bl = band(l), bh = band(h);
          *out++ =
              nan[x0] | nan[x1] || bl != bh || bl >= kMixed ? kMixed : static_cast<uint8_t>(bl);
        }
      }
    }
  });
  // The groups and their reach, as a brick map over the labels finds them.
  const BrickMap map = BrickMap::Build(labels, g.cells_, /*uniform_materials=*/true);
  for (int a = 0; a < 3; ++a) g.group_dims_[a] = (g.cells_[a] + 1) / 2;
  g.groups_.resize(static_cast<size_t>(g.group_dims_[0]) * g.group_dims_[1] * g.group_dims_[2]);
  const auto& n = g.cells_;
  const size_t plane_groups = static_cast<size_t>(g.group_dims_[0]) * g.group_dims_[1];
  ParallelFor(g.group_dims_[2], 2, [&](size_t z_begin, size_t z_end) {
    size_t k = z_begin * plane_groups;
    for (int z = static_cast<int>(z_begin); z < static_cast<int>(z_end); ++z) {
      for (int y = 0; y < g.group_dims_[1]; ++y) {
        for (int x = 0; x < g.group_dims_[0]; ++x, ++k) {
          Group& group = g.groups_[k];
          for (int s = 0; s < 8; ++s) {
            // Past the faces: the cell inside nearest to it.
            const int cx = std::min(2 * x + (s & 1), n[0] - 1);
            const int cy = std::min(2 * y + (s >> 1 & 1), n[1] - 1);
            const int cz = std::min(2 * z + (s >> 2), n[2] - 1);
            group.label[s] = labels[(static_cast<size_t>(cz) * n[1] + cy) * n[0] + cx];
          }
          for (int octant = 0; octant < 8; ++octant) {
            group.reach[octant] = static_cast<uint8_t>(map.Reach(2 * x, 2 * y, 2 * z, octant));
          }
        }
      }
    }
  });
  return g;
}

}  // namespace transtick
