#include "transtick/field_grid.h"

#include <algorithm>

#include "transtick/brick_map.h"
#include "transtick/check.h"
#include "transtick/parallel.h"

#if defined(__SSE2__)
#include <immintrin.h>
#endif

namespace transtick {
namespace {

constexpr uint8_t kMixedLabel = FieldGrid::kMixed;

// Each value's band as a byte (the edges at or below it; NaN and a band of
// 255 or more give 255), for out[0, n).
void BandRow(const float* __restrict v, int n, const std::vector<float>& edges,
             uint8_t* __restrict out) {
  if (edges.size() >= kMixedLabel) {
    for (int x = 0; x < n; ++x) {
      const auto b = std::upper_bound(edges.begin(), edges.end(), v[x]) - edges.begin();
      out[x] =
          v[x] != v[x] ? kMixedLabel : static_cast<uint8_t>(std::min<ptrdiff_t>(b, kMixedLabel));
    }
    return;
  }
  int x = 0;
#if defined(__SSE2__)
  // Sixteen values at once: each edge's comparisons, packed to bytes of -1
  // or 0, are subtracted from the count (NaN compares false); NaN then sets
  // all bits.
  for (; x + 16 <= n; x += 16) {
    const __m128 v0 = _mm_loadu_ps(v + x), v1 = _mm_loadu_ps(v + x + 4),
                 v2 = _mm_loadu_ps(v + x + 8), v3 = _mm_loadu_ps(v + x + 12);
    auto bytes = [](__m128 m0, __m128 m1, __m128 m2, __m128 m3) {
      return _mm_packs_epi16(_mm_packs_epi32(_mm_castps_si128(m0), _mm_castps_si128(m1)),
                             _mm_packs_epi32(_mm_castps_si128(m2), _mm_castps_si128(m3)));
    };
    __m128i count = _mm_setzero_si128();
    for (const float e : edges) {
      const __m128 ev = _mm_set1_ps(e);
      count = _mm_sub_epi8(count, bytes(_mm_cmpge_ps(v0, ev), _mm_cmpge_ps(v1, ev),
                                        _mm_cmpge_ps(v2, ev), _mm_cmpge_ps(v3, ev)));
    }
    const __m128i nan = bytes(_mm_cmpunord_ps(v0, v0), _mm_cmpunord_ps(v1, v1),
                              _mm_cmpunord_ps(v2, v2), _mm_cmpunord_ps(v3, v3));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + x), _mm_or_si128(count, nan));
  }
#endif
  for (; x < n; ++x) {
    uint8_t b = 0;
    for (const float e : edges) b += v[x] >= e;
    out[x] = v[x] != v[x] ? kMixedLabel : b;
  }
}

// The labels of a row of n + 1 cells from the bands of the four voxel rows
// their corners read (a, b, c, d): the band all eight corners share, else
// kMixed. lo and hi (n bytes) are scratch.
void LabelRow(const uint8_t* __restrict a, const uint8_t* __restrict b, const uint8_t* __restrict c,
              const uint8_t* __restrict d, int n, uint8_t* __restrict lo, uint8_t* __restrict hi,
              uint8_t* __restrict out) {
  int x = 0;
#if defined(__SSE2__)
  auto load = [](const uint8_t* p) { return _mm_loadu_si128(reinterpret_cast<const __m128i*>(p)); };
  for (; x + 16 <= n; x += 16) {
    const __m128i va = load(a + x), vb = load(b + x), vc = load(c + x), vd = load(d + x);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(lo + x),
                     _mm_min_epu8(_mm_min_epu8(va, vb), _mm_min_epu8(vc, vd)));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(hi + x),
                     _mm_max_epu8(_mm_max_epu8(va, vb), _mm_max_epu8(vc, vd)));
  }
#endif
  for (; x < n; ++x) {
    lo[x] = std::min(std::min(a[x], b[x]), std::min(c[x], d[x]));
    hi[x] = std::max(std::max(a[x], b[x]), std::max(c[x], d[x]));
  }
  // Cell cx reads voxels cx - 1 and cx along x, clamped at the faces.
  out[0] = lo[0] == hi[0] ? hi[0] : kMixedLabel;
  int cx = 1;
