#include "transtick/brick_map.h"

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "transtick/parallel.h"

#if defined(__SSE2__)
#include <immintrin.h>
#endif

namespace transtick {
namespace {

constexpr uint8_t kMixedCell = BrickMap::kMixed;

// The least and greatest label of each column x of the n rows (n >= 1), each
// label taken as itself with uniform materials, else as 0 for void and
// kMixed for anything else.
void ColumnRange(const uint8_t* const* rows, int n, int width, bool uniform, uint8_t* __restrict lo,
                 uint8_t* __restrict hi) {
  auto as = [uniform](uint8_t l) -> uint8_t { return uniform || l == 0 ? l : kMixedCell; };
  for (int x = 0; x < width; ++x) lo[x] = hi[x] = as(rows[0][x]);
  for (int r = 1; r < n; ++r) {
    const uint8_t* __restrict row = rows[r];
    for (int x = 0; x < width; ++x) {
      const uint8_t m = as(row[x]);
      lo[x] = std::min(lo[x], m);
      hi[x] = std::max(hi[x], m);
    }
  }
}

// Cell c of a row is made of columns 2c and 2c + 1: the label they share,
// else kMixed, for c in [0, cells).
void PairLabels(const uint8_t* __restrict lo, const uint8_t* __restrict hi, int cells,
                uint8_t* __restrict out) {
  int c = 0;
#if defined(__SSE2__)
  // Even and odd bytes apart (the low and high byte of each 16-bit lane,
  // packed back without saturating: each is at most 255), then as one.
  const __m128i low = _mm_set1_epi16(0x00ff), ones = _mm_set1_epi8(-1);
  auto load = [](const uint8_t* p) { return _mm_loadu_si128(reinterpret_cast<const __m128i*>(p)); };
  auto even = [&](__m128i a, __m128i b) {
    return _mm_packus_epi16(_mm_and_si128(a, low), _mm_and_si128(b, low));
  };
  auto odd = [](__m128i a, __m128i b) {
    return _mm_packus_epi16(_mm_srli_epi16(a, 8), _mm_srli_epi16(b, 8));
  };
  for (; c + 16 <= cells; c += 16) {
    const __m128i l0 = load(lo + 2 * c), l1 = load(lo + 2 * c + 16);
    const __m128i h0 = load(hi + 2 * c), h1 = load(hi + 2 * c + 16);
    const __m128i l = _mm_min_epu8(even(l0, l1), odd(l0, l1));
    const __m128i h = _mm_max_epu8(even(h0, h1), odd(h0, h1));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + c),
                     _mm_or_si128(h, _mm_xor_si128(_mm_cmpeq_epi8(l, h), ones)));
  }
#endif
  for (; c < cells; ++c) {
    const uint8_t l = std::min(lo[2 * c], lo[2 * c + 1]), h = std::max(hi[2 * c], hi[2 * c + 1]);
    out[c] = l == h ? h : kMixedCell;
  }
}

}  // namespace

void BrickMap::SetDims(std::array<int, 3> dims) {
  for (int a = 0; a < 3; ++a) {
    bdims_[a] = (dims[a] + kBrick - 1) >> kShift;
    cdims_[a] = bdims_[a] * (kBrick / 2);
    cinside_[a] = (dims[a] + 1) / 2;
  }
  bricks_.assign(static_cast<size_t>(bdims_[0]) * bdims_[1] * bdims_[2], 0);
  cells_.assign(static_cast<size_t>(cdims_[0]) * cdims_[1] * cdims_[2], 0);
}

BrickMap BrickMap::Build(std::span<const uint8_t> labels, std::array<int, 3> dims,
                         bool uniform_materials, int y_begin, int y_end) {
  BrickMap b;
  b.SetDims(dims);
  // A cell's material is the one its voxels inside the volume (up to 2^3)
  // share, else it is mixed; without uniform materials every voxel that is
  // not void counts as mixed. A cell with no voxel inside the volume stays
  // void. Per row of cells, from the least and greatest of each column of
  // its voxels: bytes, compared sixteen at a time.
  std::vector<uint8_t> seen(b.cells_.size(), 0);
  const size_t plane = static_cast<size_t>(dims[0]) * dims[1];
  const int nx = dims[0], cells_x = b.cinside_[0];
  // Pairs of planes, which share their cells, on as many threads.
  ParallelFor(b.cinside_[2], 2, [&](size_t pair_begin, size_t pair_end) {
    // One more column than the volume, so that an odd width pairs its last
    // voxel with itself.
    std::vector<uint8_t> lo(nx + 1), hi(nx + 1);
    for (int cz = static_cast<int>(pair_begin); cz < static_cast<int>(pair_end); ++cz) {
      for (int cy = 0; cy < b.cinside_[1]; ++cy) {
        const uint8_t* rows[4];
        int n = 0;
        for (int z = 2 * cz; z < std::min(2 * cz + 2, dims[2]); ++z) {
          for (int y = 2 * cy; y < std::min(2 * cy + 2, dims[1]); ++y) {
            rows[n++] = labels.data() + z * plane + static_cast<size_t>(y) * nx;
          }
        }
        ColumnRange(rows, n, nx, uniform_materials, lo.data(), hi.data());
        lo[nx] = lo[nx - 1];
        hi[nx] = hi[nx - 1];
        const size_t at = b.CellIndex(0, 2 * cy, 2 * cz);
        PairLabels(lo.data(), hi.data(), cells_x, b.cells_.data() + at);
        std::fill_n(seen.data() + at, cells_x, 1);
      }
    }
  });
  // A brick has the material its cells with voxels share, else it is mixed.
  std::vector<uint8_t> brick_seen(b.bricks_.size(), 0);
  b.ForEachBrickCell([&](size_t brick, size_t cell) {
    if (!seen[cell]) return;
    if (!brick_seen[brick]) {
      brick_seen[brick] = 1;
      b.bricks_[brick] = b.cells_[cell];
    } else if (b.bricks_[brick] != b.cells_[cell]) {
      b.bricks_[brick] = kMixed;
    }
  });
  b.FillCells();
  b.ComputeReach(y_begin, y_end < 0 ? dims[1] : y_end);
  return b;
}

