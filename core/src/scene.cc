#include "transtick/scene.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "transtick/check.h"
#include "transtick/parallel.h"

namespace transtick {
namespace {

// A ray's position is computed in world units, over the volume's whole
// extent, and must still place it within a small fraction of the smallest
// voxel in double precision, or the slab that starts a ray and the one that
// checks it disagree on its cell. So the volume's largest extent may be at
// most this many of its smallest voxels: the error stays near 10^-5 voxel.
// Real scans are 10^3 to 10^4 voxels across.
constexpr double kMaxExtentInVoxels = 1e11;

absl::Status CheckSpacing(const std::array<int, 3>& dims, const std::array<double, 3>& spacing) {
  for (int a = 0; a < 3; ++a) {
    if (!(spacing[a] > 0) || !std::isfinite(spacing[a])) {
      return absl::InvalidArgumentError(
          absl::StrCat("volume spacing ", a, " is ", spacing[a], ", must be positive"));
    }
  }
  const double smallest = std::min({spacing[0], spacing[1], spacing[2]});
  const double extent = std::max({dims[0] * spacing[0], dims[1] * spacing[1], dims[2] * spacing[2]});
  if (extent / smallest > kMaxExtentInVoxels) {
    return absl::InvalidArgumentError(absl::StrCat(
        "volume spacing ", spacing[0], " x ", spacing[1], " x ", spacing[2], ": the volume is ",
        extent / smallest, " of its smallest voxels across, more than the ", kMaxExtentInVoxels,
        " a ray can resolve in double precision"));
  }
  return absl::OkStatus();
}

absl::Status CheckDims(const Volume& volume) {
  for (int a = 0; a < 3; ++a) {
    if (volume.dims[a] < 1 || volume.dims[a] > Sticks::kMaxExtent) {
      return absl::InvalidArgumentError(absl::StrCat("volume dimension ", a, " is ", volume.dims[a],
                                                     ", must be in [1, ", Sticks::kMaxExtent, "]"));
    }
  }
  if (auto s = CheckSpacing(volume.dims, volume.spacing); !s.ok()) return s;
  if (volume.values.size() != volume.VoxelCount()) {
    return absl::InvalidArgumentError(absl::StrCat("volume holds ", volume.values.size(),
                                                   " values for ", volume.VoxelCount(), " voxels"));
  }
  return absl::OkStatus();
}

// Min and max over the 3x3x3 neighbourhood, separably (x, then y, then
// z), clamped at borders: at each step r = pick(pick(v, lower), upper),
// with pick(r, u) = std::min(r, u) or std::max(r, u), so a NaN already in
// r stays and one in u is passed over. Calls plane(z, lo, hi) once for
// each z with the filtered plane z (x fastest), for ranges of planes on as
// many threads (ParallelFor), in order within a range. Works a plane at a
// time, keeping three planes filtered along x and y, and a row at a time,
// which the compiler vectorises: a voxel at a time, with a branch per
// neighbour and four volume-sized arrays faulted in, a smooth cthead scene
// spent half its build here. Filter3Planes filters planes [z_begin, z_end)
// on the calling thread.
template <typename Plane>
void Filter3Planes(const Volume& v, int z_begin, int z_end, Plane plane) {
  const int nx = v.dims[0], ny = v.dims[1], nz = v.dims[2];
  const size_t area = static_cast<size_t>(nx) * ny;
  // r = pick(pick(r, a), b) over rows, with a or b absent (null).
  auto row = [nx](const float* l, const float* h, const float* la, const float* ha,
                  const float* lb, const float* hb, float* lo, float* hi) {
    if (la && lb) {
      for (int x = 0; x < nx; ++x) {
        lo[x] = std::min(std::min(l[x], la[x]), lb[x]);
        hi[x] = std::max(std::max(h[x], ha[x]), hb[x]);
      }
    } else if (la || lb) {
      const float* lc = la ? la : lb;
      const float* hc = la ? ha : hb;
      for (int x = 0; x < nx; ++x) {
        lo[x] = std::min(l[x], lc[x]);
        hi[x] = std::max(h[x], hc[x]);
      }
    } else {
      std::copy(l, l + nx, lo);
      std::copy(h, h + nx, hi);
    }
  };
  std::vector<float> xl(area), xh(area);          // one plane along x
  std::vector<float> yl(3 * area), yh(3 * area);  // three along x and y, by z % 3
  std::vector<float> out_l(area), out_h(area);
  auto filter_xy = [&](int z) {
    const float* a = v.values.data() + z * area;
    for (int y = 0; y < ny; ++y) {
      const float* r = a + static_cast<size_t>(y) * nx;
      float* l = xl.data() + static_cast<size_t>(y) * nx;
      float* h = xh.data() + static_cast<size_t>(y) * nx;
      if (nx == 1) {
        l[0] = h[0] = r[0];
        continue;
      }
      l[0] = std::min(r[0], r[1]);
      h[0] = std::max(r[0], r[1]);
      for (int x = 1; x + 1 < nx; ++x) {
        l[x] = std::min(std::min(r[x], r[x - 1]), r[x + 1]);
        h[x] = std::max(std::max(r[x], r[x - 1]), r[x + 1]);
      }
      l[nx - 1] = std::min(r[nx - 1], r[nx - 2]);
      h[nx - 1] = std::max(r[nx - 1], r[nx - 2]);
    }
    float* l = yl.data() + (z % 3) * area;
    float* h = yh.data() + (z % 3) * area;
    for (int y = 0; y < ny; ++y) {
      const size_t at = static_cast<size_t>(y) * nx, up = at + nx;
      const bool before = y > 0, after = y + 1 < ny;
      row(xl.data() + at, xh.data() + at, before ? xl.data() + at - nx : nullptr,
          before ? xh.data() + at - nx : nullptr, after ? xl.data() + up : nullptr,
          after ? xh.data() + up : nullptr, l + at, h + at);
    }
  };
  if (z_begin > 0) filter_xy(z_begin - 1);
  filter_xy(z_begin);
  for (int z = z_begin; z < z_end; ++z) {
    if (z + 1 < nz) filter_xy(z + 1);
    auto slot = [&](std::vector<float>& p, int k) { return p.data() + (k % 3) * area; };
    const bool before = z > 0, after = z + 1 < nz;
    for (int y = 0; y < ny; ++y) {
      const size_t at = static_cast<size_t>(y) * nx;
      row(slot(yl, z) + at, slot(yh, z) + at, before ? slot(yl, z - 1) + at : nullptr,
          before ? slot(yh, z - 1) + at : nullptr, after ? slot(yl, z + 1) + at : nullptr,
          after ? slot(yh, z + 1) + at : nullptr, out_l.data() + at, out_h.data() + at);
    }
    plane(z, out_l.data(), out_h.data());
  }
}

template <typename Plane>
void Filter3(const Volume& v, Plane plane) {
  ParallelFor(v.dims[2], 4, [&](size_t z_begin, size_t z_end) {
    Filter3Planes(v, static_cast<int>(z_begin), static_cast<int>(z_end), plane);
  });
}

}  // namespace

std::vector<uint8_t> DvrVisibility(const Volume& volume, const TransferFunction& transfer) {
  // A fine table of "is alpha > 0 anywhere in this value bin", with a prefix
  // count so a [lo, hi] query is two lookups. Bins are conservative: a bin is
  // visible if the transfer function is non-zero at either end or at any
  // control point inside it.
  constexpr int kBins = 8192;
  auto range = volume.Range();
  const float lo = range[0], hi = range[1];
  // A range wider than a float holds (hi - lo overflows) is divided in
  // double, as the tracer's table does.
  const float width = !(hi > lo)               ? 1.0f
                      : std::isfinite(hi - lo) ? (hi - lo) / kBins
                                               : static_cast<float>((double{hi} - lo) / kBins);
  std::vector<uint32_t> prefix(kBins + 1, 0);
  for (int b = 0; b < kBins; ++b) {
    float v0 = lo + b * width, v1 = lo + (b + 1) * width;
    bool visible = transfer.Evaluate(v0)[3] > 0 || transfer.Evaluate(v1)[3] > 0;
    for (const TransferPoint& p : transfer.points) {
      if (p.value >= v0 && p.value <= v1 && p.rgba[3] > 0) visible = true;
    }
    prefix[b + 1] = prefix[b] + (visible ? 1 : 0);
  }
  auto bin = [&](float v) {
    // Clamped before the conversion, which is undefined for NaN (a NaN
    // voxel, or a range wider than a float holds) and values out of range.
    const float b = (v - lo) / width;
    return b >= kBins - 1 ? kBins - 1 : (b > 0 ? static_cast<int>(b) : 0);
  };
  std::vector<uint8_t> labels(volume.values.size());
  const size_t area = static_cast<size_t>(volume.dims[0]) * volume.dims[1];
  Filter3(volume, [&](int z, const float* mn, const float* mx) {
    uint8_t* out = labels.data() + z * area;
    for (size_t i = 0; i < area; ++i) {
      out[i] = prefix[bin(mx[i]) + 1] - prefix[bin(mn[i])] > 0 ? 1 : 0;
    }
  });
  return labels;
}

absl::StatusOr<Scene> Scene::ForSurfaces(const Volume& volume, const Classification& classification,
                                         SceneUse use) {
  return MakeSurfaces(volume, classification, use, nullptr);
}

absl::StatusOr<Scene> Scene::ForSurfaces(Volume&& volume, const Classification& classification,
                                         SceneUse use) {
  return MakeSurfaces(volume, classification, use, &volume.values);
}

absl::StatusOr<Scene> Scene::ForDvr(const Volume& volume, const TransferFunction& transfer,
                                    SceneUse use) {
  return MakeDvr(volume, transfer, use, nullptr);
}

absl::StatusOr<Scene> Scene::ForDvr(Volume&& volume, const TransferFunction& transfer,
                                    SceneUse use) {
  return MakeDvr(volume, transfer, use, &volume.values);
}

absl::StatusOr<Scene> Scene::MakeSurfaces(const Volume& volume,
                                          const Classification& classification, SceneUse use,
                                          std::vector<float>* take) {
  if (auto s = CheckDims(volume); !s.ok()) return s;
  if (auto s = classification.Validate(); !s.ok()) return s;
  std::vector<uint8_t> labels(volume.values.size());
  // The paper's sticks, for either surface model: smooth surfaces walk the
  // field's cells instead (field(), built below), but slabs are cut, sent
  // and moved as sticks and scalars alike.
  ParallelFor(labels.size(), size_t{1} << 16, [&](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) labels[i] = classification.Classify(volume.values[i]);
  });
  Scene scene;
  scene.mode_ = RenderMode::kSurfaces;
  scene.dims_ = volume.dims;
  scene.spacing_ = volume.spacing;
  scene.value_range_ = volume.Range();
  scene.sticks_ = Sticks::Encode(labels, volume.dims, 0, volume.dims[1]);
  const bool reach = use == SceneUse::kTrace && WalksBricks(scene.mode_, classification);
  scene.bricks_ = BrickMap::Build(labels, volume.dims, /*uniform_materials=*/true, 0,
                                  reach ? volume.dims[1] : 0);
  scene.classification_ = classification;
  scene.scalar_y_begin_ = 0;
  scene.scalar_planes_ = volume.dims[1];
  scene.scalars_ = take ? std::exchange(*take, {}) : volume.values;
  if (use == SceneUse::kTrace) scene.BuildField();
  if (classification.surface == SurfaceModel::kSmooth) {
    scene.summary_ = FieldSummary::Build(scene.scalars_, volume.dims, Bands(classification));
  }
  return scene;
}

