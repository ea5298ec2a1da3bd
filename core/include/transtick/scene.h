// The data a tracer reads: the sticks of a slab, the scalars around it (for
// gradients and dvr samples) and the global brick map used to skip
// uniform space. A whole-volume scene is the slab [0, dims[1]).
#ifndef TRANSTICK_SCENE_H_
#define TRANSTICK_SCENE_H_

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "absl/status/statusor.h"
#include "transtick/check.h"
#include "transtick/brick_map.h"
#include "transtick/classification.h"
#include "transtick/field_grid.h"
#include "transtick/field_summary.h"
#include "transtick/sticks.h"
#include "transtick/volume.h"

namespace transtick {

enum class RenderMode { kSurfaces, kDvr };
// "surfaces" or "dvr", for logs and messages.
const char* RenderModeName(RenderMode mode);

// Scalars of planes [y_begin, y_end) of a volume: x fastest, then y, then z.
struct ScalarPlanes {
  int y_begin = 0;
  int y_end = 0;
  std::vector<float> values;
};

// Planes of scalars kept beyond each side of a slab: gradients by central
// differences at a point interpolated from the 8 nearest voxel centres reach
// two planes out.
inline constexpr int kGhostPlanes = 2;

// What a scene is built for. A scene to trace holds what its walks look
// up: the brick map's reach where the tracer walks the map (voxel surfaces
// and dvr), the field's grid for smooth surfaces. The root only cuts its
// scene into slabs, whose workers build those for their own planes: its
// scene holds neither (docs/design.md, "What a scene holds").
enum class SceneUse { kTrace, kCut };

// Immutable after construction; thread-safe for concurrent reads. Movable,
// not copyable (it can be large).
class Scene {
 public:
  Scene() = default;
  Scene(Scene&&) = default;
  Scene& operator=(Scene&&) = default;
  Scene(const Scene&) = delete;
  Scene& operator=(const Scene&) = delete;

  // Surfaces mode: labels from the classification.
  static absl::StatusOr<Scene> ForSurfaces(const Volume& volume,
                                           const Classification& classification,
                                           SceneUse use = SceneUse::kTrace);
  // Dvr mode: a voxel is labelled 1 when the transfer function is non-zero
  // somewhere between the min and max of its 3x3x3 neighbourhood, so no
  // trilinear sample in a void voxel can have opacity.
  static absl::StatusOr<Scene> ForDvr(const Volume& volume, const TransferFunction& transfer,
                                      SceneUse use = SceneUse::kTrace);
  // The same scenes, taking the volume's samples as the scene's scalars
  // instead of copying them: the volume is left without values when the
  // scene is made, untouched when an error is returned.
  static absl::StatusOr<Scene> ForSurfaces(Volume&& volume, const Classification& classification,
                                           SceneUse use = SceneUse::kTrace);
  static absl::StatusOr<Scene> ForDvr(Volume&& volume, const TransferFunction& transfer,
                                      SceneUse use = SceneUse::kTrace);

  // Whether the tracer of this mode and classification walks the brick map
  // (and needs its reach): voxel surfaces and dvr do, smooth surfaces walk
  // the field's grid instead.
  static bool WalksBricks(RenderMode mode, const Classification& classification) {
    return mode == RenderMode::kDvr || classification.surface != SurfaceModel::kSmooth;
  }

  // Assembles a slab scene from parts (as a worker receives them). The
  // field summary may be empty (then rays leaving the slab always go on).
  // REQUIRES: scalars hold planes [ScalarBegin(y_begin), ScalarEnd(y_end)).
  static absl::StatusOr<Scene> FromParts(RenderMode mode, std::array<int, 3> dims,
                                         std::array<double, 3> spacing,
                                         std::array<float, 2> value_range, Sticks sticks,
                                         std::vector<float> scalars, BrickMap bricks,
                                         Classification classification, TransferFunction transfer,
                                         FieldSummary summary = {});

  // A copy of the slab [y_begin, y_end) of this scene.
  // REQUIRES: this scene holds the slab and its ghost planes.
  Scene Slab(int y_begin, int y_end) const;

  // The scalars of planes [y_begin, y_end) in the layout of the store.
  // REQUIRES: the planes are stored here.
  ScalarPlanes CopyScalars(int y_begin, int y_end) const;

  // A new slab [y_begin, y_end) of this scene's volume, classification and
  // brick map, from sticks blocks and scalar planes gathered here and from
  // the other slabs (balancing moves planes between workers this way).
  // Fails when a track or a scalar plane of the new slab is missing.
  absl::StatusOr<Scene> Reslab(int y_begin, int y_end, const std::vector<std::string>& blocks,
                               const std::vector<ScalarPlanes>& planes) const;

  int ScalarBegin(int y_begin) const { return std::max(0, y_begin - kGhostPlanes); }
  int ScalarEnd(int y_end) const { return std::min(dims_[1], y_end + kGhostPlanes); }