size_t BrickMap::ReachBytes(std::array<int, 3> dims, int y_begin, int y_end) {
  BrickMap b;
  for (int a = 0; a < 3; ++a) b.cdims_[a] = ((dims[a] + kBrick - 1) >> kShift) * (kBrick / 2);
  b.SetReachRows(y_begin, y_end);
  return 8 * b.reach_cells_;
}

void BrickMap::SetReachRows(int y_begin, int y_end) {
  // The rows of cells that hold planes [y_begin, y_end).
  row_begin_ = std::clamp(y_begin >> 1, 0, cdims_[1]);
  rows_ = y_end > y_begin ? std::clamp((y_end + 1) >> 1, row_begin_, cdims_[1]) - row_begin_ : 0;
  if (rows_ == 0) row_begin_ = 0;  // no reach is one state, whatever the range
  reach_cells_ = static_cast<size_t>(cdims_[0]) * rows_ * cdims_[2];
}

BrickMap BrickMap::ForSlab(int y_begin, int y_end) const {
  BrickMap b;
  b.bdims_ = bdims_;
  b.bricks_ = bricks_;
  b.cdims_ = cdims_;
  b.cinside_ = cinside_;
  b.cells_ = cells_;
  b.ComputeReach(y_begin, y_end);
  return b;
}

std::vector<uint8_t> BrickMap::bytes() const {
  std::vector<uint8_t> out = bricks_;
  ForEachBrickCell([&](size_t brick, size_t cell) {
    if (bricks_[brick] == kMixed) out.push_back(cells_[cell]);
  });
  return out;
}

uint8_t BrickMap::MaxMaterial() const {
  uint8_t most = 0;
  for (uint8_t m : cells_) {
    if (m != kMixed) most = std::max(most, m);
  }
  return most;
}

void BrickMap::FillCells() {
  // The cells of uniform bricks have the brick's material.
  ForEachBrickCell([&](size_t brick, size_t cell) {
    if (bricks_[brick] != kMixed) cells_[cell] = bricks_[brick];
  });
}