absl::StatusOr<Scene> Scene::MakeDvr(const Volume& volume, const TransferFunction& transfer,
                                     SceneUse use, std::vector<float>* take) {
  if (auto s = CheckDims(volume); !s.ok()) return s;
  if (auto s = transfer.Validate(); !s.ok()) return s;
  std::vector<uint8_t> labels = DvrVisibility(volume, transfer);
  Scene scene;
  scene.mode_ = RenderMode::kDvr;
  scene.dims_ = volume.dims;
  scene.spacing_ = volume.spacing;
  scene.value_range_ = volume.Range();
  scene.sticks_ = Sticks::Encode(labels, volume.dims, 0, volume.dims[1]);
  scene.bricks_ = BrickMap::Build(labels, volume.dims, /*uniform_materials=*/false, 0,
                                  use == SceneUse::kTrace ? volume.dims[1] : 0);
  scene.transfer_ = transfer;
  scene.scalar_y_begin_ = 0;
  scene.scalar_planes_ = volume.dims[1];
  scene.scalars_ = take ? std::exchange(*take, {}) : volume.values;
  return scene;
}

absl::StatusOr<Scene> Scene::FromParts(RenderMode mode, std::array<int, 3> dims,
                                       std::array<double, 3> spacing,
                                       std::array<float, 2> value_range, Sticks sticks,
                                       std::vector<float> scalars, BrickMap bricks,
                                       Classification classification, TransferFunction transfer,
                                       FieldSummary summary) {
  if (auto s = CheckSpacing(dims, spacing); !s.ok()) return s;
  Scene scene;
  scene.mode_ = mode;
  scene.dims_ = dims;
  scene.spacing_ = spacing;
  scene.value_range_ = value_range;
  scene.scalar_y_begin_ = scene.ScalarBegin(sticks.y_begin());
  scene.scalar_planes_ = scene.ScalarEnd(sticks.y_end()) - scene.scalar_y_begin_;
  size_t want = static_cast<size_t>(dims[0]) * scene.scalar_planes_ * dims[2];
  if (scalars.size() != want) {
    return absl::InvalidArgumentError(
        absl::StrCat("slab scalars: ", scalars.size(), " values, expected ", want));
  }
  if (sticks.dims() != dims || bricks.brick_dims()[0] != (dims[0] + 7) / 8) {
    return absl::InvalidArgumentError("slab parts disagree on the volume's dimensions");
  }
  if (mode == RenderMode::kSurfaces) {
    if (auto s = classification.Validate(); !s.ok()) return s;
  } else {
    if (auto s = transfer.Validate(); !s.ok()) return s;
  }
  // The walk hands a uniform brick's or cell's material to the tracer,
  // which looks it up in the classification.
  const size_t materials = mode == RenderMode::kSurfaces ? classification.materials.size() : 0;
  if (bricks.MaxMaterial() > materials) {
    return absl::InvalidArgumentError(
        absl::StrCat("brick map: material ", int{bricks.MaxMaterial()}, " of ", materials));
  }
  if (!summary.empty() && summary.brick_dims() != FieldSummary::BricksOf(dims)) {
    return absl::InvalidArgumentError("field summary and slab disagree on the volume's dimensions");
  }
  // The reach of the slab's planes where the tracer walks the map, else
  // none.
  if (!WalksBricks(mode, classification)) {
    if (bricks.HoldsReach()) bricks = bricks.ForSlab(0, 0);
  } else if (!bricks.ReachCovers(sticks.y_begin(), sticks.y_end())) {
    bricks = bricks.ForSlab(sticks.y_begin(), sticks.y_end());
  }
  scene.sticks_ = std::move(sticks);
  scene.scalars_ = std::move(scalars);
  scene.bricks_ = std::move(bricks);
  scene.classification_ = std::move(classification);
  scene.transfer_ = std::move(transfer);
  scene.BuildField();
  if (!scene.field_.empty()) scene.summary_ = std::move(summary);
  return scene;
}