  RenderMode mode() const { return mode_; }
  const std::array<int, 3>& dims() const { return dims_; }
  const std::array<double, 3>& spacing() const { return spacing_; }
  // Smallest and largest value of the whole volume (for dvr lookup tables).
  const std::array<float, 2>& value_range() const { return value_range_; }
  int y_begin() const { return sticks_.y_begin(); }
  int y_end() const { return sticks_.y_end(); }
  const Sticks& sticks() const { return sticks_; }
  const BrickMap& bricks() const { return bricks_; }
  const Classification& classification() const { return classification_; }
  const TransferFunction& transfer() const { return transfer_; }
  const std::vector<float>& scalars() const { return scalars_; }
  // Smooth surfaces: the cells of the field the slab's rays walk (rows
  // y_begin() .. y_end() of cells), labelled by band; empty otherwise.
  const FieldGrid& field() const { return field_; }
  // Smooth surfaces: the whole field's bands a brick at a time, the same on
  // every node (field_summary.h); empty otherwise.
  const FieldSummary& summary() const { return summary_; }
  int scalar_y_begin() const { return scalar_y_begin_; }
  // One past the last stored scalar plane.
  int scalar_y_end() const { return scalar_y_begin_ + scalar_planes_; }

  // The scalar at a voxel, indices clamped to the volume.
  // REQUIRES: the clamped y lies in the stored planes.
  float Scalar(int x, int y, int z) const {
    x = x < 0 ? 0 : (x >= dims_[0] ? dims_[0] - 1 : x);
    y = y < 0 ? 0 : (y >= dims_[1] ? dims_[1] - 1 : y);
    z = z < 0 ? 0 : (z >= dims_[2] ? dims_[2] - 1 : z);
    TRANSTICK_DCHECK_GE(y, scalar_y_begin_);
    TRANSTICK_DCHECK_LT(y, scalar_y_begin_ + scalar_planes_);
    return scalars_[(static_cast<size_t>(z) * scalar_planes_ + (y - scalar_y_begin_)) * dims_[0] +
                    x];
  }

  // The scalars at the eight voxels (x + i, y + j, z + k), i, j, k in
  // {0, 1}, indexed i + 2j + 4k, each clamped as Scalar does.
  // REQUIRES: the clamped planes are stored.
  void Corners(int x, int y, int z, float out[8]) const {
    const int nx = dims_[0];
    if (x >= 0 && x + 1 < nx && y >= scalar_y_begin_ && y + 1 < scalar_y_begin_ + scalar_planes_ &&
        z >= 0 && z + 1 < dims_[2]) {
      const size_t row = static_cast<size_t>(nx), plane = row * scalar_planes_;
      const float* p = scalars_.data() + (z * static_cast<size_t>(scalar_planes_) +
                                          (y - scalar_y_begin_)) * row + x;
      out[0] = p[0], out[1] = p[1], out[2] = p[row], out[3] = p[row + 1];
      p += plane;
      out[4] = p[0], out[5] = p[1], out[6] = p[row], out[7] = p[row + 1];
      return;
    }
    for (int k = 0; k < 8; ++k) out[k] = Scalar(x + (k & 1), y + ((k >> 1) & 1), z + (k >> 2));
  }

  // Bytes held: sticks, scalars, the brick map, the field's cells and its
  // summary.
  size_t MemoryBytes() const;
  // The bytes this scene holds when built to trace (SceneUse::kTrace):
  // MemoryBytes, with the reach and field grid a scene to cut leaves out
  // counted as if built. What the workers hold for these planes, give or
  // take the ghost planes of their slabs.
  size_t TracingBytes() const;

  // Whether `other` holds the same volume's parts bit for bit: mode, size,
  // spacing, value range, sticks, brick map and reach, scalars (compared
  // as bytes: NaN and -0 as themselves), field grid and summary. The
  // classification or transfer function they were built from is not
  // compared. For checks: a build on any number of threads
  // (BuildThreads) gives the same parts.
  bool SameParts(const Scene& other) const;

 private:
  // Scenes from `volume`, its samples taken from *take when given.
  static absl::StatusOr<Scene> MakeSurfaces(const Volume& volume,
                                            const Classification& classification, SceneUse use,
                                            std::vector<float>* take);
  static absl::StatusOr<Scene> MakeDvr(const Volume& volume, const TransferFunction& transfer,
                                       SceneUse use, std::vector<float>* take);
  // Labels the field's cells for smooth surfaces (field()).
  void BuildField();

  RenderMode mode_ = RenderMode::kSurfaces;
  std::array<int, 3> dims_ = {0, 0, 0};
  std::array<double, 3> spacing_ = {1, 1, 1};
  std::array<float, 2> value_range_ = {0, 0};
  Sticks sticks_;
  BrickMap bricks_;
  Classification classification_;
  TransferFunction transfer_;
  // Planes [scalar_y_begin_, scalar_y_begin_ + scalar_planes_), x fastest, then
  // y, then z.
  int scalar_y_begin_ = 0;
  int scalar_planes_ = 0;
  std::vector<float> scalars_;
  FieldGrid field_;
  FieldSummary summary_;
};

// Labels for the dvr empty-space map (see Scene::ForDvr).
std::vector<uint8_t> DvrVisibility(const Volume& volume, const TransferFunction& transfer);


}  // namespace transtick

#endif  // TRANSTICK_SCENE_H_
