#include "transtick/synthetic.h"

#include <algorithm>
#include <cstddef>

namespace transtick {
namespace {

// SplitMix64 (Steele, Lea, Flood 2014): tiny, good enough for test data, and
// unlike <random>'s distributions gives the same numbers on every platform.
class SplitMix64 {
 public:
  explicit SplitMix64(uint64_t seed) : state_(seed) {}
  uint64_t Next() {
    uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [0, 1), from the top 24 bits so every value is a float exactly.
  float NextUnit() { return static_cast<float>(Next() >> 40) * (1.0f / 16777216.0f); }
  // Uniform in [0, n); the multiply-shift bias is below 2^-32 * n.
  uint32_t NextBelow(uint32_t n) {
    return static_cast<uint32_t>(((Next() >> 32) * uint64_t{n}) >> 32);
  }

 private:
  uint64_t state_;
};

// A volume with the given dims (negative ones taken as 0) and zero samples.
Volume Empty(std::array<int, 3> dims) {
  Volume volume;
  for (int i = 0; i < 3; ++i) volume.dims[i] = std::max(dims[i], 0);
  volume.values.assign(volume.VoxelCount(), 0.0f);
  return volume;
}

// One ellipsoid of the phantom, in coordinates where the volume spans
// [-1, 1] along every axis.
struct Ellipsoid {
  double center[3];
  double axes[3];
  float value;  // added inside
};

// Axis-aligned version of the 3-D Shepp-Logan head (Kak & Slaney), with
// CT-like values: skull 1000, brain 400, ventricles 200, lesions above.
constexpr Ellipsoid kHead[] = {
    {{0.0, 0.0, 0.0}, {0.69, 0.92, 0.9}, 1000.0f},
    {{0.0, -0.0184, 0.0}, {0.6624, 0.874, 0.88}, -600.0f},
    {{0.22, 0.0, 0.0}, {0.11, 0.31, 0.22}, -200.0f},
    {{-0.22, 0.0, 0.0}, {0.16, 0.41, 0.28}, -200.0f},
    {{0.0, 0.35, -0.15}, {0.21, 0.25, 0.41}, 100.0f},
    {{0.0, 0.1, 0.25}, {0.046, 0.046, 0.05}, 150.0f},
    {{0.0, -0.1, 0.25}, {0.046, 0.046, 0.05}, 150.0f},
    {{-0.08, -0.605, 0.0}, {0.046, 0.023, 0.05}, 150.0f},
    {{0.0, -0.605, 0.0}, {0.023, 0.023, 0.02}, 150.0f},
    {{0.06, -0.605, 0.0}, {0.023, 0.046, 0.02}, 150.0f},
};

}  // namespace

Volume MakeSphere(std::array<int, 3> dims, std::array<double, 3> center, double radius,
                  float inside) {
  Volume volume = Empty(dims);
  const double r2 = radius * radius;
  for (int z = 0; z < volume.dims[2]; ++z) {
    const double dz = z + 0.5 - center[2];
    for (int y = 0; y < volume.dims[1]; ++y) {
      const double dy = y + 0.5 - center[1];
      for (int x = 0; x < volume.dims[0]; ++x) {
        const double dx = x + 0.5 - center[0];
        if (dx * dx + dy * dy + dz * dz <= r2) volume.values[volume.Index(x, y, z)] = inside;
      }
    }
  }
  return volume;
}

Volume MakeSlab(std::array<int, 3> dims, int axis, int lo, int hi, float inside) {
  Volume volume = Empty(dims);
  if (axis < 0 || axis > 2) return volume;
  for (int z = 0; z < volume.dims[2]; ++z) {
    for (int y = 0; y < volume.dims[1]; ++y) {
      for (int x = 0; x < volume.dims[0]; ++x) {
        const int i = axis == 0 ? x : axis == 1 ? y : z;
        if (lo <= i && i < hi) volume.values[volume.Index(x, y, z)] = inside;
      }
    }
  }
  return volume;
}

Volume MakeNoisyPhantom(std::array<int, 3> dims, uint32_t seed, float noise) {
  Volume volume = Empty(dims);
  SplitMix64 rng(seed);
  for (int z = 0; z < volume.dims[2]; ++z) {
    const double pz = (z + 0.5) / volume.dims[2] * 2.0 - 1.0;
    for (int y = 0; y < volume.dims[1]; ++y) {
      const double py = (y + 0.5) / volume.dims[1] * 2.0 - 1.0;
      for (int x = 0; x < volume.dims[0]; ++x) {
        const double px = (x + 0.5) / volume.dims[0] * 2.0 - 1.0;
        const double p[3] = {px, py, pz};
        float value = 0.0f;
        for (const Ellipsoid& e : kHead) {
          double sum = 0.0;
          for (int i = 0; i < 3; ++i) {
            const double d = (p[i] - e.center[i]) / e.axes[i];
            sum += d * d;
          }
          if (sum <= 1.0) value += e.value;
        }
        // Draw for every voxel, inside or not, so the noise at a voxel
        // depends only on the seed and the voxel's position.
        value += (rng.NextUnit() * 2.0f - 1.0f) * noise;
        volume.values[volume.Index(x, y, z)] = std::max(value, 0.0f);
      }
    }
  }
  return volume;
}

Volume MakeRandom(std::array<int, 3> dims, uint32_t seed, int levels) {
  Volume volume = Empty(dims);
  if (levels <= 1) return volume;  // one level: all zero
  SplitMix64 rng(seed);
  for (float& v : volume.values) {
    v = static_cast<float>(rng.NextBelow(static_cast<uint32_t>(levels)));
  }
  return volume;
}

}  // namespace transtick