Scene Scene::Slab(int y_begin, int y_end) const {
  const int sb = ScalarBegin(y_begin), se = ScalarEnd(y_end);
  auto slab = Reslab(y_begin, y_end, sticks_.EncodeRows(y_begin, y_end), {CopyScalars(sb, se)});
  TRANSTICK_CHECK(slab.ok());
  return *std::move(slab);
}

ScalarPlanes Scene::CopyScalars(int y_begin, int y_end) const {
  TRANSTICK_CHECK(y_begin >= scalar_y_begin_ && y_end <= scalar_y_begin_ + scalar_planes_);
  ScalarPlanes p;
  p.y_begin = y_begin;
  p.y_end = y_end;
  const size_t row = static_cast<size_t>(y_end - y_begin) * dims_[0];
  p.values.reserve(row * dims_[2]);
  for (int z = 0; z < dims_[2]; ++z) {
    auto first = scalars_.begin() +
                 (static_cast<size_t>(z) * scalar_planes_ + (y_begin - scalar_y_begin_)) * dims_[0];
    p.values.insert(p.values.end(), first, first + row);
  }
  return p;
}

absl::StatusOr<Scene> Scene::Reslab(int y_begin, int y_end, const std::vector<std::string>& blocks,
                                    const std::vector<ScalarPlanes>& planes) const {
  const int max_material = mode_ == RenderMode::kSurfaces ? classification_.MaxLabel() : 1;
  auto sticks = Sticks::FromBlocks(dims_, y_begin, y_end, max_material, blocks);
  if (!sticks.ok()) return sticks.status();
  Scene s;
  s.mode_ = mode_;
  s.dims_ = dims_;
  s.spacing_ = spacing_;
  s.value_range_ = value_range_;
  s.bricks_ =
      WalksBricks(mode_, classification_) ? bricks_.ForSlab(y_begin, y_end) : bricks_.ForSlab(0, 0);
  s.classification_ = classification_;
  s.transfer_ = transfer_;
  s.summary_ = summary_;
  s.sticks_ = *std::move(sticks);
  s.scalar_y_begin_ = ScalarBegin(y_begin);
  s.scalar_planes_ = ScalarEnd(y_end) - s.scalar_y_begin_;
  const size_t nx = dims_[0];
  s.scalars_.resize(nx * s.scalar_planes_ * dims_[2]);
  std::vector<uint8_t> covered(s.scalar_planes_, 0);
  for (const ScalarPlanes& p : planes) {
    const int n = p.y_end - p.y_begin;
    if (n <= 0 || p.values.size() != static_cast<size_t>(n) * nx * dims_[2]) {
      return absl::InvalidArgumentError(absl::StrCat("scalar planes [", p.y_begin, ", ", p.y_end,
                                                     "): ", p.values.size(), " values"));
    }
    const int lo = std::max(p.y_begin, s.scalar_y_begin_);
    const int hi = std::min(p.y_end, s.scalar_y_begin_ + s.scalar_planes_);
    for (int y = lo; y < hi; ++y) covered[y - s.scalar_y_begin_] = 1;
    if (lo >= hi) continue;
    for (int z = 0; z < dims_[2]; ++z) {
      const float* from = p.values.data() + (static_cast<size_t>(z) * n + (lo - p.y_begin)) * nx;
      float* to = s.scalars_.data() +
                  (static_cast<size_t>(z) * s.scalar_planes_ + (lo - s.scalar_y_begin_)) * nx;
      std::copy(from, from + static_cast<size_t>(hi - lo) * nx, to);
    }
  }
  for (int i = 0; i < s.scalar_planes_; ++i) {
    if (!covered[i]) {
      return absl::InvalidArgumentError(
          absl::StrCat("slab [", y_begin, ", ", y_end, "): no scalars for plane ",
                       s.scalar_y_begin_ + i));
    }
  }
  s.BuildField();
  return s;
}

