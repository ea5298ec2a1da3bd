#include "transtick/field_summary.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"
#include "transtick/check.h"
#include "transtick/isosurface.h"

namespace transtick {
namespace {

// The least and greatest value of a box of voxels, and whether one is NaN.
struct Range {
  float lo = std::numeric_limits<float>::infinity();
  float hi = -std::numeric_limits<float>::infinity();
  bool nan = false;
  void Add(const Range& r) {
    lo = std::min(lo, r.lo);
    hi = std::max(hi, r.hi);
    nan |= r.nan;
  }
  void Add(float v) {
    if (v != v) {
      nan = true;
    } else {
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
  }
};

// The voxels whose values the cells of brick b and the cells next to it
// read, along an axis of n voxels: cells 8b - 1 .. 8b + 8, cell c reading
// voxels c - 1 and c, clamped to the volume.
std::pair<int, int> VoxelSpan(int b, int n) {
  return {std::clamp(8 * b - 2, 0, n - 1), std::clamp(8 * b + 8, 0, n - 1)};
}

}  // namespace

FieldSummary FieldSummary::Build(const std::vector<float>& values, std::array<int, 3> dims,
                                 const Bands& bands) {
  const int nx = dims[0], ny = dims[1], nz = dims[2];
  TRANSTICK_CHECK(nx > 0 && ny > 0 && nz > 0);
  TRANSTICK_CHECK_EQ(values.size(), static_cast<size_t>(nx) * ny * nz);
  FieldSummary s;
  s.dims_ = dims;
  s.bricks_ = BricksOf(dims);
  const int bx = s.bricks_[0], by = s.bricks_[1], bz = s.bricks_[2];
  // Along x first: per voxel row, the range of each brick's span.
  std::vector<Range> rows(static_cast<size_t>(bx) * ny * nz);
  for (int z = 0; z < nz; ++z) {
    for (int y = 0; y < ny; ++y) {
      const float* row = values.data() + (static_cast<size_t>(z) * ny + y) * nx;
      for (int b = 0; b < bx; ++b) {
        const auto [x0, x1] = VoxelSpan(b, nx);
        Range r;
        for (int x = x0; x <= x1; ++x) r.Add(row[x]);
        rows[(static_cast<size_t>(z) * ny + y) * bx + b] = r;
      }
    }
  }
  s.labels_.resize(static_cast<size_t>(bx) * by * bz);
  const std::vector<float>& edges = bands.edges();
  auto band = [&](float v) {
    return static_cast<int>(std::upper_bound(edges.begin(), edges.end(), v) - edges.begin());
  };
  size_t k = 0;
  for (int cz = 0; cz < bz; ++cz) {
    const auto [z0, z1] = VoxelSpan(cz, nz);
    for (int cy = 0; cy < by; ++cy) {
      const auto [y0, y1] = VoxelSpan(cy, ny);
      for (int cx = 0; cx < bx; ++cx, ++k) {
        Range r;
        for (int z = z0; z <= z1; ++z) {
          for (int y = y0; y <= y1; ++y) r.Add(rows[(static_cast<size_t>(z) * ny + y) * bx + cx]);
        }
        // A NaN corner makes a cell mixed (FieldGrid::Build), so its brick.
        const int lo = band(r.lo), hi = band(r.hi);
        s.labels_[k] = r.nan || lo != hi || lo >= kMixed ? kMixed : static_cast<uint8_t>(lo);
      }
    }
  }
  s.FindShell();
  return s;
}

absl::StatusOr<FieldSummary> FieldSummary::FromBytes(std::array<int, 3> dims, int bands,
                                                     std::string_view bytes) {
  FieldSummary s;
  for (int a = 0; a < 3; ++a) {
    if (dims[a] <= 0) return absl::InvalidArgumentError("field summary: a volume without voxels");
  }
  s.dims_ = dims;
  s.bricks_ = BricksOf(dims);
  size_t want = 1;
  for (int a = 0; a < 3; ++a) {
    // Past the bytes given, the product can only grow: no overflow.
    if (want <= bytes.size()) want *= static_cast<size_t>(s.bricks_[a]);
  }
  if (bytes.size() != want) {
    return absl::InvalidArgumentError(absl::StrCat("field summary: ", bytes.size(),
                                                   " bytes, expected ", want, " (one per brick of ",
                                                   s.bricks_[0], "x", s.bricks_[1], "x",
                                                   s.bricks_[2], ")"));
  }
  s.labels_.assign(bytes.begin(), bytes.end());
  for (size_t i = 0; i < s.labels_.size(); ++i) {
    const uint8_t b = s.labels_[i];
    if (b != kMixed && b >= bands) {
      return absl::InvalidArgumentError(absl::StrCat("field summary: brick ", i, " names band ",
                                                     int{b}, " of ", bands));
    }
  }
  s.FindShell();
  return s;
}

void FieldSummary::FindShell() {
  shell_.clear();
  has_void_ = false;
  const int bx = bricks_[0], by = bricks_[1], bz = bricks_[2];
  for (int z = 0; z < bz; ++z) {
    for (int y = 0; y < by; ++y) {
      for (int x = 0; x < bx; ++x) {
        if (At(x, y, z) == 0) {
          has_void_ = true;
          continue;
        }
        bool shell = x == 0 || y == 0 || z == 0 || x == bx - 1 || y == by - 1 || z == bz - 1;
        for (int n = 0; n < 27 && !shell; ++n) {
          shell = At(x + n % 3 - 1, y + n / 3 % 3 - 1, z + n / 9 - 1) == 0;
        }
        if (shell)
          shell_.push_back(static_cast<uint32_t>((static_cast<size_t>(z) * by + y) * bx + x));
      }
    }
  }
}

PixelMask::PixelMask(int width, int height)
    : width_(width),
      height_(height),
      words_per_row_((static_cast<size_t>(width) + 63) / 64),
      bits_(words_per_row_ * height) {
  TRANSTICK_CHECK(width > 0 && height > 0);
}

void PixelMask::Set(const Camera::PixelRect& r) {
  const int x0 = std::max(r.x0, 0), x1 = std::min(r.x1, width_);
  const int y0 = std::max(r.y0, 0), y1 = std::min(r.y1, height_);
  if (x0 >= x1) return;
  for (int y = y0; y < y1; ++y) {
    uint64_t* row = bits_.data() + static_cast<size_t>(y) * words_per_row_;
    for (int x = x0; x < x1;) {
      // The bits [x, end) of one word.
      const int end = std::min(x1, (x | 63) + 1);
      const int n = end - x;
      row[x >> 6] |= (n == 64 ? ~0ull : ((1ull << n) - 1)) << (x & 63);
      x = end;
    }
  }
}

size_t PixelMask::Count() const {
  size_t n = 0;
  for (uint64_t w : bits_) n += std::popcount(w);
  return n;
}

PixelMask FieldSummary::PixelsMeeting(const Camera& camera, const std::array<double, 3>& spacing,
                                      size_t max_boxes) const {
  if (labels_.empty() || !has_void_) return {};
  // World space (the volume's frame): index point p is (p - dims / 2) *
  // spacing, as Tracer::MakePrimary maps rays the other way.
  Vec3 half, lo_world, hi_world;
  for (int a = 0; a < 3; ++a) {
    half[a] = dims_[a] * 0.5;
    lo_world[a] = -half[a] * spacing[a];
    hi_world[a] = half[a] * spacing[a];
  }
  // Every ray must enter the volume from outside: each corner of the
  // volume's box in front of the plane through the eye across the view.
  for (int corner = 0; corner < 8; ++corner) {
    const Vec3 p{corner & 1 ? hi_world[0] : lo_world[0], corner & 2 ? hi_world[1] : lo_world[1],
                 corner & 4 ? hi_world[2] : lo_world[2]};
    const Vec3 d = p - camera.eye();
    if (!(Dot(d, camera.forward()) > 1e-6 * (1 + Length(d)))) return {};
  }
  if (max_boxes == 0) {
    max_boxes = std::max<size_t>(4096, static_cast<size_t>(camera.width()) * camera.height() / 8);
  }
  // The boxes of 2^shift bricks a side that hold a brick of the shell.
  int shift = 0;
  std::array<int, 3> boxes = bricks_;
  std::vector<uint32_t> coarse;
  const std::vector<uint32_t>* held = &shell_;
  while (held->size() > max_boxes && (boxes[0] > 1 || boxes[1] > 1 || boxes[2] > 1)) {
    ++shift;
    for (int a = 0; a < 3; ++a) boxes[a] = ((bricks_[a] - 1) >> shift) + 1;
    std::vector<uint8_t> marked(static_cast<size_t>(boxes[0]) * boxes[1] * boxes[2], 0);
    coarse.clear();
    for (uint32_t k : shell_) {
      const size_t x = (k % bricks_[0]) >> shift, y = (k / bricks_[0] % bricks_[1]) >> shift,
                   z = (k / (static_cast<size_t>(bricks_[0]) * bricks_[1])) >> shift;
      const size_t c = (z * boxes[1] + y) * boxes[0] + x;
      if (!marked[c]) coarse.push_back(static_cast<uint32_t>(c));
      marked[c] = 1;
    }
    held = &coarse;
  }
  PixelMask mask(camera.width(), camera.height());
  const double size = 8.0 * (1 << shift);  // cells a box spans
  for (uint32_t k : *held) {
    const size_t per_plane = static_cast<size_t>(boxes[0]) * boxes[1];
    const int b[3] = {static_cast<int>(k % boxes[0]), static_cast<int>(k / boxes[0] % boxes[1]),
                      static_cast<int>(k / per_plane)};
    // Box b holds cells size * b .. size * (b + 1) - 1: [size * b - 0.5,
    // size * (b + 1) - 0.5] in index space, clipped to the volume's box,
    // where rays walk.
    Vec3 lo, hi;
    for (int a = 0; a < 3; ++a) {
      const double from = std::max(b[a] * size - 0.5, 0.0);
      const double to = std::min((b[a] + 1) * size - 0.5, static_cast<double>(dims_[a]));
      lo[a] = (from - half[a]) * spacing[a];
      hi[a] = (to - half[a]) * spacing[a];
    }
    const Camera::PixelRect r = camera.Bounds(lo, hi);
    if (r.x0 == 0 && r.y0 == 0 && r.x1 == camera.width() && r.y1 == camera.height()) return {};
    mask.Set(r);
  }
  return mask;
}

bool FieldSummary::Clear(const Vec3& origin, const RayAxes& axes, double t0, double t1,
                         int band) const {
  if (labels_.empty() || band < 0 || band >= kMixed || !std::isfinite(t0) || !std::isfinite(t1) ||
      !(t0 <= t1)) {
    return false;
  }
  // Brick b holds cells 8b .. 8b + 7, spanning [8b - 0.5, 8b + 7.5]: the
  // brick a point lies in, and the time the ray crosses the face ahead of
  // it, each from its plane. The brick of a point just outside the
  // summary's (the ray on a face) is the nearest.
  int b[3];
  double next[3];
  constexpr double kSize = 1 << kShift;
  for (int a = 0; a < 3; ++a) {
    const double p = origin[a] + axes.dir[a] * t0;
    if (!std::isfinite(p)) return false;
    b[a] = static_cast<int>(std::clamp(std::floor((p + 0.5) / kSize), 0.0, bricks_[a] - 1.0));
    next[a] = axes.step[a] == 0
                  ? std::numeric_limits<double>::infinity()
                  : ((b[a] + (axes.step[a] > 0)) * kSize - 0.5 - origin[a]) * axes.inv[a];
  }
  // A ray crosses at most one brick face per brick along each axis.
  const int limit = bricks_[0] + bricks_[1] + bricks_[2] + 3;
  for (int i = 0; i < limit; ++i) {
    if (At(b[0], b[1], b[2]) != band) return false;
    int a = 0;
    if (next[1] < next[a]) a = 1;
    if (next[2] < next[a]) a = 2;
    if (!(next[a] < t1)) return true;
    b[a] += axes.step[a];
    if (b[a] < 0 || b[a] >= bricks_[a]) return true;  // out of the field's cells
    next[a] = ((b[a] + (axes.step[a] > 0)) * kSize - 0.5 - origin[a]) * axes.inv[a];
  }
  return false;
}

}  // namespace transtick