#if defined(__SSE2__)
  // Where the least and greatest band agree, that band; elsewhere all bits.
  const __m128i ones = _mm_set1_epi8(-1);
  for (; cx + 16 <= n; cx += 16) {
    const __m128i l = _mm_min_epu8(load(lo + cx - 1), load(lo + cx));
    const __m128i h = _mm_max_epu8(load(hi + cx - 1), load(hi + cx));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + cx),
                     _mm_or_si128(h, _mm_xor_si128(_mm_cmpeq_epi8(l, h), ones)));
  }
#endif
  for (; cx < n; ++cx) {
    const uint8_t l = std::min(lo[cx - 1], lo[cx]), h = std::max(hi[cx - 1], hi[cx]);
    out[cx] = l == h ? h : kMixedLabel;
  }
  out[n] = lo[n - 1] == hi[n - 1] ? hi[n - 1] : kMixedLabel;
}

}  // namespace

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
  // A cell's label, by the rule of field_grid.h: kMixed when a corner is NaN,
  // or when its least and greatest corner lie in different bands or in a
  // band of 255 or more; else that band. A band (the edges at or below a
  // value) never decreases with the value, so the least and greatest
  // corner's bands are the least and greatest of the corners' bands. Each
  // voxel's band is therefore found once, as a byte (255 for NaN and for a
  // band of 255 or more), and a cell's label is the band its eight corners
  // share, or kMixed (255) when they differ: bytes compared sixteen at once.
  const size_t row = nx, plane = row * scalar_planes;
  auto voxel_row = [&](int y, int z) {
    TRANSTICK_CHECK(y >= scalar_y_begin && y < scalar_y_begin + scalar_planes);
    return scalars.data() + z * plane + (y - scalar_y_begin) * row;
  };
  // The voxel rows the cells read: row_begin - 1 .. row_end - 1, clamped.
  const int y0 = std::clamp(row_begin - 1, 0, ny - 1), y1 = std::clamp(row_end - 1, 0, ny - 1);
  const size_t band_plane = static_cast<size_t>(y1 - y0 + 1) * nx;
  // Planes of cells on as many threads, each keeping the voxel bands of the
  // two planes of voxels its cells read.
  const size_t plane_cells = static_cast<size_t>(g.cells_[0]) * g.cells_[1];
  ParallelFor(nz + 1, 4, [&](size_t z_begin, size_t z_end) {
    std::vector<uint8_t> bands_of[2] = {std::vector<uint8_t>(band_plane),
                                        std::vector<uint8_t>(band_plane)};
    int held[2] = {-1, -1};  // the voxel plane each holds
    auto plane_bands = [&](int z) -> const uint8_t* {
      for (int k = 0; k < 2; ++k) {
        if (held[k] == z) return bands_of[k].data();
      }
      // The other plane is the one still needed (z - 1 of the next cell plane).
      const int k = held[0] == z - 1 ? 1 : 0;
      for (int y = y0; y <= y1; ++y) {
        BandRow(voxel_row(y, z), nx, edges, bands_of[k].data() + (y - y0) * nx);
      }
      held[k] = z;
      return bands_of[k].data();
    };
    std::vector<uint8_t> lo(nx), hi(nx);
    uint8_t* out = labels.data() + z_begin * plane_cells;
    for (int cz = static_cast<int>(z_begin); cz < static_cast<int>(z_end); ++cz) {
      const uint8_t* back = plane_bands(std::clamp(cz - 1, 0, nz - 1));
      const uint8_t* front = plane_bands(std::clamp(cz, 0, nz - 1));
      for (int cy = row_begin; cy < row_end; ++cy) {
        const size_t ya = (std::clamp(cy - 1, 0, ny - 1) - y0) * row;
        const size_t yb = (std::clamp(cy, 0, ny - 1) - y0) * row;
        LabelRow(back + ya, back + yb, front + ya, front + yb, nx, lo.data(), hi.data(), out);
        out += nx + 1;
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