void BrickMap::ComputeReach(int y_begin, int y_end) {
  SetReachRows(y_begin, y_end);
  if (reach_cells_ == 0) {
    // No rows: none to compute (the passes below would still run over the
    // whole map, for nothing).
    reach_.clear();
    return;
  }
  // For each octant, the largest uniform box at each cell by the classic
  // largest-square recurrence in 3D: the box of side r + 1 with the cell at
  // its corner is uniform when the cell is and the boxes of side r at its
  // seven neighbours toward the octant are, in its material. One pass per
  // octant, from the octant's far corner back. Cells past the volume's
  // faces, and a border around the grid that keeps every neighbour in
  // bounds, match anything with reach kMaxReach: the traversal clips its
  // boxes to the volume.
  const int nx = cdims_[0] + 2, ny = cdims_[1] + 2, nz = cdims_[2] + 2;
  constexpr uint16_t kAny = 0xffff;
  const size_t n = static_cast<size_t>(nx) * ny * nz;
  std::vector<uint16_t> m(n, kAny);
  auto index = [&](int x, int y, int z) { return (static_cast<size_t>(z) * ny + y) * nx + x; };
  size_t k = 0;
  for (int z = 1; z + 1 < nz; ++z)
    for (int y = 1; y + 1 < ny; ++y)
      for (int x = 1; x + 1 < nx; ++x, ++k) {
        if (x <= cinside_[0] && y <= cinside_[1] && z <= cinside_[2]) m[index(x, y, z)] = cells_[k];
      }
  reach_.assign(8 * reach_cells_, 0);
  // The octants on as many threads (each writes its own eighth of reach_).
  ParallelFor(8, 1, [&](size_t octant_begin, size_t octant_end) {
    // 16 bits like the materials, so that the loops over rows vectorise.
    std::vector<uint16_t> r(n);
    std::vector<uint16_t> rows(nx);  // the bound from the neighbours off the row
    for (int octant = static_cast<int>(octant_begin); octant < static_cast<int>(octant_end);
         ++octant) {
      const int sx = octant & 1 ? -1 : 1, sy = octant & 2 ? -1 : 1, sz = octant & 4 ? -1 : 1;
      std::fill(r.begin(), r.end(), static_cast<uint16_t>(kMaxReach));
      // Toward the octant's far corner first: each cell after its neighbours.
      // Rows (padded, as y below) behind the kept ones toward the octant are
      // not needed.
      const int first_row = row_begin_ + 1, last_row = row_begin_ + rows_;
      for (int zi = 1; zi + 1 < nz; ++zi) {
        const int z = sz > 0 ? nz - 1 - zi : zi;
        for (int yi = 1; yi + 1 < ny; ++yi) {
          const int y = sy > 0 ? ny - 1 - yi : yi;
          if (sy > 0 ? y < first_row : y > last_row) break;
          const size_t row = index(0, y, z);
          // The six neighbours in the rows ahead along y and z, at x and at
          // x + sx: simple loops over rows, which the compiler vectorises.
          const uint16_t* __restrict mrow = &m[row];
          uint16_t* __restrict bounds = rows.data();
          for (int x = 1; x + 1 < nx; ++x) bounds[x] = mrow[x] == kMixed ? 0 : kMaxReach;
          const size_t ahead[3] = {index(0, y + sy, z), index(0, y, z + sz),
                                   index(0, y + sy, z + sz)};
          for (size_t a : ahead) {
            for (int dx : {0, sx}) {
              // Offsets from the row's start, never before the array's.
              const uint16_t* __restrict mq = m.data() + a;
              const uint16_t* __restrict rq = r.data() + a;
              for (int x = 1; x + 1 < nx; ++x) {
                // rq + 1 for a neighbour of the same material, kMaxReach for
                // one past the faces, else 0, without branches (a cell past
                // the faces itself gets a meaningless bound, never used).
                const uint16_t same = static_cast<uint16_t>(-(mq[x + dx] == mrow[x]));
                const uint16_t any = static_cast<uint16_t>(-(mq[x + dx] == kAny));
                const uint16_t bound =
                    static_cast<uint16_t>(((rq[x + dx] + 1) & same) | (kMaxReach & any));
                bounds[x] = bounds[x] < bound ? bounds[x] : bound;
              }
            }
          }
          // The neighbour along the row, in order from the far end.
          for (int xi = 1; xi + 1 < nx; ++xi) {
            const int x = sx > 0 ? nx - 1 - xi : xi;
            const size_t here = row + x, q = here + sx;
            const uint16_t mine = m[here];
            if (mine == kAny) continue;
            const int bound = m[q] == kAny ? kMaxReach : (m[q] == mine ? r[q] + 1 : 0);
            r[here] = static_cast<uint16_t>(std::min<int>(rows[x], bound));
          }
        }
      }
      uint8_t* out = reach_.data() + octant * reach_cells_;
      size_t at = 0;
      for (int z = 1; z + 1 < nz; ++z)
        for (int y = first_row; y <= last_row; ++y)
          for (int x = 1; x + 1 < nx; ++x, ++at)
            out[at] = m[index(x, y, z)] == kAny ? 0 : static_cast<uint8_t>(r[index(x, y, z)]);
    }
  });
}

absl::StatusOr<BrickMap> BrickMap::FromBytes(std::array<int, 3> dims, std::vector<uint8_t> bytes,
                                             int y_begin, int y_end) {
  BrickMap b;
  b.SetDims(dims);
  const size_t n = b.bricks_.size();
  const size_t mixed =
      bytes.size() < n ? 0 : static_cast<size_t>(std::count(bytes.begin(), bytes.begin() + n, kMixed));
  const size_t want = n + 64 * mixed;
  if (bytes.size() != want) {
    return absl::InvalidArgumentError(absl::StrCat(
        "brick map: ", bytes.size(), " bytes, expected ", bytes.size() < n ? n : want, " (", n,
        " bricks", bytes.size() < n ? "" : absl::StrCat(", ", mixed, " mixed"), ")"));
  }
  std::copy(bytes.begin(), bytes.begin() + n, b.bricks_.begin());
  const uint8_t* cells = bytes.data() + n;
  b.ForEachBrickCell([&](size_t brick, size_t cell) {
    if (b.bricks_[brick] == kMixed) b.cells_[cell] = *cells++;
  });
  b.FillCells();
  b.ComputeReach(y_begin, y_end < 0 ? dims[1] : y_end);
  return b;
}

}  // namespace transtick
