// An in-process ring for the fuzzers: one scene cut into slabs, a tracer per
// slab, and the loop that passes rays between the slabs as the workers do
// (tests/testing.cc RenderSlabs does the same for whole images). The rules
// the cluster relies on are checks here, so that breaking one is a crash the
// fuzzer reports:
//   - no Trace call reaches the tracer's hard bounds (counters.truncated
//     stays 0: docs/design.md, "Why every ray ends");
//   - a ray and the rays it spawns finish within a bounded number of calls;
//   - every ray handed on and every deposit survive the wire form, and the
//     display's decoder accepts the deposit;
//   - a ray this ring made (RunPixel) is accepted by each neighbour it is
//     handed to, and its pixel gets one primary deposit and as many shadow
//     deposits as that deposit reports.
// Not thread-safe; small scenes only (each slab is a copy).
#ifndef TRANSTICK_TESTS_FUZZ_FUZZ_RING_H_
#define TRANSTICK_TESTS_FUZZ_FUZZ_RING_H_

#include <cstdint>
#include <vector>

#include "transtick/camera.h"
#include "transtick/ray.h"
#include "transtick/ring_layout.h"
#include "transtick/scene.h"
#include "transtick/tracer.h"

namespace transtick::fuzz {

class FuzzRing {
 public:
  // REQUIRES: `cuts` valid for whole.dims()[1] planes (ValidCuts).
  FuzzRing(const Scene& whole, const std::vector<int>& cuts, const Camera& camera,
           const RenderSettings& settings);
  FuzzRing(const FuzzRing&) = delete;
  FuzzRing& operator=(const FuzzRing&) = delete;

  int slabs() const { return layout_.slabs(); }
  const RingLayout& layout() const { return layout_; }
  const Tracer& tracer(int slab) const { return tracers_[slab]; }
  // Pixels of the frame: what the decoders take as their limit.
  uint32_t pixel_limit() const { return pixel_limit_; }

  // What is known of where a ray came from.
  enum class Origin {
    // Made by this ring: every hand-off must pass the neighbour's Validate.
    kRing,
    // Arrived from a peer and passed Validate there: its state need not be
    // one a tracer makes (t_start may lie anywhere behind t), so a hand-off
    // the neighbour refuses is dropped, as a worker drops it, and counted.
    kPeer,
  };

  // Traces `ray` on slab `slab`, and every ray it spawns, to the end;
  // appends their deposits, as the display decodes them, to `deposits`.
  // REQUIRES: tracer(slab).Validate(ray) is OK.
  void Run(int slab, const RayDescriptor& ray, Origin origin, std::vector<Deposit>* deposits);

  // The primary ray of pixel (col, row) as the slabs make it
  // (RingLayout::Primary: exactly one slab traces it or deposits its miss),
  // traced to the end; checks that the pixel's deposits add up to a
  // complete pixel and appends them to `deposits`. REQUIRES: the pixel lies
  // in the image.
  void RunPixel(int col, int row, std::vector<Deposit>* deposits);

  // Hand-offs dropped by Run with Origin::kPeer.
  uint64_t refused() const { return refused_; }

 private:
  std::vector<Scene> slabs_;
  std::vector<Tracer> tracers_;  // tracers_[i] traces slabs_[i]
  RingLayout layout_;
  int width_;
  uint32_t pixel_limit_;
  int64_t max_calls_;  // per Run: the bound on Trace calls
  uint64_t refused_ = 0;
};

}  // namespace transtick::fuzz

#endif  // TRANSTICK_TESTS_FUZZ_FUZZ_RING_H_
