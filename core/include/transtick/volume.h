// A scalar voxel volume held in memory.
#ifndef TRANSTICK_VOLUME_H_
#define TRANSTICK_VOLUME_H_

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace transtick {

// The sample types the readers accept. Values are converted to float on load.
enum class ScalarType { kUint8, kInt8, kUint16, kInt16, kUint32, kInt32, kFloat32, kFloat64 };

std::string_view ScalarTypeName(ScalarType type);
size_t ScalarTypeSize(ScalarType type);

// Index axis a's unit vector in world coordinates is direction[a].
using Direction = std::array<std::array<double, 3>, 3>;
inline constexpr Direction kIdentityDirection = {{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};

// A regular grid of scalar samples, x fastest, then y, then z. Voxel (x, y, z)
// covers the box [x, x+1) x [y, y+1) x [z, z+1) in index space; the volume's
// own frame is index space scaled by `spacing` (millimetres, or whatever the
// file says). Samples are stored as float whatever the source type: 4 bytes
// per voxel.
//
// Orientation (docs/formats.md, "Orientation"): the centre of sample
// (i, j, k) lies in world space (patient coordinates, LPS: +x toward the
// patient's left, +y posterior, +z superior) at
//   origin + direction[0]·i·spacing[0] + direction[1]·j·spacing[1] + direction[2]·k·spacing[2].
// The readers leave `direction` a rotation (orthonormal, determinant +1): a
// file whose axes are a reflection is read with its x samples reversed
// (`x_reversed`), which describes the same world geometry.
//
// A value type; not thread-safe for concurrent mutation, safe for concurrent
// reads.
struct Volume {
  std::array<int, 3> dims = {0, 0, 0};
  std::array<double, 3> spacing = {1.0, 1.0, 1.0};
  ScalarType source_type = ScalarType::kFloat32;
  std::vector<float> values;  // dims[0] * dims[1] * dims[2] samples
  std::array<double, 3> origin = {0.0, 0.0, 0.0};
  Direction direction = kIdentityDirection;
  bool x_reversed = false;  // the reader reversed x to turn a reflection into a rotation
  // What the reader passed over or chose that a user should know of (a
  // DICOM directory's other files and series), one sentence each; shown by
  // `transtick info` and logged by the root.
  std::vector<std::string> notes;

  size_t VoxelCount() const {
    return static_cast<size_t>(dims[0]) * static_cast<size_t>(dims[1]) *
           static_cast<size_t>(dims[2]);
  }
  size_t Index(int x, int y, int z) const {
    return (static_cast<size_t>(z) * static_cast<size_t>(dims[1]) + static_cast<size_t>(y)) *
               static_cast<size_t>(dims[0]) +
           static_cast<size_t>(x);
  }
  // REQUIRES: 0 <= x < dims[0], 0 <= y < dims[1], 0 <= z < dims[2].
  float At(int x, int y, int z) const { return values[Index(x, y, z)]; }

  // Smallest and largest finite sample (NaN and infinities are left out);
  // {0, 0} for a volume without one.
  std::array<float, 2> Range() const;
};

// Counts of the finite `values` in `bins` equal bins over `range` (as
// Volume::Range() gives it): value v falls in bin floor((v - lo) / w), w =
// (hi - lo) / bins (1 when hi <= lo), computed in double and clamped to [0,
// bins). NaN and infinities are not counted. The same counts on any number
// of threads.
// REQUIRES: bins >= 1.
std::vector<uint64_t> Histogram(std::span<const float> values, std::array<float, 2> range,
                                int bins);

}  // namespace transtick

#endif  // TRANSTICK_VOLUME_H_
