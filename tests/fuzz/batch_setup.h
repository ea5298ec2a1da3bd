// What the batch fuzzer runs against, shared with the seed writer so that
// the seeds hold rays valid for it: small synthetic scenes, each with a
// camera, settings and a ring of slabs.
//
// An input of the batch fuzzer is one header byte and a batch:
//   bit 0      0: the rest is a ray batch (packed rays, docs/formats.md)
//                 that arrives at a worker from a neighbour;
//              1: the rest is two bytes, the image's width - 1 and height - 1
//                 (each taken mod 64), then a deposit batch (packed pixel records)
//                 that arrives at the display.
//   rays only:
//   bits 1-3   the configuration, 0 .. kBatchConfigs - 1;
//   bits 4-5   the slab that receives the batch (mod the ring's slabs);
//   bit 6      repair: before Validate, make each record's direction a unit
//              world direction, its cell the one at t, and its other fields
//              plausible, so that mutations reach the tracer, not only
//              Validate's first test.
#ifndef TRANSTICK_TESTS_FUZZ_BATCH_SETUP_H_
#define TRANSTICK_TESTS_FUZZ_BATCH_SETUP_H_

#include <cstdint>
#include <memory>
#include <vector>

#include "fuzz_ring.h"
#include "transtick/camera.h"
#include "transtick/ray.h"
#include "transtick/scene.h"
#include "transtick/tracer.h"

namespace transtick::fuzz {

inline constexpr uint8_t kDepositBatch = 1;
inline constexpr int kBatchConfigs = 8;
inline constexpr uint8_t kRepair = 1 << 6;

inline uint8_t RayHeader(int config, int slab, bool repair) {
  return static_cast<uint8_t>(config << 1 | (slab & 3) << 4 | (repair ? kRepair : 0));
}
inline int ConfigOf(uint8_t header) { return (header >> 1) & 7; }
inline int SlabOf(uint8_t header) { return (header >> 4) & 3; }

// One configuration: a scene (surfaces or dvr, shared between
// configurations), a view, settings and the ring over the scene's slabs.
struct BatchConfig {
  const Scene* scene;
  Camera camera;
  RenderSettings settings;
  std::unique_ptr<FuzzRing> ring;
};

// Built once, on first use; not thread-safe (the fuzzer runs one input at a
// time). The rings count hand-offs they refuse, hence not const.
class BatchSetup {
 public:
  static BatchSetup& Get();

  BatchConfig& config(int i) { return configs_[i]; }

 private:
  BatchSetup();

  Scene surfaces_;
  Scene dvr_;
  std::vector<BatchConfig> configs_;
};

// Makes `ray` plausible for `tracer`'s scene (the repair bit above): a unit
// world direction, the cell at t, 0 <= t_start <= t within the diagonal,
// a known kind and material, transmittance in [0, 1]. Geometry that cannot
// be repaired (non-finite, far away) is left for Validate to refuse.
void Repair(const Scene& scene, const Tracer& tracer, RayDescriptor* ray);

}  // namespace transtick::fuzz

#endif  // TRANSTICK_TESTS_FUZZ_BATCH_SETUP_H_