void Scene::BuildField() {
  field_ = FieldGrid();
  if (mode_ != RenderMode::kSurfaces || classification_.surface != SurfaceModel::kSmooth ||
      y_begin() >= y_end()) {
    return;
  }
  // Cell c spans [c - 0.5, c + 0.5] along y: cells y_begin .. y_end hold
  // every point of the slab's planes.
  field_ = FieldGrid::Build(scalars_, dims_, scalar_y_begin_, scalar_planes_, y_begin(),
                            y_end() + 1, Bands(classification_));
}

bool Scene::SameParts(const Scene& o) const {
  auto same_bytes = [](const auto& a, const auto& b) {
    return a.size() == b.size() &&
           (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(a[0])) == 0);
  };
  return mode_ == o.mode_ && dims_ == o.dims_ &&
         std::memcmp(spacing_.data(), o.spacing_.data(), sizeof(spacing_)) == 0 &&
         std::memcmp(value_range_.data(), o.value_range_.data(), sizeof(value_range_)) == 0 &&
         sticks_ == o.sticks_ && bricks_ == o.bricks_ && scalar_y_begin_ == o.scalar_y_begin_ &&
         scalar_planes_ == o.scalar_planes_ && same_bytes(scalars_, o.scalars_) &&
         field_ == o.field_ && summary_ == o.summary_;
}

size_t Scene::MemoryBytes() const {
  return sticks_.MemoryBytes() + scalars_.size() * sizeof(float) + bricks_.MemoryBytes() +
         field_.MemoryBytes() + summary_.MemoryBytes();
}

size_t Scene::TracingBytes() const {
  size_t bytes = sticks_.MemoryBytes() + scalars_.size() * sizeof(float) + bricks_.MemoryBytes() +
                 summary_.MemoryBytes();
  if (WalksBricks(mode_, classification_) && !bricks_.ReachCovers(y_begin(), y_end())) {
    bytes += BrickMap::ReachBytes(dims_, y_begin(), y_end());
  }
  if (!WalksBricks(mode_, classification_) && y_begin() < y_end()) {
    bytes += FieldGrid::MemoryBytesFor(dims_, y_begin(), y_end() + 1);  // BuildField's rows
  }
  return bytes;
}

const char* RenderModeName(RenderMode mode) {
  return mode == RenderMode::kDvr ? "dvr" : "surfaces";
}

}  // namespace transtick
