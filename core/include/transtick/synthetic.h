// Volumes built in code, with known answers, for tests and benchmarks.
#ifndef TRANSTICK_SYNTHETIC_H_
#define TRANSTICK_SYNTHETIC_H_

#include <array>
#include <cstdint>

#include "transtick/volume.h"

namespace transtick {

// A ball of value `inside` (elsewhere 0) centred at `center` (index space,
// voxel centres at i + 0.5) with radius `radius` voxels.
Volume MakeSphere(std::array<int, 3> dims, std::array<double, 3> center, double radius,
                  float inside = 100.0f);

// Value `inside` where lo <= index(axis) < hi, else 0: a slab across `axis`.
Volume MakeSlab(std::array<int, 3> dims, int axis, int lo, int hi, float inside = 100.0f);

// Several overlapping ellipsoids of different values plus uniform noise of
// amplitude `noise`, deterministic for a given seed: a head-like phantom.
Volume MakeNoisyPhantom(std::array<int, 3> dims, uint32_t seed, float noise = 5.0f);

// Uniformly random integer values in [0, levels), deterministic for a seed.
// With few levels this makes many short runs: a hard case for sticks.
Volume MakeRandom(std::array<int, 3> dims, uint32_t seed, int levels);

}  // namespace transtick

#endif  // TRANSTICK_SYNTHETIC_H_
